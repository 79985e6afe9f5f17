"""Nearest map point within a distance, on a bucket grid (Numba): the queries of every ICP iteration.

ICP (motion/icp.py) asks for the nearest local-map point of each of ~400–600 scan points, ~8 times per
scan, with a distance bound; through scipy's cKDTree that was about half of the scan-matching time, most
of it per-call overhead and tree descent on a map of ~1,000 points. Here the map points are bucketed in
square cells (a counting sort) and a query looks at the cells in rings around its own, nearest cells
first, skipping a cell whose box is already farther than the best point found or the bound.

The answer is the cKDTree's: squared distances are computed as it computes them (dx² + dy², no fused
multiply-add), a point counts when that is strictly below bound², and the distance returned is its
square root. Only an exact tie between two map points (equal squared distances to the last bit) may be
broken differently — which of the two the tree returns depends on its build. tests/test_nearest.py
compares the two on random and quantised point sets.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..features.jit import kernel

CELLS_PER_POINT = 8  # the grid has at most this many cells per map point (its memory and build time) ...
MIN_CELL = 0.1  # m: ... and cells no smaller than this
SLACK = 1e-9  # relative: a cell's box distance is compared with this margin (rounding of its corners)


@dataclass(frozen=True)
class BucketGrid:
    """Map points bucketed by cell: points ``xy`` (k, 2) sorted by cell, their indices ``index`` in the
    original array, and ``start`` (nx·ny + 1) where each cell's points begin (cell (i, j) is i·ny + j)."""

    xy: np.ndarray
    index: np.ndarray
    start: np.ndarray
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
        start = np.zeros(nx * ny + 1, dtype=np.int64)
        np.cumsum(np.bincount(key, minlength=nx * ny), out=start[1:])
        return BucketGrid(np.ascontiguousarray(points[order]), order, start, lo, cell, nx, ny)

    def query(self, q: np.ndarray, bound: float) -> tuple[np.ndarray, np.ndarray]:
        """(distance, index) of the nearest map point to each row of ``q`` closer than ``bound``; where
        there is none, inf and k (the number of map points) — as cKDTree.query with
        ``distance_upper_bound``."""
        dist = np.empty(len(q))
        idx = np.empty(len(q), dtype=np.int64)
        ox, oy = float(self.origin[0]), float(self.origin[1])
        _query(q, bound, self.xy, self.index, self.start, ox, oy, self.cell, self.nx, self.ny, dist, idx)
        return dist, idx


@kernel
def _query(q, bound, xy, index, start, ox, oy, cell, nx, ny, dist, idx):
    """Fill ``dist``/``idx`` (see :meth:`BucketGrid.query`)."""
    k = len(xy)
    rings = int(bound / cell) + 2  # every cell a point closer than ``bound`` can lie in
    for n in range(len(q)):
        px, py = q[n, 0], q[n, 1]
        cx, cy = int(math.floor((px - ox) / cell)), int(math.floor((py - oy) / cell))
        best, found = bound * bound, -1
        for r in range(rings):
            near = (r - 1) * cell  # no point of ring r (cells r away from q's) is nearer than this
            if near > 0.0 and near * near * (1.0 - SLACK) >= best:
                break
            for i in range(max(cx - r, 0), min(cx + r, nx - 1) + 1):
                if i == cx - r or i == cx + r:  # a full column of the ring
                    j0, j1, step = max(cy - r, 0), min(cy + r, ny - 1), 1
                else:  # its two ends
                    j0, j1, step = cy - r, cy + r, max(2 * r, 1)
                for j in range(j0, j1 + 1, step):
                    if 0 <= j < ny:
                        best, found = _scan_cell(
                            px,
                            py,
                            xy,
                            index,
                            start,
                            i * ny + j,
                            ox + i * cell,
                            oy + j * cell,
                            cell,
                            best,
                            found,
                        )
            if cx - r <= 0 and cx + r >= nx - 1 and cy - r <= 0 and cy + r >= ny - 1:
                break  # the ring covered the whole grid
        if found < 0:
            dist[n], idx[n] = np.inf, k
        else:
            dist[n], idx[n] = math.sqrt(best), found


@kernel
def _scan_cell(px, py, xy, index, start, c, x0, y0, cell, best, found):
    """(best squared distance, its point) after the points of cell ``c`` (lower-left corner x0, y0),
    unless the whole cell is farther than ``best``. A point counts when strictly nearer (as cKDTree);
    an exact tie goes to the lower index."""
    if start[c] == start[c + 1] or _box2(px, py, x0, y0, cell) > best * (1.0 + SLACK):
        return best, found
    for m in range(start[c], start[c + 1]):
        dx = xy[m, 0] - px
        dy = xy[m, 1] - py
        d2 = dx * dx + dy * dy
        if d2 < best or (d2 == best and 0 <= index[m] < found):
            best, found = d2, index[m]
    return best, found


@kernel
def _box2(px, py, x0, y0, cell):
    """Squared distance from (px, py) to the box [x0, x0 + cell] × [y0, y0 + cell]."""
    dx = max(x0 - px, 0.0, px - x0 - cell)
    dy = max(y0 - py, 0.0, py - y0 - cell)
    return dx * dx + dy * dy
