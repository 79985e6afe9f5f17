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
