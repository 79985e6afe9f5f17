"""EKF-SLAM over natural corners (NOTES §5): pure models and the filter that owns the state."""

import numpy as np

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
    "load_kernels",
    "OdometryIncrement",
    "inverse_observe",
    "motion_model",
    "motion_noise",
    "observe",
    "odometry_increment",
]


def load_kernels() -> None:
    """Load (on a machine's first run: compile) the compiled update (kernels.py) now, so that the first
    timed update of a run does not pay it: one update of a one-landmark state, with Σ a view of a larger
    buffer (spare capacity) and a whole one (full capacity)."""
    for capacity in (2, 1):
        ekf = Ekf.from_state(
            EkfConfig(initial_capacity=capacity), np.array([0, 0, 0, 1.0, 1.0, 1.0]), np.eye(6)
        )
        ekf.update([0], [[1.0, 1.0, 1.0]], np.eye(3)[None])
