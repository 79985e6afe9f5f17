"""Loop-closure verification between two closed submaps with no pose prior (Issue 16, item 3).

    match = match_submaps(a, b, cfg.loops, loop_associator(cfg.association, cfg.loops), cfg.scan_match)

The relative pose a→b is b's origin in a's frame (graph/submap.py). Four steps:

1. **Hypotheses** (geometric constraints, as in Neira–Tardós relocation): a pair of b's corners (i, j)
   agrees with a pair of a's (k, l) when their lengths differ by less than ``pair_distance`` and each
   corner's φ (pose-invariant) by less than ``pair_phi`` from its partner's — in both orderings
   (i↔k, j↔l) and (i↔l, j↔k). Each agreement fixes a rigid transform a→b. Agreements implying about the
   same pose (a Hough cell of ``VOTE_XY`` × ``VOTE_THETA``) are one candidate pose with as many votes:
   the true pose, implied by every pair of its matched corners, has the most even when most of b lies
   outside a. The longest pair (it fixes the heading best) of every cell is tried first, cells by
   votes, then every cell's second longest, and so on, at most ``max_hypotheses`` in all: different
   poses (a symmetric room's) are all taken before any is taken twice. Their *support* — b's corners
   that land within ``SUPPORT_DISTANCE`` of one of a's, φ within ``pair_phi``, at the hypothesis' pose
   (RANSAC's consensus, all hypotheses at once) — orders them again. Only those supported by
   ``min_corners`` corners or more, and by at least as many as the best set found so far less
   ``SUPPORT_SLACK``, go to the associator (the first one always does): an associator call costs
   ~1–10 ms, and its set is hardly ever larger than the support (on the office fixtures: never), so a
   hypothesis with less support can neither beat the best set nor tie it (step 2's ambiguity).
2. **Association** under each hypothesis: the configured associator (ICNN, JCBB or PCA) looks for the
   largest jointly compatible set between b's corners — the observations, seen from b's origin, the
   "robot" — and a's corners — the map, with a's joint covariance — with the robot's pose the
   hypothesis, its covariance diag(σ_xy², σ_xy², σ_θ²) (``hypothesis_sigma_*``). A hypothesis not
   clearly apart from a set of ``min_corners`` or more already found is skipped: it would find the
   same solution again. The best
   set has the most corners (distinct a corners: ICNN may give one to two), ties by the lower joint
   D²; its pose is the least-squares rigid transform of the matched corners (:func:`fit_rigid`).
3. **Refinement**: point-to-line ICP (motion/icp.py) of b's points onto a's from that pose. ICP moves
   the pose (x, y, θ) additively in the map frame, here a's, so its covariance is already the
   covariance of the three numbers of a→b in a's frame: the submap convention, no conversion.
4. **Fitness**: the share of b's points *overlapping* a — within ``OVERLAP_DISTANCE`` of a point of a
   after the refinement (b's points farther away lie where a saw nothing, e.g. beyond its range, and
   say nothing for or against) — that lie within ``inlier_distance`` of a point of a. The overlap is
   wide (1 m) on purpose: a wrong alignment shifts walls by decimetres, and those points must count
   against it, not drop out. Fewer than ``MIN_OVERLAP_POINTS`` overlapping points give fitness 0.

The associator's search under one hypothesis is bounded by ``max_nodes`` (:func:`loop_associator`); a
search cut short leaves the best set unknown, so the match is rejected ("search budget") — a missed
closure, never a wrong one.

Accepted with ≥ ``min_corners`` corners and fitness ≥ ``min_fitness``. Rejected as ambiguous when
another set of as many corners implies a clearly different pose (``AMBIGUOUS_XY`` / ``AMBIGUOUS_THETA``
apart): a symmetric room. A wrong closure costs far more than a missed one. Telling two *identical*
rooms apart is not possible here: the matcher returns the pose that aligns them; the graph's gate
(its prediction and marginal covariance) rejects it.

A pair the corners cannot verify (``few corners``, ``no hypothesis``: a corridor driven the other way
round shows few corners from both sides; ``low fitness``: a corner pose its points refute) can be
verified on the points alone, around the graph's
prediction: graph/points.py (hierarchy.py decides when, ``loops.point_search``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..association import AssociationConfig, Associator, make_associator
from ..filter.models import observe
from ..geometry import transform_points, wrap_angle
from ..motion.icp import NORMAL_NEIGHBOURS, LocalMap, register
from ..motion.params import ScanMatchConfig
from ..types import Prediction
from .params import LoopConfig
from .submap import CornerPairs, LoopMatch, Submap, local_map

VOTE_XY = 0.5  # m: Hough cell of a hypothesis' translation, for the votes that order them
VOTE_THETA = 0.2  # rad: ... and of its heading (about: the circle is cut into THETA_CELLS equal cells)
# an even count, cells centred on 0 and on ±π: the turns a revisit most often has (the same way round,
# the other way round) are each inside one cell, not cut in two at a cell's edge
THETA_CELLS = 2 * round(np.pi / VOTE_THETA)
AMBIGUOUS_XY = 0.5  # m: two corner sets this far apart in translation are different poses
AMBIGUOUS_THETA = 0.2  # rad: ... or in heading
OVERLAP_DISTANCE = 1.0  # m: a point of b this close to a point of a overlaps a (counts for the fitness)
MIN_OVERLAP_POINTS = 20  # fewer overlapping points are no evidence: fitness 0
SUPPORT_DISTANCE = 0.3  # m: a corner of b this close to one of a at a hypothesis' pose supports it
SUPPORT_SLACK = 1  # a hypothesis is associated when its support ≥ the best set's corners − this

# why a match was rejected (LoopMatch.reason)
NO_HYPOTHESIS = "no hypothesis"  # no pair of b's corners agrees with a pair of a's
FEW_CORNERS = "few corners"  # the best set has fewer than min_corners corners
AMBIGUOUS = "ambiguous"  # another set of as many corners implies a different pose
LOW_FITNESS = "low fitness"  # the refined pose puts too few of b's points on a's
BUDGET = "search budget"  # the associator's search under a hypothesis reached loops.max_nodes


@dataclass(frozen=True)
class Hypotheses:
    """Corner-pair correspondences between submaps a and b, in the order they are tried.

    pairs : (h, 4) int64 (i, j, k, l): b's corner i ↔ a's corner k and b's j ↔ a's l
    poses : (h, 3) the rigid transform a→b each implies (b's origin in a's frame)
    length : (h,) m, length of b's pair;  votes : (h,) agreements in the same Hough cell
    support : (h,) b's corners near one of a's at the pose (:func:`support`)
    """

    pairs: np.ndarray
    poses: np.ndarray
    length: np.ndarray
    votes: np.ndarray
    support: np.ndarray

    def __len__(self) -> int:
        return len(self.pairs)


@dataclass(frozen=True)
class CornerSet:
    """A jointly compatible set found under one hypothesis.

    pairs : (c, 2) int64 (b's corner, a's corner);  pose : (3,) least-squares a→b of those corners
    n : distinct a corners matched;  joint_d2 : the associator's joint D²;  hypothesis : index tried
    budget_hit : the associator's search stopped at its node budget (the set may not be the best)
    """

    pairs: np.ndarray
    pose: np.ndarray
    n: int
    joint_d2: float
    hypothesis: int
    budget_hit: bool = False

    def key(self) -> tuple[int, float]:
        """Sort key of "better": more corners, then lower joint D²."""
        return (-self.n, self.joint_d2)


def match_submaps(
    a: Submap,
    b: Submap,
    cfg: LoopConfig,
    associate: Associator,
    icp: ScanMatchConfig,
    maps: Callable[[Submap], LocalMap] = local_map,
) -> LoopMatch:
    """Verify a loop closure between submaps a and b (module docstring); never raises on empty input.
    ``maps``: a's points as ICP's map (a cache of them: graph/submap.LocalMaps)."""
    hyps = pair_hypotheses(a.landmarks, b.landmarks, cfg, a.corner_pairs, b.corner_pairs)
    sets = corner_sets(a, b, hyps, cfg, associate)
    if not sets:
        return rejected(np.full(3, np.nan), 0, NO_HYPOTHESIS)
    if sets[-1].budget_hit:
        return rejected(sets[-1].pose, sets[-1].n, BUDGET)
    best = min(sets, key=CornerSet.key)
    if best.n < cfg.min_corners:
        return rejected(best.pose, best.n, FEW_CORNERS)
    if any(s.n == best.n and _far_apart(s.pose, best.pose) for s in sets):
        return rejected(best.pose, best.n, AMBIGUOUS)
    if len(a.points) < NORMAL_NEIGHBOURS or len(b.points) < 3:  # nothing to refine or measure with
        return rejected(best.pose, best.n, LOW_FITNESS)
    local = maps(a)
    reg = register(b.points, local, best.pose, icp)
    fitness = overlap_fitness(b.points, local, reg.pose, cfg.inlier_distance)
    accepted = fitness >= cfg.min_fitness
    reason = "" if accepted else LOW_FITNESS
    return LoopMatch(reg.pose, reg.cov, best.n, fitness, accepted, reason, best.pairs)


def loop_associator(assoc: AssociationConfig, cfg: LoopConfig) -> Associator:
    """The configured associator for loop verification: JCBB's and PCA's search bounded by
    ``loops.max_nodes`` nodes per hypothesis (or by the association section's own budget when tighter)."""

    def bound(nodes: int) -> int:
        return min((n for n in (nodes, cfg.max_nodes) if n > 0), default=0)

    jcbb, pca = assoc.jcbb, assoc.pca
    return make_associator(
        replace(
            assoc,
            jcbb=replace(jcbb, max_nodes=bound(jcbb.max_nodes)),
            pca=replace(pca, max_nodes=bound(pca.max_nodes)),
        )
    )


def rejected(pose: np.ndarray, n: int, reason: str) -> LoopMatch:
    """A rejection before ICP: the corners' pose (NaN when none), no covariance (NaN), fitness 0."""
    return LoopMatch(np.asarray(pose, dtype=float), np.full((3, 3), np.nan), n, 0.0, False, reason)


def _far_apart(p: np.ndarray, q: np.ndarray) -> bool:
    """Two a→b poses are clearly different: ``AMBIGUOUS_XY`` or ``AMBIGUOUS_THETA`` apart."""
    return bool(np.hypot(*(p[:2] - q[:2])) > AMBIGUOUS_XY or abs(wrap_angle(p[2] - q[2])) > AMBIGUOUS_THETA)


# ---------------------------------------------------------------------------------------- 1. hypotheses


def pair_hypotheses(
    a: np.ndarray,
    b: np.ndarray,
    cfg: LoopConfig,
    a_pairs: CornerPairs | None = None,
    b_pairs: CornerPairs | None = None,
) -> Hypotheses:
    """Every agreement of a pair of b's corners (n_b, 3) with a pair of a's (n_a, 3) (module docstring),
    at most ``cfg.max_hypotheses`` (kept by rank in their Hough cell, then votes, then length), ordered by
    support, ties in that order. ``a_pairs``/``b_pairs``: their
    :class:`~cornerslam_cli.graph.submap.CornerPairs` when kept (a closed submap's), else made here."""
    a, b = np.asarray(a, dtype=float).reshape(-1, 3), np.asarray(b, dtype=float).reshape(-1, 3)
    a_pairs = CornerPairs.of(a) if a_pairs is None else a_pairs
    b_pairs = CornerPairs.of(b) if b_pairs is None else b_pairs
    ai, aj, ad = a_pairs.sorted_i, a_pairs.sorted_j, a_pairs.sorted_length
    bi, bj, bd = b_pairs.i, b_pairs.j, b_pairs.length
    # a's pairs with |length − b's| < pair_distance: a window of the sorted lengths per b pair
    lo = np.searchsorted(ad, bd - cfg.pair_distance, side="right")
    count = np.searchsorted(ad, bd + cfg.pair_distance, side="left") - lo
    rb = np.repeat(np.arange(len(bd)), count)
    ra = lo[rb] + np.arange(len(rb)) - np.repeat(np.cumsum(count) - count, count)
    # both orderings: (i↔k, j↔l) and (i↔l, j↔k)
    I, J = np.concatenate((bi[rb], bi[rb])), np.concatenate((bj[rb], bj[rb]))
    K, L = np.concatenate((ai[ra], aj[ra])), np.concatenate((aj[ra], ai[ra]))
    same_phi = _same_phi(a, b, cfg.pair_phi)
    ok = same_phi[I, K] & same_phi[J, L]
    pairs = np.column_stack((I, J, K, L))[ok]
    length = np.concatenate((bd[rb], bd[rb]))[ok]
    poses = pair_transform(b[pairs[:, 0], :2], b[pairs[:, 1], :2], a[pairs[:, 2], :2], a[pairs[:, 3], :2])
    votes, rank = _votes(poses, length)
    order = np.lexsort((-length, -votes, rank))[: cfg.max_hypotheses]
    n = support(poses[order], a, b, cfg.pair_phi, same_phi)
    order = order[np.argsort(-n, kind="stable")]
    return Hypotheses(
        pairs[order].astype(np.int64), poses[order], length[order], votes[order], np.sort(n)[::-1]
    )


def _same_phi(a: np.ndarray, b: np.ndarray, pair_phi: float) -> np.ndarray:
    """(n_b, n_a) whether b's corner's φ is within ``pair_phi`` of a's corner's."""
    return np.abs(wrap_angle(b[:, None, 2] - a[None, :, 2])) < pair_phi


def pair_transform(p1: np.ndarray, p2: np.ndarray, q1: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """(h, 3) rigid transforms T with T(p1) ≈ q1 and T(p2) ≈ q2, points (h, 2): the heading turns
    p2 − p1 onto q2 − q1, the translation puts the midpoints together."""
    dp, dq = p2 - p1, q2 - q1
    theta = wrap_angle(np.arctan2(dq[:, 1], dq[:, 0]) - np.arctan2(dp[:, 1], dp[:, 0]))
    c, s = np.cos(theta), np.sin(theta)
    mp, mq = 0.5 * (p1 + p2), 0.5 * (q1 + q2)
    t = mq - np.column_stack((c * mp[:, 0] - s * mp[:, 1], s * mp[:, 0] + c * mp[:, 1]))
    return np.column_stack((t, theta))


def _votes(poses: np.ndarray, length: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(h,) how many of the poses fall in each one's Hough cell (``VOTE_XY`` × ``VOTE_XY`` × a heading cell)
    and (h,) each one's rank in its cell by decreasing length (0 = the cell's longest pair)."""
    cells = np.floor(poses / np.array([VOTE_XY, VOTE_XY, 1.0]))
    cells[:, 2] = theta_cells(poses[:, 2])
    cells = np.clip(cells, -(2**20), 2**20 - 1).astype(np.int64) + 2**20  # 21 bits each
    key = (cells[:, 0] << 42) | (cells[:, 1] << 21) | cells[:, 2]  # one int64 per cell
    votes, rank = np.empty(len(key), dtype=np.int64), np.empty(len(key), dtype=np.int64)
    if len(key) == 0:
        return votes, rank
    by_cell = np.lexsort((-length, key))  # by cell, then by decreasing length: cells are runs
    run_key = key[by_cell]
    starts = np.ones(len(key), dtype=bool)
    np.not_equal(run_key[1:], run_key[:-1], out=starts[1:])
    first = np.flatnonzero(starts)  # where each cell's run starts
    counts = np.empty_like(first)
    counts[:-1], counts[-1] = first[1:] - first[:-1], len(key) - first[-1]
    cell = np.repeat(np.arange(len(first)), counts)  # each sorted pose's cell
    votes[by_cell] = counts[cell]
    rank[by_cell] = np.arange(len(key)) - first[cell]
    return votes, rank


def theta_cells(theta: np.ndarray) -> np.ndarray:
    """(h,) the Hough cell of each heading (rad), 0 … ``THETA_CELLS`` − 1 around the circle, cell 0
    centred on 0 and cell ``THETA_CELLS`` / 2 on ±π: headings either side of π (a corridor driven the
    other way round) or of 0 fall in one cell, not two halves."""
    width = 2.0 * np.pi / THETA_CELLS
    return np.floor(np.asarray(theta) / width + 0.5) % THETA_CELLS


def support(
    poses: np.ndarray, a: np.ndarray, b: np.ndarray, pair_phi: float, same_phi: np.ndarray | None = None
) -> np.ndarray:
    """(h,) for each pose (h, 3) a→b, how many of b's corners (n_b, 3) land within ``SUPPORT_DISTANCE``
    of one of a's (n_a, 3) with φ within ``pair_phi`` (``same_phi``: :func:`_same_phi` when at hand):
    O(h · n_b · n_a), vectorised."""
    c, s = np.cos(poses[:, 2])[:, None], np.sin(poses[:, 2])[:, None]
    x = poses[:, :1] + c * b[None, :, 0] - s * b[None, :, 1]  # (h, n_b) b's corners in a's frame
    y = poses[:, 1:2] + s * b[None, :, 0] + c * b[None, :, 1]
    d2 = (x[..., None] - a[None, None, :, 0]) ** 2 + (y[..., None] - a[None, None, :, 1]) ** 2
    same_phi = _same_phi(a, b, pair_phi) if same_phi is None else same_phi  # (n_b, n_a)
    near = (d2 < SUPPORT_DISTANCE**2) & same_phi[None]
    return near.any(axis=2).sum(axis=1)


# ---------------------------------------------------------------------------------------- 2. association


def corner_sets(
    a: Submap, b: Submap, hyps: Hypotheses, cfg: LoopConfig, associate: Associator
) -> list[CornerSet]:
    """The jointly compatible set the associator finds under each hypothesis supported well enough
    (module docstring, steps 1–2; the first is always tried); a hypothesis not clearly apart
    (:func:`_far_apart`) from a set of ``min_corners`` or more already found is skipped: it would
    find that solution again."""
    if len(hyps) == 0:
        return []
    z, C = b.landmarks, b.landmark_blocks.copy()
    n = len(a.landmarks)
    P = np.zeros((3 + 3 * n, 3 + 3 * n))  # the state [hypothesis, a's corners]: blockdiag(Σ_hyp, a's P)
    P[:3, :3] = np.diag([cfg.hypothesis_sigma_xy**2] * 2 + [cfg.hypothesis_sigma_theta**2])
    P[3:, 3:] = a.landmark_P
    P = 0.5 * (P + P.T)  # (symmetric to the last bit, as a filter holds it)
    found: list[CornerSet] = []
    most = 0  # corners of the best set so far
    for h in range(len(hyps)):
        if h and hyps.support[h] < max(cfg.min_corners, most - SUPPORT_SLACK):
            break  # sorted by support: the rest can neither beat nor tie the best set
        if any(s.n >= cfg.min_corners and not _far_apart(s.pose, hyps.poses[h]) for s in found):
            continue  # the same solution as a set already found
        # a's corners as the filter at the hypothesis' pose would predict them (models.observe)
        h_, H_r, H_l = observe(hyps.poses[h], a.landmarks)
        result = associate(z, C, Prediction(h=h_, H_r=H_r, H_l=H_l, P=P))
        matched = np.flatnonzero(result.pairs >= 0)
        pairs = np.column_stack((matched, result.pairs[matched])).astype(np.int64)
        pose = fit_rigid(b, a, pairs) if len(pairs) >= 2 else hyps.poses[h]
        n_a = len(set(pairs[:, 1].tolist()))
        found.append(CornerSet(pairs, pose, n_a, result.joint_d2, h, result.budget_hit))
        if result.budget_hit:
            break  # the best set under this hypothesis is unknown: the match is rejected
        most = max(most, found[-1].n)
    return found


def fit_rigid(b: Submap, a: Submap, pairs: np.ndarray) -> np.ndarray:
    """Least-squares a→b (3,) putting b's matched corners on a's: weighted Procrustes on x, y.

    pairs : (c, 2) (b's corner, a's corner), c ≥ 2. Weight of a pair 2 / tr(Σ_a + Σ_b) of the two
    position covariances (the trace does not depend on the frame, so no rotation is needed); φ does not
    change with the frame, so it only gated the pairs.
    """
    p, q = b.landmarks[pairs[:, 0], :2], a.landmarks[pairs[:, 1], :2]
    Cb, Ca = b.landmark_blocks[pairs[:, 0]], a.landmark_blocks[pairs[:, 1]]
    w = 2.0 / ((Cb[:, 0, 0] + Cb[:, 1, 1]) + (Ca[:, 0, 0] + Ca[:, 1, 1]))  # the xy blocks' traces
    w = w / w.sum()
    mp, mq = w @ p, w @ q
    H = (w[:, None] * (p - mp)).T @ (q - mq)  # Σ w (p − p̄)(q − q̄)ᵀ
    theta = np.arctan2(H[0, 1] - H[1, 0], H[0, 0] + H[1, 1])
    t = mq - transform_points(mp[None, :], (0.0, 0.0, theta))[0]
    return np.array([t[0], t[1], wrap_angle(theta)])


# ---------------------------------------------------------------------------------------- 4. fitness


def overlap_fitness(points: np.ndarray, local: LocalMap, pose: np.ndarray, inlier_distance: float) -> float:
    """Share of ``points`` (b's frame) placed by ``pose`` that overlap ``local`` (within
    ``OVERLAP_DISTANCE`` of one of its points) and lie within ``inlier_distance`` of one; 0 when fewer
    than ``MIN_OVERLAP_POINTS`` overlap."""
    dist, _ = local.grid.query(transform_points(points, pose), OVERLAP_DISTANCE)
    overlap = int(np.count_nonzero(dist < OVERLAP_DISTANCE))
    if overlap < MIN_OVERLAP_POINTS:
        return 0.0
    return float(np.count_nonzero(dist < inlier_distance)) / overlap


AGREE_XY, AGREE_THETA = 0.5, 0.2  # m, rad: two closures of one submap agree on where it is


def chi2(pred: np.ndarray, pred_cov: np.ndarray, pose: np.ndarray, cov: np.ndarray) -> float:
    """Mahalanobis² of a measured a→b ``pose`` against the graph's prediction ``pred``, on the sum of the
    prediction's joint-marginal covariance and the measurement's (both of (x, y, θ) in a's frame)."""
    e = np.asarray(pose, dtype=float) - pred
    e[2] = wrap_angle(e[2])
    return float(e @ np.linalg.solve(pred_cov + cov, e))


def agree(poses: list[np.ndarray]) -> bool:
    """Whether the global poses one submap's closures imply are all within AGREE_XY / AGREE_THETA."""
    if len(poses) < 2:
        return True
    P = np.array(poses)
    d = np.hypot(*(P[:, None, :2] - P[None, :, :2]).transpose(2, 0, 1))
    dth = np.abs(wrap_angle(P[:, None, 2] - P[None, :, 2]))
    return bool(d.max() <= AGREE_XY and dth.max() <= AGREE_THETA)
