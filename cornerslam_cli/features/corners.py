"""Natural corners of one scan: paper Algorithm 2 and the corner covariance (eq 9–13).

A corner is z = (x, y, φ) in the sensor frame with a 3×3 covariance.

* **Type I** (line intersection). Every pair of segments — not only neighbours in the scan — whose closest
  end points are nearer than d_min and whose lines are at least ``min_angle`` from parallel; the
  intersection must lie within dp_max of both segments (it may extend a segment over the last missed
  beams). This is the prose of Algorithm 2; its pseudo-code (line 4 vs line 9) contradicts itself.
  Eq 9 in the form N·c = (r_i, r_j), N = [n_iᵀ; n_jᵀ]; φ = |wrap(α_i − α_j)|, the angle between the two
  lines' normals. With r >= 0 both normals point away from the sensor, so φ is the same from every pose
  that sees the same faces of the two walls (π − the angle of the wedge they make).
  Covariance (eq 11–13): C = F diag(C_li, C_lj) Fᵀ, F = ∂(x, y, φ)/∂(r_i, α_i, r_j, α_j); the two lines use
  disjoint beams, so they are independent.
* **Type II** (end point). A segment end whose next beam (in scan order, away from the segment) is valid
  and more than d_min away and off the segment's line — a measured depth jump. An end next to dropped
  beams (no return, beyond range, the field of view's edge, the robot's body) is not judged: what lies
  there is unknown. The corner is the intersection of the line
  with its normal through the end beam's point q, i.e. q projected on the line: c = q − (n·q − r) n.
  The true edge lies between the end beam and the next beam's bearing: the corner is moved to the middle of
  that gap along the line and gets gap²/12 more variance along it (uniform); ends whose gap is wider than
  ``endpoint_max_gap`` (grazing walls) are dropped.
  φ is not observable for an end point; it is set to ``endpoint_phi`` (default π/2: the line meets its
  normal, which also lets a type II sighting of a right-angled edge match the type I landmark of the same
  edge) with the prior variance ``endpoint_phi_sigma²``, uncorrelated with (x, y).
  Covariance of the projected point c: exact first order in all the segment's beams. The end beam enters
  twice, through q and through the line it helped fit, so C = A C_l Aᵀ − A J_e C_e J_eᵀ Aᵀ + G_e C_e G_eᵀ,
  with A = ∂c/∂(r, α), J_e = ∂(r, α)/∂(ρ_e, θ_e), G_e = A J_e + (I − n nᵀ) ∂q/∂(ρ_e, θ_e),
  C_e = diag(σρ_e², σθ²). The shift to the middle of the gap is not propagated (C stays c's, plus the
  gap²/12): the midpoint halves the end beam's share along the line, so the sensor part of the
  along-line variance is overstated, up to ~3.8× at normal incidence (docs/results/review_features_filter.md).
* **drop_occluded** (on by default): the end point on the farther side of a depth jump is the edge of an
  occlusion shadow that moves with the viewpoint; it is dropped when the beam next to it is nearer.
  Corners of either type lying farther behind the measured range at their bearing than
  the margin (``occlusion_margin`` + 3σρ) are hidden behind a surface and are dropped too.
* **Duplicates**: several segment pairs (and an end point) can give the same physical corner. Corners
  closer than ``duplicate_radius`` are one: type I is preferred to type II, then the smallest position
  uncertainty (trace of the 2×2 block) — the pair of lines that best represents the walls. Corners are not
  averaged: their errors are correlated through shared segments.
All covariances are symmetrised and get ``COV_FLOOR`` on the diagonal; non-finite corners are dropped.
Corners are returned in bearing order.

The loops over segment pairs, ends and corners run compiled (corner_kernels.py).
"""

from __future__ import annotations

import numpy as np

from ..types import Corners, Scan, Segments
from . import corner_kernels
from .params import CornersConfig, SensorConfig
from .sensor import kernel_model


def type_one(segs: Segments, cfg: CornersConfig):
    """Type I corners from all admissible segment pairs: (z, cov, segs (m, 2))."""
    return corner_kernels.type_one(segs.alpha, segs.r, segs.cov, segs.p1, segs.p2, cfg.d_min, cfg.min_angle,
                                   cfg.dp_max)  # fmt: skip


def spacing(scan: Scan) -> float:
    """The scan's beam spacing (its angle increment, else the median difference of its bearings)."""
    if scan.angle_increment > 0:
        return float(scan.angle_increment)
    return float(np.median(np.diff(scan.angles))) if len(scan.angles) > 1 else 0.0


def extract_corners(
    scan: Scan, segs: Segments, jac_ends: np.ndarray, sensor: SensorConfig, cfg: CornersConfig
) -> Corners:
    """Algorithm 2 on the segments of one scan (``jac_ends`` from ``lines.extract_segments``)."""
    if len(segs) == 0:
        return Corners.empty()
    rho, theta = (
        np.ascontiguousarray(scan.ranges, dtype=float),
        np.ascontiguousarray(scan.angles, dtype=float),
    )
    step, model = spacing(scan), kernel_model(sensor)
    lines = (segs.alpha, segs.r, segs.cov, segs.p1, segs.p2, segs.first, segs.last)
    ends = (cfg.d_min, cfg.min_angle, cfg.dp_max, cfg.endpoints, cfg.drop_occluded, cfg.endpoint_max_gap,
            cfg.endpoint_phi, cfg.endpoint_phi_sigma)  # fmt: skip
    z, cov, which, kind, ok = corner_kernels.candidates(
        rho, theta, scan.beam_index, lines, jac_ends, step, model, ends
    )
    if len(z) == 0:
        return Corners.empty()
    ok &= np.linalg.eigvalsh(np.where(ok[:, None, None], cov, np.eye(3))).min(axis=1) > 0
    checks = (cfg.drop_occluded, cfg.free_space_check, cfg.occlusion_margin, cfg.duplicate_radius)
    keep = corner_kernels.select(z, cov, kind, which, ok, rho, theta, step, segs.p1, segs.p2, model, checks)
    return Corners(z=z[keep], cov=cov[keep], kind=kind[keep], segs=which[keep])
