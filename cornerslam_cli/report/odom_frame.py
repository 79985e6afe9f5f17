"""A run's outputs in the log's odometry frame.

The filter works in its map frame, the base at the first scan (the EKF starts at zero). The outputs
are written in the odometry frame of the log, where that map frame is the first odometry pose,
``map2odom``: poses are composed with it, points moved by it, position covariances turned by its
yaw (R Σ Rᵀ); a corner's φ, an angle between two lines, and headings' variances do not change.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ..geometry import compose, rotate_covariance, transform_points

if TYPE_CHECKING:
    from ..slam import StepRecord


def in_odom_frame(r: StepRecord, map2odom: np.ndarray) -> StepRecord:
    """The step's record with its pose, pose variances and segments moved from the filter's map frame
    into the odometry frame by ``map2odom`` (the first odometry pose). A map frame that is the
    odometry frame (odometry starting at zero) leaves the record exactly as the filter gave it."""
    if not np.any(map2odom):
        return r
    cov = np.array([[[r.pose_var[0], r.cov_xy], [r.cov_xy, r.pose_var[1]]]])
    cov = rotate_covariance(cov, float(map2odom[2]))[0]
    return replace(
        r,
        pose=compose(map2odom, r.pose),
        pose_var=np.array([cov[0, 0], cov[1, 1], r.pose_var[2]]),
        cov_xy=float(cov[0, 1]),
        segments_map=transform_points(r.segments_map.reshape(-1, 2), map2odom).reshape(-1, 4),
    )


def landmarks_in_odom_frame(landmarks: dict[str, np.ndarray], map2odom: np.ndarray) -> dict[str, np.ndarray]:
    """map.csv's columns moved like :func:`in_odom_frame`: positions and their covariances (φ, an
    angle between two lines, does not depend on the frame)."""
    if not np.any(map2odom) or len(landmarks["id"]) == 0:
        return landmarks
    cov = np.stack(
        (landmarks["var_x"], landmarks["cov_xy"], landmarks["cov_xy"], landmarks["var_y"]), axis=-1
    )
    cov = rotate_covariance(cov.reshape(-1, 2, 2), float(map2odom[2]))
    xy = transform_points(np.column_stack((landmarks["x"], landmarks["y"])), map2odom)
    moved = {
        "x": xy[:, 0],
        "y": xy[:, 1],
        "var_x": cov[:, 0, 0],
        "var_y": cov[:, 1, 1],
        "cov_xy": cov[:, 0, 1],
    }
    return {**landmarks, **moved}
