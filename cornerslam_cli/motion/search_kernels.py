"""Compiled (Numba) parts of the correlative search (motion/correlative.py), bit for bit the numpy
expressions they replace.

The search's branch and bound expanded one coarse cell at a time in Python — a gather, a sum and an argmax
of 16 numbers each — and on a real log that overhead was most of the front end's time (5 of 13 s on
infinite-corridor). Same sums in the same order: numpy sums an (n, k, l) gather over its first axis point
after point, and over a contiguous axis (a gather of one cell) pairwise (:func:`pairwise_sum`, numpy's
``pairwise_sum`` for float64), both from −0.0. tests/test_scanmatch.py compares the compiled search with
the numpy one it replaced (tests/_correlative_reference.py): same pose, score and count, exactly.

The field's inputs came next (2.7 ms of a front-end search on infinite-corridor, 5.5 s of its 20 s run):
scipy's distance transform (1.1 ms) and the coarse cells' block maximum (0.35 ms), both exact, so their
compiled versions (:func:`squared_distances`, :func:`block_max`) give the same numbers bit for bit
(tests against scipy and numpy: tests/test_scanmatch.py).
"""

from __future__ import annotations

import numpy as np

from ..features.jit import kernel
from ..smallmat import pairwise_sum


@kernel
def _offset_sums(F, pxa, pya, ox, oy, out, column):
    """out[i, j] = Σ_p F[pxa[p] + ox[i], pya[p] + oy[j]] for the offsets ``ox`` × ``oy``, summed as numpy
    sums the gather F[pxa[:, None, None] + ox[:, None], pya[:, None, None] + oy] over its points: in
    order, but pairwise for a single offset (that gather is contiguous); ``column``: scratch of
    len(pxa)."""
    n = len(pxa)
    if len(ox) == 1 and len(oy) == 1:
        for p in range(n):
            column[p] = F[pxa[p] + ox[0], pya[p] + oy[0]]
        out[0, 0] = -0.0 + pairwise_sum(column, 0, n)
        return
    for i in range(len(ox)):
        for j in range(len(oy)):
            out[i, j] = -0.0
    for p in range(n):
        for i in range(len(ox)):
            row = pxa[p] + ox[i]
            for j in range(len(oy)):
                out[i, j] += F[row, pya[p] + oy[j]]


@kernel
def coarse_sums(U, px, py, offs):
    """S (A, nc, nc): S[a, i, j] = Σ_p U[px[a, p] + offs[i], py[a, p] + offs[j]] (the coarse bounds of
    correlative.Search.prepare), summed as numpy sums that gather over its points axis (pairwise when
    nc = 1)."""
    A, n = px.shape
    out = np.empty((A, len(offs), len(offs)))
    column = np.empty(n)
    for a in range(A):
        _offset_sums(U, px[a], py[a], offs, offs, out[a], column)
    return out


@kernel
def branch_and_bound(L, px, py, bound, order, n_side, block, pull, turn_term, shift_term, excluded, turned):
    """The best fine pose of the coarse cells in ``order`` (flat indices of ``bound``, (A, nc, nc)),
    expanded best bound first until no bound beats the best score (correlative.search): returns (best
    score, its angle index, x offset, y offset, fine poses scored). Score of angle a, offsets (ox, oy):
    Σ_p L[px[a, p] + ox, py[a, p] + oy] / n − pull · ((turn_term[a] + shift_term[ox]) + shift_term[oy]),
    −inf where ``excluded[ox, oy]`` and ``turned[a]``. Ties keep the first found, in numpy's argmax order."""
    nc = bound.shape[1]
    n = px.shape[1]
    out = np.empty((block, block))
    column = np.empty(n)
    offsets = np.arange(n_side)
    best, best_a, best_x, best_y, evaluated = -1.0, -1, -1, -1, 0
    for flat in order:
        a = flat // (nc * nc)
        i = (flat // nc) % nc
        j = flat % nc
        if bound[a, i, j] <= best:
            break
        x0, y0 = block * i, block * j
        x1, y1 = min(x0 + block, n_side), min(y0 + block, n_side)
        _offset_sums(L, px[a], py[a], offsets[x0:x1], offsets[y0:y1], out, column)
        cell_best, cx, cy = -np.inf, x0, y0
        first = True
        for ox in range(x0, x1):
            for oy in range(y0, y1):
                sc = out[ox - x0, oy - y0] / n - pull * ((turn_term[a] + shift_term[ox]) + shift_term[oy])
                if turned[a] and excluded[ox, oy]:
                    sc = -np.inf
                if first or sc > cell_best:
                    cell_best, cx, cy, first = sc, ox, oy, False
        evaluated += (x1 - x0) * (y1 - y0)
        if cell_best > best:
            best, best_a, best_x, best_y = cell_best, a, cx, cy
    return best, best_a, best_x, best_y, evaluated


# ------------------------------------------------------------------------ the likelihood field's inputs


@kernel
def squared_distances(free):
    """D (float64, shape of ``free``): the squared Euclidean distance, in cells, from each cell to the
    nearest cell that is not ``free`` (0 on those) — ``ndimage.distance_transform_edt(free) ** 2`` before
    its square root. Exact: Felzenszwalb & Huttenlocher's two passes (the distance along each column,
    then the lower envelope of parabolas along each row) on integers held exactly in float64 (sides
    < 2²⁵ cells). The parabolas' intersections are the only divisions; rounding is monotone, so a rounded
    comparison of two of them can only drop a parabola that is lowest on no integer cell, and a rounded
    intersection cannot cross an integer cell but where both parabolas are equal on it. A grid with no
    cell that is not free (the caller's ``free.all()`` case) gives ``far`` everywhere. Rows are walked in
    memory order."""
    nx, ny = free.shape
    far = float(nx * nx + ny * ny + 1)  # beyond every real squared distance
    g = np.empty((nx, ny))  # squared distance along each column (far: none in the column)
    near = np.full(ny, -1)  # per column: the last cell not free seen (downwards, then upwards)
    for i in range(nx):
        for j in range(ny):
            if not free[i, j]:
                near[j] = i
            g[i, j] = far if near[j] < 0 else float((i - near[j]) * (i - near[j]))
    near[:] = -1
    for i in range(nx - 1, -1, -1):
        for j in range(ny):
            if not free[i, j]:
                near[j] = i
            elif near[j] >= 0:
                g[i, j] = min(g[i, j], float((near[j] - i) * (near[j] - i)))
    out = np.empty((nx, ny))
    v = np.empty(ny, np.int64)  # the envelope's parabolas (their apexes' columns) ...
    z = np.empty(ny + 1)  # ... and where each takes over
    for i in range(nx):
        k, s = -1, 0.0
        for q in range(ny):
            f = g[i, q]
            if f >= far:
                continue
            while k >= 0:
                p = v[k]
                s = ((f + q * q) - (g[i, p] + p * p)) / (2.0 * (q - p))
                if s > z[k]:
                    break
                k -= 1
            if k < 0:
                k, z[0] = 0, -np.inf
            else:
                k += 1
                z[k] = s
            v[k], z[k + 1] = q, np.inf
        if k < 0:  # no column holds a cell that is not free: the whole grid is free
            out[i, :] = far
            continue
        k = 0
        for q in range(ny):
            while z[k + 1] < q:
                k += 1
            p = v[k]
            out[i, q] = float((q - p) * (q - p)) + g[i, p]
    return out


@kernel
def block_max(L, b):
    """U[i, j] = max of L[i : i + b, j : j + b] (cells beyond the edge count as 0; L holds no NaN and
    nothing below 0: a likelihood field): a maximum along each row, then of b rows, in memory order."""
    nx, ny = L.shape
    rows = np.zeros((nx, ny))
    for i in range(nx):
        for t in range(b):
            for j in range(ny - t):
                rows[i, j] = max(rows[i, j], L[i, j + t])
    U = np.zeros((nx, ny))
    for i in range(nx):
        for t in range(i, min(i + b, nx)):
            for j in range(ny):
                U[i, j] = max(U[i, j], rows[t, j])
    return U
