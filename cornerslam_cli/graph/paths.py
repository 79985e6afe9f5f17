"""Where each closed submap's robot went, for finding loop-closure candidates (hierarchy.py).

A submap's path is kept thinned (one position per ``PATH_CELL``, its own frame) with a disc holding it.
Which earlier paths come within a radius of a new one, under the graph's current origins: the discs rule
out the far submaps first (one distance per submap), so the exact point-to-point distances — the cost
that grew with every submap of the log — are computed only near the new path, and are the same.
"""

from __future__ import annotations

import numpy as np

from ..geometry import transform_points
from ..motion.icp import voxel_thin

PATH_CELL = 0.5  # m: a submap's path kept for finding candidates, one position per cell
DISC_SLACK = 1e-6  # m: rounding allowance of the discs' distance bound


class Paths:
    """Each closed submap's thinned path (own frame) and the disc (centre, radius) holding it."""

    def __init__(self):
        self.paths: list[np.ndarray] = []
        self.centres: list[np.ndarray] = []
        self.radii: list[float] = []

    def add(self, positions: np.ndarray) -> None:
        """The next submap's robot positions (s, 2), its own frame."""
        path = positions[voxel_thin(positions, PATH_CELL)]
        centre = 0.5 * (path.min(axis=0) + path.max(axis=0))
        self.paths.append(path)
        self.centres.append(centre)
        self.radii.append(float(np.hypot(*(path - centre).T).max()))

    def reach(self, i: int) -> float:
        """How far submap i's path goes from its origin (m)."""
        return float(np.hypot(*self.paths[i].T).max())

    def closest(self, b: int, last: int, poses: np.ndarray, radius: float) -> np.ndarray:
        """(last + 1,) for each of submaps 0..last, the smallest distance between its path and b's with
        the origins at ``poses`` (global frame); ``inf`` for those whose disc stays beyond ``radius`` of
        b's (their paths are farther than that)."""
        centres = self._centres(poses[: last + 1], slice(0, last + 1))
        centre_b = self._centres(poses[b : b + 1], slice(b, b + 1))[0]
        gaps = np.hypot(*(centres - centre_b).T) - np.array(self.radii[: last + 1]) - self.radii[b]
        near = np.flatnonzero(gaps <= radius + DISC_SLACK)
        closest = np.full(last + 1, np.inf)
        if len(near):
            path_b = transform_points(self.paths[b], poses[b])
            owner = np.concatenate([np.full(len(self.paths[a]), a) for a in near])
            path_a = np.concatenate([transform_points(self.paths[a], poses[a]) for a in near])
            d = np.sqrt(((path_a[:, None, :] - path_b[None, :, :]) ** 2).sum(axis=2)).min(axis=1)
            np.minimum.at(closest, owner, d)
        return closest

    def _centres(self, poses: np.ndarray, which: slice) -> np.ndarray:
        """(k, 2) the discs' centres of submaps ``which`` with their origins at ``poses`` (k, 3)."""
        local = np.array(self.centres[which]).reshape(-1, 2)
        c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
        x = poses[:, 0] + c * local[:, 0] - s * local[:, 1]
        return np.column_stack((x, poses[:, 1] + s * local[:, 0] + c * local[:, 1]))
