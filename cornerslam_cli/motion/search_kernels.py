"""Compiled (Numba) parts of the correlative search (motion/correlative.py), bit for bit the numpy
expressions they replace.

The search's branch and bound expanded one coarse cell at a time in Python — a gather, a sum and an argmax
of 16 numbers each — and on a real log that overhead was most of the front end's time (5 of 13 s on
infinite-corridor). Same sums in the same order: numpy sums an (n, k, l) gather over its first axis point
after point, and over a contiguous axis (a gather of one cell) pairwise (:func:`pairwise_sum`, numpy's
``pairwise_sum`` for float64), both from −0.0. tests/test_scanmatch.py compares the compiled search with
the numpy one it replaced (tests/_correlative_reference.py): same pose, score and count, exactly.
"""

from __future__ import annotations

import numpy as np

from ..features.jit import kernel
from ..smallmat import pairwise_sum


@kernel
def _cell_sums(L, pxa, pya, x0, x1, y0, y1, out, column):
    """out[ox − x0, oy − y0] = Σ_p L[pxa[p] + ox, pya[p] + oy] for the offsets of one cell, summed as numpy
    sums the gather L[pxa[:, None, None] + ox, pya[:, None, None] + oy] over its first axis; ``column``:
    scratch of len(pxa)."""
    n = len(pxa)
    if x1 - x0 == 1 and y1 - y0 == 1:  # a gather of one offset is contiguous: numpy sums it pairwise
        for p in range(n):
            column[p] = L[pxa[p] + x0, pya[p] + y0]
        out[0, 0] = -0.0 + pairwise_sum(column, 0, n)
        return
    for i in range(x1 - x0):
        for j in range(y1 - y0):
            out[i, j] = -0.0
    for p in range(n):
        for i in range(x1 - x0):
            for j in range(y1 - y0):
                out[i, j] += L[pxa[p] + x0 + i, pya[p] + y0 + j]


@kernel
def coarse_sums(U, px, py, offs):
    """S (A, nc, nc): S[a, i, j] = Σ_p U[px[a, p] + offs[i], py[a, p] + offs[j]] (the coarse bounds of
    correlative.Search.prepare), summed as numpy sums that gather over its points axis (pairwise when
    nc = 1)."""
    A, n = px.shape
    nc = len(offs)
    out = np.empty((A, nc, nc))
    column = np.empty(n)
    cell = np.empty((nc, nc))
    for a in range(A):
        if nc == 1:
            for p in range(n):
                column[p] = U[px[a, p] + offs[0], py[a, p] + offs[0]]
            out[a, 0, 0] = -0.0 + pairwise_sum(column, 0, n)
            continue
        for i in range(nc):
            for j in range(nc):
                cell[i, j] = -0.0
        for p in range(n):
            for i in range(nc):
                row = px[a, p] + offs[i]
                for j in range(nc):
                    cell[i, j] += U[row, py[a, p] + offs[j]]
        out[a] = cell
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
    best, best_a, best_x, best_y, evaluated = -1.0, -1, -1, -1, 0
    for flat in order:
        a = flat // (nc * nc)
        i = (flat // nc) % nc
        j = flat % nc
        if bound[a, i, j] <= best:
            break
        x0, y0 = block * i, block * j
        x1, y1 = min(x0 + block, n_side), min(y0 + block, n_side)
        _cell_sums(L, px[a], py[a], x0, x1, y0, y1, out, column)
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
