"""Loop-closure verification on scan points alone, around the pose graph's prediction (issue 16).

    match = match_points(a, b, *graph.relative(a.index, b.index), cfg.loops, cfg.scan_match)

For a pair of submaps whose corners give no verdict (graph/loops.py: ``few corners``, ``no hypothesis``
— a corridor driven the other way round shows few corners from both sides) or a pose its points refute
(``low fitness``). Unlike the corner search
this needs a prior, the graph's predicted a→b and its covariance; hierarchy.py decides when to ask
(``loops.point_search``, ``point_searches``). Same conventions as graph/loops.py: a→b is b's origin in
a's frame, the match's covariance in a's frame.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ..geometry import relative
from ..motion.correlative import Exclusion, Search, SearchResult, Window
from ..motion.icp import NORMAL_NEIGHBOURS, LocalMap, register, voxel_thin
from ..motion.params import ScanMatchConfig
from .loops import (
    AMBIGUOUS,
    AMBIGUOUS_THETA,
    AMBIGUOUS_XY,
    LOW_FITNESS,
    MIN_OVERLAP_POINTS,
    overlap_fitness,
    rejected,
)
from .params import LoopConfig
from .submap import LoopMatch, Submap, local_map

NOT_DISTINCT = "not distinct on points"  # the points fit as well moved along the fit's weak direction
POINTS = "verified on points"  # accepted on the scan points alone (the corners could not verify it)
POINT_VOXEL = 0.2  # m: b's points thinned for the correlative search (its cost grows with their number)
POINT_MAX = 500  # ... and at most this many of them (every k-th)
MIN_WINDOW_XY, MIN_WINDOW_THETA = 0.3, 0.05  # m, rad: the search window is at least ICP's basin
POINT_MAX_CELLS = 25  # the window's half-width in grid cells at most (memory: angles × points × cells²)
# the search's grid: this many times the front end's (scan_match.search_resolution): it only has to find
# ICP's basin, and a submap's points reach far (the angular step shrinks with their range), so at the
# front end's 0.1 m a search cost ~25 ms and loop closing dominated infinite-corridor's last 10 %
POINT_RES = 2.0
# the ambiguity check's exclusions, in AMBIGUOUS_XY / AMBIGUOUS_THETA: the last (4 m, 1.6 rad) leaves
# only the far corners of the widest window (POINT_MAX_CELLS cells either way)
AWAY_STEPS = (1.0, 2.0, 4.0, 8.0)


def match_points(
    a: Submap,
    b: Submap,
    prior: np.ndarray,
    prior_cov: np.ndarray,
    cfg: LoopConfig,
    icp: ScanMatchConfig,
    maps: Callable[[Submap], LocalMap] = local_map,
) -> LoopMatch:
    """Verify a→b on the two submaps' scan points alone, for a pair whose corners cannot (too few seen
    from both: a corridor driven the other way round; or a corner pose the points refute). Unlike
    :func:`match_submaps` this needs a prior: the graph's predicted a→b ``prior`` and its covariance
    ``prior_cov`` (a's frame); ``maps``: a's points as ICP's map (a cache of them: graph/submap.LocalMaps).

    The correlative search (motion/correlative.py) finds the best pose of b's points (thinned) on a's
    within ±3σ of the prior (at least ICP's basin; at most ``point_max_xy`` / ``point_max_theta`` and
    ``POINT_MAX_CELLS`` cells of its grid, ``POINT_RES`` × ``scan_match.search_resolution``: the search's
    memory grows with the square of it); ICP refines it on all points. Accepted when the fitness is
    ≥ ``min_fitness`` and the fit is distinct: (1) moved ``point_shift`` either way along the refined
    fit's weakest direction, the fitness falls below ``point_distinct`` × its own — along a featureless
    corridor it does not, and the prior, not the points, would be fixing the pose along it; (2) the best
    pose of the window away from it (``AMBIGUOUS_XY`` / ``AMBIGUOUS_THETA``) scores below
    ``point_distinct`` × its score — a parallel corridor, a repeated door, is refused (``ambiguous``) as a
    symmetric place is on corners."""
    if not searchable(a, b):
        return rejected(np.full(3, np.nan), 0, LOW_FITNESS)
    prior = np.asarray(prior, dtype=float)
    res = POINT_RES * icp.search_resolution
    window = points_window(prior_cov, cfg, res)
    pts = b.points[voxel_thin(b.points, POINT_VOXEL)]
    pts = pts[:: -(-len(pts) // POINT_MAX)]
    field = Search.prepare(pts, a.points, prior, window, res, icp.search_sigma)
    found = field.best()
    local = maps(a)
    reg = register(b.points, local, found.pose, icp)
    fitness = overlap_fitness(b.points, local, reg.pose, cfg.inlier_distance)
    if fitness < cfg.min_fitness:
        return LoopMatch(reg.pose, reg.cov, 0, fitness, False, LOW_FITNESS)
    if not distinct(b.points, local, reg.pose, reg.cov, fitness, cfg):
        return LoopMatch(reg.pose, reg.cov, 0, fitness, False, NOT_DISTINCT)
    if elsewhere(field, found, b.points, local, reg.pose, cfg, icp):
        return LoopMatch(reg.pose, reg.cov, 0, fitness, False, AMBIGUOUS)
    return LoopMatch(reg.pose, reg.cov, 0, fitness, True, "")


def elsewhere(
    field: Search,
    found: SearchResult,
    points: np.ndarray,
    local: LocalMap,
    pose: np.ndarray,
    cfg: LoopConfig,
    icp: ScanMatchConfig,
) -> bool:
    """Whether another place scores ``point_distinct`` × as well as the search's best pose ``found``
    (ICP took it to ``pose``): the best pose of the window away from it (``AMBIGUOUS_XY`` /
    ``AMBIGUOUS_THETA``, then twice, four and eight times that) that scores so, unless ICP from it comes
    back to ``pose`` — the slope of the same fit (on a 0.2 m grid, a wall seen end-on holds the score past
    0.5 m), not another place; then the next, farther away. Past the last exclusion nothing is let off:
    one that scores so there is another place, wherever ICP takes it."""
    for grow in AWAY_STEPS:
        away = Exclusion(found.pose, grow * AMBIGUOUS_XY, grow * AMBIGUOUS_THETA)
        other = field.best(exclude=away)
        if not (np.isfinite(other.score) and other.score >= cfg.point_distinct * found.score):
            return False
        if grow == AWAY_STEPS[-1]:
            return True
        back = relative(pose, register(points, local, other.pose, icp).pose)
        if math.hypot(back[0], back[1]) > AMBIGUOUS_XY or abs(back[2]) > AMBIGUOUS_THETA:
            return True
    return False


def searchable(a: Submap, b: Submap) -> bool:
    """Whether the two submaps hold enough points for :func:`match_points` to search at all."""
    return len(a.points) >= NORMAL_NEIGHBOURS and len(b.points) >= MIN_OVERLAP_POINTS


def points_window(prior_cov: np.ndarray, cfg: LoopConfig, res: float) -> Window:
    """The search window of :func:`match_points`: ±3σ of the prior, at least ICP's basin, at most the
    caps (``point_max_*``, ``POINT_MAX_CELLS`` cells); the caps when the prior has no usable covariance."""
    cap_xy, cap_theta = min(cfg.point_max_xy, POINT_MAX_CELLS * res), cfg.point_max_theta
    if not np.isfinite(prior_cov).all():
        return Window(cap_xy, cap_theta)
    sx = math.sqrt(max(float(np.linalg.eigvalsh(prior_cov[:2, :2]).max()), 0.0))
    st = math.sqrt(max(float(prior_cov[2, 2]), 0.0))
    return Window(min(max(3.0 * sx, MIN_WINDOW_XY), cap_xy), min(max(3.0 * st, MIN_WINDOW_THETA), cap_theta))


def distinct(
    points: np.ndarray, local: LocalMap, pose: np.ndarray, cov: np.ndarray, fitness: float, cfg: LoopConfig
) -> bool:
    """Whether ``points`` fit ``local`` at ``pose`` clearly better than at ``pose`` moved ``point_shift``
    either way along the weakest direction of the fit's covariance ``cov`` (its largest xy eigenvector)."""
    if not np.isfinite(cov).all():
        return False
    weak = np.linalg.eigh(cov[:2, :2])[1][:, 1]
    for sign in (1.0, -1.0):
        moved = np.asarray(pose, dtype=float).copy()
        moved[:2] += sign * cfg.point_shift * weak
        if overlap_fitness(points, local, moved, cfg.inlier_distance) >= cfg.point_distinct * fitness:
            return False
    return True
