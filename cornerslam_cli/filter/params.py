"""Config section of the EKF (NOTES §5)."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class EkfConfig:
    """Odometry motion noise (rot1, trans, rot2 model, variances proportional to motion) and options."""

    alpha1: float = 0.05  # rot noise from rotation
    alpha2: float = 0.01  # rot noise from translation (rad²/m²)
    alpha3: float = 0.05  # trans noise from translation
    alpha4: float = 0.01  # trans noise from rotation
    min_sigma_xy: float = 0.002  # floor per step, metres
    min_sigma_theta: float = math.radians(0.1)  # floor per step
    init_sigma_xy: float = 0.0
    init_sigma_theta: float = 0.0
    update: str = "sequential"  # sequential (paper block update per pair) | batched
    joseph: bool = False
    tentative_sightings: int = 1  # 1 = landmarks are created at once
