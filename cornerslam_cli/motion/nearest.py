"""Nearest map points on a bucket grid (Numba): the queries of every ICP iteration and the neighbourhoods
of the local map's normals.

ICP (motion/icp.py) asks for the nearest local-map point of each of ~400–600 scan points, ~8 times per
scan, with a distance bound, and each local-map rebuild for the 7 nearest map points of every map point;
through scipy's cKDTree that was most of the scan-matching time, mostly per-call overhead and tree
descent on a map of ~1,000 points. Here the map points are bucketed in square cells (a counting sort),
and a query looks at the cells that overlap a square around its point, of half-width half a cell first,
doubled until the square holds the answer (every point nearer than the square's half-width lies in it)
or reaches the bound: most queries look at one to four cells. When the first square holds no point, a
summed-area table of the cells' counts tells whether the bound's square (the largest) holds any: if not,
no square does, and the answer ("none") is given without looking at them (a submap's points beyond the
other submap, in loop closing's fitness and first ICP iterations).

The answer is the cKDTree's: squared distances are computed as it computes them (dx² + dy², no fused
multiply-add), a point counts when that is strictly below bound², and the distance returned is its
square root. The answer is the least (squared distance, index), whatever order the cells are visited
in; only an exact tie between two map points (equal squared distances to the last bit) may be broken
differently from the tree — which of the two it returns depends on its build. tests/test_nearest.py
compares the two on random and quantised point sets.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..features.jit import kernel

CELLS_PER_POINT = 8  # the grid has at most this many cells per map point (its memory and build time) ...
MIN_CELL = 0.1  # m: ... and cells no smaller than this
FIRST_SQUARE = 0.5  # cells: half-width of a query's first square
SLACK = 1e-9  # relative (and metres): a square is widened by this (rounding of the cells' edges)


@dataclass(frozen=True)
class BucketGrid:
    """Map points bucketed by cell: points ``xy`` (k, 2) sorted by cell, their indices ``index`` in the
    original array, and ``start`` (nx·ny + 1) where each cell's points begin (cell (i, j) is i·ny + j);
    ``counts`` (nx + 1, ny + 1): how many points lie in the cells (< i, < j), a summed-area table."""

    xy: np.ndarray
    index: np.ndarray
    start: np.ndarray
    counts: np.ndarray
    origin: np.ndarray  # lower-left corner of cell (0, 0)
    cell: float
    nx: int
    ny: int

    @staticmethod
    def build(points: np.ndarray) -> BucketGrid:
        lo = points.min(axis=0)
        extent = points.max(axis=0) - lo
        area = float(extent[0] + MIN_CELL) * float(extent[1] + MIN_CELL)
        cell = max(MIN_CELL, math.sqrt(area / (CELLS_PER_POINT * len(points))))
        nx, ny = int(extent[0] / cell) + 1, int(extent[1] / cell) + 1
        ij = np.minimum(((points - lo) / cell).astype(np.int64), (nx - 1, ny - 1))
        key = ij[:, 0] * ny + ij[:, 1]
        order = np.argsort(key, kind="stable")
        per_cell = np.bincount(key, minlength=nx * ny)
        start = np.zeros(nx * ny + 1, dtype=np.int64)
        np.cumsum(per_cell, out=start[1:])
        counts = np.zeros((nx + 1, ny + 1), dtype=np.int64)
        np.cumsum(np.cumsum(per_cell.reshape(nx, ny), axis=0), axis=1, out=counts[1:, 1:])
        return BucketGrid(np.ascontiguousarray(points[order]), order, start, counts, lo, cell, nx, ny)

    def arrays(self) -> tuple:
        """The grid as :func:`nearest_within` takes it after the queries: (xy, index, start, counts, ox,
        oy, cell, nx, ny)."""
        ox, oy = float(self.origin[0]), float(self.origin[1])
        return self.xy, self.index, self.start, self.counts, ox, oy, self.cell, self.nx, self.ny

    def query(self, q: np.ndarray, bound: float) -> tuple[np.ndarray, np.ndarray]:
        """(distance, index) of the nearest map point to each row of ``q`` closer than ``bound``; where
        there is none, inf and k (the number of map points) — as cKDTree.query with
        ``distance_upper_bound``."""
        dist = np.empty(len(q))
        idx = np.empty(len(q), dtype=np.int64)
        nearest_within(q, bound, *self.arrays(), dist, idx)
        return dist, idx

    def neighbours(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(distances, indices), each (n, k), of the ``k`` ≤ n nearest map points of every map point
        (itself first), nearest first — as cKDTree.query(points, k)."""
        n = len(self.xy)
        dist, idx = np.empty((n, k)), np.empty((n, k), dtype=np.int64)
        points = np.empty_like(self.xy)
        points[self.index] = self.xy
        ox, oy = float(self.origin[0]), float(self.origin[1])
        _neighbours(points, self.xy, self.index, self.start, ox, oy, self.cell, self.nx, self.ny, dist, idx)
        return dist, idx


@kernel
def nearest_within(q, bound, xy, index, start, counts, ox, oy, cell, nx, ny, dist, idx):
    """Fill ``dist``/``idx`` (see :meth:`BucketGrid.query`)."""
    k = len(xy)
    for n in range(len(q)):
        px, py = q[n, 0], q[n, 1]
        half = min(bound, FIRST_SQUARE * cell)
        first = True
        while True:  # squares of doubling half-width: the first that holds a point within it has the nearest
            best_d2, best_i, _ = _nearest(px, py, half, xy, index, start, ox, oy, cell, nx, ny)
            if best_i >= 0 or not half < bound:  # (not <: also a NaN bound ends it)
                break
            # the squares grow to the bound's, each inside the next (_square is monotone in half): with no
            # point in that one, none finds one
            if first and _count(px, py, bound, counts, ox, oy, cell, nx, ny) == 0:
                break
            first = False
            half = min(2.0 * half, bound)
        if best_i < 0:
            dist[n], idx[n] = np.inf, k
        else:
            dist[n], idx[n] = math.sqrt(best_d2), best_i


@kernel
def nearest_within_moving(q, bound, xy, index, start, counts, ox, oy, cell, nx, ny, dist, idx, clear, at):
    """:func:`nearest_within` of points that move a little between calls (ICP's iterations), the same
    answers: a point's query that found nothing leaves in ``clear`` (len(q)) a distance within which no
    map point lies from where it then was, kept in ``at`` (len(q), 2); while the point has moved less
    than that distance less ``bound`` (and a rounding margin) since, nothing lies within ``bound`` of it
    either (triangle inequality) and it is answered without a look. ``clear`` < 0: not known (the
    caller starts with −1 everywhere)."""
    k = len(xy)
    for n in range(len(q)):
        px, py = q[n, 0], q[n, 1]
        if clear[n] >= 0.0 and clear[n] - math.hypot(px - at[n, 0], py - at[n, 1]) >= bound + _margin(
            px, py, ox, oy
        ):
            dist[n], idx[n] = np.inf, k
            continue
        half = min(bound, FIRST_SQUARE * cell)
        first = True
        while True:
            if half < bound:
                best_d2, best_i, _ = _nearest(px, py, half, xy, index, start, ox, oy, cell, nx, ny)
                if best_i >= 0:
                    break
                if first and _count(px, py, bound, counts, ox, oy, cell, nx, ny) == 0:
                    # (nearest_within's shortcut) no map point in the cells of the bound's square
                    i0, i1, j0, j1 = _square(px, py, bound, ox, oy, cell, nx, ny)
                    away = _clearance(px, py, np.inf, i0, i1, j0, j1, ox, oy, cell, nx, ny)
                    clear[n], at[n, 0], at[n, 1] = away - _margin(px, py, ox, oy), px, py
                    break
                first = False
                half = min(2.0 * half, bound)
                continue
            # the last square: also how far every map point is from (px, py) at the least
            best_d2, best_i, away = _nearest_and_clearance(
                px, py, half, xy, index, start, ox, oy, cell, nx, ny
            )
            if best_i < 0:
                clear[n], at[n, 0], at[n, 1] = away - _margin(px, py, ox, oy), px, py
            break
        if best_i < 0:
            dist[n], idx[n] = np.inf, k
        else:
            dist[n], idx[n] = math.sqrt(best_d2), best_i
            clear[n] = -1.0


@kernel
def _margin(px, py, ox, oy):
    """Metres: far more than the rounding of a clearance and of a move at these coordinates."""
    return 1e-9 * (1.0 + abs(px) + abs(py) + abs(ox) + abs(oy))


@kernel
def _nearest_and_clearance(px, py, half, xy, index, start, ox, oy, cell, nx, ny):
    """:func:`_nearest`, and a distance from (px, py) within which no map point lies (rounding aside):
    the least distance to the points of the cells looked at, or to the edge of those cells where cells
    lie beyond it, whichever is less — or, when that is less, the distance to the grid's box, which holds
    every map point."""
    best_d2, best_i, least = _nearest(px, py, half, xy, index, start, ox, oy, cell, nx, ny, True)
    i0, i1, j0, j1 = _square(px, py, half, ox, oy, cell, nx, ny)
    return best_d2, best_i, _clearance(px, py, least, i0, i1, j0, j1, ox, oy, cell, nx, ny)


@kernel
def _clearance(px, py, least, i0, i1, j0, j1, ox, oy, cell, nx, ny):
    """A distance from (px, py) within which no map point lies (rounding aside), the points of cells
    i0..i1 × j0..j1 being at squared distance ``least`` at the least: the less of √least and the distance
    to those cells' edge where cells lie beyond it — or, when more, the distance to the grid's box, which
    holds every map point."""
    box = max(ox - px, px - (ox + nx * cell), oy - py, py - (oy + ny * cell), 0.0)
    if i0 > i1 or j0 > j1:  # no cell looked at: the box alone
        return box
    inner = math.sqrt(least)
    if i0 > 0:
        inner = min(inner, px - (ox + i0 * cell))
    if i1 < nx - 1:
        inner = min(inner, ox + (i1 + 1) * cell - px)
    if j0 > 0:
        inner = min(inner, py - (oy + j0 * cell))
    if j1 < ny - 1:
        inner = min(inner, oy + (j1 + 1) * cell - py)
    return max(box, inner)


@kernel
def _count(px, py, half, counts, ox, oy, cell, nx, ny):
    """How many map points lie in the cells of the square of half-width ``half`` around (px, py)
    (:func:`_square`), from the summed-area table ``counts``."""
    i0, i1, j0, j1 = _square(px, py, half, ox, oy, cell, nx, ny)
    if i0 > i1 or j0 > j1:
        return 0
    return counts[i1 + 1, j1 + 1] - counts[i0, j1 + 1] - counts[i1 + 1, j0] + counts[i0, j0]


@kernel
def _nearest(px, py, half, xy, index, start, ox, oy, cell, nx, ny, track=False):
    """(squared distance, index) of the least such pair among the points of the cells overlapping the
    square of half-width ``half`` around (px, py) whose squared distance is below half², index −1 for
    none; with ``track``, the least squared distance of any point looked at (else inf).
    :func:`_collect` of a list of one entry, comparison for comparison, with the entry held in local
    variables rather than arrays (what ICP's queries spend their time in)."""
    i0, i1, j0, j1 = _square(px, py, half, ox, oy, cell, nx, ny)
    best_d2, best_i, least = half * half, -1, np.inf
    for i in range(i0, i1 + 1):
        for c in range(i * ny + j0, i * ny + j1 + 1):
            for m in range(start[c], start[c + 1]):
                dx = xy[m, 0] - px
                dy = xy[m, 1] - py
                e = dx * dx + dy * dy
                if track:
                    least = min(least, e)
                if e < best_d2 or (e == best_d2 and 0 <= index[m] < best_i):
                    best_d2, best_i = e, index[m]
    return best_d2, best_i, least


@kernel
def _neighbours(points, xy, index, start, ox, oy, cell, nx, ny, dist, idx):
    """Fill ``dist``/``idx`` (n, k) (see :meth:`BucketGrid.neighbours`)."""
    n, k = idx.shape
    d2, found = np.empty(k), np.empty(k, dtype=np.int64)
    for p in range(n):
        px, py = points[p, 0], points[p, 1]
        half = FIRST_SQUARE * cell
        while True:  # the k nearest within a square are the k nearest once the k-th is within its half-width
            d2[:], found[:] = np.inf, -1
            _collect(px, py, half, xy, index, start, ox, oy, cell, nx, ny, d2, found)
            if d2[k - 1] < half * half or _covers(px, py, half, ox, oy, cell, nx, ny) or half == np.inf:
                break
            half *= 2.0
        for j in range(k):
            dist[p, j], idx[p, j] = math.sqrt(d2[j]), found[j]


@kernel
def _collect(px, py, half, xy, index, start, ox, oy, cell, nx, ny, d2, found):
    """Merge the points of the cells overlapping the square of half-width ``half`` around (px, py) into
    the sorted lists ``d2``/``found`` of the len(d2) least (squared distance, index) so far; a point
    counts when strictly below the last entry's squared distance (an exact tie: the lower index first)."""
    i0, i1, j0, j1 = _square(px, py, half, ox, oy, cell, nx, ny)
    last = len(d2) - 1
    for i in range(i0, i1 + 1):
        for c in range(i * ny + j0, i * ny + j1 + 1):
            for m in range(start[c], start[c + 1]):
                dx = xy[m, 0] - px
                dy = xy[m, 1] - py
                e = dx * dx + dy * dy
                if e < d2[last] or (e == d2[last] and 0 <= index[m] < found[last]):
                    s = last  # insertion: shift the farther entries down
                    while s > 0 and (e < d2[s - 1] or (e == d2[s - 1] and index[m] < found[s - 1])):
                        d2[s], found[s] = d2[s - 1], found[s - 1]
                        s -= 1
                    d2[s], found[s] = e, index[m]


@kernel
def _square(px, py, half, ox, oy, cell, nx, ny):
    """Cell ranges (i0, i1, j0, j1), inclusive and inside the grid, of the square of half-width ``half``
    (widened by SLACK) around (px, py)."""
    h = half * (1.0 + SLACK) + SLACK
    if math.isnan(px) or math.isnan(py):
        return 0, -1, 0, -1
    # clamped as floats: a point far outside the grid gives an empty range, not an integer overflow
    i0 = min(max(math.floor((px - h - ox) / cell), 0.0), float(nx))
    i1 = max(min(math.floor((px + h - ox) / cell), nx - 1.0), -1.0)
    j0 = min(max(math.floor((py - h - oy) / cell), 0.0), float(ny))
    j1 = max(min(math.floor((py + h - oy) / cell), ny - 1.0), -1.0)
    return int(i0), int(i1), int(j0), int(j1)


@kernel
def _covers(px, py, half, ox, oy, cell, nx, ny):
    """Whether the square of half-width ``half`` around (px, py) covers the whole grid."""
    i0, i1, j0, j1 = _square(px, py, half, ox, oy, cell, nx, ny)
    return i0 == 0 and j0 == 0 and i1 == nx - 1 and j1 == ny - 1
