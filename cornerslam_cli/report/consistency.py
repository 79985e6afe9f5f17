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

The nearest earlier or later neighbour is found in kd-trees over power-of-two runs of blocks (a range
of blocks is at most two such runs per level), so a long log costs O(n log n), not one tree query per
pair of blocks. The trees are built one at a time, each asked by every block that needs it, so memory
holds one tree, not one per run (together some ten copies of a long log's points).
"""

from __future__ import annotations

import math

import numpy as np

from ..motion.icp import cell_keys
from ..results import MapConsistency
from .occupancy import ScanStore

CELL = 0.05  # m: the grid of the occupied-cell count
REVISIT_GAP = 100  # scans
REVISIT_CAP = 0.3  # m
REVISIT_BLOCK = 25  # scans: neighbours come from blocks at least REVISIT_GAP // REVISIT_BLOCK away
OCCUPIED_SCANS = 500  # scans whose occupied cells are found at once


def place(pts: list[np.ndarray], poses: np.ndarray) -> np.ndarray:
    """All scan points (each scan's (k, 2) points in its own frame) in the map frame, placed with
    ``poses`` (n, 3): one pose per scan."""
    offsets = scan_offsets(pts)
    out = np.empty((offsets[-1], 2))  # filled in place: no second copy of a long log's points
    for i, (p, (x, y, th)) in enumerate(zip(pts, poses, strict=True)):
        c, s = math.cos(th), math.sin(th)
        out[offsets[i] : offsets[i + 1], 0] = x + c * p[:, 0] - s * p[:, 1]
        out[offsets[i] : offsets[i + 1], 1] = y + s * p[:, 0] + c * p[:, 1]
    return out


def scan_offsets(pts: list[np.ndarray]) -> np.ndarray:
    """(n + 1,) where each scan's points start in :func:`place`'s array, and their total last."""
    return np.concatenate(([0], np.cumsum([len(p) for p in pts], dtype=np.int64)))


def occupied_cells(pts: list[np.ndarray], poses: np.ndarray, cell: float = CELL) -> int:
    """Distinct ``cell``-sized grid cells hit by the scan points placed with ``poses``: the cells of
    ``OCCUPIED_SCANS`` scans at a time (a long log's temporaries stay small), then their union."""
    cells = [np.zeros(0, dtype=np.int64)]
    for i in range(0, len(pts), OCCUPIED_SCANS):
        cells.append(
            np.unique(cell_keys(place(pts[i : i + OCCUPIED_SCANS], poses[i : i + OCCUPIED_SCANS]), cell))
        )
    return len(np.unique(np.concatenate(cells)))


def revisit_misalignment(pts: list[np.ndarray], poses: np.ndarray) -> tuple[float, float]:
    """(mean capped nearest-neighbour distance over the revisited points, share of points revisited)
    of the scan points placed with ``poses``; NaN and 0 when no point is revisited."""
    from scipy.spatial import cKDTree

    placed = place(pts, poses)
    offsets = scan_offsets(pts)
    seen = np.flatnonzero(np.diff(offsets))  # the scans with points
    n_blocks = int(seen[-1]) // REVISIT_BLOCK + 1 if len(seen) else 0
    starts = offsets[np.minimum(REVISIT_BLOCK * np.arange(n_blocks + 1), len(pts))]  # block b's first point
    best = np.full(len(placed), np.inf)
    for (a, z), blocks in _runs_asked(n_blocks).items():
        tree = cKDTree(placed[starts[a] : starts[z]])  # one tree at a time: memory of one, not of all
        for b in blocks:
            q = slice(starts[b], starts[b + 1])
            best[q] = np.minimum(best[q], tree.query(placed[q], distance_upper_bound=REVISIT_CAP)[0])
        del tree
    d = best[np.isfinite(best)]
    return (float(d.mean()) if len(d) else float("nan")), len(d) / max(len(placed), 1)


def _runs_asked(n_blocks: int) -> dict[tuple[int, int], list[int]]:
    """Per run of blocks [a, z) (:func:`dyadic_runs`), the blocks whose points look for a neighbour in
    it: every block b asks the runs covering the blocks at least ``REVISIT_GAP // REVISIT_BLOCK``
    before and after it."""
    gap = REVISIT_GAP // REVISIT_BLOCK
    asked: dict[tuple[int, int], list[int]] = {}
    for b in range(n_blocks):
        for lo, hi in ((0, b - gap + 1), (b + gap, n_blocks)):
            for run in dyadic_runs(lo, hi):
                asked.setdefault(run, []).append(b)
    return asked


def dyadic_runs(lo: int, hi: int) -> list[tuple[int, int]]:
    """[lo, hi) as aligned power-of-two runs [a, a + 2^k) (a divisible by 2^k), fewest first-to-last;
    empty when lo >= hi."""
    runs = []
    lo = max(lo, 0)
    while lo < hi:
        size = lo & -lo if lo else 1 << (hi - 1).bit_length()
        while lo + size > hi:
            size //= 2
        runs.append((lo, lo + size))
        lo += size
    return runs


def map_consistency(pts: list[np.ndarray], poses: np.ndarray, odoms: np.ndarray) -> MapConsistency:
    """The consistency figures of the scans ``pts`` placed with the estimate ``poses`` and with the
    odometry ``odoms`` (each (n, 3), one per scan, the scan's laser pose)."""
    cells, odom_cells = occupied_cells(pts, poses), occupied_cells(pts, odoms)
    revisit, share = revisit_misalignment(pts, poses)
    odom_revisit, odom_share = revisit_misalignment(pts, odoms)
    return MapConsistency(
        cell=CELL,
        scans=len(pts),
        points=sum(len(p) for p in pts),
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
    laser_poses = np.column_stack((np.asarray(store.origins).reshape(-1, 2), store.headings))
    return map_consistency(store.in_laser_frame(), laser_poses, odoms)
