"""Map consistency: how well a trajectory's map agrees with itself, without ground truth.

Every scan's points are placed in the map with the trajectory under test, and two figures compare
the result with the same scans placed with the wheel odometry:

- **occupied cells**: distinct ``CELL``-sized grid cells hit by the placed points. The same walls drawn
  twice (a doubled or fanned-out map) occupy more cells, so fewer is crisper; the ratio to the
  odometry's count is the figure to read (below 1: the estimate draws a sharper map than the wheels).
- **revisit misalignment**: for each point, the distance to the nearest point of any scan at least
  ``REVISIT_GAP`` scans earlier or later (scans grouped in blocks of ``REVISIT_BLOCK``), capped at
  ``REVISIT_CAP`` m; the figure is the mean over the points that have such a neighbour within the cap
  (the parts of the building seen again after a loop), with the share of such points. A smaller
  figure is a map that agrees with itself across the loop.

Bounded memory: the placed points are never all held at once. The map is cut into **tiles**, rectangles
of ``BIN``-cell squares split at their weighted median until a tile holds at most ``TILE_POINTS`` points
(one square may hold more: a robot parked for a long time); a tile's points are placed again from the
scans, ``CHUNK`` points at a time, with those of a ``MARGIN`` around it (every neighbour within the cap
of a point inside). Each cell lies in one tile, so the occupied cells are the sum of the tiles' counts.
Inside a tile, the nearest earlier or later neighbour is found on a bucket grid whose cells hold their
points in block order (report/revisit_grid.py). The figures are those of the definition over all points
at once: the same cells and shares, and with one tile (up to a million kept beams: every sample log and
the real logs of the panel) the same mean bit for bit; with several, the mean is the sum of the tiles'
sums, which may differ from one sum in its last bits (relative 1e-15). Memory: one tile (~50 bytes a
point, its search ~50 more: the points sorted by cell, the answers) and one chunk (~150 bytes a point)
at a time, where all of a long log's points once took ~50 bytes each (peak traced on the 1,252-scan
simulated lap, 1.3 M points in four tiles: 55 MB; 50 MB with the kd-trees).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence

import numpy as np

from ..results import MapConsistency
from .occupancy import ScanStore, per_point_rotations
from .revisit_grid import nearest_far

CELL = 0.05  # m: the grid of the occupied-cell count
REVISIT_GAP = 100  # scans
REVISIT_CAP = 0.3  # m
REVISIT_BLOCK = 25  # scans: neighbours come from blocks at least REVISIT_GAP // REVISIT_BLOCK away
CHUNK = 50_000  # points placed at once (with their cells and blocks: ~4 MB)
BIN = 32  # cells (1.6 m): the squares tiles are made of
TILE_POINTS = 1_000_000  # points of a tile at most (unless one BIN square has more): ~50 MB of temporaries
MARGIN = math.ceil(REVISIT_CAP / CELL) + 1  # cells around a tile whose points it needs as neighbours


def place(pts: Sequence[np.ndarray], poses: np.ndarray) -> np.ndarray:
    """All scan points (each scan's (k, 2) points in its own frame) in the map frame, placed with
    ``poses`` (n, 3): one pose per scan."""
    if not len(pts):
        return np.empty((0, 2))
    p = np.concatenate(pts)
    n = [len(q) for q in pts]
    x, y, th = np.asarray(poses, dtype=float).reshape(-1, 3).T
    c, s = per_point_rotations(th, n)
    out = np.empty((len(p), 2))
    out[:, 0] = np.repeat(x, n) + c * p[:, 0] - s * p[:, 1]
    out[:, 1] = np.repeat(y, n) + s * p[:, 0] + c * p[:, 1]
    return out


def cell_index(xy: np.ndarray) -> np.ndarray:
    """(n, 2) int64 column and row of the ``CELL``-sized cell of each point (clipped to int32)."""
    return np.floor(np.clip(xy / CELL, -(2**31), 2**31 - 1)).astype(np.int64)


def _cell_keys(cells: np.ndarray) -> np.ndarray:
    """One int64 per cell (column, row): a 1-D unique counts them fast."""
    return (cells[:, 0] << 32) + (cells[:, 1] & 0xFFFFFFFF)


def placed_chunks(pts: Sequence[np.ndarray], poses: np.ndarray) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """The points placed with ``poses``, about ``CHUNK`` at a time (as many scans as the last ones
    suggest, at most twice as many as before): (placed (k, 2), block of each)."""
    i, n = 0, 1
    while i < len(pts):
        part = pts[i : i + n]
        scan = np.repeat(np.arange(i, i + len(part)), [len(p) for p in part])
        yield place(part, poses[i : i + len(part)]), scan // REVISIT_BLOCK
        i += len(part)
        n = max(1, min(2 * n, CHUNK * len(part) // max(len(scan), 1)))


def tiles(pts: Sequence[np.ndarray], poses: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The tiles of the placed points: (lo, hi) cell bounds (column, row; hi exclusive), together
    covering every point once (an empty list without points)."""
    keys, counts = np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    for xy, _ in placed_chunks(pts, poses):
        k, n = np.unique(_cell_keys(cell_index(xy) // BIN), return_counts=True)
        keys, inverse = np.unique(np.concatenate((keys, k)), return_inverse=True)
        counts = np.bincount(inverse, np.concatenate((counts, n))).astype(np.int64)
    if not len(keys):
        return []
    low = keys & 0xFFFFFFFF
    bins = np.column_stack((keys >> 32, low - (low >> 31 << 32)))  # the keys' (column, row) back
    return [(lo * BIN, hi * BIN) for lo, hi in split(bins, counts, bins.min(0), bins.max(0) + 1)]


def split(bins: np.ndarray, counts: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> list:
    """The box [lo, hi) of squares ``bins`` (m, 2) holding ``counts`` points, cut across its longer
    side at the weighted median into boxes of at most ``TILE_POINTS`` points (a single square is not
    cut); each box as (lo, hi)."""
    if counts.sum() <= TILE_POINTS:
        return [(lo, hi)]
    for axis in np.argsort(lo - hi, kind="stable"):  # the longer side first
        values, inverse = np.unique(bins[:, axis], return_inverse=True)
        if len(values) < 2:
            continue
        weight = np.cumsum(np.bincount(inverse.reshape(-1), counts))
        cut = values[min(int(np.searchsorted(weight, weight[-1] / 2)) + 1, len(values) - 1)]
        left = bins[:, axis] < cut
        left_hi, right_lo = hi.copy(), lo.copy()
        left_hi[axis] = right_lo[axis] = cut
        return [
            *split(bins[left], counts[left], lo, left_hi),
            *split(bins[~left], counts[~left], right_lo, hi),
        ]
    return [(lo, hi)]


def inside(cells: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Which of the cells (n, 2) lie in [lo, hi)."""
    x, y = cells[:, 0], cells[:, 1]
    return (x >= lo[0]) & (x < hi[0]) & (y >= lo[1]) & (y < hi[1])


def tile_points(
    pts: Sequence[np.ndarray], poses: np.ndarray, lo: np.ndarray, hi: np.ndarray, margin: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The placed points of the tile [lo, hi) and of ``margin`` cells around it, in scan order:
    (xy (k, 2), block of each, which are inside the tile itself, the tile's occupied cells)."""
    xy, blocks, own = [np.zeros((0, 2))], [np.zeros(0, dtype=np.int64)], [np.zeros(0, dtype=bool)]
    keys = [np.zeros(0, dtype=np.int64)]
    for p, b in placed_chunks(pts, poses):
        cells = cell_index(p)
        near = inside(cells, lo - margin, hi + margin)
        mine = inside(cells[near], lo, hi)
        xy.append(p[near])
        blocks.append(b[near])
        own.append(mine)
        keys.append(np.unique(_cell_keys(cells[near][mine])))
    return _joined(xy), _joined(blocks), _joined(own), len(np.unique(_joined(keys)))


def _joined(parts: list[np.ndarray]) -> np.ndarray:
    """The arrays of ``parts`` concatenated, the list emptied (its arrays freed before the next
    list is joined: one copy of a tile's points at a time, not two)."""
    joined = np.concatenate(parts)
    parts.clear()
    return joined


def figures(
    pts: Sequence[np.ndarray], poses: np.ndarray, revisit: bool = True
) -> tuple[int, int, float, float]:
    """(points, occupied cells, revisit mean, revisit share) of the scan points placed with ``poses``,
    a tile at a time; without ``revisit`` the revisit figures are NaN and 0."""
    cells, total, d_sum, d_count = 0, 0, 0.0, 0
    for lo, hi in tiles(pts, poses):
        xy, blocks, own, n_cells = tile_points(pts, poses, lo, hi, MARGIN if revisit else 0)
        cells += n_cells
        total += int(own.sum())
        if revisit:
            d = nearest_far(xy, blocks, own, REVISIT_GAP // REVISIT_BLOCK, REVISIT_CAP)
            d = d[np.isfinite(d)]
            d_sum += float(d.sum())  # one tile: the mean of all points, bit for bit
            d_count += len(d)
    mean = d_sum / d_count if d_count else float("nan")
    return total, cells, mean, d_count / max(total, 1)


def occupied_cells(pts: Sequence[np.ndarray], poses: np.ndarray) -> int:
    """Distinct ``CELL``-sized grid cells hit by the scan points placed with ``poses``."""
    return figures(pts, poses, revisit=False)[1]


def revisit_misalignment(pts: Sequence[np.ndarray], poses: np.ndarray) -> tuple[float, float]:
    """(mean capped nearest-neighbour distance over the revisited points, share of points revisited)
    of the scan points placed with ``poses``; NaN and 0 when no point is revisited."""
    return figures(pts, poses)[2:]


def map_consistency(pts: Sequence[np.ndarray], poses: np.ndarray, odoms: np.ndarray) -> MapConsistency:
    """The consistency figures of the scans ``pts`` placed with the estimate ``poses`` and with the
    odometry ``odoms`` (each (n, 3), one per scan, the scan's laser pose). ``pts`` is a sequence of
    (k, 2) arrays, sliced a few scans at a time (a :class:`ScanStore`'s ``laser_frame()`` view makes
    them on demand)."""
    points, cells, revisit, share = figures(pts, poses)
    _, odom_cells, odom_revisit, odom_share = figures(pts, odoms)
    return MapConsistency(
        cell=CELL,
        scans=len(pts),
        points=points,
        occupied_cells=cells,
        odom_occupied_cells=odom_cells,
        cells_vs_odom=cells / odom_cells if odom_cells else float("nan"),
        revisit_mean=revisit,
        revisit_share=share,
        odom_revisit_mean=odom_revisit,
        odom_revisit_share=odom_share,
    )


def store_consistency(store: ScanStore, odoms: np.ndarray) -> MapConsistency:
    """The map consistency of a run's kept scans (placed with the estimate) against the laser's
    poses by the odometry ``odoms`` (n, 3), one per kept scan."""
    return map_consistency(store.laser_frame(), store.poses(), odoms)
