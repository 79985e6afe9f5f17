"""What the two levels exchange: a closed submap (the local EKF's result in its own frame) and the
result of matching two submaps for a loop closure.

Frames: a submap's frame is the robot's pose at its first step (its origin). A relative pose ``a→b`` is
b's origin expressed in a's frame (x, y, θ); its covariance is of those three numbers, in a's frame —
the convention of the EKF's robot block Σ_rr when a's origin is fixed (graph/posegraph.py turns it into
GTSAM's tangent space).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry import relative, rotate_pose_covariance, transform_points


@dataclass(frozen=True)
class Submap:
    """A closed local map, in its own frame."""

    index: int
    first_step: int
    last_step: int
    landmarks: np.ndarray  # (n, 3) corners x, y, φ
    landmark_P: np.ndarray  # (3n, 3n) their joint covariance
    landmark_ids: np.ndarray  # (n,) ids in map.csv
    points: np.ndarray  # (k, 2) scan end points of its keyframes, voxel-thinned (SubmapConfig.voxel)
    end_pose: np.ndarray  # (3,) the robot at the last step: the next submap's origin
    end_cov: np.ndarray  # (3, 3) its covariance: the sequential factor of the graph
    poses: np.ndarray  # (s, 3) the robot at each of its steps (filtered, causal)


@dataclass(frozen=True)
class LoopMatch:
    """Submap b matched against an earlier submap a (graph/loops.py)."""

    pose: np.ndarray  # (3,) b's origin in a's frame
    cov: np.ndarray  # (3, 3) covariance of ``pose`` in a's frame
    n_corners: int  # corners in the jointly compatible set
    fitness: float  # share of b's points overlapping a that lie within inlier_distance of a's points
    accepted: bool
    reason: str = ""  # why not accepted ("" when accepted)
    pairs: np.ndarray | None = None  # (k, 2) matched corners: rows of b.landmarks, rows of a.landmarks


def overlap_steps(a: Submap, b: Submap, pose: np.ndarray) -> tuple[int, int]:
    """Where two submaps overlap under ``pose`` (b's origin in a's frame): the indices into ``a.poses``
    and ``b.poses`` of their closest pair of robot positions."""
    pb = transform_points(b.poses[:, :2], pose)
    d2 = ((a.poses[:, None, :2] - pb[None, :, :]) ** 2).sum(axis=-1)
    i, j = np.unravel_index(int(np.argmin(d2)), d2.shape)
    return int(i), int(j)


def keyframe_factors(
    poses: np.ndarray, covs: np.ndarray, end_cov: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A closed submap as the pose graph's chain of keyframe factors: each step's pose relative to the
    one before (the first relative to the origin) and its motion noise ``covs`` (s, 3, 3), scaled so the
    chain is as sure of the last pose as the filter was (``end_cov``: its corners narrowed what the
    motion noise alone would say; the volumes, det^(1/3), matched). Returns (rel (s, 3), cov (s, 3, 3))."""
    prev = np.vstack((np.zeros(3), poses[:-1]))
    acc = np.zeros((3, 3))
    for p0, p1, c in zip(prev, poses, covs, strict=True):
        G = np.eye(3)
        G[:2, 2] = (p0[1] - p1[1], p1[0] - p0[0])  # ∂(p0 ∘ rel)/∂p0
        acc = G @ acc @ G.T + rotate_pose_covariance(c, p0[2])
    scale = 1.0
    if np.linalg.det(acc) > 0 and np.linalg.det(end_cov) > 0:
        scale = float(np.cbrt(np.linalg.det(end_cov) / np.linalg.det(acc)))
    return relative(prev, poses), np.asarray(covs) * scale
