"""Config section of the scan-matching motion front end (``scan_match``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..ranges import check_ranges, num

MAX_RETRIES = 100  # headings tried on each side of the wheel guess (retry_angle / retry_step)


@dataclass(frozen=True)
class ScanMatchConfig:
    """Point-to-line ICP of each keyframe against a local map of the previous ones (motion/icp.py).

    The refined pose chain replaces the wheel odometry as the filter's motion input; its increments get
    the motion noise ``alpha1..4`` below (same model as ``ekf.alpha*``, Thrun §5.4). A match whose fit
    stays below ``min_fit`` falls back to the wheel increment with the ``ekf.alpha*`` noise.
    """

    enabled: bool = True
    window: int = num(10, ge=1, le=1000)  # scans kept in the local map
    # m: a scan joins the local map when the robot moved this far ...
    map_update_distance: float = num(0.1, ge=0.0, le=1000.0)
    # rad: ... or turned this much since the last scan that joined
    map_update_angle: float = num(0.1, ge=0.0, le=2 * math.pi)
    voxel: float = num(0.05, ge=0.0, le=10.0)  # m: local map thinned to one point per cell; 0 = off
    # m: the scan being matched thinned the same way (speed); 0 = off
    scan_voxel: float = num(0.05, ge=0.0, le=10.0)
    max_iterations: int = num(30, ge=1, le=1000)
    max_distance: float = num(1.0, gt=0.0, le=1000.0)  # m: correspondence distance at the first iteration ...
    min_distance: float = num(0.1, gt=0.0, le=1000.0)  # m: ... shrunk by half per iteration down to this
    # m: Cauchy kernel scale on the point-to-line residual
    robust_scale: float = num(0.05, ge=1e-6, le=1000.0)
    # m: a point within this of the map counts for the fit
    inlier_distance: float = num(0.1, gt=0.0, le=1000.0)
    # fit below this: retry from headings ±retry_angle around the wheel guess
    retry_fit: float = num(0.65, ge=0.0, le=1.0)
    retry_angle: float = num(0.35, ge=0.0, le=math.pi)  # rad
    retry_step: float = num(0.0873, gt=0.0, le=math.pi)  # rad between the retried headings
    # fit below this after retries: use the wheel odometry increment
    min_fit: float = num(0.3, ge=0.0, le=1.0)
    # m: weak pull towards the wheel guess (fixes corridor degeneracy)
    prior_sigma_xy: float = num(0.5, ge=1e-6, le=1000.0)
    prior_sigma_theta: float = num(0.5, ge=1e-6, le=2 * math.pi)  # rad
    # motion noise of a matched increment: R = V diag(α-model) Vᵀ + diag(σ_xy², σ_xy², σ_θ²), fitted on
    # Intel against the RBPF increments (least squares on the squared errors, which include the RBPF's
    # own): heading var ≈ 2.8e-5·Δθ² + 1.2e-5·d² + 7.6e-5, position var per axis ≈ 2e-4·(d² + Δθ²) +
    # 4e-4. Inflating the heading terms (α1 = 2e-4 was tried) lets close corners turn the filter away
    # from the matcher's heading during spins in place (docs/tuning.md)
    alpha1: float = num(0.00003, ge=0.0, le=100.0)  # rot → rot
    alpha2: float = num(0.000012, ge=0.0, le=100.0)  # trans → rot
    alpha3: float = num(0.0002, ge=0.0, le=100.0)  # trans → trans
    alpha4: float = num(0.0001, ge=0.0, le=100.0)  # rot → trans
    sigma_xy: float = num(0.01, gt=0.0, le=100.0)  # m per increment
    sigma_theta: float = num(0.005, gt=0.0, le=math.pi)  # rad per increment

    def __post_init__(self):
        check_ranges(self)
        if self.retry_angle / self.retry_step > MAX_RETRIES:
            raise ValueError(
                f"retry_angle / retry_step = {self.retry_angle / self.retry_step:.3g} headings to retry on "
                f"each side; at most {MAX_RETRIES} (raise retry_step or lower retry_angle)"
            )

    @property
    def alphas(self) -> tuple[float, float, float, float]:
        return (self.alpha1, self.alpha2, self.alpha3, self.alpha4)

    @property
    def floor(self) -> tuple[float, float]:
        return (self.sigma_xy, self.sigma_theta)
