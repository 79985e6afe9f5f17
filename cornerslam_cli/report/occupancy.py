"""The occupancy grid of a run: ``map.pgm`` + ``map.yaml`` (ROS map_server / nav2) and ``map_grid.png``.

Every keyframe's valid beams are ray traced from the laser's pose at the step's estimate (the pose
trajectory.csv holds, in the odometry frame): the cells a beam passes through count as passes, the
cell it ends in as a hit. A cell is occupied when at least one in ``HIT_SHARE`` of the beams that
reach it end in it (gmapping's ``occ_thresh`` of 0.25), free when beams reach it and fewer end there,
unknown when no beam reaches it. Beams without a return (NaN, inf, out of range) mark nothing, nor do
beams longer than ``MAX_BEAM`` (a range no laser measures: 1e30 m in a log with range_max = inf).

The scans are kept (float32, the odometry frame relative to the first scan's laser position, so that
odometry far from its origin — UTM-scale coordinates — keeps millimetres) until the run ends, when
the map's extent is known;
past ``MAX_POINTS`` end points the store keeps every second beam (and so on), and a grid of more than
``grid.max_cells`` cells is written at a coarser resolution: both with a warning. A cell costs five
bytes (two uint16 counts, saturating at 65,535 beams, and its value) plus the PNG's one or two. Ray tracing is
compiled (Numba): each beam is sampled once per cell along its major axis (a DDA line), in float32 cell
units; :func:`line_cells` is the same sampling in numpy (the trajectory in ``map_grid.png``).

The files follow ROS map_saver: ``mode: trinary``, pixels 0 (occupied), 254 (free), 205 (unknown),
``occupied_thresh: 0.65``, ``free_thresh: 0.196``, ``negate: 0``; the image's first row is the top
(largest y) and ``origin`` is the pose of the lower-left pixel's corner in the odometry frame.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..features.jit import kernel

OCCUPIED, FREE, UNKNOWN = 0, 254, 205  # map_saver's trinary pixel values
OCCUPIED_THRESH, FREE_THRESH = 0.65, 0.196  # map_saver's thresholds: 0 → occupied, 254 → free, 205 → unknown
HIT_SHARE = 4  # a cell is occupied when at least 1 in HIT_SHARE of the beams reaching it end in it
MAX_POINTS = 8_000_000  # end points kept (64 MB as float32) before the store is thinned
MAX_BEAM = 1000.0  # m: longer beams (a range of 1e30 m in a log with range_max = inf) are not traced
CHUNK = 500_000  # beams traced (or cells classified) at once: ~40 MB of temporaries
COUNT_MAX = np.iinfo(np.uint16).max  # beams ending in / passing a cell are counted up to this
PATH = 1  # the trajectory's pixels in map_grid.png (a palette image: one byte per cell)
PNG_COLOURS = {OCCUPIED: (0, 0, 0), FREE: (255, 255, 255), UNKNOWN: (190, 190, 190), PATH: (31, 119, 180)}


class ScanStore:
    """The scans of a run as rays: per scan the laser's position and its beams' end points, in the
    odometry frame (float32, less ``anchor``: the first scan's laser position, float64), thinned to at
    most ``max_points`` end points. The poses are kept packed (16 bytes a scan), and a thinned scan is a
    copy: a view would keep all of its beams."""

    def __init__(self, max_points: int = MAX_POINTS):
        self.max_points = max_points
        self.stride = 1  # every stride-th beam of a scan is kept
        self.origins = array("f")  # the laser's position per scan (x, y)
        self.headings = array("d")  # the laser's heading per scan (with origins: its pose)
        self.points: list[np.ndarray] = []
        self.n_points = 0
        self.n_seen = 0  # end points given, before thinning
        self.anchor = np.zeros(2)  # what ``origins`` and ``points`` are stored less of (the first origin)

    def add(self, laser2odom: np.ndarray, points: np.ndarray) -> None:
        """One scan: ``points`` (k, 2) in the laser frame, the laser at pose ``laser2odom`` (x, y, θ)."""
        if not self.headings:
            self.anchor = np.array(laser2odom[:2], dtype=float)
        self.n_seen += len(points)
        c, s = math.cos(laser2odom[2]), math.sin(laser2odom[2])
        p = np.asarray(points, dtype=float)[:: self.stride]
        p = p[np.hypot(p[:, 0], p[:, 1]) <= MAX_BEAM]
        at = np.asarray(laser2odom[:2], dtype=float) - self.anchor
        moved = np.column_stack((c * p[:, 0] - s * p[:, 1], s * p[:, 0] + c * p[:, 1])) + at
        self.origins.extend(at.astype(np.float32).tolist())
        self.headings.append(float(laser2odom[2]))
        self.points.append(moved.astype(np.float32))
        self.n_points += len(moved)
        while self.n_points > self.max_points:
            self.stride *= 2
            for i, q in enumerate(self.points):
                self.points[i] = q[::2].copy()
            self.n_points = sum(len(q) for q in self.points)

    def xy(self) -> np.ndarray:
        """(n, 2) float32 the laser's position per scan less ``anchor``: a view of the store's, written
        through."""
        return np.frombuffer(self.origins, dtype=np.float32).reshape(-1, 2)

    def poses(self) -> np.ndarray:
        """(n, 3) the laser's pose per scan (x, y, θ), float64."""
        return np.column_stack((self.xy() + self.anchor, self.headings))

    def move(self, index: np.ndarray, delta: np.ndarray) -> None:
        """Move scan i by the pose ``delta[index[i]]`` (x, y, θ, applied on the left: the smoothed
        pose of its step ∘ the pose it was kept at⁻¹); a zero delta leaves a scan untouched."""
        origins = self.xy()
        for i, k in enumerate(np.asarray(index)):
            dx, dy, dth = (float(v) for v in delta[k])
            if dx == 0.0 and dy == 0.0 and dth == 0.0:
                continue
            c, s = math.cos(dth), math.sin(dth)
            R = np.array([[c, -s], [s, c]])
            dx, dy = R @ self.anchor + (dx, dy) - self.anchor  # the same move of the stored (less anchor)
            origins[i] = (R @ origins[i].astype(float) + (dx, dy)).astype(np.float32)
            self.headings[i] += dth
            self.points[i] = (self.points[i].astype(float) @ R.T + (dx, dy)).astype(np.float32)

    def in_laser_frame(self, scans: slice = slice(None)) -> list[np.ndarray]:
        """The kept end points of each scan of ``scans`` (all by default) back in its laser's frame
        (float64), the scans' arrays views of one."""
        points = self.points[scans]
        if not points:
            return []
        n = [len(q) for q in points]
        xy = np.repeat(self.xy()[scans].astype(float), n, axis=0)
        c, s = per_point_rotations(np.frombuffer(self.headings)[scans], n)
        d = np.concatenate(points).astype(float) - xy
        out = np.column_stack((c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]))
        return np.split(out, np.cumsum(n)[:-1])

    def laser_frame(self) -> LaserFrame:
        """The kept scans in their lasers' frames as a sequence made on demand, a slice at a time."""
        return LaserFrame(self)

    def rays(self, scans: slice = slice(None)) -> tuple[np.ndarray, np.ndarray]:
        """(n, 2) start and (n, 2) end of every kept beam of ``scans`` (all by default), float64."""
        points = self.points[scans]
        if not points:
            return np.empty((0, 2)), np.empty((0, 2))
        counts = [len(q) for q in points]
        start = np.repeat(self.xy()[scans].astype(float), counts, axis=0)
        return start + self.anchor, np.concatenate(points).astype(float) + self.anchor

    def parts(self, size: int) -> list[slice]:
        """Consecutive runs of scans of about ``size`` kept end points each (a larger scan alone)."""
        ends = np.cumsum([len(q) for q in self.points])
        if not len(ends):
            return []
        cuts = np.searchsorted(ends, np.arange(size, ends[-1], size), side="right")
        edges = np.unique(np.concatenate(([0], cuts, [len(ends)])))
        return [slice(i, j) for i, j in zip(edges[:-1].tolist(), edges[1:].tolist(), strict=True)]


def per_point_rotations(headings: np.ndarray, counts: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """cos and sin of each scan's heading repeated for its ``counts`` points: math's, as the scans
    were once turned one at a time (numpy's may differ in the last bit)."""
    th = np.asarray(headings, dtype=float).tolist()
    return np.repeat([math.cos(t) for t in th], counts), np.repeat([math.sin(t) for t in th], counts)


class LaserFrame:
    """A :class:`ScanStore`'s scans back in their lasers' frames (float64 (k, 2) each), made when
    sliced: a long log's points are never all converted at once (report/consistency.py)."""

    def __init__(self, store: ScanStore):
        self.store = store

    def __len__(self) -> int:
        return len(self.store.points)

    def __getitem__(self, scans: slice) -> list[np.ndarray]:
        return self.store.in_laser_frame(scans)


@dataclass(frozen=True)
class Grid:
    """An occupancy grid: ``cells`` (rows, cols) of OCCUPIED / FREE / UNKNOWN, row 0 at the lowest y;
    cell (i, j) covers x ∈ origin_x + [j, j + 1)·resolution, y ∈ origin_y + [i, i + 1)·resolution."""

    cells: np.ndarray
    resolution: float
    origin: tuple[float, float]

    def nav_values(self) -> np.ndarray:
        """The cells as nav_msgs/OccupancyGrid's int8 values: 100 occupied, 0 free, −1 unknown."""
        values = np.full(self.cells.shape, -1, dtype=np.int8)
        values[self.cells == OCCUPIED] = 100
        values[self.cells == FREE] = 0
        return values

    def index(self, xy: np.ndarray) -> np.ndarray:
        """(n, 2) integer (row, col) of the cells holding the points ``xy`` (n, 2)."""
        ij = np.floor((np.asarray(xy, dtype=float) - self.origin) / self.resolution).astype(np.int64)
        return ij[:, ::-1]


def grid_shape(lo: np.ndarray, hi: np.ndarray, resolution: float) -> tuple[int, int]:
    """(rows, cols) of a grid at ``resolution`` covering [lo, hi] with one cell to spare."""
    cols, rows = (np.floor((hi - lo) / resolution).astype(np.int64) + 2).tolist()
    return rows, cols


def fitting_resolution(lo: np.ndarray, hi: np.ndarray, resolution: float, max_cells: int) -> float:
    """``resolution``, doubled until the grid over [lo, hi] has at most ``max_cells`` cells."""
    while math.prod(grid_shape(lo, hi, resolution)) > max_cells:
        resolution *= 2.0
    return resolution


def line_cells(start: np.ndarray, end: np.ndarray, lo: np.ndarray, resolution: float, cols: int):
    """Flat cell indices along the segments ``start`` → ``end`` (n, 2), one sample per cell along each
    segment's major axis, the end itself excluded; and the end's own flat cell per segment. Returns
    (beam of each sample, flat cell of each sample, flat cell of each end)."""
    a, b = cell_units(start, lo, resolution), cell_units(end, lo, resolution)
    d = b - a
    n = np.maximum(np.ceil(np.abs(d).max(axis=1)), 1.0).astype(np.int64)  # samples per segment
    beam = np.repeat(np.arange(len(n)), n)
    first = np.cumsum(n) - n
    t = (np.arange(len(beam)) - first[beam]).astype(np.float32) / n[beam].astype(np.float32)
    cells = _flat(a[beam, 0] + t * d[beam, 0], a[beam, 1] + t * d[beam, 1], cols)
    return beam, cells, _flat(b[:, 0], b[:, 1], cols)


def cell_units(xy: np.ndarray, lo: np.ndarray, resolution: float) -> np.ndarray:
    """The points ``xy`` (n, 2) in cell units from ``lo``, float32 (exact to 1/1000 cell)."""
    return ((xy - lo) / resolution).astype(np.float32)


def _flat(u: np.ndarray, v: np.ndarray, cols: int) -> np.ndarray:
    """Flat index (row · cols + col) of the cells holding the points (u, v), in cell units."""
    return np.floor(v).astype(np.int64) * cols + np.floor(u).astype(np.int64)


@kernel
def trace(a, b, cols, hits, passes):
    """Count the rays ``a`` → ``b`` (n, 2, float32 cell units) into ``hits`` (the end's cell) and
    ``passes`` (the other cells of :func:`line_cells`' samples, by the same float32 arithmetic),
    saturating at COUNT_MAX: what line_cells' cells would count, without its temporaries."""
    for k in range(len(a)):
        d0, d1 = b[k, 0] - a[k, 0], b[k, 1] - a[k, 1]
        n = max(math.ceil(max(abs(d0), abs(d1))), 1)
        end = math.floor(b[k, 1]) * cols + math.floor(b[k, 0])
        if hits[end] < COUNT_MAX:
            hits[end] += 1
        nf = np.float32(n)
        for i in range(n):
            t = np.float32(i) / nf
            cell = math.floor(a[k, 1] + t * d1) * cols + math.floor(a[k, 0] + t * d0)
            if cell != end and passes[cell] < COUNT_MAX:
                passes[cell] += 1


def build_grid(store: ScanStore, resolution: float, max_cells: int, warn: Callable[[str], None]) -> Grid:
    """Ray trace the stored scans into a :class:`Grid` at ``resolution`` (coarser when the map would
    exceed ``max_cells`` cells; a store thinned past ``MAX_POINTS``: both warned through ``warn``)."""
    parts = store.parts(CHUNK)  # rays made a part at a time: never all of a long log's at once
    if store.stride > 1:
        warn(
            f"occupancy grid: {store.n_seen} beams are more than {store.max_points}: "
            f"one beam in {store.stride} of each scan traced"
        )
    box = extent(store, parts)
    if box is None:
        return Grid(np.full((1, 1), UNKNOWN, dtype=np.uint8), resolution, (0.0, 0.0))
    lo, hi = box
    fit = fitting_resolution(lo, hi, resolution, max_cells)
    if fit != resolution:
        rows, cols = grid_shape(lo, hi, resolution)
        warn(
            f"occupancy grid: {cols} × {rows} cells at {resolution:g} m exceed grid.max_cells={max_cells}: "
            f"written at {fit:g} m"
        )
    rows, cols = grid_shape(lo, hi, fit)
    lo = lo - fit / 2  # half a cell of margin on each side
    hits = np.zeros(rows * cols, dtype=np.uint16)
    passes = np.zeros(rows * cols, dtype=np.uint16)
    for scans in parts:
        start, end = store.rays(scans)
        trace(cell_units(start, lo, fit), cell_units(end, lo, fit), cols, hits, passes)
    return Grid(classify(hits, passes).reshape(rows, cols), fit, (float(lo[0]), float(lo[1])))


def extent(store: ScanStore, parts: list[slice]) -> tuple[np.ndarray, np.ndarray] | None:
    """(lo, hi) corners of the box holding every kept beam's start and end; None when there is none."""
    lo = hi = None
    for scans in parts:  # float32 as stored (float64 only at the end: the same bounds)
        points = store.points[scans]
        seen = np.array([len(q) > 0 for q in points], dtype=bool)
        if seen.any():
            start, end = store.xy()[scans][seen], np.concatenate(points)
            a, b = np.minimum(start.min(0), end.min(0)), np.maximum(start.max(0), end.max(0))
            lo, hi = (a, b) if lo is None else (np.minimum(lo, a), np.maximum(hi, b))
    return None if lo is None else (lo.astype(float) + store.anchor, hi.astype(float) + store.anchor)


def classify(hits: np.ndarray, passes: np.ndarray) -> np.ndarray:
    """OCCUPIED / FREE / UNKNOWN per cell from the beams ending in it (``hits``) and passing it
    (``passes``): occupied when hits ≥ (hits + passes) / HIT_SHARE. In slices of CHUNK cells, so the
    temporaries stay small next to the counts."""
    cells = np.full(len(hits), UNKNOWN, dtype=np.uint8)
    for lo in range(0, len(cells), CHUNK):
        h, p = hits[lo : lo + CHUNK].astype(np.int32), passes[lo : lo + CHUNK].astype(np.int32)
        part = cells[lo : lo + CHUNK]
        part[p > 0] = FREE
        part[(h > 0) & ((HIT_SHARE - 1) * h >= p)] = OCCUPIED
    return cells


def write_grid(dest: Path, grid: Grid, name: str = "map") -> None:
    """``NAME.pgm`` (binary P5, top row first) and ``NAME.yaml`` (map_server) of ``grid`` in ``dest``."""
    rows, cols = grid.cells.shape
    with open(dest / f"{name}.pgm", "wb") as f:
        f.write(f"P5\n# cornerslam occupancy grid, {grid.resolution:g} m/cell\n{cols} {rows}\n255\n".encode())
        f.write(np.ascontiguousarray(grid.cells[::-1]).tobytes())
    (dest / f"{name}.yaml").write_text(
        f"image: {name}.pgm\n"
        "mode: trinary\n"
        f"resolution: {grid.resolution!r}\n"
        f"origin: [{grid.origin[0]!r}, {grid.origin[1]!r}, 0.0]\n"
        "negate: 0\n"
        f"occupied_thresh: {OCCUPIED_THRESH}\n"
        f"free_thresh: {FREE_THRESH}\n"
    )


def read_grid(dest: Path, name: str = "map") -> Grid | None:
    """The grid :func:`write_grid` wrote in ``dest`` (None when its NAME.pgm or NAME.yaml is missing or
    not of that form): the cells back with row 0 at the lowest y."""
    try:
        data = (dest / f"{name}.pgm").read_bytes()
        meta = dict(line.split(": ", 1) for line in (dest / f"{name}.yaml").read_text().splitlines())
        head = data.split(b"\n", 4)  # P5, the comment, "cols rows", 255, the pixels
        cols, rows = (int(v) for v in head[2].split())
        cells = np.frombuffer(head[4], dtype=np.uint8)[: rows * cols].reshape(rows, cols)[::-1]
        x, y, _ = (float(v) for v in meta["origin"].strip("[]").split(","))
        return Grid(np.ascontiguousarray(cells), float(meta["resolution"]), (x, y))
    except (OSError, ValueError, KeyError, IndexError):
        return None


def draw_grid(path: Path, grid: Grid, poses: np.ndarray) -> None:
    """``map_grid.png``: the grid (black occupied, white free, grey unknown), top row first, with the
    trajectory ``poses`` (n, 3) drawn in blue; one pixel per cell."""
    from PIL import Image  # matplotlib's own image library, without matplotlib's import time

    pixels = grid.cells.copy()
    if len(poses) > 1:
        rows, cols = grid.cells.shape
        lo = np.asarray(grid.origin)
        xy = np.clip(poses[:, :2], lo, lo + (np.array([cols, rows]) - 0.5) * grid.resolution)
        _, cells, ends = line_cells(xy[:-1], xy[1:], lo, grid.resolution, cols)
        pixels.reshape(-1)[np.concatenate((cells, ends))] = PATH
    palette = np.zeros((256, 3), dtype=np.uint8)
    for value, colour in PNG_COLOURS.items():
        palette[value] = colour
    image = Image.fromarray(np.ascontiguousarray(pixels[::-1]), mode="P")
    image.putpalette(palette.tobytes())
    image.save(path)
