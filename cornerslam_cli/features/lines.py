"""Line segments of one scan: paper Algorithm 1 (split and merge) and the line fit with covariance (eq 2–8).

Pipeline, on the valid beams of a scan in bearing order (a *range* is a run of consecutive beams); steps
1–6 run compiled (``segment_kernels.py``, Numba) and are written here in numpy as their reference:

1. breakpoint split  — gap between neighbours > adaptive d_max(ρ, Δφ) (Borges & Aldon 2004)
2. angle split       — angle between the chords (p_i−k, p_i) and (p_i, p_i+k) > a_max, at the sharpest point
                       of each run above a_max; k is chosen per beam so a chord is ``angle_split_chord`` long
                       (the paper's single-beam chords only measure noise on a 0.25° scan)
3. distance split    — split-and-merge: while a range's fitted line leaves a point farther than l_max, split
                       at the point farthest from the chord of its end points
4. merge             — adjacent ranges (gap < d_mergeMax, angle < a_mergeMax) whose merged line stays within
                       l_max of both ranges' end vertices become one
5. boundary refine   — a beam at the border of two touching ranges goes to the line it is closer to
6. end trim          — a first/last beam more than 4 RMS residuals off its range's line is split off
7. filters           — at least ``min_points`` beams and ``min_length`` metres

Fit (eq 2–4): weighted total least squares, x·cos α + y·sin α = r with r >= 0, α in (−π, π].  The
Cartesian form used here (centroid and weighted scatter matrix, α = ½·atan2(−2Sxy, Syy − Sxx)) is the same
minimiser as the paper's polar eq 3.  Weights w_i = 1 / (σρ_i² + ρ_i²σθ²), the isotropic variance of the
beam's point (the paper's w_i = 1/σθ² + 1/σρ² mixes units); they are held fixed in the covariance.

The weights treat each point's noise as isotropic, but range noise lies along the beam: E[scatter] gains
Σ w_i Cov(p_i), whose across/along-line term (σρ² − ρ²σθ²)·sin·cos(incidence) tilts the line at oblique
incidence. r and α come out biased by ~0.3–0.6 σ with the URG-04LX preset and up to ~1.5 σ with the
paper's 3 %-of-range model at 45–70° (docs/results/review_features_filter.md §1; not corrected here).

Covariance (eq 5–8): C_l = J_ρ C_ρ J_ρᵀ + J_θ C_θ J_θᵀ with the full first-order Jacobian, including the
dependence of r on α through the centroid that the paper's eq 7 drops:
    ∂α/∂p_i = −w_i (u_i n + e_i d) / (S_dd − S_nn),   ∂r/∂p_i = (w_i / W) n + (p̄·d) ∂α/∂p_i
n = (cos α, sin α), d = (−sin α, cos α), e_i, u_i the residual and along-line coordinate of p_i − p̄,
S_nn, S_dd = Σ w e², Σ w u² (the scatter matrix's eigenvalues); then ∂p_i/∂ρ_i, ∂p_i/∂θ_i.

Over 400 lines because Algorithm 1 is one pipeline: the steps above share the vectorised range
bookkeeping (``starts``/``ends``) and the weighted fit, and read best in order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..types import Scan, Segments
from . import fit_kernels, segment_kernels
from .params import LinesConfig, SensorConfig
from .sensor import COV_FLOOR, beam_variances, kernel_model


@dataclass(frozen=True)
class LineFits:
    """Weighted TLS lines of the ranges [starts, ends) of one scan, with covariance.

    r, alpha : (k,) Hessian normal form, r >= 0;  cov : (k, 2, 2) covariance of (r, α)
    p1, p2 : (k, 2) first / last point projected on the line
    jac_ends : (k, 2, 2, 2) ∂(r, α)/∂(ρ, θ) of the first [:, 0] and last [:, 1] beam (type II corners need
        the correlation between a line and its own end beam)
    ok : (k,) the fit is finite and well conditioned (points not all at one spot)
    """

    r: np.ndarray
    alpha: np.ndarray
    cov: np.ndarray
    p1: np.ndarray
    p2: np.ndarray
    jac_ends: np.ndarray
    ok: np.ndarray


def beam_weights(rho: np.ndarray, var_rho: np.ndarray, var_theta: np.ndarray) -> np.ndarray:
    """w_i = 1 / (σρ² + ρ²σθ²), the inverse isotropic variance of each beam's point (eq 2)."""
    return 1.0 / (var_rho + rho**2 * var_theta + COV_FLOOR)


def _moments(x, y, w, starts, ends):
    """Weighted centroid and central scatter (two-pass) of each non-empty range [starts, ends)."""
    cnt = ends - starts
    seg = np.repeat(np.arange(len(starts)), cnt)
    W = np.add.reduceat(w, starts)
    mx = np.add.reduceat(w * x, starts) / W
    my = np.add.reduceat(w * y, starts) / W
    dx, dy = x - mx[seg], y - my[seg]
    sxx = np.add.reduceat(w * dx * dx, starts)
    syy = np.add.reduceat(w * dy * dy, starts)
    sxy = np.add.reduceat(w * dx * dy, starts)
    return seg, W, mx, my, sxx, syy, sxy


def _line_from_moments(mx, my, sxx, syy, sxy):
    """Eq 3–4: the direction of least scatter, r >= 0, α in (−π, π]. Works on arrays and on floats."""
    alpha = 0.5 * np.arctan2(-2.0 * sxy, syy - sxx)
    r = mx * np.cos(alpha) + my * np.sin(alpha)
    flip = r < 0
    r = np.where(flip, -r, r)
    alpha = np.where(flip, alpha + np.pi, alpha)
    alpha = np.where(alpha > np.pi, alpha - 2.0 * np.pi, alpha)
    return r, alpha


def fit_lines(rho, theta, var_rho, var_theta, starts, ends, w=None) -> LineFits:
    """Fit one line per range [starts, ends) of beams (ρ, θ) with per-beam variances (eq 2–8).

    ``w`` overrides the weights (default ``beam_weights``), e.g. to hold them fixed in a derivative check.
    """
    starts = np.asarray(starts, dtype=np.int64)
    ends = np.asarray(ends, dtype=np.int64)
    k = len(starts)
    if k == 0:
        z = np.zeros(0)
        return LineFits(
            z, z, np.zeros((0, 2, 2)), np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2, 2, 2)), z > 0
        )
    # gather the beams of the ranges (they may skip beams between ranges)
    cnt = ends - starts
    offs = np.cumsum(cnt) - cnt
    idx = np.arange(cnt.sum()) - np.repeat(offs - starts, cnt)
    rho, theta, var_rho = rho[idx], theta[idx], var_rho[idx]
    var_theta = np.broadcast_to(var_theta, idx.shape) if np.ndim(var_theta) == 0 else var_theta[idx]
    cos_t, sin_t = np.cos(theta), np.sin(theta)
    x, y = rho * cos_t, rho * sin_t
    w = beam_weights(rho, var_rho, var_theta) if w is None else np.asarray(w, dtype=float)[idx]
    seg, W, mx, my, sxx, syy, sxy = _moments(x, y, w, offs, offs + cnt)
    r, alpha = _line_from_moments(mx, my, sxx, syy, sxy)
    c, s = np.cos(alpha), np.sin(alpha)
    # eigenvalues of the scatter matrix: S_nn across the line, S_dd along it
    half_tr = 0.5 * (sxx + syy)
    rad = np.hypot(0.5 * (sxx - syy), sxy)
    den = 2.0 * rad  # S_dd − S_nn
    ok = np.isfinite(r) & np.isfinite(alpha) & (den > 1e-9 * np.maximum(half_tr, 1e-300)) & (cnt >= 2)
    den = np.where(ok, den, 1.0)

    cs, ss = c[seg], s[seg]
    dx, dy = x - mx[seg], y - my[seg]
    e = dx * cs + dy * ss  # residual across the line
    u = -dx * ss + dy * cs  # coordinate along the line
    # ∂α/∂p_i and ∂r/∂p_i (module docstring)
    ga_x = -w * (u * cs - e * ss) / den[seg]
    ga_y = -w * (u * ss + e * cs) / den[seg]
    pd = (-mx * s + my * c)[seg]  # p̄·d
    wn = w / W[seg]
    gr_x = wn * cs + pd * ga_x
    gr_y = wn * ss + pd * ga_y
    # chain rule through p_i = ρ_i (cos θ_i, sin θ_i)
    dr_drho = gr_x * cos_t + gr_y * sin_t
    da_drho = ga_x * cos_t + ga_y * sin_t
    dr_dth = rho * (-gr_x * sin_t + gr_y * cos_t)
    da_dth = rho * (-ga_x * sin_t + ga_y * cos_t)
    crr = np.add.reduceat(dr_drho**2 * var_rho + dr_dth**2 * var_theta, offs)
    cra = np.add.reduceat(dr_drho * da_drho * var_rho + dr_dth * da_dth * var_theta, offs)
    caa = np.add.reduceat(da_drho**2 * var_rho + da_dth**2 * var_theta, offs)
    cov = np.empty((k, 2, 2))
    cov[:, 0, 0] = crr + COV_FLOOR
    cov[:, 1, 1] = caa + COV_FLOOR
    cov[:, 0, 1] = cov[:, 1, 0] = cra

    first, last = offs, offs + cnt - 1
    # jac_ends[segment, end, (r, α), (ρ, θ)] of the first (end 0) and last (end 1) beam
    ends2 = np.column_stack((first, last))
    jac_ends = np.empty((k, 2, 2, 2))
    jac_ends[:, :, 0, 0] = dr_drho[ends2]
    jac_ends[:, :, 0, 1] = dr_dth[ends2]
    jac_ends[:, :, 1, 0] = da_drho[ends2]
    jac_ends[:, :, 1, 1] = da_dth[ends2]
    p1 = np.column_stack((x[first] - e[first] * c, y[first] - e[first] * s))
    p2 = np.column_stack((x[last] - e[last] * c, y[last] - e[last] * s))
    ok &= np.isfinite(cov).all(axis=(1, 2)) & np.isfinite(p1).all(1) & np.isfinite(p2).all(1)
    ok &= np.isfinite(jac_ends).all(axis=(1, 2, 3))
    return LineFits(r, alpha, cov, p1, p2, jac_ends, ok)


def fit_ranges(rho, theta, sensor: SensorConfig, starts, ends, compiled: bool = True) -> LineFits:
    """Fit the ranges [starts, ends) of a scan's beams with the sensor model, in two passes.

    Weights and variances computed from the measured ranges correlate with their noise (σρ grows with ρ,
    so a beam measured long gets less weight) and bias r by a good fraction of σ with the paper's
    3 %-of-range model. The second pass evaluates the model at the range the first line predicts for each
    beam, ρ̂_i = r / cos(θ_i − α), which does not depend on that beam's noise.
    """
    starts, ends = np.asarray(starts, dtype=np.int64), np.asarray(ends, dtype=np.int64)
    if compiled and len(starts):
        return _fit_ranges_compiled(rho, theta, sensor, starts, ends)
    var_rho, var_theta = beam_variances(rho, sensor)
    if len(starts) == 0:
        return fit_lines(rho, theta, var_rho, var_theta, starts, ends)
    cnt = ends - starts
    offs = np.cumsum(cnt) - cnt
    seg = np.repeat(np.arange(len(cnt)), cnt)
    idx = np.arange(cnt.sum()) - np.repeat(offs - starts, cnt)
    th = theta[idx]
    x, y = rho[idx] * np.cos(th), rho[idx] * np.sin(th)
    w = beam_weights(rho[idx], var_rho[idx], var_theta if np.ndim(var_theta) == 0 else var_theta[idx])
    r1, a1 = _line_from_moments(*_moments(x, y, w, offs, offs + cnt)[2:])  # first pass: the line only
    cos_i = np.cos(th - a1[seg])
    rho_hat = np.where(cos_i > 1e-3, r1[seg] / np.where(cos_i > 1e-3, cos_i, 1.0), rho[idx])
    rho_hat = np.where(np.isfinite(rho_hat) & (rho_hat > 0), rho_hat, rho[idx])
    vr, vt = beam_variances(rho_hat, sensor)
    full_vr, full_w = var_rho.copy(), np.ones_like(rho)
    full_vr[idx] = vr
    full_w[idx] = beam_weights(rho_hat, vr, vt)
    return fit_lines(rho, theta, full_vr, var_theta, starts, ends, full_w)


def _fit_ranges_compiled(rho, theta, sensor: SensorConfig, starts, ends) -> LineFits:
    """:func:`fit_ranges` by the kernels of ``fit_kernels.py``: the same numbers, bit for bit (numpy's
    arctan2 and hypot between the kernels; tests/test_features_lines.py compares the two)."""
    model = kernel_model(sensor)
    rho, theta = np.ascontiguousarray(rho, dtype=float), np.ascontiguousarray(theta, dtype=float)
    beams = fit_kernels.first_pass(rho, theta, starts, ends, model)
    idx, seg, offs, cnt, x, y, cos_t, sin_t, vt, (_, mx, my, sxx, syy, sxy) = beams
    half = 0.5 * np.arctan2(-2.0 * sxy, syy - sxx)
    vr, w, mom = fit_kernels.second_pass(rho, theta, idx, seg, offs, cnt, x, y, vt, half, mx, my, model)
    _, _, _, sxx, syy, sxy = mom
    half, rad = 0.5 * np.arctan2(-2.0 * sxy, syy - sxx), np.hypot(0.5 * (sxx - syy), sxy)
    fit = fit_kernels.covariance(rho, idx, seg, offs, cnt, x, y, cos_t, sin_t, vr, vt, w, half, rad, mom)
    return LineFits(*fit)


# ---------------------------------------------------------------------------------------------------------
# Algorithm 1, steps 1–5. A partition of the beams is an increasing int array ``starts`` (starts[0] == 0);
# range i is [starts[i], starts[i + 1]) with the last one ending at n.


def _ends(starts: np.ndarray, n: int) -> np.ndarray:
    return np.append(starts[1:], n)


def breakpoint_starts(x, y, rho, theta, cfg: LinesConfig, beam_index=None) -> np.ndarray:
    """Step 1: starts of the point sets separated by an adaptive breakpoint (Borges & Aldon 2004).

    d_max = ρ·sin Δφ / sin(λ − Δφ) + breakpoint_sigma, ρ the nearer of the two beams, Δφ their actual
    bearing difference (dropped beams widen it); Δφ >= λ always breaks. More than
    ``max_missing_beams`` dropped beams between two points (no return: the laser saw through there)
    also break: as Δφ nears λ the formula would otherwise join surfaces metres apart.
    """
    dphi = np.diff(theta)
    gap = np.hypot(np.diff(x), np.diff(y))
    lam = cfg.breakpoint_lambda
    rho_near = np.minimum(rho[:-1], rho[1:])
    d_max = rho_near * np.sin(dphi) / np.sin(np.maximum(lam - dphi, 1e-12)) + cfg.breakpoint_sigma
    brk = (dphi >= lam) | ~(gap <= d_max)
    if beam_index is not None and cfg.max_missing_beams > 0:
        brk |= np.abs(np.diff(beam_index)) - 1 > cfg.max_missing_beams  # (beams may run clockwise)
    return np.concatenate(([0], np.flatnonzero(brk) + 1))


def angle_split_starts(
    x, y, rho, theta, starts, cfg: LinesConfig, sigma=None, spacing: float = 0.0
) -> np.ndarray:
    """Step 2: add a start at the sharpest beam of every run where the windowed chord angle exceeds a_max.

    The chords (p_i−k, p_i) and (p_i, p_i+k) stay inside the beam's point set; k = ⌈chord_i / (ρ_i Δφ)⌉ with
    Δφ the beam spacing (``spacing``, else the median) and
    chord_i = max(angle_split_chord, angle_split_sigmas·σ_i), σ_i the beam's
    point standard deviation, so that noise alone seldom bends a chord pair by a_max (a 3σ error at the
    middle beam bends it by 2·atan(3 / angle_split_sigmas) ≈ 17° with the default 20). A chord shorter
    than half of chord_i (near a set's ends) does not vote: the distance split decides there.
    """
    n = len(x)
    if n < 3:
        return starts
    dphi = spacing if spacing > 0 else float(np.median(np.diff(theta)))
    chord = (
        cfg.angle_split_chord
        if sigma is None
        else np.maximum(cfg.angle_split_chord, cfg.angle_split_sigmas * sigma)
    )
    k = np.ceil(chord / np.maximum(rho * max(dphi, 1e-9), 1e-9))
    k = np.minimum(k, n).astype(np.int64)
    ends = _ends(starts, n)
    set_id = np.repeat(np.arange(len(starts)), ends - starts)
    i = np.arange(n)
    lo = np.maximum(i - k, starts[set_id])
    hi = np.minimum(i + k, ends[set_id] - 1)
    v1x, v1y = x - x[lo], y - y[lo]
    v2x, v2y = x[hi] - x, y[hi] - y
    l1, l2 = np.hypot(v1x, v1y), np.hypot(v2x, v2y)
    voting = (l1 >= 0.5 * chord) & (l2 >= 0.5 * chord)
    cos_a = (v1x * v2x + v1y * v2y) / np.where(voting, l1 * l2, 1.0)
    ang = np.arccos(np.clip(cos_a, -1.0, 1.0))
    idx = np.flatnonzero(voting & (ang > cfg.angle_split_max))
    if idx.size == 0:
        return starts
    new_run = np.concatenate(([True], (np.diff(idx) > 1) | (set_id[idx[1:]] != set_id[idx[:-1]])))
    run = np.cumsum(new_run) - 1
    order = np.lexsort((-ang[idx], run))
    best = idx[order[np.concatenate(([True], run[order][1:] != run[order][:-1]))]]
    return np.union1d(starts, best[best > 0])


def distance_split_starts(x, y, w, starts, cfg: LinesConfig) -> np.ndarray:
    """Step 3 (split-and-merge): split every range whose TLS line leaves a point beyond l_max.

    The split goes at the point farthest from the chord of the range's end points (the TLS line of a
    corner-shaped range can be equally far from the corner and the ends); that point starts the second
    range. All ranges are processed together, one vectorised pass per level.
    """
    n = len(x)
    min_split = max(3, cfg.min_points)
    while True:
        ends = _ends(starts, n)
        cnt = ends - starts
        seg, _, mx, my, sxx, syy, sxy = _moments(x, y, w, starts, ends)
        r, alpha = _line_from_moments(mx, my, sxx, syy, sxy)
        res = np.abs(x * np.cos(alpha)[seg] + y * np.sin(alpha)[seg] - r[seg])
        need = ~(np.maximum.reduceat(res, starts) <= cfg.split_distance) & (cnt >= min_split)
        if not need.any():
            return starts
        fx, fy = x[starts][seg], y[starts][seg]
        cx, cy = (x[ends - 1] - x[starts])[seg], (y[ends - 1] - y[starts])[seg]
        norm = np.hypot(cx, cy)
        dist = np.where(
            norm > 0,
            np.abs(cx * (y - fy) - cy * (x - fx)) / np.where(norm > 0, norm, 1.0),
            np.hypot(x - fx, y - fy),
        )
        dist[starts] = -1.0
        dist[ends - 1] = -1.0
        dist = np.nan_to_num(dist, nan=-1.0)
        top = np.maximum.reduceat(dist, starts)
        hit = np.flatnonzero(dist == top[seg])
        first_hit = hit[np.concatenate(([True], seg[hit][1:] != seg[hit][:-1]))]
        split_at = first_hit[need[seg[first_hit]]]
        split_at = split_at[dist[split_at] >= 0]
        if split_at.size == 0:
            return starts
        starts = np.union1d(starts, split_at)


def merge_starts(x, y, w, starts, cfg: LinesConfig) -> np.ndarray:
    """Step 4: merge adjacent ranges whose gap < d_mergeMax and angle < a_mergeMax, left to right.

    A merge is kept only if the merged line stays within l_max of the vertices of both ranges (first / last
    point projected on its own line; raw points for ranges of one or two beams), so a merge never undoes a
    distance split. Moments of a merged range come from the parts (parallel-axis rule): O(1) per test.
    The angle test only applies between ranges of at least ``min_points`` beams, and allows for the noise of
    short ranges: |Δα| < a_mergeMax + 3·sqrt(1/S_dd,1 + 1/S_dd,2), 1/S_dd the variance of α of a range fitted
    with weights 1/σ² (S_dd its weighted scatter along the line).
    """
    n = len(x)
    m = len(starts)
    if m < 2:
        return starts
    ends = _ends(starts, n)
    cnt = ends - starts
    _, W, mx, my, sxx, syy, sxy = _moments(x, y, w, starts, ends)
    r, alpha = _line_from_moments(mx, my, sxx, syy, sxy)
    fi, la = starts, ends - 1
    proj = cnt >= 3
    ef, el = (
        x[fi] * np.cos(alpha) + y[fi] * np.sin(alpha) - r,
        x[la] * np.cos(alpha) + y[la] * np.sin(alpha) - r,
    )
    ef, el = np.where(proj, ef, 0.0), np.where(proj, el, 0.0)
    vf = np.column_stack((x[fi] - ef * np.cos(alpha), y[fi] - ef * np.sin(alpha))).tolist()
    vl = np.column_stack((x[la] - el * np.cos(alpha), y[la] - el * np.sin(alpha))).tolist()
    gaps = np.hypot(x[fi[1:]] - x[la[:-1]], y[fi[1:]] - y[la[:-1]]).tolist()
    sdd = (0.5 * (sxx + syy) + np.hypot(0.5 * (sxx - syy), sxy)).tolist()
    W, mx, my, sxx, syy, sxy = (a.tolist() for a in (W, mx, my, sxx, syy, sxy))
    alpha, cnt = alpha.tolist(), cnt.tolist()
    l_max, a_max, min_pts = cfg.split_distance, cfg.merge_angle, cfg.min_points

    keep = [0]
    cur = (W[0], mx[0], my[0], sxx[0], syy[0], sxy[0])
    cur_alpha, cur_n, cur_vertices, cur_sdd = alpha[0], cnt[0], [vf[0], vl[0]], sdd[0]
    for j in range(1, m):
        merged = None
        if gaps[j - 1] < cfg.merge_gap:
            dalpha = abs(math.remainder(cur_alpha - alpha[j], 2.0 * math.pi))
            tol = a_max + 3.0 * math.sqrt(1.0 / max(cur_sdd, 1e-300) + 1.0 / max(sdd[j], 1e-300))
            if cur_n < min_pts or cnt[j] < min_pts or dalpha < tol:
                W1, x1, y1, a1, b1, c1 = cur
                Wt = W1 + W[j]
                f = W1 * W[j] / Wt
                ddx, ddy = x1 - mx[j], y1 - my[j]
                mom = (
                    Wt,
                    (W1 * x1 + W[j] * mx[j]) / Wt,
                    (W1 * y1 + W[j] * my[j]) / Wt,
                    a1 + sxx[j] + f * ddx * ddx,
                    b1 + syy[j] + f * ddy * ddy,
                    c1 + sxy[j] + f * ddx * ddy,
                )
                rm, am = _line_from_moments(*mom[1:])
                rm, am = float(rm), float(am)
                ca, sa = math.cos(am), math.sin(am)
                verts = cur_vertices + [vf[j], vl[j]]
                if all(abs(vx * ca + vy * sa - rm) <= l_max for vx, vy in verts):
                    half_tr, rad = 0.5 * (mom[3] + mom[4]), math.hypot(0.5 * (mom[3] - mom[4]), mom[5])
                    merged = (mom, am, verts, half_tr + rad)
        if merged is None:
            keep.append(j)
            cur, cur_alpha, cur_n, cur_vertices, cur_sdd = (
                (W[j], mx[j], my[j], sxx[j], syy[j], sxy[j]),
                alpha[j],
                cnt[j],
                [vf[j], vl[j]],
                sdd[j],
            )
        else:
            cur, cur_alpha, cur_vertices, cur_sdd = merged
            cur_n += cnt[j]
    return starts[keep]


def refine_boundaries(x, y, w, starts, cfg: LinesConfig, sweeps: int = 2) -> np.ndarray:
    """Step 5: move the beam at the border of two touching ranges to the line it lies closer to.

    A split puts the corner beam on one side arbitrarily; on a noiseless corner that beam biases the other
    line. Only borders between ranges of >= 3 beams closer than d_mergeMax are touched.
    """
    n = len(x)
    for _ in range(sweeps):
        if len(starts) < 2:
            return starts
        ends = _ends(starts, n)
        cnt = ends - starts
        _, _, mx, my, sxx, syy, sxy = _moments(x, y, w, starts, ends)
        r, alpha = _line_from_moments(mx, my, sxx, syy, sxy)
        c, s = np.cos(alpha), np.sin(alpha)
        b = starts[1:]  # border between range i (left) and i + 1 (right)
        left, right = np.arange(len(b)), np.arange(1, len(b) + 1)
        touching = (cnt[left] >= 4) & (cnt[right] >= 4)
        touching &= np.hypot(x[b] - x[b - 1], y[b] - y[b - 1]) < cfg.merge_gap

        dist = lambda i, seg: np.abs(x[i] * c[seg] + y[i] * s[seg] - r[seg])  # noqa: B023
        to_left = touching & (dist(b, left) < dist(b, right))
        to_right = touching & ~to_left & (dist(b - 1, right) < dist(b - 1, left))
        if not (to_left.any() or to_right.any()):
            return starts
        starts = starts.copy()
        starts[1:] += to_left.astype(np.int64) - to_right.astype(np.int64)
    return starts


def trim_ends(x, y, w, starts, cfg: LinesConfig, sweeps: int = 2) -> np.ndarray:
    """Step 6: split off a range's first or last beam when it lies more than 4 RMS residuals off the line.

    A beam just past a corner or breakpoint can sit within l_max of the wrong line (e.g. the last beam
    of a grazing wall). The RMS is that of the range's other beams, so the test does not depend on the
    noise model.
    The beam split off becomes a one-beam range and is dropped by the filters.
    """
    n = len(x)
    for _ in range(sweeps):
        ends = _ends(starts, n)
        cnt = ends - starts
        seg, W, mx, my, sxx, syy, sxy = _moments(x, y, w, starts, ends)
        r, alpha = _line_from_moments(mx, my, sxx, syy, sxy)
        e = x * np.cos(alpha)[seg] + y * np.sin(alpha)[seg] - r[seg]
        sse = np.add.reduceat(e * e, starts)
        big = cnt >= cfg.min_points
        e0, e1 = e[starts], e[ends - 1]
        # RMS of the other beams of the range (leave the tested one out)
        cut_first = big & (e0 * e0 > 16.0 * (sse - e0 * e0) / np.maximum(cnt - 1, 1))
        cut_last = big & (e1 * e1 > 16.0 * (sse - e1 * e1) / np.maximum(cnt - 1, 1))
        if not (cut_first.any() or cut_last.any()):
            return starts
        starts = np.union1d(starts, np.concatenate((starts[cut_first] + 1, ends[cut_last] - 1)))
    return starts


def partition(x, y, rho, theta, w, beam_index, spacing: float, cfg: LinesConfig, compiled: bool = True):
    """Steps 1–6 on a scan's valid beams (points x, y; ranges, bearings; weights w): the starts of the
    ranges. ``compiled`` runs ``segment_kernels.partition`` (the default: ~20× faster on a 1,081-beam
    scan), else the numpy functions above; both make the same decisions (tests/test_features_lines.py).
    ``spacing``: the beam spacing (≤ 0: the median bearing difference)."""
    if not compiled:
        starts = breakpoint_starts(x, y, rho, theta, cfg, beam_index)
        starts = angle_split_starts(x, y, rho, theta, starts, cfg, 1.0 / np.sqrt(w), spacing)
        starts = distance_split_starts(x, y, w, starts, cfg)
        starts = merge_starts(x, y, w, starts, cfg)
        starts = refine_boundaries(x, y, w, starts, cfg)
        return trim_ends(x, y, w, starts, cfg)
    return segment_kernels.partition(
        x, y, rho, theta, w, np.asarray(beam_index, dtype=np.int64),
        spacing if spacing > 0 else float(np.median(np.diff(theta))),
        cfg.breakpoint_lambda, cfg.breakpoint_sigma, cfg.max_missing_beams,
        cfg.angle_split_max, cfg.angle_split_chord, cfg.angle_split_sigmas,
        cfg.split_distance, cfg.merge_angle, cfg.merge_gap, cfg.min_points,
    )  # fmt: skip


def extract_segments(scan: Scan, sensor: SensorConfig, cfg: LinesConfig) -> tuple[Segments, np.ndarray]:
    """Algorithm 1 on one scan. Returns the segments and their end-beam Jacobians (k, 2, 2, 2).

    The Jacobians (``LineFits.jac_ends``) let ``corners`` correlate a type II corner with its own line.
    """
    rho = np.asarray(scan.ranges, dtype=float)
    theta = np.asarray(scan.angles, dtype=float)
    n = len(rho)
    none = (Segments.empty(), np.zeros((0, 2, 2, 2)))
    if n < max(2, cfg.min_points) or not (np.isfinite(rho).all() and np.isfinite(theta).all()):
        return none
    var_rho, var_theta = beam_variances(rho, sensor)  # segmentation only: the final fit is two-pass
    x, y = rho * np.cos(theta), rho * np.sin(theta)
    w = beam_weights(rho, var_rho, var_theta)
    if not (np.isfinite(x).all() and np.isfinite(y).all() and np.isfinite(w).all()):
        return none

    starts = partition(x, y, rho, theta, w, scan.beam_index, scan.angle_increment, cfg)  # steps 1-6
    ends = _ends(starts, n)

    sel = (ends - starts) >= cfg.min_points  # step 7
    starts, ends = starts[sel], ends[sel]
    fit = fit_ranges(rho, theta, sensor, starts, ends)
    keep = fit.ok & (np.hypot(*(fit.p2 - fit.p1).T) >= cfg.min_length)
    if not keep.any():
        return none
    segs = Segments(
        r=fit.r[keep],
        alpha=fit.alpha[keep],
        cov=fit.cov[keep],
        p1=fit.p1[keep],
        p2=fit.p2[keep],
        n_points=(ends - starts)[keep],
        first=starts[keep],
        last=ends[keep] - 1,
    )
    return segs, fit.jac_ends[keep]
