"""Config section of the scan-matching motion front end (``scan_match``)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ScanMatchConfig:
    """Point-to-line ICP of each keyframe against a local map of the previous ones (motion/icp.py).

    The refined pose chain replaces the wheel odometry as the filter's motion input; its increments get
    the motion noise ``alpha1..4`` below (same model as ``ekf.alpha*``, Thrun §5.4). A match whose fit
    stays below ``min_fit`` falls back to the wheel increment with the ``ekf.alpha*`` noise.
    """

    enabled: bool = True
    window: int = 10  # scans kept in the local map
    map_update_distance: float = 0.1  # m: a scan joins the local map when the robot moved this far ...
    map_update_angle: float = 0.1  # rad: ... or turned this much since the last scan that joined
    voxel: float = 0.05  # m: local map thinned to one point per cell; 0 = off
    scan_voxel: float = 0.05  # m: the scan being matched thinned the same way (speed); 0 = off
    max_iterations: int = 30
    max_distance: float = 1.0  # m: correspondence distance at the first iteration ...
    min_distance: float = 0.1  # m: ... shrunk by half per iteration down to this
    robust_scale: float = 0.05  # m: Cauchy kernel scale on the point-to-line residual
    inlier_distance: float = 0.1  # m: a point within this of the map counts for the fit
    retry_fit: float = 0.65  # fit below this: retry from headings ±retry_angle around the wheel guess
    retry_angle: float = 0.35  # rad
    retry_step: float = 0.0873  # rad between the retried headings
    min_fit: float = 0.3  # fit below this after retries: use the wheel odometry increment
    prior_sigma_xy: float = 0.5  # m: weak pull towards the wheel guess (fixes corridor degeneracy)
    prior_sigma_theta: float = 0.5  # rad
    # motion noise of a matched increment: R = V diag(α-model) Vᵀ + diag(σ_xy², σ_xy², σ_θ²), fitted on
    # Intel against the RBPF increments (least squares on the squared errors, which include the RBPF's
    # own): heading var ≈ 2.8e-5·Δθ² + 1.2e-5·d² + 7.6e-5, position var per axis ≈ 2e-4·(d² + Δθ²) +
    # 4e-4. Inflating the heading terms (α1 = 2e-4 was tried) lets close corners turn the filter away
    # from the matcher's heading during spins in place (docs/tuning.md)
    alpha1: float = 0.00003  # rot → rot
    alpha2: float = 0.000012  # trans → rot
    alpha3: float = 0.0002  # trans → trans
    alpha4: float = 0.0001  # rot → trans
    sigma_xy: float = 0.01  # m per increment
    sigma_theta: float = 0.005  # rad per increment

    def __post_init__(self):
        if self.window < 1 or self.max_iterations < 1:
            raise ValueError("scan_match.window and scan_match.max_iterations must be >= 1")
        positive = ("max_distance", "min_distance", "robust_scale", "inlier_distance", "prior_sigma_xy")
        for name in (*positive, "prior_sigma_theta", "retry_step", "sigma_xy", "sigma_theta"):
            if not getattr(self, name) > 0:
                raise ValueError(f"scan_match.{name} must be > 0, got {getattr(self, name)}")
        for name in ("map_update_distance", "map_update_angle", "voxel", "scan_voxel", "retry_angle"):
            if getattr(self, name) < 0:
                raise ValueError(f"scan_match.{name} must be >= 0, got {getattr(self, name)}")
        for name in ("retry_fit", "min_fit"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"scan_match.{name} must be in [0, 1], got {getattr(self, name)}")
        if min(self.alphas) < 0:
            raise ValueError("scan_match.alpha1..4 must be >= 0")

    @property
    def alphas(self) -> tuple[float, float, float, float]:
        return (self.alpha1, self.alpha2, self.alpha3, self.alpha4)

    @property
    def floor(self) -> tuple[float, float]:
        return (self.sigma_xy, self.sigma_theta)
