"""Config section of the EKF (NOTES §5)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from ..ranges import check_ranges, num

TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class EkfConfig:
    """Odometry motion noise (rot1, trans, rot2 model, variances proportional to motion) and options.

    Motion noise (Thrun's α1..α4; per keyframe, in control space):
    var(rot) = alpha1·rot² + alpha2·trans², var(trans) = alpha3·trans² + alpha4·(rot1² + rot2²),
    plus a floor diag(min_sigma_xy², min_sigma_xy², min_sigma_theta²) in the pose space.
    """

    alpha1: float = num(0.05, ge=0.0, le=100.0)  # rot variance per rot² (rad²/rad²)
    alpha2: float = num(0.01, ge=0.0, le=100.0)  # rot variance per trans² (rad²/m²)
    alpha3: float = num(0.05, ge=0.0, le=100.0)  # trans variance per trans² (m²/m²)
    alpha4: float = num(0.01, ge=0.0, le=100.0)  # trans variance per rot² (m²/rad²)
    min_sigma_xy: float = num(0.002, ge=0.0, le=100.0)  # floor per prediction, metres
    min_sigma_theta: float = num(math.radians(0.1), ge=0.0, le=math.pi)  # floor per prediction, radians
    # metres: below, the heading of travel is undefined, so rot1 = 0 and the turn is rot2
    pure_rotation_eps: float = num(1e-3, ge=0.0, le=1000.0)
    reverse_motion: bool = True  # travel > 90° off the heading is driving backwards (trans < 0)
    # initial pose standard deviation (0: the map frame is the first pose)
    init_sigma_xy: float = num(0.0, ge=0.0, le=1000.0)
    init_sigma_theta: float = num(0.0, ge=0.0, le=TWO_PI)
    # sequential: the paper's block update pair by pair | batched: one update with the stacked H
    update: Literal["sequential", "batched"] = "sequential"
    fuse: bool = True  # apply the rank-3 terms of one update() call in one pass over Σ (exact, faster)
    joseph: bool = False  # Joseph form (I−KH)Σ(I−KH)ᵀ + KCKᵀ, as a rank-6 block update
    # health check: max|Σ − Σᵀ| ≤ tol · max(1, max diag Σ)
    symmetry_tol: float = num(1e-9, ge=0.0, le=1.0)
    # landmarks preallocated (Σ holds (3 + 3n)² floats: 72 MB at the 1,000 allowed); doubles when full
    initial_capacity: int = num(64, ge=1, le=1000)
    # sightings before a landmark is confirmed; 1 = tentative stage off
    tentative_sightings: int = num(1, ge=1, le=1000)
    # keyframes a tentative landmark may go unseen before it is dropped
    tentative_max_age: int = num(5, ge=0, le=1_000_000)

    def __post_init__(self) -> None:
        check_ranges(self)
        if self.update not in ("sequential", "batched"):
            raise ValueError(f"update must be 'sequential' or 'batched', got {self.update!r}")

    @property
    def alphas(self) -> tuple[float, float, float, float]:
        return (self.alpha1, self.alpha2, self.alpha3, self.alpha4)
