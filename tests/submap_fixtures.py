"""Closed submaps built from the simulated worlds, for the loop-closing tests (not a conftest: plain imports).

A submap is what the local EKF would hand over, built here without the filter from scans taken at
*known* poses: each scan ray-cast in a world (simworld.py) with a precise sensor's noise, its corners
extracted by the real extractor (features/), moved into the submap's frame (the first pose), and
grouped into landmarks by proximity (same place within ``MERGE_DISTANCE``, same φ within
``MERGE_PHI``). A landmark is the mean of its sightings, its covariance the mean of theirs (sightings of
one corner from nearby poses share their errors, so averaging does not shrink it); the joint P is
block-diagonal. Corners seen only once are dropped (a filter would not confirm them). The scans' end
points, in the submap frame, are thinned to one per ``SubmapConfig().voxel`` cell.

``identical_rooms_world`` builds the perceptual-aliasing world: a row of identical furnished rooms off
one corridor, so a submap of one room matches a submap of another exactly.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from cornerslam_cli import simworld as sw
from cornerslam_cli.features import CornersConfig, LinesConfig, SensorConfig, extract
from cornerslam_cli.geometry import relative, rotate_pose_covariance, transform_points, wrap_angle
from cornerslam_cli.graph.params import SubmapConfig
from cornerslam_cli.graph.submap import Submap
from cornerslam_cli.motion.icp import voxel_thin

#: a 1,081-beam 270° Hokuyo
HOKUYO = np.linspace(-3 * np.pi / 4, 3 * np.pi / 4, 1081)
#: a precise sensor's noise model (about a UTM-30LX): σρ = 1 cm, σθ = 0.05°
PRECISE = SensorConfig(model="linear", a=0.01, b=0.0, sigma_theta=math.radians(0.05))
MAX_RANGE = 10.0  # m
MERGE_DISTANCE = 0.25  # m: a corner this close to a landmark (submap frame) is another sighting of it
MERGE_PHI = 0.3  # rad: ... if its φ agrees this well
MIN_SIGHTINGS = 2

# one furnished room of identical_rooms_world, in room coordinates: (cx, cy, w, h, angle) of its boxes
ROOM_W, ROOM_H, ROOM_GAP, CORRIDOR = 6.0, 5.0, 0.2, 2.0
ROOM_FURNITURE = (
    (1.5, 1.2, 1.0, 0.6, 0.0),
    (4.2, 3.3, 0.8, 0.8, math.radians(30.0)),
    (4.8, 1.0, 0.4, 0.4, 0.0),
)


def build_submap(
    world: sw.World, poses: np.ndarray, index: int = 0, seed: int = 0, first_id: int = 0
) -> Submap:
    """The submap of scans taken at ``poses`` (s, 3) in ``world`` (module docstring), in poses[0]'s frame."""
    rng = np.random.default_rng(seed)
    origin = np.asarray(poses[0], dtype=float)
    local = relative(origin, np.asarray(poses, dtype=float))  # each pose in the submap's frame
    z, C, points = [], [], []
    for pose, rel in zip(poses, local, strict=True):
        scan = sw.simulate_scan(world, pose, HOKUYO, MAX_RANGE, sigma_range=0.01, rng=rng)
        _, corners = extract(scan, PRECISE, LinesConfig(), CornersConfig())
        z.append(np.column_stack((transform_points(corners.z[:, :2], rel), corners.z[:, 2])))
        C.extend(rotate_pose_covariance(c, float(rel[2])) for c in corners.cov)
        points.append(transform_points(scan.points(), rel))
    landmarks, landmark_P = merge_sightings(np.concatenate(z), np.asarray(C).reshape(-1, 3, 3))
    pts = np.concatenate(points)
    n = len(landmarks)
    return Submap(
        index=index,
        first_step=0,
        last_step=len(poses) - 1,
        landmarks=landmarks,
        landmark_P=landmark_P,
        landmark_ids=np.arange(first_id, first_id + n, dtype=np.int64),
        points=pts[voxel_thin(pts, SubmapConfig().voxel)],
        end_pose=local[-1],
        end_cov=np.diag([1e-4, 1e-4, 1e-5]),
        poses=local,
    )


def merge_sightings(z: np.ndarray, C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Landmarks (n, 3) and their block-diagonal joint covariance (3n, 3n) from corner sightings z (m, 3),
    C (m, 3, 3) in one frame: greedy grouping, mean of each group, mean of its covariances."""
    groups: list[list[int]] = []
    means: list[np.ndarray] = []
    for s in range(len(z)):
        for g, mean in enumerate(means):
            if (
                np.hypot(*(z[s, :2] - mean[:2])) < MERGE_DISTANCE
                and abs(wrap_angle(z[s, 2] - mean[2])) < MERGE_PHI
            ):
                groups[g].append(s)
                means[g] = z[groups[g]].mean(axis=0)
                break
        else:
            groups.append([s])
            means.append(z[s].copy())
    kept = [g for g in groups if len(g) >= MIN_SIGHTINGS]
    landmarks = np.array([z[g].mean(axis=0) for g in kept]).reshape(-1, 3)
    P = np.zeros((3 * len(kept), 3 * len(kept)))
    for k, g in enumerate(kept):
        P[3 * k : 3 * k + 3, 3 * k : 3 * k + 3] = C[g].mean(axis=0)
    return landmarks, P


def corners_submap(landmarks: np.ndarray, sigma_xy: float = 0.01, sigma_phi: float = 0.03) -> Submap:
    """A submap of the given corners (n, 3) alone (no points), each with covariance
    diag(σ_xy², σ_xy², σ_φ²); the joint P block-diagonal."""
    landmarks = np.asarray(landmarks, dtype=float).reshape(-1, 3)
    n = len(landmarks)
    P = np.kron(np.eye(n), np.diag([sigma_xy**2, sigma_xy**2, sigma_phi**2]))
    return Submap(
        0, 0, 0, landmarks, P, np.arange(n, dtype=np.int64), np.zeros((0, 2)), np.zeros(3), np.zeros((3, 3)),
        np.zeros((1, 3)),
    )  # fmt: skip


def empty_submap() -> Submap:
    """A submap with no landmarks and no points (a robot that saw nothing)."""
    return corners_submap(np.zeros((0, 3)))


def straight_path(start: Sequence[float], end: Sequence[float], step: float = 0.25) -> np.ndarray:
    """Poses (k, 3) every ``step`` metres from ``start`` to ``end`` (x, y), heading along the line."""
    return sw.path_poses(np.array([start, end], dtype=float), step, closed=False)


def spin(x: float, y: float, headings: Sequence[float]) -> np.ndarray:
    """Poses (k, 3) at one place turning through ``headings`` (rad)."""
    return np.array([(x, y, h) for h in headings], dtype=float)


def identical_rooms_world(n: int = 4) -> sw.World:
    """``n`` identical furnished rooms side by side (``ROOM_W`` × ``ROOM_H``, walls ``ROOM_GAP`` thick),
    each with a door to one corridor along their north side: perceptual aliasing."""
    walls = []
    for r in range(n):
        x0 = r * (ROOM_W + ROOM_GAP)
        walls.append(sw.room(x0, 0.0, x0 + ROOM_W, ROOM_H, doors={"N": [(ROOM_W / 2, 1.0)]}))
        walls += [sw.rectangle(x0 + cx, cy, w, h, ang) for cx, cy, w, h, ang in ROOM_FURNITURE]
    length = n * (ROOM_W + ROOM_GAP)
    # the corridor's south wall (the rooms' north walls) with the same door gaps, measured from x = -1
    doors = [(room_door(r)[0] + 1.0, 1.0) for r in range(n)]
    walls.append(sw.room(-1.0, ROOM_H, length + 1.0, ROOM_H + CORRIDOR, doors={"S": doors}))
    return sw.make_world(walls, "identical_rooms")


def room_origin(r: int) -> np.ndarray:
    """(x, y) of room ``r``'s south-west corner in ``identical_rooms_world``."""
    return np.array([r * (ROOM_W + ROOM_GAP), 0.0])


def room_door(r: int) -> np.ndarray:
    """(x, y) of the middle of room ``r``'s door into the corridor in ``identical_rooms_world``."""
    return room_origin(r) + (ROOM_W / 2, ROOM_H)


def symmetric_room_world() -> sw.World:
    """A bare 6 × 4 m rectangle, centred on (3, 2): seen from its centre it looks the same turned by π."""
    return sw.make_world([sw.room(0.0, 0.0, 6.0, 4.0)], "symmetric_room")
