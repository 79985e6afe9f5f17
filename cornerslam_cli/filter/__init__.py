"""EKF-SLAM over natural corners (NOTES §5): pure models and the filter that owns the state."""

from .ekf import Ekf
from .models import (
    OdometryIncrement,
    inverse_observe,
    motion_model,
    motion_noise,
    observe,
    odometry_increment,
)
from .params import EkfConfig

__all__ = [
    "Ekf",
    "EkfConfig",
    "OdometryIncrement",
    "inverse_observe",
    "motion_model",
    "motion_noise",
    "observe",
    "odometry_increment",
]
