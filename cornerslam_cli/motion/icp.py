"""Scan matching: point-to-line ICP of each keyframe against a local map of the previous ones.

Wheel odometry on real robots drifts in heading by degrees per turn (Intel log: 99th percentile 16° per
scan), and corners alone rarely fix heading (a single corner constrains position, not heading, and the
paper's φ is pose-invariant). The usual cure, as in laser_scan_matcher or KISS-ICP, is to refine each
odometry increment by registering the scan; the refined pose chain is then the filter's motion input.

Frames: points in the robot base frame; poses (x, y, θ) in the *motion frame*, which starts at the first
odometry pose and is what the filter's prediction differentiates. The local map holds the last
``window`` scans that moved the robot far enough, placed with their refined poses and thinned to one
point per voxel, and (``near_history`` > 0) those of the older map scans whose pose lies near the robot's
(:func:`near_scans`: a place revisited, or passed slowly). Per scan:

1. guess = previous refined pose ∘ wheel increment;
2. Gauss–Newton on Σ ρ(nᵢ·(R pᵢ + t − qᵢ)) with qᵢ the nearest map point and nᵢ its normal (PCA of its 5
   neighbours; points on no line get none and are skipped), ρ a Cauchy kernel, correspondences within a
   distance shrinking from ``max_distance`` to ``min_distance``, plus a weak prior towards the guess so a
   corridor (unconstrained along its axis) keeps the wheel estimate along it;
3. fit = share of scan points within ``inlier_distance`` of the map; when the odometry's window
   (``search_sigmas`` σ of its noise model) is wider than ICP's basin (``search_min_*``), ICP also runs
   from the best pose of a correlative search over it (motion/correlative.py: a wrong odometry turn is
   the usual cause) and is kept when it fits better by ``FIT_MARGIN``;
4. below ``min_fit`` the wheel increment is used and the frame is flagged; otherwise the match is fused
   with the wheel increment by their covariances (motion/fusion.py).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..geometry import (
    apart,
    compose,
    pose_from_matrix,
    relative,
    rotate_pose_covariance,
    transform_points,
    within_range,
    wrap_angle,
)
from .correlative import Window, search
from .fusion import BiasTaken, OdometryFusion, student_fit
from .kernels import first_in_cell, icp_iterations, line_terms, neighbour_scatter
from .nearest import BucketGrid
from .params import ScanMatchConfig

NORMAL_NEIGHBOURS = 5
NORMAL_MAX_SPREAD = 0.5  # m: the 5th neighbour farther than this → no normal (isolated point)
NORMAL_FLATNESS = 0.2  # smaller / larger eigenvalue of the neighbourhood scatter below this → on a line
NORMAL_TIE = 1e-9  # relative: a neighbour this close to the 5th's distance is tied with it and joins
NORMAL_TIED_EXTRA = 2  # neighbours queried beyond the 5th to find those tied with it
SHRINK = 0.5
MAX_RHO = 0.98  # residual correlation used at most: an inflation of 99
FIT_EVIDENCE = 0.1  # a match fitting this much better than the odometry's pose outvotes it past the gate
FIT_MARGIN = 0.02  # a fit better by more than this replaces the match from the odometry's guess
CONVERGED = 1e-4  # largest step component (m or rad) that ends the iterations


def voxel_thin(points: np.ndarray, size: float) -> np.ndarray:
    """Indices of one point per ``size`` × ``size`` cell (the first in input order); all when size is 0."""
    if size <= 0 or len(points) == 0:
        return np.arange(len(points))
    return first_in_cell(np.ascontiguousarray(points, dtype=float), float(size))


def line_normals(points: np.ndarray, grid: BucketGrid) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (k, 2) of the line each point lies on (PCA of its 5 nearest neighbours) and which
    points have one (neighbours close and on a line; a point in clutter gets none).

    Neighbours as far as the 5th (to ``NORMAL_TIE``) join it: on a laser scan with ranges quantised to
    1 cm, the two beams either side of a point are often exactly equidistant from it, and which one the
    kd-tree calls 5th would otherwise be decided by the last bit of the coordinates — so by the CPU's
    floating-point kernels (docs/results/intel_spread.md). ``grid`` is the bucket grid of ``points``
    (motion/nearest.py: the kd-tree's neighbours, faster).
    """
    n = len(points)
    k = min(NORMAL_NEIGHBOURS, n)
    q = min(NORMAL_NEIGHBOURS + NORMAL_TIED_EXTRA, n)
    dist, idx = grid.neighbours(q)
    # the k nearest and any tied with the k-th; their 2×2 scatter [[a, b], [b, c]] about their mean
    a, b, c = scatter = np.empty((3, n))  # rows: contiguous, as numpy's SIMD loops below had them
    neighbour_scatter(points, dist, idx, k, NORMAL_TIE, scatter)
    # in closed form (batched eigh is slower): major axis at angle ψ with tan 2ψ = 2b / (a − c),
    # eigenvalues (a + c)/2 ± h
    psi = 0.5 * np.arctan2(2.0 * b, a - c)
    h = np.hypot(0.5 * (a - c), b)
    small, large = 0.5 * (a + c) - h, 0.5 * (a + c) + h
    on_line = (dist[:, k - 1] < NORMAL_MAX_SPREAD) & (small < NORMAL_FLATNESS * large)
    normals = np.column_stack((-np.sin(psi), np.cos(psi)))
    return normals, on_line & (k == NORMAL_NEIGHBOURS)


def overlap(grid: BucketGrid, points: np.ndarray, inlier_distance: float) -> float:
    """Share of ``points`` within ``inlier_distance`` of the points of ``grid``."""
    dist, _ = grid.query(points, inlier_distance)
    return float(np.mean(dist < inlier_distance))


@dataclass
class LocalMap:
    """Map points (k, 2), their bucket grid (the nearest-point queries of ICP and the normals'
    neighbourhoods: motion/nearest.py), unit normals (k, 2) and which points have a usable normal.

    ``padded_points``/``padded_normals`` have one extra row (a zero normal) at index k, where the
    grid sends queries with no neighbour in range: residual and Jacobian rows of such points, and of
    points without a normal, are then zero without any masking.
    """

    points: np.ndarray
    grid: BucketGrid
    normals: np.ndarray
    has_normal: np.ndarray
    padded_points: np.ndarray
    padded_normals: np.ndarray

    @staticmethod
    def build(points: np.ndarray) -> LocalMap:
        grid = BucketGrid.build(points)
        normals, has_normal = line_normals(points, grid)
        padded_points = np.vstack((points, np.zeros((1, 2))))
        padded_normals = np.vstack((np.where(has_normal[:, None], normals, 0.0), np.zeros((1, 2))))
        return LocalMap(points, grid, normals, has_normal, padded_points, padded_normals)

    def fit(self, placed: np.ndarray, inlier_distance: float) -> float:
        """Share of the ``placed`` points (motion frame) within ``inlier_distance`` of the map."""
        return overlap(self.grid, placed, inlier_distance)


def load_kernels() -> None:
    """Load (on a machine's first run: compile) the scan matcher's Numba kernels (motion/nearest.py,
    motion/kernels.py, search_kernels.py, the fusion's Student-t fit) now, so that the first timed match
    of a run does not pay it: one :func:`register` of a corner against itself, one correlative search of
    it, one fit of a single sample."""
    s = np.linspace(0.0, 1.0, 21)
    corner = np.concatenate((np.column_stack((s, 0.0 * s)), np.column_stack((0.0 * s, s))))
    register(corner[voxel_thin(corner, 0.05)], LocalMap.build(corner), np.zeros(3), ScanMatchConfig())
    search(corner, corner, np.zeros(3), Window(0.2, 0.1), 0.1, 0.1)
    student_fit(np.zeros((1, 3)), np.eye(3)[None], np.zeros((1, 3, 2)))


@dataclass(frozen=True)
class Registration:
    pose: np.ndarray  # refined pose of the scan in the motion frame
    fit: float  # share of scan points within inlier_distance of the map
    cov: np.ndarray  # (3, 3) covariance of ``pose`` (motion frame; rotation about the robot)


def register(
    points: np.ndarray,
    local: LocalMap,
    start: np.ndarray,
    cfg: ScanMatchConfig,
    prior: np.ndarray | None = None,
) -> Registration:
    """ICP of ``points`` (base frame) against ``local`` from ``start``, with a weak prior towards
    ``prior`` (default ``start``): the odometry's guess, so an ill-posed direction stays with it."""
    guess = start if prior is None else prior
    prior_info = np.array([cfg.prior_sigma_xy**-2, cfg.prior_sigma_xy**-2, cfg.prior_sigma_theta**-2])
    prior_info_scaled = prior_info * cfg.robust_scale**2  # the data term below is in units of robust_scale²
    loop = (cfg.max_iterations, cfg.min_distance, SHRINK, CONVERGED, cfg.robust_scale)
    M = icp_iterations(
        np.ascontiguousarray(points, dtype=float), local.grid.arrays(), local.padded_points,
        local.padded_normals, np.asarray(start, dtype=float), np.asarray(guess, dtype=float),
        prior_info_scaled, float(cfg.max_distance), loop,
    )  # fmt: skip
    q = points @ M[:2, :2].T + M[:2, 2]
    dist, idx = local.grid.query(q, cfg.inlier_distance)
    fit = float(np.mean(dist < cfg.inlier_distance))
    terms = _line_terms(q, idx, local, M, cfg.robust_scale)
    return Registration(pose_from_matrix(M), fit, _covariance(terms, prior_info, cfg))


def _line_terms(q: np.ndarray, idx: np.ndarray, local: LocalMap, M: np.ndarray, scale: float):
    """Jacobian J (n, 3), Cauchy weights w and point-to-line residuals r of the placed points ``q``
    against their nearest map points ``idx``; None with fewer than 3 usable correspondences."""
    J, w, r = np.empty((len(q), 3)), np.empty(len(q)), np.empty(len(q))
    # ∂r/∂(x, y, θ) of the pose itself (turning about the robot, not the map origin: far from the
    # origin that keeps rotation and translation decoupled): (n_x, n_y, (q − t) × n); zero rows: no
    # neighbour in range, or a neighbour with no normal
    used = line_terms(q, idx, local.padded_points, local.padded_normals, M[:2, 2], scale, J, w, r)
    return None if used < 3 else (J, w, r)


def _covariance(terms, prior_info: np.ndarray, cfg) -> np.ndarray:
    """Covariance of the registered pose: (JᵀWJ / (σ̂²·c) + prior)⁻¹ at the solution, from the
    point-to-line ``terms`` (J, w, r) of the correspondences within ``inlier_distance``.

    σ̂² is the weighted mean squared point-to-line residual (the scan's own noise, not a configured
    one). c corrects for residuals that are not independent: neighbouring points of a scan are
    measured against the same stretch of map wall, so their residuals move together; with ρ the lag-1
    correlation of the residuals in beam order (an AR(1) model), n points carry the information of
    n·(1 − ρ)/(1 + ρ) independent ones, so c = (1 + ρ)/(1 − ρ) (at least ``cov_inflation``).
    """
    if terms is None:  # fewer than 3 usable correspondences within inlier_distance
        return np.diag(1.0 / prior_info)
    J, w, r = terms
    used = np.abs(J[:, :2]).sum(axis=1) > 0
    dof = max(float(w[used].sum()) - 3.0, 1.0)
    sigma2 = max(float(np.sum(w * r * r)) / dof, cfg.min_residual_sigma**2)
    c = max(cfg.cov_inflation, _ar1_inflation(r[used] * np.sqrt(w[used])))
    H = (J * w[:, None]).T @ J / (sigma2 * c) + np.diag(prior_info)
    cov = np.linalg.inv(H)
    return 0.5 * (cov + cov.T)


def _ar1_inflation(r: np.ndarray) -> float:
    """(1 + ρ)/(1 − ρ) for the lag-1 autocorrelation ρ ∈ [0, MAX_RHO] of the sequence ``r``."""
    if len(r) < 4:
        return 1.0
    r = r - r.mean()
    den = float(r @ r)
    if den <= 0.0:
        return 1.0
    rho = min(max(float(r[1:] @ r[:-1]) / den, 0.0), MAX_RHO)
    return (1.0 + rho) / (1.0 - rho)


@dataclass(frozen=True)
class MapScan:
    """One scan of the local map: its refined pose (3,) and its points (k, 2) placed with it (motion
    frame), thinned to one point per voxel."""

    pose: np.ndarray
    points: np.ndarray


def near_scans(poses: np.ndarray, pose: np.ndarray, radius: float, angle: float, most: int) -> np.ndarray:
    """Indices, in increasing order, of the ``poses`` (k, 3) within ``radius`` (m) of ``pose`` and within
    ``angle`` (rad) of its heading; of more than ``most`` such, the ``most`` nearest (ties: the older)."""
    d = np.hypot(poses[:, 0] - pose[0], poses[:, 1] - pose[1])
    idx = np.flatnonzero((d <= radius) & (np.abs(wrap_angle(poses[:, 2] - pose[2])) <= angle))
    if len(idx) > most:
        idx = np.sort(idx[np.argsort(d[idx], kind="stable")[:most]])
    return idx


@dataclass(frozen=True)
class MatchResult:
    pose: np.ndarray  # fused pose of the scan in the motion frame (the filter's motion input)
    fit: float  # share of scan points within inlier_distance of the map after the match
    matched: bool  # the scan match was fused; False: the odometry increment alone (no map, low fit, gated)
    cov: np.ndarray  # (3, 3) covariance of the increment into this scan, previous scan's frame
    searched: bool = False  # the correlative search ran (the odometry window exceeded ICP's basin)
    taken: BiasTaken | None = None  # how it was fused (None: first scan; kept with recalibrate)


class ScanMatcher:
    """Fuses a stream of (points, wheel odometry pose) with scan matches into a motion-frame pose chain."""

    def __init__(self, cfg: ScanMatchConfig, odometry_noise: Callable[[np.ndarray], np.ndarray]):
        self.cfg = cfg
        self.odometry_noise = odometry_noise  # covariance of an odometry increment (the filter's model)
        self.fusion = OdometryFusion(cfg)
        self.scans: deque[MapScan] = deque(maxlen=cfg.window)  # the last map scans
        self.history: deque[MapScan] = deque(maxlen=cfg.near_history)  # older ones (near_scans)
        self.local: LocalMap | None = None
        self.pose: np.ndarray | None = None  # fused pose of the previous scan
        self.odom: np.ndarray | None = None  # wheel pose of the previous scan
        self.last_map_pose: np.ndarray | None = None
        self.n_matched = self.n_searched = self.n_fallback = 0

    @property
    def n_rejected(self) -> int:
        return self.fusion.n_rejected

    @property
    def odom_scale(self) -> float:
        """The learnt scale of the odometry's noise model (motion/fusion.py)."""
        return self.fusion.k

    def warm_up(self, scans: list[tuple[np.ndarray, np.ndarray]]) -> None:
        """Learn the noise scales and bias (motion/fusion.py) on the first keyframes before matching
        them for real: a throw-away pass over ``scans`` (points, odometry pose), whose learnt state
        (and samples) this matcher starts from — so the first matches are judged like later ones."""
        probe = ScanMatcher(self.cfg, self.odometry_noise)
        for points, odom in scans:
            probe.step(points, odom)
        if len(probe.fusion.samples) >= self.cfg.adapt_min_samples:
            self.fusion.k, self.fusion.s, self.fusion.c = probe.fusion.k, probe.fusion.s, probe.fusion.c
            self.fusion.along = probe.fusion.along
            self.fusion.samples = probe.fusion.samples

    def step(self, points: np.ndarray, odom: np.ndarray) -> MatchResult:
        """Fused pose of the scan whose base-frame ``points`` were taken at wheel pose ``odom``.

        Across an odometry jump (already re-anchored by logs/sync.py) the wheel increment is only the
        first guess and the local map is kept: the match usually recovers the motion.
        """
        odom = np.asarray(odom, dtype=float)
        if self.pose is None:
            result = MatchResult(odom.copy(), 1.0, True, np.zeros((3, 3)))
        else:
            result = self._match(points, relative(self.odom, odom))
            self.fusion.note_step()
        self.pose, self.odom = result.pose, odom
        self._grow_map(points, result.pose)
        return result

    def _match(self, points: np.ndarray, o: np.ndarray) -> MatchResult:
        """Match, fuse with the odometry increment ``o`` (previous scan's frame), or fall back to it."""
        cfg = self.cfg
        cov_o = self.odometry_noise(o)
        guess = compose(self.pose, o)
        points = points[voxel_thin(points, cfg.scan_voxel)]
        if self.local is None or len(points) < 3:
            return self._fallback(o, cov_o, 0.0)
        reg, searched = register(points, self.local, guess, cfg), False
        window = self._window(cov_o)
        wide = window.xy > cfg.search_min_xy or window.theta > cfg.search_min_theta
        near = within_range(points, cfg.search_range) if wide else points[:0]
        if len(near) >= 3:
            # the odometry may be outside ICP's basin: ICP also from the best pose of the whole window,
            # kept when it fits clearly better (near-equal fits: the one from the odometry, e.g. along
            # a corridor where the search's cells are as good as each other)
            found = search(near, self.local.points, guess, window, cfg.search_resolution, cfg.search_sigma)
            other = register(points, self.local, found.pose, cfg, prior=guess)
            if other.fit > reg.fit + FIT_MARGIN:
                reg = other
            searched = True
            self.n_searched += 1
        if reg.fit < cfg.min_fit:
            return self._fallback(o, cov_o, reg.fit, searched)
        m = relative(self.pose, reg.pose)
        fused = self.fusion.fuse(
            o,
            cov_o,
            m,
            rotate_pose_covariance(reg.cov, -self.pose[2]),
            lambda: reg.fit >= self._fit_at(points, guess) + FIT_EVIDENCE,
        )
        self.n_matched += fused.accepted
        # the match's error its fit cannot see, passed on with the weight the match got (none when the
        # odometry is exact and the fusion hardly weighs the match)
        floor = np.diag([cfg.sigma_xy**2, cfg.sigma_xy**2, cfg.sigma_theta**2])
        cov = fused.cov + fused.gain @ floor @ fused.gain.T
        taken = self.fusion.taken(o, fused.gain)
        return MatchResult(compose(self.pose, fused.inc), reg.fit, fused.accepted, cov, searched, taken)

    def _fit_at(self, points: np.ndarray, pose: np.ndarray) -> float:
        """Share of ``points`` within ``inlier_distance`` of the local map at ``pose``."""
        return self.local.fit(transform_points(points, pose), self.cfg.inlier_distance)

    def _fallback(self, o: np.ndarray, cov_o: np.ndarray, fit: float, searched: bool = False) -> MatchResult:
        self.n_fallback += 1
        pose, taken = compose(self.pose, self.fusion.corrected(o)), self.fusion.taken(o, np.zeros((3, 3)))
        return MatchResult(pose, fit, False, self.fusion.k * cov_o, searched, taken)

    def _window(self, cov_o: np.ndarray) -> Window:
        """Search half-widths: ``search_sigmas`` standard deviations of the odometry model (k = 1: the
        window does not shrink with the learnt scale, so a slip on good odometry is still found),
        capped at ``search_max_*``."""
        cfg = self.cfg
        sx = np.sqrt(max(cov_o[0, 0], cov_o[1, 1]))
        st = np.sqrt(cov_o[2, 2])
        return Window(
            min(cfg.search_sigmas * sx, cfg.search_max_xy), min(cfg.search_sigmas * st, cfg.search_max_theta)
        )

    def _grow_map(self, points: np.ndarray, pose: np.ndarray) -> None:
        """Add the scan to the local map if the robot moved enough since the last one that joined; the
        map is the union of the window's scans and of the history's near this one (:meth:`_near`), thinned
        to one point per voxel (the window's first: the newest placements win a cell), normals computed on
        it (denser than one scan: better normals on sparse 1° scans)."""
        cfg = self.cfg
        last, apart_enough = self.last_map_pose, (cfg.map_update_distance, cfg.map_update_angle)
        if len(points) < NORMAL_NEIGHBOURS or (last is not None and not apart(pose, last, *apart_enough)):
            return
        self.last_map_pose = pose.copy()
        placed = transform_points(points, pose)
        if len(self.scans) == self.scans.maxlen:
            self.history.append(self.scans[0])  # leaves the window (kept when near_history > 0)
        self.scans.append(MapScan(pose.copy(), placed[voxel_thin(placed, cfg.voxel)]))  # thinned alone first
        pts = window = np.concatenate([s.points for s in self.scans])
        if near := self._near(pose, window):
            pts = np.concatenate([window, *(s.points for s in near)])
        self.local = LocalMap.build(pts[voxel_thin(pts, cfg.voxel)])

    def _near(self, pose: np.ndarray, window: np.ndarray) -> list[MapScan]:
        """The history's scans near ``pose`` (the scan that joined: the map serves the scans until the
        next joins, within ``map_update_distance`` of it), oldest first; with ``near_min_fit`` > 0 only
        those of which that share of points lies within ``inlier_distance`` of the ``window``'s points
        (a scan placed with a pose the chain has since drifted from would double the walls)."""
        if not self.history:
            return []
        cfg = self.cfg
        poses = np.array([s.pose for s in self.history])
        near = [
            self.history[i] for i in near_scans(poses, pose, cfg.near_radius, cfg.near_angle, cfg.near_max)
        ]
        if cfg.near_min_fit <= 0 or not near:
            return near
        grid = BucketGrid.build(window)
        return [s for s in near if overlap(grid, s.points, cfg.inlier_distance) >= cfg.near_min_fit]
