"""Compiled (Numba) parts of ICP (motion/icp.py), bit for bit the numpy expressions they replace.

Each ICP iteration and each local-map rebuild ran a dozen numpy calls on a few hundred to a few thousand
numbers; the call overhead was most of their time. These kernels compute the same expressions, operation
for operation, in loops: elementwise + − × ÷ round as numpy's float64 loops do, ``einsum("ij,ij->i")``
accumulates from +0 as numpy's does, and a sum over a row of ≤ 7 numbers is sequential from −0.0, as
numpy's pairwise sum is below 8 elements. What numpy computes with other kernels — the (n, 2) @ (2, 2)
placement (BLAS, fused multiply-adds), arctan2, hypot, sin and cos (SIMD versions) — stays in numpy.
tests/test_scanmatch.py checks the kernels against the numpy expressions exactly.
"""

from __future__ import annotations

import numpy as np

from ..features.jit import kernel


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
