"""The map consistency's revisit search on a bucket grid (Numba): per point, the nearest point of a scan
block far enough away in time, within a distance cap.

A tile's points (report/consistency.py) are bucketed in square cells of half the cap (a counting sort),
each cell's points in block order, so the points a query may not use (its own block and its neighbours
in time: most of a cell's points) are one run of the cell found by bisection, and a cell holding only
those is passed by at the cost of two comparisons. A query looks at rings of cells around its own,
nearest first, skipping cells farther than the nearest point found so far, until the square searched
holds every point nearer than that one, or every point within the cap (at most 5 × 5 cells). This
replaced kd-trees over power-of-two runs of blocks, each asked by every block that needed it (~10 tree
queries a point: 10 s of a 19 s run of the 1,252-scan simulated lap, now ~1.5 s). Smaller cells were
slower on that lap: a query then passes by more cells than it saves distances.

The answer is the kd-trees': squared distances are computed as cKDTree computes them (dx² + dy², no
fused multiply-add), a point counts when that is strictly below cap², and the distance returned is the
square root of the least. The least squared distance does not depend on the order the points are
visited in, so the distances are the trees' bit for bit (tests/test_consistency.py compares them).
"""

from __future__ import annotations

import math

import numpy as np

from ..features.jit import kernel

CELLS_PER_CAP = 2  # cells across the cap ...
CELLS_PER_POINT = 4  # ... unless the grid would have more than this many cells per point (8 bytes each)
SLACK = 1e-9  # m: a searched square is taken this much smaller (rounding of the cells' edges)


def nearest_far(xy: np.ndarray, blocks: np.ndarray, query: np.ndarray, gap: int, cap: float) -> np.ndarray:
    """Per point of ``query`` (a mask of xy (n, 2)), the distance to the nearest point of ``xy`` whose
    block (``blocks``, one int per point, ascending) is at least ``gap`` away from its own, inf when
    none is nearer than ``cap``."""
    asked = np.flatnonzero(query)
    best = np.full(len(asked), np.inf)
    if not len(asked):
        return best
    lo = xy.min(axis=0)
    extent = xy.max(axis=0) - lo
    area = float(extent[0] + cap) * float(extent[1] + cap)
    cell = max(cap / CELLS_PER_CAP, math.sqrt(area / (CELLS_PER_POINT * len(xy))))
    grid = (float(lo[0]), float(lo[1]), cell, int(extent[0] / cell) + 1, int(extent[1] / cell) + 1)
    key = np.empty(len(xy), dtype=np.int64)
    _cell_keys(xy, *grid, key)
    start = np.zeros(grid[3] * grid[4] + 1, dtype=np.int64)
    np.cumsum(np.bincount(key, minlength=grid[3] * grid[4]), out=start[1:])
    by_cell = np.empty_like(xy), np.empty_like(blocks)
    _bucket(xy, blocks, key, start, *by_cell)
    del key
    _search(xy, blocks, asked, *by_cell, start, *grid, gap, cap, best)
    return best


@kernel
def _cell_of(x, y, ox, oy, cell, nx, ny):
    """(i, j) of the cell holding the point (x, y) on the grid of corner (ox, oy)."""
    return min(int((x - ox) / cell), nx - 1), min(int((y - oy) / cell), ny - 1)


@kernel
def _cell_keys(xy, ox, oy, cell, nx, ny, key):
    """Fill ``key`` with the flat cell (i·ny + j) of each point."""
    for m in range(len(xy)):
        i, j = _cell_of(xy[m, 0], xy[m, 1], ox, oy, cell, nx, ny)
        key[m] = i * ny + j


@kernel
def _bucket(xy, blocks, key, start, by_cell_xy, by_cell_blocks):
    """Counting sort of the points by cell (stable: each cell's points keep their block order)."""
    fill = start[:-1].copy()
    for m in range(len(xy)):
        k = fill[key[m]]
        by_cell_xy[k, 0], by_cell_xy[k, 1], by_cell_blocks[k] = xy[m, 0], xy[m, 1], blocks[m]
        fill[key[m]] += 1


@kernel
def _search(points, blocks, asked, xy, block, start, ox, oy, cell, nx, ny, gap, cap, best):
    """Fill ``best`` (see :func:`nearest_far`): rings of cells around each query's own, nearest first;
    ``xy``/``block`` are the points by cell."""
    cap2 = cap * cap
    for n in range(len(asked)):
        qx, qy, b = points[asked[n], 0], points[asked[n], 1], blocks[asked[n]]
        px, py = qx - ox, qy - oy  # from the grid's corner
        ci, cj = _cell_of(qx, qy, ox, oy, cell, nx, ny)
        d2 = cap2
        r = 0
        while True:
            for i in range(max(ci - r, 0), min(ci + r, nx - 1) + 1):
                for j in range(max(cj - r, 0), min(cj + r, ny - 1) + 1):
                    if abs(i - ci) == r or abs(j - cj) == r:  # on the ring
                        d2 = _visit(qx, qy, b, px, py, i, j, gap, xy, block, start, ny, cell, d2)
            g = _square_margin(px, py, ci, cj, r, cell)
            if g >= cap or (g > 0.0 and d2 < g * g) or r > nx + ny:
                break
            r += 1
        if d2 < cap2:
            best[n] = math.sqrt(d2)


@kernel
def _square_margin(px, py, ci, cj, r, cell):
    """How far every point outside the cells within ``r`` of cell (ci, cj) is at least from the point
    (px, py) (from the grid's corner), less SLACK."""
    x = min(px - (ci - r) * cell, (ci + r + 1) * cell - px)
    y = min(py - (cj - r) * cell, (cj + r + 1) * cell - py)
    return min(x, y) - SLACK


@kernel
def _visit(qx, qy, b, px, py, i, j, gap, xy, block, start, ny, cell, d2):
    """``d2`` lowered by the points of cell (i, j) (see :func:`_cell_least`), unless the cell lies
    farther than sqrt(d2) from the query (at px, py from the grid's corner)."""
    if _gap2(px, i * cell, cell) + _gap2(py, j * cell, cell) >= d2:
        return d2
    c = i * ny + j
    return _cell_least(qx, qy, b, gap, xy, block, start[c], start[c + 1], d2)


@kernel
def _gap2(p, lo, cell):
    """Squared distance from coordinate p to the interval [lo, lo + cell], less SLACK (0 inside)."""
    d = max(lo - p, p - (lo + cell), 0.0) - SLACK
    return d * d if d > 0.0 else 0.0


@kernel
def _cell_least(px, py, b, gap, xy, block, s, e, d2):
    """The least of ``d2`` and the squared distances from (px, py) to the points [s, e) of one cell
    (in block order) whose block is at least ``gap`` from ``b``."""
    if s == e or (block[s] > b - gap and block[e - 1] < b + gap):
        return d2
    near_lo = s + np.searchsorted(block[s:e], b - gap, side="right")  # [near_lo, near_hi): too near in time
    near_hi = s + np.searchsorted(block[s:e], b + gap, side="left")
    return _least(px, py, xy, near_hi, e, _least(px, py, xy, s, near_lo, d2))


@kernel
def _least(px, py, xy, s, e, d2):
    """The least of ``d2`` and the squared distances from (px, py) to the points [s, e)."""
    for m in range(s, e):
        dx = xy[m, 0] - px
        dy = xy[m, 1] - py
        e2 = dx * dx + dy * dy
        if e2 < d2:
            d2 = e2
    return d2
