"""Compiled (Numba) kernels of Algorithm 1's steps 1–6: the partition of a scan's beams into ranges.

``lines.py`` holds the same steps as vectorised numpy (``breakpoint_starts``, ``angle_split_starts``,
``distance_split_starts``, ``merge_starts``, ``refine_boundaries``, ``trim_ends``), which read as the
algorithm's specification; these kernels make the same decisions beam by beam and range by range,
without the per-call overhead of ~400 small numpy calls per scan
(1,081 beams are too few for numpy's vector loops to pay). They decide *where* ranges start and end
only: the lines, covariances and corners returned to the user are still computed by the numpy fit
(``lines.fit_ranges``) on the resulting partition, so outputs do not depend on which implementation
partitioned the beams — unless a sum or an arctan2/hypot lands within the last bit of a threshold (numpy
sums pairwise and uses SIMD arctan2/hypot, these kernels sum in order and call libm); the tests compare
the two partitions on simulated, real and random scans.

Compiled once per machine and cached (``jit.kernel``: ``__pycache__`` beside this file; 10–30 s on first use).
"""

from __future__ import annotations

import math

import numpy as np

from .jit import kernel


@kernel
def _mask_of(starts, n):
    """(n,) bool, True at the given starts."""
    mask = np.zeros(n, np.bool_)
    for s in starts:
        mask[s] = True
    return mask


@kernel
def _starts_of(mask):
    """The sorted indices where ``mask`` is True (int64)."""
    out = np.empty(mask.sum(), np.int64)
    k = 0
    for i in range(len(mask)):
        if mask[i]:
            out[k] = i
            k += 1
    return out


@kernel
def breakpoints(x, y, rho, theta, beam_index, lam, sigma, max_missing):
    """Step 1 (``lines.breakpoint_starts``): starts of the point sets split by the adaptive breakpoint
    d_max = ρ sin Δφ / sin(λ − Δφ) + σ, or by more than ``max_missing`` dropped beams (0: not checked)."""
    n = len(x)
    is_start = np.zeros(n, np.bool_)
    is_start[0] = True
    last_dphi, sin_dphi, sin_rest = math.nan, 0.0, 1.0
    for i in range(n - 1):
        dphi = theta[i + 1] - theta[i]
        if dphi != last_dphi:  # the spacing repeats from beam to beam: its sines only when it changes
            last_dphi, sin_dphi, sin_rest = dphi, math.sin(dphi), math.sin(max(lam - dphi, 1e-12))
        gap = math.hypot(x[i + 1] - x[i], y[i + 1] - y[i])
        d_max = min(rho[i], rho[i + 1]) * sin_dphi / sin_rest + sigma
        brk = dphi >= lam or not gap <= d_max
        if max_missing > 0 and abs(beam_index[i + 1] - beam_index[i]) - 1 > max_missing:
            brk = True
        is_start[i + 1] = brk
    return _starts_of(is_start)


@kernel
def angle_splits(x, y, rho, w, starts, dphi, a_max, chord_min, chord_sigmas):
    """Step 2 (``lines.angle_split_starts``): a start at the sharpest beam of every run of beams whose
    chords (p_i−k, p_i), (p_i, p_i+k) — k beams spanning chord_i = max(chord_min, chord_sigmas·σ_i),
    inside the beam's set — bend by more than a_max; a chord shorter than chord_i / 2 does not vote."""
    n = len(x)
    if n < 3:
        return starts
    ends = _ends(starts, n)
    is_start = _mask_of(starts, n)
    best, best_ang, ang = -1, 0.0, 0.0
    for j in range(len(starts)):
        for i in range(starts[j], ends[j]):
            chord = max(chord_min, chord_sigmas * (1.0 / math.sqrt(w[i])))
            k = min(math.ceil(chord / max(rho[i] * max(dphi, 1e-9), 1e-9)), n)
            lo, hi = max(i - k, starts[j]), min(i + k, ends[j] - 1)
            v1x, v1y = x[i] - x[lo], y[i] - y[lo]
            v2x, v2y = x[hi] - x[i], y[hi] - y[i]
            l1, l2 = math.hypot(v1x, v1y), math.hypot(v2x, v2y)
            sharp = False
            if l1 >= 0.5 * chord and l2 >= 0.5 * chord:
                ang = math.acos(min(max((v1x * v2x + v1y * v2y) / (l1 * l2), -1.0), 1.0))
                sharp = ang > a_max
            if sharp and (best < 0 or ang > best_ang):
                best, best_ang = i, ang
            if best >= 0 and (not sharp or i == ends[j] - 1):  # the run ended: keep its sharpest beam
                is_start[best] = True  # (beam 0 is a start already)
                best = -1
    return _starts_of(is_start)


@kernel
def _moments(x, y, w, s, e):
    """Weighted centroid and central scatter (two-pass) of beams [s, e): (W, mx, my, sxx, syy, sxy)."""
    W = 0.0
    sx = 0.0
    sy = 0.0
    for i in range(s, e):
        W += w[i]
        sx += w[i] * x[i]
        sy += w[i] * y[i]
    mx, my = sx / W, sy / W
    sxx = 0.0
    syy = 0.0
    sxy = 0.0
    for i in range(s, e):
        dx, dy = x[i] - mx, y[i] - my
        sxx += w[i] * dx * dx
        syy += w[i] * dy * dy
        sxy += w[i] * dx * dy
    return W, mx, my, sxx, syy, sxy


@kernel
def _line(mx, my, sxx, syy, sxy):
    """Eq 3–4 on one range's moments: (r, α) with r >= 0, α in (−π, π] (``lines._line_from_moments``)."""
    alpha = 0.5 * math.atan2(-2.0 * sxy, syy - sxx)
    r = mx * math.cos(alpha) + my * math.sin(alpha)
    if r < 0:
        r = -r
        alpha = alpha + math.pi
    if alpha > math.pi:
        alpha = alpha - 2.0 * math.pi
    return r, alpha


@kernel
def _range_line(x, y, w, s, e):
    """(r, α) of the weighted TLS line through beams [s, e)."""
    _, mx, my, sxx, syy, sxy = _moments(x, y, w, s, e)
    return _line(mx, my, sxx, syy, sxy)


@kernel
def _ends(starts, n):
    ends = np.empty_like(starts)
    ends[:-1] = starts[1:]
    ends[-1] = n
    return ends


@kernel
def _farthest_from_chord(x, y, s, e):
    """Index of the first beam of [s, e) farthest from the chord of its end beams (ends excluded,
    NaN distances count as −1); −1 when no interior beam has a distance >= 0."""
    fx, fy = x[s], y[s]
    cx, cy = x[e - 1] - fx, y[e - 1] - fy
    norm = math.hypot(cx, cy)
    best, top = -1, -1.0
    for i in range(s + 1, e - 1):
        if norm > 0:
            d = abs(cx * (y[i] - fy) - cy * (x[i] - fx)) / norm
        else:
            d = math.hypot(x[i] - fx, y[i] - fy)
        if d > top:  # NaN never wins; the first of equal maxima does
            best, top = i, d
    return best if top >= 0 else -1


@kernel
def distance_split(x, y, w, starts, split_distance, min_points):
    """Step 3 (``lines.distance_split_starts``): split each range at the beam farthest from its chord
    while its TLS line leaves a beam farther than l_max; ranges are independent, so depth first."""
    n = len(x)
    min_split = max(3, min_points)
    ends = _ends(starts, n)
    is_start = _mask_of(starts, n)
    stack = np.empty((len(starts) + 2 * n + 2, 2), np.int64)  # ranges to check: each split pushes two
    top = len(starts)
    stack[:top, 0], stack[:top, 1] = starts[::-1], ends[::-1]  # popped left to right
    while top:
        top -= 1
        s, e = stack[top, 0], stack[top, 1]
        if e - s < min_split:
            continue
        r, alpha = _range_line(x, y, w, s, e)
        c, sn = math.cos(alpha), math.sin(alpha)
        need = False
        for i in range(s, e):
            if not abs(x[i] * c + y[i] * sn - r) <= split_distance:  # NaN: too far (numpy propagates it)
                need = True
                break
        if not need:
            continue
        k = _farthest_from_chord(x, y, s, e)
        if k < 0:
            continue
        is_start[k] = True
        stack[top, 0], stack[top, 1] = k, e
        stack[top + 1, 0], stack[top + 1, 1] = s, k
        top += 2
    return _starts_of(is_start)


@kernel
def _vertices(x, y, s, e, r, alpha):
    """First and last beam of [s, e) projected on its line (raw points for fewer than 3 beams)."""
    c, sn = math.cos(alpha), math.sin(alpha)
    proj = e - s >= 3
    out = np.empty((2, 2))
    for v, i in enumerate((s, e - 1)):
        off = x[i] * c + y[i] * sn - r if proj else 0.0
        out[v, 0] = x[i] - off * c
        out[v, 1] = y[i] - off * sn
    return out


@kernel
def _remainder_2pi(a):
    """IEEE remainder of ``a`` by 2π (``math.remainder``): in [−π, π]."""
    two_pi = 2.0 * math.pi
    return a - two_pi * round(a / two_pi)


@kernel
def merge(x, y, w, starts, split_distance, merge_angle, merge_gap, min_points):
    """Step 4 (``lines.merge_starts``): merge adjacent ranges left to right while the merged line stays
    within l_max of every merged range's vertices; moments of a merge from its parts (parallel axes)."""
    n, m = len(x), len(starts)
    if m < 2:
        return starts
    ends = _ends(starts, n)
    mom = np.empty((m, 6))
    alpha, sdd = np.empty(m), np.empty(m)
    verts = np.empty((m, 2, 2))
    for j in range(m):
        W, mx, my, sxx, syy, sxy = _moments(x, y, w, starts[j], ends[j])
        mom[j, 0], mom[j, 1], mom[j, 2], mom[j, 3], mom[j, 4], mom[j, 5] = W, mx, my, sxx, syy, sxy
        r, alpha[j] = _line(mx, my, sxx, syy, sxy)
        sdd[j] = 0.5 * (sxx + syy) + math.hypot(0.5 * (sxx - syy), sxy)
        verts[j] = _vertices(x, y, starts[j], ends[j], r, alpha[j])
    keep = np.zeros(m, np.bool_)
    keep[0] = True
    cur = mom[0].copy()
    new = np.empty(6)
    cur_alpha, cur_n, cur_sdd = alpha[0], ends[0] - starts[0], sdd[0]
    group = np.empty((2 * m, 2))  # the vertices of the ranges merged into the current one
    group[:2] = verts[0]
    n_verts = 2
    for j in range(1, m):
        merged = False
        gap = math.hypot(x[starts[j]] - x[ends[j - 1] - 1], y[starts[j]] - y[ends[j - 1] - 1])
        if gap < merge_gap:
            dalpha = abs(_remainder_2pi(cur_alpha - alpha[j]))
            tol = merge_angle + 3.0 * math.sqrt(1.0 / max(cur_sdd, 1e-300) + 1.0 / max(sdd[j], 1e-300))
            cnt_j = ends[j] - starts[j]
            if cur_n < min_points or cnt_j < min_points or dalpha < tol:
                W1, x1, y1, a1, b1, c1 = cur[0], cur[1], cur[2], cur[3], cur[4], cur[5]
                Wj = mom[j, 0]
                Wt = W1 + Wj
                f = W1 * Wj / Wt
                ddx, ddy = x1 - mom[j, 1], y1 - mom[j, 2]
                new[0] = Wt
                new[1] = (W1 * x1 + Wj * mom[j, 1]) / Wt
                new[2] = (W1 * y1 + Wj * mom[j, 2]) / Wt
                new[3] = a1 + mom[j, 3] + f * ddx * ddx
                new[4] = b1 + mom[j, 4] + f * ddy * ddy
                new[5] = c1 + mom[j, 5] + f * ddx * ddy
                rm, am = _line(new[1], new[2], new[3], new[4], new[5])
                ca, sa = math.cos(am), math.sin(am)
                group[n_verts : n_verts + 2] = verts[j]
                within = True
                for v in range(n_verts + 2):
                    if not abs(group[v, 0] * ca + group[v, 1] * sa - rm) <= split_distance:
                        within = False
                        break
                if within:
                    merged = True
                    cur[:] = new
                    cur_alpha = am
                    cur_n += cnt_j
                    n_verts += 2
                    cur_sdd = 0.5 * (new[3] + new[4]) + math.hypot(0.5 * (new[3] - new[4]), new[5])
        if not merged:
            keep[j] = True
            cur[:] = mom[j]
            cur_alpha, cur_n, cur_sdd = alpha[j], ends[j] - starts[j], sdd[j]
            group[:2] = verts[j]
            n_verts = 2
    return starts[keep]


@kernel
def _lines_of(x, y, w, starts, ends):
    """(r, α) of every range, each (m,)."""
    m = len(starts)
    r, alpha = np.empty(m), np.empty(m)
    for j in range(m):
        r[j], alpha[j] = _range_line(x, y, w, starts[j], ends[j])
    return r, alpha


@kernel
def _off_line(x, y, i, r, alpha):
    return abs(x[i] * math.cos(alpha) + y[i] * math.sin(alpha) - r)


@kernel
def refine(x, y, w, starts, merge_gap, sweeps=2):
    """Step 5 (``lines.refine_boundaries``): the beam at the border of two touching ranges (>= 4 beams
    each, nearer than d_mergeMax) goes to the line it is closer to; all borders of a sweep at once."""
    n = len(x)
    for _ in range(sweeps):
        m = len(starts)
        if m < 2:
            return starts
        ends = _ends(starts, n)
        r, alpha = _lines_of(x, y, w, starts, ends)
        new = starts.copy()
        moved = False
        for i in range(m - 1):
            b = starts[i + 1]
            if ends[i] - starts[i] < 4 or ends[i + 1] - starts[i + 1] < 4:
                continue
            if not math.hypot(x[b] - x[b - 1], y[b] - y[b - 1]) < merge_gap:
                continue
            if _off_line(x, y, b, r[i], alpha[i]) < _off_line(x, y, b, r[i + 1], alpha[i + 1]):
                new[i + 1] += 1
                moved = True
            elif _off_line(x, y, b - 1, r[i + 1], alpha[i + 1]) < _off_line(x, y, b - 1, r[i], alpha[i]):
                new[i + 1] -= 1
                moved = True
        if not moved:
            return starts
        starts = new
    return starts


@kernel
def trim(x, y, w, starts, min_points, sweeps=2):
    """Step 6 (``lines.trim_ends``): split off a range's first or last beam lying more than 4 RMS
    residuals (of the range's other beams) off its line."""
    n = len(x)
    for _ in range(sweeps):
        m = len(starts)
        ends = _ends(starts, n)
        is_start = _mask_of(starts, n)
        cut = False
        for j in range(m):
            s, e = starts[j], ends[j]
            r, alpha = _range_line(x, y, w, s, e)
            c, sn = math.cos(alpha), math.sin(alpha)
            sse = 0.0
            for i in range(s, e):
                d = x[i] * c + y[i] * sn - r
                sse += d * d
            if e - s < min_points:
                continue
            e0 = x[s] * c + y[s] * sn - r
            e1 = x[e - 1] * c + y[e - 1] * sn - r
            rest = max(e - s - 1, 1)
            if e0 * e0 > 16.0 * (sse - e0 * e0) / rest:
                is_start[s + 1] = cut = True
            if e1 * e1 > 16.0 * (sse - e1 * e1) / rest:
                is_start[e - 1] = cut = True
        if not cut:
            return starts
        starts = _starts_of(is_start)
    return starts


@kernel
def partition(x, y, rho, theta, w, beam_index, dphi, lam, bp_sigma, max_missing, a_max, chord_min,
              chord_sigmas, split_distance, merge_angle, merge_gap, min_points):  # fmt: skip
    """Steps 1–6: the starts of the ranges (``lines.extract_segments`` documents the parameters)."""
    starts = breakpoints(x, y, rho, theta, beam_index, lam, bp_sigma, max_missing)
    starts = angle_splits(x, y, rho, w, starts, dphi, a_max, chord_min, chord_sigmas)
    starts = distance_split(x, y, w, starts, split_distance, min_points)
    starts = merge(x, y, w, starts, split_distance, merge_angle, merge_gap, min_points)
    starts = refine(x, y, w, starts, merge_gap)
    return trim(x, y, w, starts, min_points)
