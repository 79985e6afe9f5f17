"""Compiled (Numba) parts of ICP (motion/icp.py), bit for bit the numpy expressions they replace.

Each ICP iteration and each local-map rebuild ran a dozen numpy calls on a few hundred to a few thousand
numbers; the call overhead was most of their time. These kernels compute the same expressions, operation
for operation, in loops: elementwise + − × ÷ round as numpy's float64 loops do, ``einsum("ij,ij->i")``
accumulates from +0 as numpy's does, and a sum over a row of ≤ 7 numbers is sequential from −0.0, as
numpy's pairwise sum is below 8 elements. What numpy computes with other kernels — the (n, 2) @ (2, 2)
placement (BLAS, fused multiply-adds), arctan2, hypot, sin and cos (SIMD versions) — stays in numpy.
tests/test_scanmatch.py checks the kernels against the numpy expressions exactly. Two exceptions, equal
to rounding only: :func:`gauss_newton_step`, the normal equations and their 3 × 3 solve, which numpy
computed with BLAS and LAPACK (sums in another order, fused multiply-adds); and :func:`icp_iterations`,
the whole Gauss–Newton loop of icp.register in one kernel (its placement of the points and its heading
are libm's, not BLAS's and numpy's SIMD arctan2).
"""

from __future__ import annotations

import math

import numpy as np

from ..features.jit import kernel
from .nearest import nearest_within_moving


@kernel
def line_terms(q, idx, points, normals, t, scale, J, w, r):
    """Fill J (n, 3), w, r of ICP's point-to-line terms (icp._line_terms) for the placed points ``q``
    matched to map rows ``idx`` of ``points``/``normals`` (padded: a zero normal for no match), the
    pose's translation ``t``; return how many rows have a non-zero normal."""
    used = 0
    for i in range(len(q)):
        m = idx[i]
        nx, ny = normals[m, 0], normals[m, 1]
        used += abs(nx) + abs(ny) != 0.0
        acc = 0.0
        acc += (q[i, 0] - points[m, 0]) * nx
        acc += (q[i, 1] - points[m, 1]) * ny
        r[i] = acc
        u = acc / scale
        w[i] = 1.0 / (1.0 + u * u)
        J[i, 0] = nx
        J[i, 1] = ny
        J[i, 2] = (q[i, 0] - t[0]) * ny - (q[i, 1] - t[1]) * nx
    return used


@kernel
def neighbour_scatter(points, dist, idx, k, tie, out):
    """Fill ``out`` (3, n) with the scatter (a, b, c) = (Σx², Σxy, Σy²) of each point's neighbours
    ``idx`` (n, q) about their mean, counting the k nearest and any within ``tie`` (relative) of the
    k-th (icp.line_normals)."""
    n, q = idx.shape
    keep = np.empty(q)
    for i in range(n):
        bound = dist[i, k - 1] * (1.0 + tie)
        count = 0
        sx, sy = -0.0, -0.0
        for j in range(q):
            keep[j] = 1.0 if dist[i, j] <= bound else 0.0
            count += dist[i, j] <= bound
            sx += points[idx[i, j], 0] * keep[j]
            sy += points[idx[i, j], 1] * keep[j]
        mx, my = sx / count, sy / count
        a, b, c = -0.0, -0.0, -0.0
        for j in range(q):
            dx = (points[idx[i, j], 0] - mx) * keep[j]
            dy = (points[idx[i, j], 1] - my) * keep[j]
            a += dx * dx
            b += dx * dy
            c += dy * dy
        out[0, i], out[1, i], out[2, i] = a, b, c


@kernel
def gauss_newton_step(J, w, r, prior, off, step):
    """Fill ``step`` (3,) with ICP's Gauss–Newton step −H⁻¹g, H = JᵀWJ + diag(prior), g = JᵀWr +
    prior·off (icp.register), H by its Cholesky factor in closed form. Not bit for bit numpy's (BLAS
    sums, LAPACK's solve): the same to rounding (tests/test_scanmatch.py)."""
    h00 = h01 = h02 = h11 = h12 = h22 = g0 = g1 = g2 = 0.0
    for i in range(len(w)):
        a, b, c, wi = J[i, 0], J[i, 1], J[i, 2], w[i]
        wa, wb, wc = wi * a, wi * b, wi * c
        h00 += wa * a
        h01 += wa * b
        h02 += wa * c
        h11 += wb * b
        h12 += wb * c
        h22 += wc * c
        g0 += wa * r[i]
        g1 += wb * r[i]
        g2 += wc * r[i]
    h00 += prior[0]
    h11 += prior[1]
    h22 += prior[2]
    g0 += prior[0] * off[0]
    g1 += prior[1] * off[1]
    g2 += prior[2] * off[2]
    # H = L Lᵀ; forward then back substitution
    l00 = math.sqrt(h00)
    l10 = h01 / l00
    l20 = h02 / l00
    l11 = math.sqrt(h11 - l10 * l10)
    l21 = (h12 - l20 * l10) / l11
    l22 = math.sqrt(h22 - l20 * l20 - l21 * l21)
    y0 = g0 / l00
    y1 = (g1 - l10 * y0) / l11
    y2 = (g2 - l20 * y0 - l21 * y1) / l22
    x2 = y2 / l22
    x1 = (y1 - l21 * x2) / l11
    x0 = (y0 - l10 * x1 - l20 * x2) / l00
    step[0], step[1], step[2] = -x0, -x1, -x2


@kernel
def _cell_index(v):
    """⌊v⌋ as int64 of v clipped to the int32 range (no overflow); INT64_MIN for NaN, as numpy's cast
    gives on x86."""
    if math.isnan(v):
        return np.int64(-(2**63))
    return np.int64(math.floor(min(max(v, -(2.0**31)), 2.0**31 - 1)))


@kernel
def _cell_key(x, y, size):
    """The int64 key of the ``size`` cell of (x, y): (i << 32) + (j & 0xFFFFFFFF), as numpy computed it."""
    return (_cell_index(x / size) << 32) + (_cell_index(y / size) & 0xFFFFFFFF)


@kernel
def first_in_cell(points, size):
    """Indices, ascending, of the first point (in input order) of every ``size`` × ``size`` cell: a hash
    set of the cells' keys, one pass (``np.unique(keys, return_index=True)`` sorted the keys)."""
    n = len(points)
    bits = 1
    while (1 << bits) < 2 * n:
        bits += 1
    mask = (1 << bits) - 1
    table, filled = np.empty(mask + 1, np.int64), np.zeros(mask + 1, np.bool_)
    keep = np.empty(n, np.int64)
    m = 0
    for i in range(n):
        key = _cell_key(points[i, 0], points[i, 1], size)
        # Fibonacci hashing (2⁶⁴/φ, unsigned: wraps by definition) on the top bits, linear probing
        slot = np.int64((np.uint64(key) * np.uint64(11400714819323198485)) >> np.uint64(64 - bits))
        while filled[slot] and table[slot] != key:
            slot = (slot + 1) & mask
        if not filled[slot]:
            filled[slot], table[slot] = True, key
            keep[m] = i
            m += 1
    return keep[:m]


@kernel
def icp_iterations(points, grid, padded_points, padded_normals, start, guess, prior, dmax, cfg):
    """The Gauss–Newton iterations of icp.register from pose ``start``: the (3, 3) matrix of the pose
    they end at. Each places ``points``, takes their nearest map points within ``dmax`` (``grid``:
    BucketGrid.arrays), their point-to-line terms, and steps −(JᵀWJ + prior)⁻¹ (JᵀWr + prior·off), off
    the pose's offset from ``guess``; ``dmax`` shrinks to ``min_distance``; they stop with fewer than 3
    usable correspondences or a step below ``converged`` at the least ``dmax``. ``cfg``:
    (max_iterations, min_distance, shrink, converged, robust_scale)."""
    max_iterations, min_distance, shrink, converged, scale = cfg
    n = len(points)
    q, dist, idx = np.empty((n, 2)), np.empty(n), np.empty(n, np.int64)
    clear, at = np.full(n, -1.0), np.empty((n, 2))  # points far from the map stay unlooked at a while
    J, w, r = np.empty((n, 3)), np.empty(n), np.empty(n)
    t, off, step = np.array([start[0], start[1]]), np.empty(3), np.empty(3)
    c, s = math.cos(start[2]), math.sin(start[2])
    for _ in range(max_iterations):
        for i in range(n):
            q[i, 0] = points[i, 0] * c - points[i, 1] * s + t[0]
            q[i, 1] = points[i, 0] * s + points[i, 1] * c + t[1]
        nearest_within_moving(q, dmax, *grid, dist, idx, clear, at)
        if line_terms(q, idx, padded_points, padded_normals, t, scale, J, w, r) < 3:
            break
        theta = math.atan2(s, c)
        off[0], off[1] = t[0] - guess[0], t[1] - guess[1]
        off[2] = (theta - guess[2] + np.pi) % (2.0 * np.pi) - np.pi
        gauss_newton_step(J, w, r, prior, off, step)
        t[0], t[1] = t[0] + step[0], t[1] + step[1]
        c, s = math.cos(theta + step[2]), math.sin(theta + step[2])
        dmax = max(min_distance, dmax * shrink)
        if max(abs(step[0]), abs(step[1]), abs(step[2])) < converged and dmax <= min_distance:
            break
    return np.array([[c, -s, t[0]], [s, c, t[1]], [0.0, 0.0, 1.0]])
