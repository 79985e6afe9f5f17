"""Compiled (Numba) corner extraction (``corners.extract_corners``): the candidates of both types with their
covariances, then the occlusion and free-space checks, the merging of duplicates and the bearing order.

The numpy version ran ~60 calls per scan on a few dozen numbers each (≈ 0.7–1 ms a 1,081-beam scan, most
of it call overhead); these kernels loop over the segment pairs and ends once. They evaluate the same
expressions as corners.py's docstring states them; the small matrix products are summed in loops, so the
covariances equal the numpy version's (BLAS's) to rounding, not bit for bit, and arctan2 is libm's, not
numpy's SIMD one. tests/test_features_corners.py compares them with the numpy version
(tests/_corners_reference.py) on noisy scans.

``sensor`` is the noise model as a tuple: (linear, a, b, near_range, sigma_r_near, sigma_r_rel,
sigma_theta), as lines.py passes it to fit_kernels.
"""

from __future__ import annotations

import math

import numpy as np

from ..smallmat import product
from .jit import kernel
from .sensor import COV_FLOOR

_TYPE_ONE, _TYPE_TWO = 1, 2
_SAMPLES = (0.25, 0.5, 0.75)  # where the free-space check looks along a segment's extension


@kernel
def _wrap(a):
    """``geometry.wrap_angle`` of one angle: [-π, π)."""
    return (a + np.pi) % (2.0 * np.pi) - np.pi


@kernel
def _sigma_range(rho, sensor):
    """σρ(ρ) of ``sensor.sigma_range`` for one range."""
    if sensor[0]:
        return sensor[1] + sensor[2] * rho
    return sensor[4] if rho <= sensor[3] else sensor[5] * rho


@kernel
def _sandwich(F, C):
    """F C Fᵀ of small matrices."""
    return product(product(F, C), F.T)


@kernel
def _segment_distance(px, py, a, b):
    """Distance from (px, py) to the segment a–b ((2,) end points)."""
    abx, aby = b[0] - a[0], b[1] - a[1]
    L2 = abx * abx + aby * aby
    t = ((px - a[0]) * abx + (py - a[1]) * aby) / (L2 if L2 > 0 else 1.0)
    if t < 0.0:
        t = 0.0
    elif t > 1.0:
        t = 1.0
    return math.hypot(a[0] + t * abx - px, a[1] + t * aby - py)


@kernel
def intersection(ai, aj, ri, rj, cov_i, cov_j):
    """Eq 9–13 for the lines (r_i, α_i), (r_j, α_j): the corner (3,) and its covariance (3, 3)."""
    D = math.sin(aj - ai)  # det N; N⁻¹ = (1/D) [[sin αj, −sin αi], [−cos αj, cos αi]]
    n00, n01 = math.sin(aj) / D, -math.sin(ai) / D
    n10, n11 = -math.cos(aj) / D, math.cos(ai) / D
    cx, cy = n00 * ri + n01 * rj, n10 * ri + n11 * rj
    dphi = _wrap(ai - aj)
    sgn = 1.0 if dphi >= 0 else -1.0
    # N dc = dr − diag(d_i·c, d_j·c) dα,  d = (−sin α, cos α)
    dic = -math.sin(ai) * cx + math.cos(ai) * cy
    djc = -math.sin(aj) * cx + math.cos(aj) * cy
    F = np.zeros((3, 4))
    F[0, 0], F[0, 1], F[0, 2], F[0, 3] = n00, -dic * n00, n01, -djc * n01
    F[1, 0], F[1, 1], F[1, 2], F[1, 3] = n10, -dic * n10, n11, -djc * n11
    F[2, 1], F[2, 3] = sgn, -sgn
    C = np.zeros((4, 4))
    C[:2, :2], C[2:, 2:] = cov_i, cov_j
    return np.array([cx, cy, abs(dphi)]), _sandwich(F, C)


@kernel
def _admissible(i, j, alpha, p1, p2, d_min, min_angle):
    """Segments i and j have end points nearer than d_min and are at least min_angle from parallel."""
    d = math.inf
    for a in (p1[i], p2[i]):
        for b in (p1[j], p2[j]):
            dab = math.hypot(a[0] - b[0], a[1] - b[1])
            if math.isnan(dab):
                return False
            d = min(d, dab)
    phi = abs(_wrap(alpha[i] - alpha[j]))
    return d < d_min and phi >= min_angle and phi <= np.pi - min_angle


@kernel
def type_one(alpha, r, cov, p1, p2, d_min, min_angle, dp_max):
    """Type I corners of every admissible pair i < j whose intersection lies within dp_max of both
    segments, pairs in ``np.triu_indices`` order: z (m, 3), cov (m, 3, 3), pairs (m, 2)."""
    k = len(r)
    cap = k * (k - 1) // 2
    z, C, pairs = np.empty((cap, 3)), np.empty((cap, 3, 3)), np.empty((cap, 2), np.int64)
    m = 0
    for i in range(k):
        for j in range(i + 1, k):
            if not _admissible(i, j, alpha, p1, p2, d_min, min_angle):
                continue
            zc, cc = intersection(alpha[i], alpha[j], r[i], r[j], cov[i], cov[j])
            if (
                _segment_distance(zc[0], zc[1], p1[i], p2[i]) <= dp_max
                and _segment_distance(zc[0], zc[1], p1[j], p2[j]) <= dp_max
            ):
                z[m], C[m] = zc, cc
                pairs[m, 0], pairs[m, 1] = i, j
                m += 1
    return z[:m], C[:m], pairs[:m]


@kernel
def _is_end_corner(rho, theta, beam_index, b, nb, a, r, d_min, drop_occluded):
    """Beam b ends a segment (line (r, a)) at a measured depth jump to the next beam nb."""
    if nb < 0 or nb >= len(rho) or abs(beam_index[nb] - beam_index[b]) != 1:
        return False  # the field of view's edge or dropped beams: what lies there is unknown
    xb, yb = rho[b] * math.cos(theta[b]), rho[b] * math.sin(theta[b])
    xn, yn = rho[nb] * math.cos(theta[nb]), rho[nb] * math.sin(theta[nb])
    jump = math.hypot(xn - xb, yn - yb)
    off_line = abs(xn * math.cos(a) + yn * math.sin(a) - r)
    if not (jump > d_min and off_line > d_min):
        return False
    return not (drop_occluded and rho[nb] < rho[b])


@kernel
def end_corner(rho_b, theta_b, a, r, seg_cov, jac_end, var_r, var_t):
    """The end beam (ρ, θ) projected on its segment's line (r, α): c (2,), its covariance (2, 2) exact to
    first order in the segment's beams (corners.py), and P = I − n nᵀ (along the line)."""
    ca, sa = math.cos(a), math.sin(a)
    xb, yb = rho_b * math.cos(theta_b), rho_b * math.sin(theta_b)
    e = xb * ca + yb * sa - r
    c = np.array([xb - e * ca, yb - e * sa])
    dq = yb * ca - xb * sa
    A = np.array([[ca, -dq * ca + e * sa], [sa, -dq * sa - e * ca]])  # ∂c/∂(r, α)
    ct, st = math.cos(theta_b), math.sin(theta_b)
    Q = np.array([[ct, -rho_b * st], [st, rho_b * ct]])  # ∂q/∂(ρ, θ)
    P = np.array([[sa * sa, -sa * ca], [-ca * sa, ca * ca]])  # d dᵀ, d = (−sin α, cos α)
    AJ = product(A, jac_end)
    Ce = np.array([[var_r, 0.0], [0.0, var_t]])
    Ge = AJ + product(P, Q)
    return c, _sandwich(A, seg_cov) - _sandwich(AJ, Ce) + _sandwich(Ge, Ce), P


@kernel
def type_two(rho, theta, beam_index, first, last, alpha, r, seg_cov, jac_ends, spacing, sensor, cfg):
    """Type II corners at segment ends facing a depth jump, first ends then last ends:
    z (m, 3), cov (m, 3, 3), segment (m,). ``cfg``: (d_min, drop_occluded, endpoint_max_gap,
    endpoint_phi, endpoint_phi_sigma)."""
    d_min, drop_occluded, max_gap, phi, phi_sigma = cfg
    k = len(r)
    z, C, seg = np.zeros((2 * k, 3)), np.zeros((2 * k, 3, 3)), np.empty(2 * k, np.int64)
    m = 0
    for end in range(2):
        step = -1 if end == 0 else 1  # the next beam away from the segment
        for s in range(k):
            b = first[s] if end == 0 else last[s]
            if not _is_end_corner(rho, theta, beam_index, b, b + step, alpha[s], r[s], d_min, drop_occluded):
                continue
            sr = _sigma_range(rho[b], sensor)
            c, cxy, P = end_corner(
                rho[b], theta[b], alpha[s], r[s], seg_cov[s], jac_ends[s, end], sr * sr, sensor[6] ** 2
            )
            # the edge lies between the end beam and the next beam's bearing, where the line would be hit
            # next: centre of that gap, variance gap²/12 along the line (uniform)
            th_next = theta[b] + step * spacing
            cos_next = math.cos(th_next - alpha[s])
            t_next = r[s] / cos_next if cos_next > 1e-6 else np.nan
            gx, gy = t_next * math.cos(th_next) - c[0], t_next * math.sin(th_next) - c[1]
            gap = math.hypot(gx, gy)
            if not gap <= max_gap:
                continue  # grazing wall (or none to hit)
            z[m, 0], z[m, 1], z[m, 2] = c[0] + 0.5 * gx, c[1] + 0.5 * gy, phi
            C[m, :2, :2] = cxy + (gap**2 / 12.0) * P
            C[m, 2, 2] = phi_sigma**2
            seg[m] = s
            m += 1
    return z[:m], C[:m], seg[:m]


@kernel
def _measured(ranges, angles, spacing, bearing, dropped, farther):
    """The measured range at one bearing (the numpy version: tests/_corners_reference.py's
    ``measured_range``): the nearer (``farther``: the farther) of the at most two
    valid beams within one beam spacing of it; ``dropped`` in a gap of dropped beams, nan outside the
    field of view."""
    n = len(ranges)
    if n < 2:
        return np.nan
    k = np.searchsorted(angles, bearing)
    measured = -np.inf if farther else np.inf
    for nb in (k - 1, k):
        if 0 <= nb < n and abs(angles[nb] - bearing) <= spacing:
            measured = max(measured, ranges[nb]) if farther else min(measured, ranges[nb])
    if math.isfinite(measured):
        return measured
    return dropped if angles[0] <= bearing <= angles[n - 1] else np.nan


@kernel
def _margin(rho, sensor, margin):
    """Tolerance of a range comparison: ``occlusion_margin`` + 3σρ at that range."""
    return margin + 3.0 * _sigma_range(rho if math.isfinite(rho) else 0.0, sensor)


@kernel
def _hidden(x, y, ranges, angles, spacing, sensor, margin):
    """The point lies behind both beams bracketing its bearing by more than the margin (both must be in
    front: next to a corner a steep wall legitimately comes nearer by several centimetres per beam)."""
    measured = _measured(ranges, angles, spacing, math.atan2(y, x), np.nan, True)
    return measured < math.hypot(x, y) - _margin(measured, sensor, margin)


@kernel
def _seen_through(cx, cy, segs, p1, p2, ranges, angles, spacing, sensor, margin):
    """A type I corner's segments, extended from their nearer ends to it, cross space the scan saw through
    (a beam measured more than the margin beyond the extension; dropped beams count as seen through).

    This rejects "virtual" intersections, e.g. a box face extended to a wall 15 cm behind it; at a real
    corner the beams between a segment's end and the corner hit that same wall."""
    for s in segs:
        d1 = math.hypot(p1[s, 0] - cx, p1[s, 1] - cy)
        d2 = math.hypot(p2[s, 0] - cx, p2[s, 1] - cy)
        e = p1[s] if d1 <= d2 else p2[s]
        for f in _SAMPLES:
            qx, qy = e[0] + f * (cx - e[0]), e[1] + f * (cy - e[1])
            measured = _measured(ranges, angles, spacing, math.atan2(qy, qx), np.inf, False)
            rq = math.hypot(qx, qy)
            if measured > rq + _margin(rq, sensor, margin):
                return True
    return False


@kernel
def _merged(z, cov, kind, idx, radius):
    """Of the corners ``idx``, those kept when corners within ``radius`` of each other are one: type I
    before type II, then the smaller trace of the position covariance (``np.lexsort`` order)."""
    trace = np.array([cov[i, 0, 0] + cov[i, 1, 1] for i in idx])
    order = np.argsort(trace, kind="mergesort")
    order = order[np.argsort(kind[idx[order]], kind="mergesort")]
    kept = np.empty(len(idx), np.int64)
    m = 0
    for a in idx[order]:
        if not _near_any(z, a, kept[:m], radius):
            kept[m] = a
            m += 1
    return kept[:m]


@kernel
def _near_any(z, a, others, radius):
    """Corner a lies within ``radius`` of one of ``others``."""
    for b in others:
        if math.hypot(z[a, 0] - z[b, 0], z[a, 1] - z[b, 1]) < radius:
            return True
    return False


@kernel
def select(z, cov, kind, which, ok, ranges, angles, spacing, p1, p2, sensor, cfg):
    """Indices of the corners kept, in bearing order: ``ok`` ones neither hidden behind the scan's ranges
    (``drop_occluded``) nor, for type I, extended through free space (``free_space_check``), duplicates
    merged. ``cfg``: (drop_occluded, free_space_check, occlusion_margin, duplicate_radius)."""
    drop_occluded, free_space_check, margin, radius = cfg
    keep = ok.copy()
    for i in range(len(z)):
        if keep[i] and drop_occluded:
            keep[i] = not _hidden(z[i, 0], z[i, 1], ranges, angles, spacing, sensor, margin)
        if keep[i] and free_space_check and kind[i] == _TYPE_ONE:
            keep[i] = not _seen_through(
                z[i, 0], z[i, 1], which[i], p1, p2, ranges, angles, spacing, sensor, margin
            )
    kept = _merged(z, cov, kind, np.flatnonzero(keep), radius)
    bearing = np.array([math.atan2(z[i, 1], z[i, 0]) for i in kept])
    return kept[np.argsort(bearing, kind="mergesort")]


@kernel
def candidates(rho, theta, beam_index, segs, jac_ends, spacing, sensor, cfg):
    """Corners of both types (type I first), covariances symmetrised with ``COV_FLOOR`` on the diagonal:
    z (m, 3), cov (m, 3, 3), which (m, 2), kind (m,) int8, finite (m,) bool. ``segs``: (alpha, r, cov,
    p1, p2, first, last) of the segments; ``cfg``: (d_min, min_angle, dp_max, endpoints, drop_occluded,
    endpoint_max_gap, endpoint_phi, endpoint_phi_sigma)."""
    alpha, r, seg_cov, p1, p2, first, last = segs
    d_min, min_angle, dp_max, endpoints, drop_occluded, max_gap, phi, phi_sigma = cfg
    z1, c1, pairs = type_one(alpha, r, seg_cov, p1, p2, d_min, min_angle, dp_max)
    if endpoints:
        ends = (d_min, drop_occluded, max_gap, phi, phi_sigma)
        z2, c2, s2 = type_two(
            rho, theta, beam_index, first, last, alpha, r, seg_cov, jac_ends, spacing, sensor, ends
        )
    else:
        z2, c2, s2 = np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros(0, np.int64)
    m1, m = len(z1), len(z1) + len(z2)
    z, cov = np.concatenate((z1, z2)), np.concatenate((c1, c2))
    which, kind = np.full((m, 2), -1, np.int64), np.full(m, _TYPE_TWO, np.int8)
    which[:m1], kind[:m1] = pairs, _TYPE_ONE
    which[m1:, 0] = s2
    finite = np.empty(m, np.bool_)
    for t in range(m):
        cov[t] = 0.5 * (cov[t] + cov[t].T) + COV_FLOOR * np.eye(3)
        finite[t] = np.isfinite(z[t]).all() and np.isfinite(cov[t]).all()
    return z, cov, which, kind, finite
