"""Config sections of the log stage: odometry jumps (``input.odom_jump``) and keyframe selection
(``keyframes``), used by ``sync.py``; ``config.py`` assembles them into the full config."""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..ranges import check_ranges, num

TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class OdomJumpConfig:
    """Odometry jumps and resets (``logs/sync.py reanchor_odometry``).

    Between two odometry samples dt seconds apart, a move farther than ``distance`` or a turn larger
    than ``angle`` per ``period`` seconds (scaled by dt / period when dt > period) is not motion the
    robot can make: it is a jump (a reset of the odometry to zero, a relocalisation). The jump is
    not applied as motion: the odometry after it is re-anchored to continue from the pose before it,
    and the step across it adds diag(sigma_xy², sigma_xy², sigma_theta²) to the robot covariance.
    """

    distance: float = num(2.0, ge=0.0, le=1000.0)  # metres per period; 0 = no jump detection
    angle: float = num(math.pi / 2, ge=0.0, le=TWO_PI)  # radians per period
    period: float = num(0.1, gt=0.0, le=1000.0)  # seconds
    sigma_xy: float = num(0.1, ge=0.0, le=100.0)  # metres, added robot uncertainty across a jump
    sigma_theta: float = num(0.05, ge=0.0, le=TWO_PI)  # radians

    def __post_init__(self) -> None:
        check_ranges(self)


@dataclass(frozen=True)
class KeyframeConfig:
    """Process a scan only after the robot moved this much (gmapping linearUpdate/angularUpdate)."""

    linear_update: float = num(0.0, ge=0.0, le=1000.0)  # metres; 0 with angular_update 0 = every scan
    angular_update: float = num(0.0, ge=0.0, le=TWO_PI)  # radians
    max_interval: float = num(0.0, ge=0.0, le=1e6)  # seconds; 0 = no time-based keyframes

    def __post_init__(self) -> None:
        check_ranges(self)
