"""Correlative scan matching (Olson, ICRA 2009): the best pose of a scan over a whole search window.

ICP (motion/icp.py) converges to the nearest minimum; from an odometry guess a few tenths of a radian
off, on a sparse scan that overlaps the map by half, that is often a wrong one. The correlative
matcher instead scores *every* pose of a window (rotations × translations on the grid's cells) and
keeps the best, so it finds the right basin whenever the window holds it; ICP then refines from
there. The window comes from the odometry's noise model (motion/fusion.py), so it is wide only when
the odometry is uncertain.

Score of a pose: the mean over the scan's points of a likelihood field L = exp(−d² / 2σ²), d the
distance from the point's cell to the nearest map point (a Euclidean distance transform on a grid
cropped to where the scan can land), minus a small pull towards the guess (``PULL``). Search as Olson's
multi-resolution method: every rotation of the window is scored on a coarse grid whose cells hold the
maximum of ``BLOCK`` × ``BLOCK`` fine cells — an upper bound of every fine translation inside — and
coarse cells are expanded best first until no bound beats the best fine score found (branch and bound:
the result equals the exhaustive fine search, which a test checks).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import NumericalError
from .search_kernels import block_max, branch_and_bound, coarse_sums, squared_distances

BLOCK = 4  # fine cells per coarse cell side
MAX_ANGLES = 121  # rotations scored per window at most (the step grows on wide windows)
MIN_ANGLE_STEP = 0.002  # rad
# score lost per (offset / window half-width)² on each axis: among poses that fit about equally (along a
# corridor) the one nearest the odometry wins, as Karto's and Olson's searches weigh by the motion prior
PULL = 0.01


@dataclass(frozen=True)
class Window:
    """Half-widths of the search around the guess: ``xy`` metres on each axis, ``theta`` radians."""

    xy: float
    theta: float

    def pull_widths(self) -> tuple[float, float]:
        """(xy, theta) that scale the pull towards the guess: at least 1e-9 (a window of no width is one
        cell with no pull, not 0/0)."""
        return max(self.xy, 1e-9), max(self.theta, 1e-9)


@dataclass(frozen=True)
class Exclusion:
    """Poses within ``xy`` metres and ``theta`` radians of ``pose``: left out of a search."""

    pose: np.ndarray
    xy: float
    theta: float

    def near(self, guess: np.ndarray, ox: np.ndarray, oy: np.ndarray, res: float) -> np.ndarray:
        """(len(ox), len(oy)) whether the positions guess + (ox, oy)·res are within ``xy`` of the pose."""
        dx = guess[0] + ox * res - self.pose[0]
        dy = guess[1] + oy * res - self.pose[1]
        return dx[:, None] ** 2 + dy[None, :] ** 2 <= self.xy**2

    def turned(self, heading: float) -> bool:
        """Whether ``heading`` is within ``self.theta`` radians of the pose's."""
        return abs(math.remainder(heading - float(self.pose[2]), math.tau)) <= self.theta


@dataclass(frozen=True)
class SearchResult:
    pose: np.ndarray  # best pose (x, y, θ) on the search grid
    score: float  # its mean likelihood, in [0, 1], minus the pull towards the guess
    evaluated: int  # fine poses scored (the exhaustive search scores angles × (2W + 1)²)


def likelihood_field(
    map_points: np.ndarray, lo: np.ndarray, shape: tuple[int, int], res: float, sigma: float
):
    """L (shape) over the cells whose lower-left corner is ``lo`` + res·(i, j): exp(−d²/2σ²), d the
    distance (m) from the cell to the nearest cell holding a map point."""
    cells = np.floor((map_points - lo) / res).astype(np.int64)
    inside = (cells >= 0).all(axis=1) & (cells[:, 0] < shape[0]) & (cells[:, 1] < shape[1])
    free = np.ones(shape, dtype=bool)
    free[cells[inside, 0], cells[inside, 1]] = False
    if free.all():
        return np.zeros(shape)
    return blur(squared_distances(free), res, sigma)  # ndimage.distance_transform_edt(free) ** 2, compiled


# exp(x) of float64 is 0.0 below this (the smallest subnormal is exp(−744.44)): a margin past it
EXP_ZERO = 746.0


def blur(sq: np.ndarray, res: float, sigma: float) -> np.ndarray:
    """exp(−d²/2σ²) of d = √sq · res, for ``sq`` (float64) holding squared cell distances (integers): the
    same numpy arithmetic as on the whole field, but on one table of the values 0 … k and a gather — a
    field has ~10⁵ cells, and past k = ⌈2 · EXP_ZERO · (σ/res)²⌉ (~1,500 at the front end's σ = res; ~370
    for loop closing's coarser grid) the blur is 0.0, which the cells beyond k take from the table's last
    entry. Bit for bit the direct formula (tested): the same correctly rounded √, ×, ÷ and the same exp on
    each value; the direct formula when the table would be no smaller than the field."""
    top = int(sq.max()) if sq.size else 0
    zero_at = 2.0 * EXP_ZERO * (sigma / res) ** 2  # (√k·res/σ)²/2 ≥ EXP_ZERO from here on
    k = min(top, int(math.ceil(zero_at)))
    if k + 1 <= sq.size:  # (a table no smaller than the field saves nothing: not built)
        table = np.exp(-0.5 * ((np.sqrt(np.arange(k + 1, dtype=float)) * res) / sigma) ** 2)
        if k == top or table[k] == 0.0:  # (else no zero where one was expected: the formula)
            return table[np.minimum(sq, k).astype(np.intp)]
    return np.exp(-0.5 * ((np.sqrt(sq) * res) / sigma) ** 2)


def angle_steps(points: np.ndarray, theta: float, res: float) -> np.ndarray:
    """Rotations (offsets from the guess) of a window of half-width ``theta``: a step that moves the
    90th-percentile-range point by one cell (Olson), coarser when that would exceed MAX_ANGLES."""
    r = float(np.percentile(np.hypot(points[:, 0], points[:, 1]), 90)) if len(points) else 1.0
    step = max(res / max(r, res), MIN_ANGLE_STEP, 2.0 * theta / (MAX_ANGLES - 1))
    k = int(np.floor(theta / step + 1e-9))
    return step * np.arange(-k, k + 1)


def search(
    points: np.ndarray,
    map_points: np.ndarray,
    guess: np.ndarray,
    window: Window,
    res: float,
    sigma: float,
    exclude: Exclusion | None = None,
) -> SearchResult:
    """The pose in ``window`` around ``guess`` that maximises the mean likelihood of ``points`` (base
    frame) on the field of ``map_points`` (motion frame) minus a small pull towards the guess;
    ``exclude``: poses near one already found are not candidates (the runner-up of an ambiguity test)."""
    return Search.prepare(points, map_points, guess, window, res, sigma).best(exclude)


@dataclass(frozen=True, eq=False)
class Search:
    """One search's field, rotated points and coarse bounds (:meth:`prepare`), asked for its best pose
    (:meth:`best`) once or more: the runner-up of an ambiguity test searches the same field again."""

    guess: np.ndarray
    window: Window
    res: float
    W: int  # the window's half-width in cells: offsets −W..W on each axis
    dthetas: np.ndarray  # (A,) rotations from the guess
    L: np.ndarray  # the likelihood field
    px: np.ndarray  # (A, n) cell of each rotated point at the window's lowest offset (−W, −W)
    py: np.ndarray
    bound: np.ndarray  # (A, nc, nc) upper bound of every fine score in each coarse cell
    order: np.ndarray  # flat indices of ``bound``, best first

    @staticmethod
    def prepare(
        points: np.ndarray,
        map_points: np.ndarray,
        guess: np.ndarray,
        window: Window,
        res: float,
        sigma: float,
    ) -> Search:
        """The field of ``map_points`` around where ``points`` can land from ``guess`` within ``window``,
        the points' cells at each rotation and the coarse bounds (arguments as :func:`search`)."""
        if not (sigma > 0.0 and math.isfinite(sigma)):
            raise ValueError(f"correlative search: sigma must be positive and finite, got {sigma}")
        W = int(np.ceil(window.xy / res))
        n_side = 2 * W + 1
        dthetas = angle_steps(points, window.theta, res)
        thetas = guess[2] + dthetas
        c, s = np.cos(thetas), np.sin(thetas)
        # (A, n, 2) scan points rotated by each candidate heading and placed at the guess's position
        rx = c[:, None] * points[None, :, 0] - s[:, None] * points[None, :, 1] + guess[0]
        ry = s[:, None] * points[None, :, 0] + c[:, None] * points[None, :, 1] + guess[1]
        margin = window.xy + 3.0 * sigma + 2.0 * res
        lo = np.array([rx.min() - margin, ry.min() - margin])
        hi = np.array([rx.max() + margin, ry.max() + margin])
        shape = tuple(int(v) for v in np.ceil((hi - lo) / res) + BLOCK)
        L = likelihood_field(map_points, lo, shape, res, sigma)
        px = np.floor((rx - lo[0]) / res).astype(np.int64) - W
        py = np.floor((ry - lo[1]) / res).astype(np.int64) - W
        n = points.shape[0]
        nc = -(-n_side // BLOCK)  # coarse cells per side
        offs = BLOCK * np.arange(nc)
        # the compiled sums index without bounds checks: every cell they read must be on the field
        reach = max(2 * W, int(offs[-1]))
        if min(px.min(), py.min()) < 0 or px.max() + reach >= L.shape[0] or py.max() + reach >= L.shape[1]:
            raise NumericalError(f"correlative search: poses off the field (guess {guess}, window {window})")
        # bound[a, i, j] = Σ_points U[px + 4i, py + 4j] / n ≥ every fine score of coarse cell (i, j)
        bound = coarse_sums(block_max(L, BLOCK), px, py, offs) / n
        # minus the smallest pull towards the guess inside each coarse cell: still a bound
        near = np.clip(0, offs - W, offs + BLOCK - 1 - W)  # per axis, the cell offset closest to the guess
        xy, theta = window.pull_widths()
        bound -= PULL * (
            (dthetas / theta)[:, None, None] ** 2
            + ((near * res / xy) ** 2)[None, :, None]
            + ((near * res / xy) ** 2)[None, None, :]
        )
        order = np.argsort(-bound, axis=None, kind="stable")
        return Search(guess, window, res, W, dthetas, L, px, py, bound, order)

    def best(self, exclude: Exclusion | None = None) -> SearchResult:
        """The best pose of the window (but those ``exclude`` covers): branch and bound over the coarse
        cells, best bound first (search_kernels.branch_and_bound)."""
        guess, window, res, W = self.guess, self.window, self.res, self.W
        n_side = 2 * W + 1
        thetas = guess[2] + self.dthetas
        offsets = np.arange(n_side) - W
        xy, theta = window.pull_widths()
        shift_term = (offsets * res / xy) ** 2
        turn_term = np.array([(d / theta) ** 2 for d in self.dthetas])
        if exclude is None:
            excluded, turned = np.zeros((n_side, n_side), dtype=bool), np.zeros(len(thetas), dtype=bool)
        else:
            excluded = exclude.near(guess, offsets, offsets, res)
            turned = np.array([exclude.turned(t) for t in thetas], dtype=bool)
        score, a, ox, oy, evaluated = branch_and_bound(
            self.L,
            self.px,
            self.py,
            self.bound,
            self.order,
            n_side,
            BLOCK,
            PULL,
            turn_term,
            shift_term,
            excluded,
            turned,
        )
        if a < 0:
            return SearchResult(guess.copy(), score, evaluated)
        pose = np.array([guess[0] + (ox - W) * res, guess[1] + (oy - W) * res, thetas[a]])
        return SearchResult(pose, score, evaluated)
