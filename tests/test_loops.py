"""Loop-closure verification between two submaps (graph/loops.py) on simulated submaps
(tests/submap_fixtures.py): known relative poses, a brute-force reference for the hypothesis step,
perceptual aliasing, and every way a match is rejected."""

from __future__ import annotations

import functools
import itertools
import math
from dataclasses import replace

import numpy as np
import pytest
from _association_helpers import observe
from scipy.stats import chi2
from submap_fixtures import (
    build_submap,
    corners_submap,
    empty_submap,
    identical_rooms_world,
    room_origin,
    spin,
    straight_path,
    symmetric_room_world,
)

from cornerslam_cli import simworld as sw
from cornerslam_cli.association import ASSOCIATORS, AssociationConfig, make_associator
from cornerslam_cli.association.params import JcbbConfig, PcaConfig
from cornerslam_cli.geometry import compose, relative, rotate_pose_covariance, transform_points, wrap_angle
from cornerslam_cli.graph import loops, points
from cornerslam_cli.graph.params import LoopConfig
from cornerslam_cli.motion.correlative import SearchResult
from cornerslam_cli.motion.params import ScanMatchConfig
from cornerslam_cli.types import Prediction

CFG = LoopConfig()
ICP = ScanMatchConfig()
PCA = make_associator(AssociationConfig(method="pca"))

# the south corridor of the office driven east, then the same stretch driven back west 0.3 m to the side
PATH_A = straight_path((5.0, 5.0), (15.0, 5.0))
PATH_B = straight_path((16.0, 5.3), (6.0, 5.3))


@functools.cache
def office_pair():
    """Submaps a, b of the same corridor from two paths, and the true a→b."""
    world = sw.office_world()
    a = build_submap(world, PATH_A, 0, seed=1)
    b = build_submap(world, PATH_B, 5, seed=2, first_id=100)
    return a, b, relative(PATH_A[0], PATH_B[0])


@functools.cache
def north_corridor():
    """A submap of the office's north corridor, east end: nothing in common with ``office_pair``'s a."""
    return build_submap(sw.office_world(), straight_path((18.0, 15.0), (25.0, 15.0)), 3, seed=3)


@functools.cache
def room_submap():
    """A submap of a furnished room of ``identical_rooms_world``, turning on the spot."""
    pose = np.r_[room_origin(0), 0.0] + (3.0, 2.5, 0.0)
    return build_submap(identical_rooms_world(), spin(*pose[:2], np.linspace(0.0, 6.0, 8)), 1, seed=4)


def pose_error(pose, truth) -> tuple[float, float]:
    """(m, rad) distance between two poses."""
    return float(np.hypot(*(pose[:2] - truth[:2]))), abs(float(wrap_angle(pose[2] - truth[2])))


# ----------------------------------------------------------------------------------- a simulated loop


@pytest.mark.parametrize("method", list(ASSOCIATORS))
def test_simulated_loop_recovers_the_known_pose(method):
    a, b, truth = office_pair()
    match = loops.match_submaps(a, b, CFG, make_associator(AssociationConfig(method=method)), ICP)
    assert match.accepted and match.reason == ""
    assert match.n_corners >= CFG.min_corners
    assert match.fitness >= CFG.min_fitness
    d_xy, d_th = pose_error(match.pose, truth)
    assert d_xy < 0.02 and d_th < math.radians(0.5)
    # the covariance is sane: symmetric positive definite, the error within ~3σ (χ²₃ at 99.7 %)
    assert np.allclose(match.cov, match.cov.T) and np.all(np.linalg.eigvalsh(match.cov) > 0)
    e = match.pose - truth
    e[2] = wrap_angle(e[2])
    assert e @ np.linalg.solve(match.cov, e) < chi2.ppf(0.997, 3)


def test_a_search_cut_short_by_the_node_budget_rejects_the_match():
    """The loop the known-pose test accepts: with a budget of one search node the associator stops
    under the first hypothesis, and the match is rejected as 'search budget' (not trusted on the
    partial set it found); the default budget lets it through."""
    a, b, _ = office_pair()
    tight = replace(CFG, max_nodes=1)
    match = loops.match_submaps(
        a, b, tight, loops.loop_associator(AssociationConfig(method="pca"), tight), ICP
    )
    assert not match.accepted and match.reason == loops.BUDGET
    sets = loops.corner_sets(
        a, b, loops.pair_hypotheses(a.landmarks, b.landmarks, tight), tight,
        loops.loop_associator(AssociationConfig(method="jcbb"), tight),
    )  # fmt: skip
    assert len(sets) == 1 and sets[0].budget_hit  # no hypothesis tried after the cut
    match = loops.match_submaps(a, b, CFG, loops.loop_associator(AssociationConfig(method="pca"), CFG), ICP)
    assert match.accepted


@pytest.mark.parametrize(
    "own, loop_budget, want",
    [(0, 30_000, 30_000), (500, 30_000, 500), (50_000, 30_000, 30_000), (0, 0, 0), (700, 0, 700)],
)
def test_loop_associator_bounds_jcbb_and_pca_by_the_tighter_budget(own, loop_budget, want):
    assoc = AssociationConfig(method="pca", jcbb=JcbbConfig(max_nodes=own), pca=PcaConfig(max_nodes=own))
    bounded = loops.loop_associator(assoc, replace(CFG, max_nodes=loop_budget))
    assert bounded.cfg.jcbb.max_nodes == bounded.cfg.pca.max_nodes == want
    assert bounded.cfg.method == "pca" and bounded.cfg.alpha == assoc.alpha


def test_covariance_is_in_a_frame():
    """Turning a's frame by α turns a→b and its covariance with it (the submap convention: the
    covariance of b's origin in a's frame); b's frame alone would leave the covariance unchanged."""
    a, b, _ = office_pair()
    alpha = 0.7
    turn = (0.0, 0.0, -alpha)  # coordinates in the frame turned by α
    a2 = replace(
        a,
        landmarks=np.column_stack((transform_points(a.landmarks[:, :2], turn), a.landmarks[:, 2])),
        landmark_P=_rotate_joint(a.landmark_P, -alpha),
        points=transform_points(a.points, turn),
    )
    m1 = loops.match_submaps(a, b, CFG, PCA, ICP)
    m2 = loops.match_submaps(a2, b, CFG, PCA, ICP)
    assert m1.accepted and m2.accepted
    expected = np.concatenate(
        (transform_points(m1.pose[None, :2], turn)[0], [wrap_angle(m1.pose[2] - alpha)])
    )
    assert pose_error(m2.pose, expected)[0] < 1e-4 and pose_error(m2.pose, expected)[1] < 1e-5
    assert np.allclose(m2.cov, rotate_pose_covariance(m1.cov, -alpha), rtol=0.02, atol=1e-12)
    assert not np.allclose(m2.cov, m1.cov, rtol=0.02, atol=1e-12)  # the turn is visible at all


def _rotate_joint(P: np.ndarray, yaw: float) -> np.ndarray:
    """A joint corner covariance (3n, 3n) in a frame turned by ``yaw``: blockdiag(J, …) P blockdiag(J, …)ᵀ."""
    n = len(P) // 3
    J = np.kron(np.eye(n), _pose_rotation(yaw))
    return J @ P @ J.T


def _pose_rotation(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


# ----------------------------------------------------------------------------------- the hypothesis step


def _reference_hypotheses(a: np.ndarray, b: np.ndarray, cfg: LoopConfig) -> dict[tuple, np.ndarray]:
    """Every agreement, by hand: ordered pairs (i, j) of b's corners against ordered pairs (k, l) of a's,
    keyed (i, j, k, l) with i < j, valued the pose a→b putting b's i, j on a's k, l (complex numbers)."""
    out = {}
    for i, j in itertools.permutations(range(len(b)), 2):
        for k, l in itertools.permutations(range(len(a)), 2):
            db = math.dist(b[i, :2], b[j, :2])
            da = math.dist(a[k, :2], a[l, :2])
            phi_ok = all(abs(wrap_angle(b[u, 2] - a[v, 2])) < cfg.pair_phi for u, v in ((i, k), (j, l)))
            if abs(da - db) >= cfg.pair_distance or not phi_ok or i > j:
                continue
            p, q = complex(*b[i, :2]), complex(*b[j, :2])
            r, t = complex(*a[k, :2]), complex(*a[l, :2])
            turn = (t - r) / abs(t - r) / ((q - p) / abs(q - p))  # e^{iθ}
            shift = (r + t) / 2 - turn * (p + q) / 2
            out[(i, j, k, l)] = np.array([shift.real, shift.imag, math.atan2(turn.imag, turn.real)])
    return out


def _reference_best(a_sub, b_sub, hypotheses: dict, cfg: LoopConfig, associate):
    """The associator under every hypothesis with a Prediction built independently of the filter; the
    set with the most distinct a corners, ties by the lower joint D² (brute force, no screening)."""
    n = len(a_sub.landmarks)
    P = np.zeros((3 + 3 * n, 3 + 3 * n))
    P[:3, :3] = np.diag([cfg.hypothesis_sigma_xy**2] * 2 + [cfg.hypothesis_sigma_theta**2])
    P[3:, 3:] = a_sub.landmark_P
    C = np.array(
        [b_sub.landmark_P[3 * m : 3 * m + 3, 3 * m : 3 * m + 3] for m in range(len(b_sub.landmarks))]
    )
    best = None
    for pose in hypotheses.values():
        h, H_r, H_l = observe(pose, a_sub.landmarks)
        result = associate(b_sub.landmarks, C, Prediction(h, H_r, H_l, P))
        matched = np.flatnonzero(result.pairs >= 0)
        key = (-len(set(result.pairs[matched].tolist())), result.joint_d2)
        if best is None or key < best[0]:
            best = (key, {(int(i), int(result.pairs[i])) for i in matched})
    return best


def test_hypotheses_and_best_set_match_brute_force():
    rng = np.random.default_rng(7)
    a = np.column_stack((rng.uniform(0, 8, 7), rng.uniform(0, 6, 7), rng.uniform(0.6, 2.6, 7)))
    truth = np.array([2.0, 1.0, 0.8])  # b's origin in a's frame
    seen = [0, 1, 2, 3, 5]
    b = np.column_stack((transform_points(a[seen, :2], relative(truth, np.zeros(3))), a[seen, 2]))
    b[:, :2] += rng.normal(0.0, 0.005, (len(seen), 2))
    b = np.vstack((b, [1.0, -2.0, 1.4]))  # a corner a never saw
    a_sub, b_sub = corners_submap(a), corners_submap(b)
    cfg = replace(CFG, max_hypotheses=100_000)

    reference = _reference_hypotheses(a, b, cfg)
    hyps = loops.pair_hypotheses(a, b, cfg)
    assert sorted(map(tuple, hyps.pairs.tolist())) == sorted(reference)
    for pair, pose in zip(hyps.pairs.tolist(), hyps.poses, strict=True):
        assert np.allclose(pose, reference[tuple(pair)], atol=1e-9)

    for associate in (make_associator(AssociationConfig(method=m)) for m in ASSOCIATORS):
        (n_ref, _), pairs_ref = _reference_best(a_sub, b_sub, reference, cfg, associate)
        best = min(loops.corner_sets(a_sub, b_sub, hyps, cfg, associate), key=loops.CornerSet.key)
        assert best.n == -n_ref == len(seen)
        assert (
            {tuple(p) for p in best.pairs.tolist()} == pairs_ref == {(m, seen[m]) for m in range(len(seen))}
        )
        assert pose_error(best.pose, truth)[0] < 0.02


def test_fit_rigid_recovers_an_exact_transform():
    rng = np.random.default_rng(3)
    a = np.column_stack((rng.uniform(-5, 5, (6, 2)), np.full(6, 1.5)))
    truth = np.array([-1.0, 3.0, -2.5])
    b = np.column_stack((transform_points(a[:, :2], relative(truth, np.zeros(3))), a[:, 2]))
    pairs = np.column_stack((np.arange(6), np.arange(6)))
    assert np.allclose(loops.fit_rigid(corners_submap(b), corners_submap(a), pairs), truth, atol=1e-12)


# ----------------------------------------------------------------------------------- perceptual aliasing


def test_identical_rooms_align_locally():
    """Room 1 against room 3 of the same shape: the matcher cannot tell them apart and returns the pose
    that aligns the rooms — the local relative pose, 12 m from the true one. Rejecting it is the graph
    gate's job (hierarchy.py: the graph's prediction and marginal covariance), not this module's."""
    world = identical_rooms_world()
    o1, o3 = np.r_[room_origin(0), 0.0], np.r_[room_origin(2), 0.0]
    pa = spin(*(o1[:2] + (3.0, 2.5)), np.linspace(0.0, 2 * np.pi, 8, endpoint=False))
    pb = spin(*(o3[:2] + (3.2, 2.3)), np.linspace(0.3, 0.3 + 2 * np.pi, 8, endpoint=False))
    a, b = build_submap(world, pa, 0, seed=1), build_submap(world, pb, 2, seed=2)
    match = loops.match_submaps(a, b, CFG, PCA, ICP)
    local = relative(pa[0] - o1, pb[0] - o3)  # b's origin in a's frame were the rooms one room
    d_xy, d_th = pose_error(match.pose, local)
    assert match.accepted and d_xy < 0.02 and d_th < math.radians(0.5)
    assert pose_error(match.pose, relative(pa[0], pb[0]))[0] > 10.0


@pytest.mark.parametrize("method", list(ASSOCIATORS))
def test_symmetric_room_is_ambiguous(method):
    """A bare rectangle seen from its centre looks the same turned by π: two poses, as many corners."""
    world = symmetric_room_world()
    a = build_submap(world, spin(3.0, 2.0, np.linspace(0.0, 2 * np.pi, 4, endpoint=False)), 0, seed=1)
    b = build_submap(world, spin(3.0, 2.0, np.linspace(0.4, 0.4 + 2 * np.pi, 4, endpoint=False)), 2, seed=2)
    associate = make_associator(AssociationConfig(method=method))
    match = loops.match_submaps(a, b, CFG, associate, ICP)
    assert not match.accepted and match.reason == loops.AMBIGUOUS
    assert match.n_corners == 4
    sets = loops.corner_sets(a, b, loops.pair_hypotheses(a.landmarks, b.landmarks, CFG), CFG, associate)
    turns = sorted(abs(float(wrap_angle(s.pose[2] - 0.4))) for s in sets if s.n == 4)  # b turned by 0.4
    assert len(turns) == 2 and turns[0] < 0.01 and abs(turns[1] - math.pi) < 0.01


# ----------------------------------------------------------------------------------- rejections


@pytest.mark.parametrize("which", ["both", "a", "b"])
def test_empty_submaps_are_rejected(which):
    a, b, _ = office_pair()
    a = empty_submap() if which in ("both", "a") else a
    b = empty_submap() if which in ("both", "b") else b
    match = loops.match_submaps(a, b, CFG, PCA, ICP)
    assert not match.accepted and match.reason == loops.NO_HYPOTHESIS
    assert match.n_corners == 0 and match.fitness == 0.0 and np.isnan(match.pose).all()


def test_one_corner_each_is_no_hypothesis():
    one = corners_submap([[1.0, 2.0, 1.57]])
    match = loops.match_submaps(one, one, CFG, PCA, ICP)
    assert not match.accepted and match.reason == loops.NO_HYPOTHESIS


def test_too_few_shared_corners_are_rejected():
    """b keeps three of its corners: they match a's exactly, but three is below min_corners."""
    a, b, _ = office_pair()
    sets = loops.corner_sets(a, b, loops.pair_hypotheses(a.landmarks, b.landmarks, CFG), CFG, PCA)
    shared = min(sets, key=loops.CornerSet.key)
    keep = np.sort(shared.pairs[:3, 0])
    idx = (3 * keep[:, None] + np.arange(3)).ravel()
    b3 = replace(b, landmarks=b.landmarks[keep], landmark_P=b.landmark_P[np.ix_(idx, idx)])
    match = loops.match_submaps(a, b3, CFG, PCA, ICP)
    assert not match.accepted and match.reason == loops.FEW_CORNERS
    assert match.n_corners == 3


@pytest.mark.parametrize(
    ("method", "reason"),
    [("jcbb", loops.FEW_CORNERS), ("pca", loops.FEW_CORNERS), ("icnn", loops.LOW_FITNESS)],
)
def test_no_overlap_is_rejected(method, reason):
    """Two corridors with nothing in common: JCBB and PCA find no jointly compatible set of
    min_corners; ICNN's nearest neighbours (not jointly compatible) make five, which the points refute."""
    a, _, _ = office_pair()
    match = loops.match_submaps(
        a, north_corridor(), CFG, make_associator(AssociationConfig(method=method)), ICP
    )
    assert not match.accepted and match.reason == reason


@pytest.mark.parametrize("points", ["none", "elsewhere"])
def test_points_that_disagree_are_low_fitness(points):
    """The corners agree but b's points do not lie on a's: none at all, or another place's."""
    a, b, _ = office_pair()
    b = replace(b, points=np.zeros((0, 2)) if points == "none" else room_submap().points)
    match = loops.match_submaps(a, b, CFG, PCA, ICP)
    assert not match.accepted and match.reason == loops.LOW_FITNESS
    assert match.n_corners >= CFG.min_corners and match.fitness < CFG.min_fitness


def test_fitness_counts_only_the_overlap():
    """Points of b beyond a's reach neither help nor hurt; points near a's but off them count against."""
    a, _, _ = office_pair()
    local = points.LocalMap.build(a.points)
    on = a.points[::3]
    far = on + (100.0, 0.0)  # nowhere near a
    near = on + (0.0, 0.4)  # within the overlap, off a's walls
    assert loops.overlap_fitness(np.vstack((on, far)), local, np.zeros(3), 0.1) == 1.0
    assert loops.overlap_fitness(far, local, np.zeros(3), 0.1) == 0.0
    mixed = loops.overlap_fitness(np.vstack((on, near)), local, np.zeros(3), 0.1)
    assert 0.3 < mixed < 0.7


# ------------------------------------------------------------------ verification on points (with a prior)
PRIOR_COV = np.diag([0.3**2, 0.3**2, 0.08**2])
PRIOR_OFF = np.array([0.4, -0.3, 0.08])  # the graph's prediction this far off the truth (1.3 σ)


@functools.cache
def corridor_pair():
    """Submaps of a featureless corridor driven east, then back west 0.3 m to the side, and the true a→b."""
    world = sw.corridor_world(40.0, 2.0)
    path_a, path_b = straight_path((5.0, 0.0), (15.0, 0.0)), straight_path((16.0, 0.3), (6.0, 0.3))
    a, b = build_submap(world, path_a, 0, seed=1), build_submap(world, path_b, 5, seed=2)
    return a, b, relative(path_a[0], path_b[0])


@functools.cache
def room_pair():
    """Two submaps of one furnished room, turning on the spot at two places 1.2 m apart, and the true a→b."""
    room = np.r_[room_origin(0), 0.0]
    path_a = spin(*(room[:2] + (3.0, 2.5)), np.linspace(0.0, 6.0, 8))
    path_b = spin(*(room[:2] + (2.0, 3.2)), np.linspace(1.0, 7.0, 8))
    world = identical_rooms_world()
    return (
        build_submap(world, path_a, 0, seed=4),
        build_submap(world, path_b, 4, seed=9),
        relative(path_a[0], path_b[0]),
    )


@pytest.mark.parametrize("pair", [office_pair, room_pair])
def test_points_recover_the_known_pose_from_the_graphs_prediction(pair):
    a, b, truth = pair()
    m = points.match_points(a, b, compose(truth, PRIOR_OFF), PRIOR_COV, CFG, ICP)
    assert m.accepted and m.reason == "" and m.fitness > 0.8
    d, dth = pose_error(m.pose, truth)
    assert d < 0.02 and dth < math.radians(0.5)
    assert np.isfinite(m.cov).all() and np.all(np.linalg.eigvalsh(m.cov) > 0)


def test_a_featureless_corridor_is_not_distinct_on_points():
    # every shift along the corridor fits as well: the prior, not the points, would fix the pose along it
    a, b, truth = corridor_pair()
    m = points.match_points(a, b, compose(truth, PRIOR_OFF), PRIOR_COV, CFG, ICP)
    assert not m.accepted and m.reason == points.NOT_DISTINCT
    assert m.fitness > CFG.min_fitness  # the walls do fit: refused for the ambiguity alone


def test_points_search_only_inside_the_predictions_window():
    # the graph places b 1.2 m across the corridor from where it is: sure of it (σ 5 cm), the truth is
    # outside the window and no pose inside puts b's walls on a's; unsure (σ 0.5 m), it is found
    a, b, truth = office_pair()
    prior = compose(truth, (0.0, 1.2, 0.0))
    sure = points.match_points(a, b, prior, np.diag([0.05**2, 0.05**2, 0.01**2]), CFG, ICP)
    assert not sure.accepted and sure.reason == loops.LOW_FITNESS
    unsure = points.match_points(a, b, prior, np.diag([0.5**2, 0.5**2, 0.01**2]), CFG, ICP)
    assert unsure.accepted
    d, dth = pose_error(unsure.pose, truth)
    assert d < 0.02 and dth < math.radians(0.5)


def test_a_prior_without_a_usable_covariance_searches_the_whole_capped_window():
    a, b, truth = office_pair()
    m = points.match_points(a, b, compose(truth, PRIOR_OFF), np.full((3, 3), np.nan), CFG, ICP)
    assert m.accepted and pose_error(m.pose, truth)[0] < 0.02
    window = points.points_window(
        np.diag([100.0, 100.0, 10.0]), replace(CFG, point_max_xy=100.0), ICP.search_resolution
    )
    assert window.xy == points.POINT_MAX_CELLS * ICP.search_resolution  # the search's memory stays bounded
    assert window.theta == CFG.point_max_theta


@functools.cache
def pillared_corridor_pair(
    period: float = 1.2, size: float = 0.3, sides: tuple[float, ...] = (0.85,), walls: bool = True
):
    """A corridor with a ``size`` pillar every ``period`` m on one wall (or at each y of ``sides``; no
    walls: a colonnade), driven east then back west: alignments ``period`` apart along it fit almost as
    well (the pillars repeat, the ends are out of view)."""
    long_walls = [sw.polyline([(-30.0, y), (60.0, y)]) for y in ((-1.0, 1.0) if walls else ())]
    xs = np.arange(-30.0, 60.0, period)
    pillars = [sw.rectangle(x, y, size, size) for x in xs for y in sides]
    world = sw.make_world(long_walls + pillars, "pillared corridor")
    path_a, path_b = straight_path((5.0, 0.0), (15.0, 0.0)), straight_path((16.0, 0.2), (6.0, 0.2))
    a, b = build_submap(world, path_a, 0, seed=1), build_submap(world, path_b, 5, seed=2)
    return a, b, relative(path_a[0], path_b[0])


def test_a_repeated_structure_inside_the_window_is_ambiguous_on_points(monkeypatch):
    # the slide test alone (distinct) is bypassed: the runner-up of the window, 1.2 m along, must refuse it
    monkeypatch.setattr(points, "distinct", lambda *args: True)
    a, b, truth = pillared_corridor_pair()
    m = points.match_points(a, b, compose(truth, PRIOR_OFF), PRIOR_COV * 9.0, CFG, ICP)
    assert not m.accepted and m.reason == loops.AMBIGUOUS
    room_a, room_b, room_truth = room_pair()  # a distinct place is not refused by the same rule
    assert points.match_points(
        room_a, room_b, compose(room_truth, PRIOR_OFF), PRIOR_COV * 9.0, CFG, ICP
    ).accepted


def test_the_window_covers_the_predictions_3_sigma_so_a_repeat_inside_it_is_seen(monkeypatch):
    # pillars every 3 m, the prediction 0.5 m off the truth along the corridor with σ 1 m: the next
    # pillar's alignment lies 2.5 m from the prediction, inside its ±3σ. The default window covers the
    # ±3σ (up to POINT_MAX_CELLS cells), sees it fit as well and refuses the match; a window capped
    # at 2 m (the default before) missed it and verified a place the points cannot tell from the next
    monkeypatch.setattr(points, "distinct", lambda *args: True)  # (the slide test alone would refuse it)
    a, b, truth = pillared_corridor_pair(3.0, 0.6, (1.0, -1.0), walls=False)
    cov = np.diag([1.0, 1.0, 0.05**2])
    for off in (0.5, -0.5):
        prior = compose(truth, (off, 0.0, 0.0))
        assert points.points_window(cov, CFG, points.POINT_RES * ICP.search_resolution).xy == 3.0
        m = points.match_points(a, b, prior, cov, CFG, ICP)
        assert not m.accepted and m.reason == loops.AMBIGUOUS
        capped = points.match_points(a, b, prior, cov, replace(CFG, point_max_xy=2.0), ICP)
        assert capped.accepted and pose_error(capped.pose, truth)[0] < 0.05


class _Field:
    """A stand-in for a correlative search's field: its best pose outside each exclusion, in order."""

    def __init__(self, runners_up):
        self.runners_up, self.excluded = list(runners_up), []

    def best(self, exclude=None):
        self.excluded.append(exclude.xy)
        return self.runners_up.pop(0)


BACK, STAYS, FAR = (0.3, 0.05, 0.02), (1.2, 0.0, 0.0), (3.0, 0.0, 0.0)  # from the match: ICP comes back, ...
AS_WELL, NOT_AS_WELL = 0.45, 0.1  # a runner-up's score against the match's 0.5 (point_distinct 0.7)


@pytest.mark.parametrize(
    "pair, runners_up, ambiguous",
    [
        # just past the exclusion, in a furnished room: ICP comes back, it is the slope of the same fit
        (room_pair, [((0.55, 0.2, 0.05), AS_WELL), (FAR, NOT_AS_WELL)], False),
        (pillared_corridor_pair, [(STAYS, AS_WELL)], True),  # the next pillar along: ICP stays there
        (pillared_corridor_pair, [(BACK, AS_WELL), (STAYS, AS_WELL)], True),  # back, then another place
        (pillared_corridor_pair, [(BACK, AS_WELL)] * 3 + [(FAR, NOT_AS_WELL)], False),
        # past the last exclusion one that scores as well is another place, wherever ICP takes it
        (pillared_corridor_pair, [(BACK, AS_WELL)] * 4, True),
    ],
)
def test_a_runner_up_is_another_place_only_when_icp_does_not_come_back_from_it(pair, runners_up, ambiguous):
    a, b, truth = pair()
    local = points.LocalMap.build(a.points)
    pose = points.register(b.points, local, truth, ICP).pose
    found = SearchResult(np.asarray(truth, dtype=float), 0.5, 0)
    field = _Field([SearchResult(compose(truth, offset), score, 0) for offset, score in runners_up])
    assert points.elsewhere(field, found, b.points, local, pose, CFG, ICP) is ambiguous
    # each runner-up that came back made the exclusion grow, and the next one out was looked at
    assert field.excluded == [g * points.AMBIGUOUS_XY for g in points.AWAY_STEPS[: len(runners_up)]]
    assert not field.runners_up


def test_a_degenerate_fit_is_not_distinct():
    a, b, truth = office_pair()
    local = points.LocalMap.build(a.points)
    assert not points.distinct(b.points, local, truth, np.full((3, 3), np.nan), 0.9, CFG)


def test_hough_votes_of_headings_either_side_of_pi_are_one_cell():
    # a corridor driven the other way round: the pairs' poses turn by about π, some a hair over (−π + ε)
    from cornerslam_cli.graph.loops import THETA_CELLS, _votes, theta_cells

    poses = np.array(
        [[1.0, 2.0, np.pi - 0.01], [1.05, 2.02, -np.pi + 0.01], [1.1, 2.1, np.pi], [1.0, 2.0, 0.3]]
    )
    votes, rank = _votes(poses, np.array([1.0, 3.0, 2.0, 1.0]))
    assert list(votes) == [3, 3, 3, 1]
    assert list(rank) == [2, 0, 1, 0]  # by decreasing length inside the cell
    # the cells tile the circle evenly: every heading a cell, neighbours 2π / THETA_CELLS apart
    theta = np.linspace(-np.pi, np.pi, 10_001)
    cells = theta_cells(theta)
    assert set(np.unique(cells)) == set(range(THETA_CELLS))
    assert cells[0] == cells[-1] == THETA_CELLS // 2 and cells[5_000] == 0  # centred on ±π and on 0
    assert theta_cells(np.array([-0.05, 0.05])).tolist() == [0, 0]
    assert np.all(np.bincount(cells.astype(int)[:-1]) <= 10_000 / THETA_CELLS + 2)
