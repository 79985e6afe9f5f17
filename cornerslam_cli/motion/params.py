"""Config section of the scan-matching motion front end (``scan_match``)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

from ..ranges import check_ranges, num


@dataclass(frozen=True)
class ScanMatchConfig:
    """Scan matching fused with the odometry (motion/icp.py, correlative.py, fusion.py).

    Each keyframe is matched against a local map of the previous ones — a correlative search over a
    window sized from the odometry's noise model (``ekf.alpha*``) when that window is wider than ICP's
    basin, then point-to-line ICP — and the match is fused with the odometry increment by their
    covariances; the fused pose chain is the filter's motion input. A match whose fit stays below
    ``min_fit``, or which disagrees with the odometry beyond ``gate``, leaves the odometry increment alone.
    """

    # keys of earlier versions, accepted with a warning and ignored (config.py)
    RETIRED: ClassVar[dict[str, str]] = {
        **dict.fromkeys(
            ("retry_fit", "retry_angle", "retry_step"),
            "the correlative search over the odometry's uncertainty window replaced the heading retries",
        ),
        **dict.fromkeys(
            ("alpha1", "alpha2", "alpha3", "alpha4"),
            "each match now brings its own covariance, fused with the odometry's (ekf.alpha*)",
        ),
    }

    enabled: bool = True
    window: int = num(10, ge=1, le=1000)  # scans kept in the local map
    # --- near scans (issue 15): map scans that left the window, the last near_history of them kept (0 =
    # off: the last window scans alone), join the local map when their pose lies within near_radius of the
    # robot's and their heading within near_angle of its heading (π: any heading, a corridor driven back
    # the other way too); of more, the near_max nearest
    near_history: int = num(100, ge=0, le=5000)  # (≤ 5000: each kept scan holds its thinned points)
    near_radius: float = num(2.0, ge=0.0, le=1000.0)  # m
    near_angle: float = num(math.pi, ge=0.0, le=math.pi)  # rad
    near_max: int = num(5, ge=1, le=1000)  # (5 on the panel: better than 10, variant_*.md)
    # ... and (> 0) only a scan of which this share of points lies within inlier_distance of the window's
    near_min_fit: float = num(0.0, ge=0.0, le=1.0)
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
    # fit below this: use the odometry increment alone
    min_fit: float = num(0.3, ge=0.0, le=1.0)
    # m: weak pull of ICP towards the odometry's guess (keeps a featureless corridor well-posed along
    # its axis)
    prior_sigma_xy: float = num(0.5, ge=1e-6, le=1000.0)
    prior_sigma_theta: float = num(0.5, ge=1e-6, le=2 * math.pi)  # rad
    # --- match covariance: (JᵀWJ / (σ̂²·cov_inflation) + prior)⁻¹, σ̂ the residuals' own spread
    # at least this inflation of the fit covariance: 5-point map normals have errors of their own that the
    # residuals do not show (1.5: NEES consistent in the ray-cast office, tests/test_fusion.py; real logs
    # learn their own scale on top, motion/fusion.py)
    cov_inflation: float = num(1.5, ge=1.0, le=1e6)
    min_residual_sigma: float = num(0.005, gt=0.0, le=10.0)  # m: floor of σ̂ (a perfect fit is not exact)
    # --- correlative search (Olson 2009) over ±search_sigmas σ of the odometry model, when wider than
    # ICP's basin (search_min_*), at most search_max_*
    search_sigmas: float = num(3.0, gt=0.0, le=100.0)
    search_min_xy: float = num(0.1, ge=0.0, le=100.0)  # m
    search_min_theta: float = num(0.05, ge=0.0, le=math.pi)  # rad
    # m: at most 5 (the search's memory and time grow with the window's area in grid cells)
    search_max_xy: float = num(1.0, gt=0.0, le=5.0)
    search_max_theta: float = num(0.6, gt=0.0, le=math.pi)  # rad
    search_resolution: float = num(0.1, ge=0.01, le=10.0)  # m: grid cell of the likelihood field
    search_sigma: float = num(0.1, gt=0.0, le=10.0)  # m: its blur exp(−d²/2σ²)
    # m: only scan points this close to the robot are searched with (the grid's area, so its cost, grows
    # with the square of it); ICP then refines with all of them
    search_range: float = num(20.0, gt=0.0, le=1000.0)
    # --- fusion with the odometry (motion/fusion.py)
    # χ²₃ of a match's disagreement with the odometry beyond which it is rejected: 30.7 = a 10⁻⁶ tail,
    # "far beyond" — real odometry errors are heavy-tailed (17° in one 30° turn on Intel)
    gate: float = num(30.7, gt=0.0, le=1e9)
    # keyframes whose disagreements set the noise scales and bias: one robot's odometry noise is
    # stationary, so a long window (400 = 100 until then); at 100 a stretch of poor matches (little
    # overlap in turns) raised the learnt odometry noise of an exact odometry for its length
    adapt_window: int = num(400, ge=1, le=100000)
    # keyframes matched once to learn the scales before the run (0 = off: learnt as the run goes). Off by
    # default: over the whole panel it did not pay — the first matches judged with learnt scales changed
    # which marginal ones were kept, for better or worse per log (docs/results/frontend_panel.md; again at
    # 20 on 2026-12-02, variant_scan_match.warmup-20.md: 8 logs better, 5 worse beyond their spread, fhw-exact
    # 0.007 → 0.261 m and edmonton 0.379 → 0.173; over the whole log, 10000, on 2026-12-04,
    # variant_scan_match.warmup-10000.md: 3 better, 8 worse — edmonton 0.352 → 0.226, its drift taken
    # out from step 1 instead of step 124, but csail-exact 0.080 → 0.260)
    warmup: int = num(0, ge=0, le=10000)
    adapt_every: int = num(25, ge=1, le=100000)  # keyframes between two re-estimates
    adapt_min_samples: int = num(5, ge=2, le=100000)  # ... the model itself (scale 1) until this many
    # error of a match that its fit cannot see, added to the fused increment's covariance with the weight
    # the match got (K·F·Kᵀ): the local map drifts with the chain it is matched against, so match errors
    # are correlated from one keyframe to the next and the corners need room to correct them; an exact
    # odometry, which the fusion hardly corrects, stays exact in the filter. Default 0: measured on the
    # panel, no floor serves the exact-odometry logs best and the noisy ones no worse
    # (docs/results/frontend_panel.md); 0.01 / 0.005 lets the corners correct the simulated lap more
    sigma_xy: float = num(0.0, ge=0.0, le=100.0)  # m per match
    sigma_theta: float = num(0.0, ge=0.0, le=math.pi)  # rad per match
    adapt_min: float = num(1e-6, gt=0.0, le=1.0)  # bounds of the learnt odometry noise scale
    adapt_max: float = num(100.0, ge=1.0, le=1e6)

    def __post_init__(self):
        check_ranges(self)
        if self.adapt_min_samples > self.adapt_window:
            raise ValueError(
                f"adapt_min_samples = {self.adapt_min_samples} exceeds adapt_window = {self.adapt_window} "
                "(the window must hold the samples)"
            )
