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
pair of blocks.
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np

from ..motion.icp import voxel_thin
from ..results import MapConsistency
from .occupancy import ScanStore

CELL = 0.05  # m: the grid of the occupied-cell count
REVISIT_GAP = 100  # scans
REVISIT_CAP = 0.3  # m
REVISIT_BLOCK = 25  # scans: neighbours come from blocks at least REVISIT_GAP // REVISIT_BLOCK away


def place(pts: list[np.ndarray], poses: np.ndarray) -> np.ndarray:
    """All scan points (each scan's (k, 2) points in its own frame) in the map frame, placed with
    ``poses`` (n, 3): one pose per scan."""
    out = [np.zeros((0, 2))]
    for p, (x, y, th) in zip(pts, poses, strict=True):
        c, s = math.cos(th), math.sin(th)
        out.append(np.column_stack((x + c * p[:, 0] - s * p[:, 1], y + s * p[:, 0] + c * p[:, 1])))
    return np.vstack(out)


def occupied_cells(pts: list[np.ndarray], poses: np.ndarray, cell: float = CELL) -> int:
    """Distinct ``cell``-sized grid cells hit by the scan points placed with ``poses``."""
    return len(voxel_thin(place(pts, poses), cell))  # one index per occupied cell


def revisit_misalignment(pts: list[np.ndarray], poses: np.ndarray) -> tuple[float, float]:
    """(mean capped nearest-neighbour distance over the revisited points, share of points revisited)
    of the scan points placed with ``poses``; NaN and 0 when no point is revisited."""
    placed = place(pts, poses)
    block = np.repeat(np.arange(len(pts)), [len(p) for p in pts]) // REVISIT_BLOCK
    n_blocks = int(block[-1]) + 1 if len(block) else 0
    starts = np.searchsorted(block, np.arange(n_blocks + 1))
    gap = REVISIT_GAP // REVISIT_BLOCK
    trees = _block_trees(placed, starts)
    dists = []
    for b in range(n_blocks):
        q = placed[starts[b] : starts[b + 1]]
        best = np.full(len(q), np.inf)
        for lo, hi in ((0, b - gap + 1), (b + gap, n_blocks)):
            for tree in (trees(a, z) for a, z in dyadic_runs(lo, hi)):
                best = np.minimum(best, tree.query(q, distance_upper_bound=REVISIT_CAP)[0])
        dists.append(best[np.isfinite(best)])
    d = np.concatenate(dists) if dists else np.zeros(0)
    return (float(d.mean()) if len(d) else float("nan")), len(d) / max(len(placed), 1)


def _block_trees(placed: np.ndarray, starts: np.ndarray):
    """A cached function: the kd-tree of the points of blocks [a, z)."""
    from scipy.spatial import cKDTree

    @cache
    def tree(a: int, z: int) -> cKDTree:
        return cKDTree(placed[starts[a] : starts[z]])

    return tree


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
