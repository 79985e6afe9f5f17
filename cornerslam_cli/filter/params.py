"""Config section of the EKF (NOTES §5)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal


@dataclass(frozen=True)
class EkfConfig:
    """Odometry motion noise (rot1, trans, rot2 model, variances proportional to motion) and options.

    Motion noise (Thrun's α1..α4; per keyframe, in control space):
    var(rot) = alpha1·rot² + alpha2·trans², var(trans) = alpha3·trans² + alpha4·(rot1² + rot2²),
    plus a floor diag(min_sigma_xy², min_sigma_xy², min_sigma_theta²) in the pose space.
    """

    alpha1: float = 0.05  # rot variance per rot² (rad²/rad²)
    alpha2: float = 0.01  # rot variance per trans² (rad²/m²)
    alpha3: float = 0.05  # trans variance per trans² (m²/m²)
    alpha4: float = 0.01  # trans variance per rot² (m²/rad²)
    min_sigma_xy: float = 0.002  # floor per prediction, metres
    min_sigma_theta: float = math.radians(0.1)  # floor per prediction, radians
    # metres: below, the heading of travel is undefined, so rot1 = 0 and the turn is rot2
    pure_rotation_eps: float = 1e-3
    reverse_motion: bool = True  # travel > 90° off the heading is driving backwards (trans < 0)
    init_sigma_xy: float = 0.0  # initial pose standard deviation (0: the map frame is the first pose)
    init_sigma_theta: float = 0.0
    # sequential: the paper's block update pair by pair | batched: one update with the stacked H
    update: Literal["sequential", "batched"] = "sequential"
    fuse: bool = True  # apply the rank-3 terms of one update() call in one pass over Σ (exact, faster)
    joseph: bool = False  # Joseph form (I−KH)Σ(I−KH)ᵀ + KCKᵀ, as a rank-6 block update
    symmetry_tol: float = 1e-9  # health check: max|Σ − Σᵀ| ≤ tol · max(1, max diag Σ)
    initial_capacity: int = 64  # landmarks preallocated; the buffer doubles when full
    tentative_sightings: int = 1  # sightings before a landmark is confirmed; 1 = tentative stage off
    tentative_max_age: int = 5  # keyframes a tentative landmark may go unseen before it is dropped

    def __post_init__(self) -> None:
        for name in (
            "alpha1",
            "alpha2",
            "alpha3",
            "alpha4",
            "min_sigma_xy",
            "min_sigma_theta",
            "init_sigma_xy",
            "init_sigma_theta",
            "pure_rotation_eps",
            "symmetry_tol",
        ):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v}")
        if self.update not in ("sequential", "batched"):
            raise ValueError(f"update must be 'sequential' or 'batched', got {self.update!r}")
        if self.initial_capacity < 1:
            raise ValueError(f"initial_capacity must be >= 1, got {self.initial_capacity}")
        if self.tentative_sightings < 1:
            raise ValueError(f"tentative_sightings must be >= 1, got {self.tentative_sightings}")
        if self.tentative_max_age < 0:
            raise ValueError(f"tentative_max_age must be >= 0, got {self.tentative_max_age}")

    @property
    def alphas(self) -> tuple[float, float, float, float]:
        return (self.alpha1, self.alpha2, self.alpha3, self.alpha4)
