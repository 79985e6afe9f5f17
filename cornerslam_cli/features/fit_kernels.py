"""Compiled (Numba) parts of the two-pass line fit (``lines.fit_ranges``), bit for bit the numpy fit.

``lines.fit_ranges`` runs ~90 numpy calls on a 1,081-beam scan, each on a few hundred numbers: the call
overhead is most of its time. These kernels compute the same expressions, operation for operation, in
loops: elementwise + − × ÷, √, cos and sin round exactly as numpy's float64 loops do, and ``_segment_sum``
sums a range exactly as ``np.add.reduceat`` does (its first element plus numpy's pairwise sum of the
rest). arctan2 and hypot are not compiled: numpy's SIMD versions differ from libm's in the last bit, so
the caller evaluates them with numpy between the kernels. tests/test_features_lines.py checks that the
result equals the numpy fit exactly.
"""

from __future__ import annotations

import math

import numpy as np

from ..smallmat import pairwise_sum
from .jit import kernel
from .sensor import COV_FLOOR


@kernel
def _segment_sums(a, offs, cnt):
    """``np.add.reduceat(a, offs)`` for ranges [offs, offs + cnt), every cnt >= 1."""
    out = np.empty(len(offs))
    for j in range(len(offs)):
        out[j] = a[offs[j]] + pairwise_sum(a, offs[j] + 1, cnt[j] - 1)
    return out


@kernel
def _variance_range(rho, linear, a, b, near, sr_near, sr_rel):
    """σρ(ρ)² of ``sensor.sigma_range`` (squared as numpy's ``**2``: one product)."""
    if linear:
        sd = a + b * rho
    else:
        sd = sr_near if rho <= near else sr_rel * rho
    return sd * sd


@kernel
def _moments(x, y, w, offs, cnt, seg):
    """``lines._moments`` of the gathered beams: W, mx, my, sxx, syy, sxy per range."""
    total = len(x)
    a, b, c = np.empty(total), np.empty(total), np.empty(total)
    for t in range(total):
        a[t], b[t] = w[t] * x[t], w[t] * y[t]
    W = _segment_sums(w, offs, cnt)
    mx = _segment_sums(a, offs, cnt) / W
    my = _segment_sums(b, offs, cnt) / W
    for t in range(total):
        dx, dy = x[t] - mx[seg[t]], y[t] - my[seg[t]]
        a[t], b[t], c[t] = w[t] * dx * dx, w[t] * dy * dy, w[t] * dx * dy
    return W, mx, my, _segment_sums(a, offs, cnt), _segment_sums(b, offs, cnt), _segment_sums(c, offs, cnt)


@kernel
def _line(half_atan, mx, my):
    """The rest of ``lines._line_from_moments`` once α = ½·atan2(…) is known: r >= 0, α in (−π, π]."""
    k = len(mx)
    r, alpha = np.empty(k), np.empty(k)
    for j in range(k):
        a = half_atan[j]
        rj = mx[j] * math.cos(a) + my[j] * math.sin(a)
        if rj < 0:
            rj = -rj
            a = a + math.pi
        if a > math.pi:
            a = a - 2.0 * math.pi
        r[j], alpha[j] = rj, a
    return r, alpha


@kernel
def first_pass(rho, theta, starts, ends, sensor):
    """Gather the ranges' beams and their first-pass moments (``fit_ranges`` up to the first line).

    Returns idx, seg, offs, cnt (the ranges' beams as in ``fit_lines``), x, y, cos θ, sin θ, vt (σθ²)
    and the moments of :func:`_moments`.
    """
    linear, a, b, near, sr_near, sr_rel, sigma_theta = sensor
    k = len(starts)
    cnt, offs = np.empty(k, np.int64), np.empty(k, np.int64)
    total = 0
    for j in range(k):
        cnt[j], offs[j] = ends[j] - starts[j], total
        total += cnt[j]
    idx, seg = np.empty(total, np.int64), np.empty(total, np.int64)
    for j in range(k):
        for t in range(cnt[j]):
            idx[offs[j] + t] = starts[j] + t
            seg[offs[j] + t] = j
    vt = sigma_theta * sigma_theta
    x, y, w = np.empty(total), np.empty(total), np.empty(total)
    cos_t, sin_t = np.empty(total), np.empty(total)
    for t in range(total):
        r, th = rho[idx[t]], theta[idx[t]]
        cos_t[t], sin_t[t] = math.cos(th), math.sin(th)
        x[t], y[t] = r * cos_t[t], r * sin_t[t]
        w[t] = 1.0 / (_variance_range(r, linear, a, b, near, sr_near, sr_rel) + r * r * vt + COV_FLOOR)
    return idx, seg, offs, cnt, x, y, cos_t, sin_t, vt, _moments(x, y, w, offs, cnt, seg)


@kernel
def second_pass(rho, theta, idx, seg, offs, cnt, x, y, vt, half_atan, mx, my, sensor):
    """The beams' variances and weights at the ranges the first line predicts, and the moments again.

    Returns vr (σρ² at ρ̂), w and the moments of :func:`_moments`.
    """
    linear, a, b, near, sr_near, sr_rel, _ = sensor
    r1, a1 = _line(half_atan, mx, my)
    total = len(idx)
    vr, w = np.empty(total), np.empty(total)
    for t in range(total):
        rho_t = rho[idx[t]]
        cos_i = math.cos(theta[idx[t]] - a1[seg[t]])
        rho_hat = r1[seg[t]] / cos_i if cos_i > 1e-3 else rho_t
        if not (math.isfinite(rho_hat) and rho_hat > 0):
            rho_hat = rho_t
        vr[t] = _variance_range(rho_hat, linear, a, b, near, sr_near, sr_rel)
        w[t] = 1.0 / (vr[t] + rho_hat * rho_hat * vt + COV_FLOOR)
    return vr, w, _moments(x, y, w, offs, cnt, seg)


@kernel
def covariance(rho, idx, seg, offs, cnt, x, y, cos_t, sin_t, vr, vt, w, half_atan, rad, moments):
    """``lines.fit_lines`` after the line: r, α, cov (k, 2, 2), p1, p2, jac_ends (k, 2, 2, 2), ok (k,).

    ``rad`` = hypot(½(Sxx − Syy), Sxy) (numpy's), half of S_dd − S_nn.
    """
    W, mx, my, sxx, syy, sxy = moments
    r, alpha = _line(half_atan, mx, my)
    k = len(r)
    c, s = np.cos(alpha), np.sin(alpha)
    den = 2.0 * rad
    ok = np.empty(k, np.bool_)
    for j in range(k):
        half_tr = 0.5 * (sxx[j] + syy[j])
        ok[j] = (
            math.isfinite(r[j])
            and math.isfinite(alpha[j])
            and den[j] > 1e-9 * max(half_tr, 1e-300)
            and cnt[j] >= 2
        )
        if not ok[j]:
            den[j] = 1.0
    total = len(idx)
    e = np.empty(total)
    dr_drho, da_drho = np.empty(total), np.empty(total)
    dr_dth, da_dth = np.empty(total), np.empty(total)
    for t in range(total):
        j = seg[t]
        cs, ss = c[j], s[j]
        dx, dy = x[t] - mx[j], y[t] - my[j]
        e[t] = dx * cs + dy * ss
        u = -dx * ss + dy * cs
        ga_x = -w[t] * (u * cs - e[t] * ss) / den[j]
        ga_y = -w[t] * (u * ss + e[t] * cs) / den[j]
        pd = -mx[j] * s[j] + my[j] * c[j]
        wn = w[t] / W[j]
        gr_x = wn * cs + pd * ga_x
        gr_y = wn * ss + pd * ga_y
        ct, st, rho_t = cos_t[t], sin_t[t], rho[idx[t]]
        dr_drho[t] = gr_x * ct + gr_y * st
        da_drho[t] = ga_x * ct + ga_y * st
        dr_dth[t] = rho_t * (-gr_x * st + gr_y * ct)
        da_dth[t] = rho_t * (-ga_x * st + ga_y * ct)
    terms = np.empty((3, total))  # summands of C_l = J_ρ C_ρ J_ρᵀ + J_θ C_θ J_θᵀ (rr, rα, αα)
    for t in range(total):
        terms[0, t] = dr_drho[t] * dr_drho[t] * vr[t] + dr_dth[t] * dr_dth[t] * vt
        terms[1, t] = dr_drho[t] * da_drho[t] * vr[t] + dr_dth[t] * da_dth[t] * vt
        terms[2, t] = da_drho[t] * da_drho[t] * vr[t] + da_dth[t] * da_dth[t] * vt
    crr, cra, caa = (
        _segment_sums(terms[0], offs, cnt),
        _segment_sums(terms[1], offs, cnt),
        _segment_sums(terms[2], offs, cnt),
    )
    cov = np.empty((k, 2, 2))
    jac = np.empty((k, 2, 2, 2))
    p1, p2 = np.empty((k, 2)), np.empty((k, 2))
    for j in range(k):
        cov[j, 0, 0] = crr[j] + COV_FLOOR
        cov[j, 1, 1] = caa[j] + COV_FLOOR
        cov[j, 0, 1] = cov[j, 1, 0] = cra[j]
        for end, t in enumerate((offs[j], offs[j] + cnt[j] - 1)):
            jac[j, end, 0, 0] = dr_drho[t]
            jac[j, end, 0, 1] = dr_dth[t]
            jac[j, end, 1, 0] = da_drho[t]
            jac[j, end, 1, 1] = da_dth[t]
            p = p1 if end == 0 else p2
            p[j, 0] = x[t] - e[t] * c[j]
            p[j, 1] = y[t] - e[t] * s[j]
        ok[j] = ok[j] and np.isfinite(cov[j]).all() and np.isfinite(jac[j]).all()
        ok[j] = ok[j] and np.isfinite(p1[j]).all() and np.isfinite(p2[j]).all()
    return r, alpha, cov, p1, p2, jac, ok
