"""The two-level SLAM (hierarchy.py): submaps close on their limits, the run's files with submaps, the
loop gate and the refusal of closures that disagree (perceptual aliasing), the paper mode untouched.

Loop verification itself (graph/loops.py) and the pose graph (graph/posegraph.py) have their own tests;
here the verifier is replaced where a test needs a closure of a known kind (right, wrong, aliased).
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from _run_helpers import run_cli

import cornerslam_cli.graph.posegraph as posegraph
import cornerslam_cli.hierarchy as hierarchy
from cornerslam_cli.config import config_from
from cornerslam_cli.frontend import frames, open_input
from cornerslam_cli.geometry import compose, compose_inverse_cov, inverse, relative, wrap_angle
from cornerslam_cli.graph.loops import agree
from cornerslam_cli.graph.params import GraphConfig
from cornerslam_cli.graph.posegraph import ISAM2_RELINEARIZE, ONLINE_RELINEARIZE, PoseGraph
from cornerslam_cli.graph.submap import LoopMatch
from cornerslam_cli.hierarchy import HierarchicalSlam, LoopRecord
from cornerslam_cli.report.tables import LOOP_COLUMNS, MAP_COLUMNS, TRAJECTORY_COLUMNS, read_csv


def test_the_online_graph_is_solved_to_the_online_tolerance():
    """The hierarchy's online graph stops at ONLINE_RELINEARIZE (graph/posegraph.py says why; its
    accuracy against a batch solve: tests/test_posegraph.py); a PoseGraph by default at the tight one."""
    hs = HierarchicalSlam(config_from({}, []), (0.0, 0.0, 0.0))
    assert hs.graph.relinearize == ONLINE_RELINEARIZE
    assert PoseGraph(GraphConfig()).relinearize == ISAM2_RELINEARIZE


def hierarchical(sim_log: Path, *sets: str) -> HierarchicalSlam:
    cfg = config_from({}, ["submaps.enabled=true", *sets])
    src = open_input(sim_log, cfg)
    hs = HierarchicalSlam(cfg, src.laser2base)
    for frame in frames(src, cfg):
        hs.step(frame)
    hs.finish()
    return hs


@pytest.mark.parametrize(
    "limit, check",
    [
        ("submaps.max_steps=6", lambda steps, travelled, landmarks: steps <= 6),
        ("submaps.max_distance=2.0", lambda steps, travelled, landmarks: travelled < 2.0 + 0.6),
        ("submaps.max_landmarks=5", lambda steps, travelled, landmarks: landmarks < 5 + 12),
    ],
)
def test_a_submap_closes_when_it_reaches_a_limit(sim_log, limit, check):
    hs = hierarchical(sim_log, limit, "loops.enabled=false")
    assert len(hs.closed) > 2
    for sub in hs.closed[:-1]:  # the last one closes at the end of the log
        steps = sub.last_step - sub.first_step + 1
        travelled = float(np.hypot(*np.diff(sub.poses[:, :2], axis=0).T).sum())
        assert check(steps, travelled, len(sub.landmarks)), (limit, steps, travelled, len(sub.landmarks))
    # the submaps tile the steps, and each one starts at its origin with zero uncertainty
    assert [s.first_step for s in hs.closed[1:]] == [s.last_step + 1 for s in hs.closed[:-1]]
    assert hs.closed[-1].last_step == hs.n_steps - 1
    for sub in hs.closed:
        assert np.linalg.norm(sub.poses[0]) < 0.5  # one step from the origin


def test_each_landmark_keeps_its_pose_relative_to_the_step_that_last_observed_it(sim_log):
    # the smoothed graph bends a submap along its keyframe nodes: map.csv places each landmark where the
    # node of its last observing step puts it, so the landmark seen from the smoothed trajectory is where
    # the filter saw it from that step (one rigid origin per submap left late landmarks off the path)
    hs = hierarchical(sim_log, "submaps.max_steps=40")
    table, final = hs.landmark_table(), hs.final_poses()
    bent = 0.0
    for sub in hs.closed:
        mine = table["submap"] == sub.index
        local = np.column_stack((sub.landmarks[:, :2], np.zeros(len(sub.landmarks))))
        last = table["last_step"][mine]
        seen = relative(sub.poses[last - sub.first_step], local)  # by the filter, in the submap's frame
        placed = np.column_stack((table["x"][mine], table["y"][mine], np.zeros(mine.sum())))
        np.testing.assert_allclose(relative(final[last], placed)[:, :2], seen[:, :2], atol=1e-9)
        at_origin = compose(hs.smoothed.poses()[sub.node], local)[:, :2]
        bent = max(bent, float(np.abs(placed[:, :2] - at_origin).max()))
    assert bent > 1e-3  # the graph did bend a submap: the test tells the two placements apart


def test_a_graph_solve_stopped_at_its_step_limit_is_a_warning(sim_log, tmp_path, monkeypatch):
    # LM's iteration cap at 1: the final smoothing stops before converging, which summary.json must say
    monkeypatch.setattr(posegraph, "LM_MAX_ITERATIONS", 1)
    s = run_cli(sim_log, tmp_path / "capped", "submaps.enabled=true", "submaps.max_steps=40")
    assert any("stopped at their step limit" in w for w in s["warnings"]), s["warnings"]
    monkeypatch.undo()
    s = run_cli(sim_log, tmp_path / "free", "submaps.enabled=true", "submaps.max_steps=40")
    assert not any("step limit" in w for w in s["warnings"]), s["warnings"]


def test_submaps_write_the_smoothed_trajectory_loops_and_linked_map(sim_log, tmp_path):
    s = run_cli(sim_log, tmp_path / "out", "submaps.enabled=true", "submaps.max_steps=8")
    out = tmp_path / "out"
    traj, mp, loops = read_csv(out / "trajectory.csv"), read_csv(out / "map.csv"), read_csv(out / "loops.csv")
    assert list(traj) == TRAJECTORY_COLUMNS and list(mp) == MAP_COLUMNS and list(loops) == LOOP_COLUMNS
    c = s["counts"]
    assert c["submaps"] == len(set(traj["submap"])) == len(set(mp["submap"]))
    assert c["loops_accepted"] + c["loops_rejected"] == len(loops["step"])
    assert s["timing"]["t_loop"] > 0 and "online_ate" in s["accuracy"]
    steps = Counter(np.asarray(traj["submap"]).astype(int).tolist())
    assert max(steps.values()) <= 8


def test_loop_searches_cut_by_the_node_budget_are_rejected_and_counted(sim_log, tmp_path):
    """loops.max_nodes=1 through the CLI: the verified pairs whose corner search it cut are in
    loops.csv as rejected, reason 'search budget', and counted with the rejected closures."""
    s = run_cli(sim_log, tmp_path / "out", "submaps.max_steps=8", "loops.max_nodes=1")
    loops = read_csv(tmp_path / "out" / "loops.csv")
    cut = np.asarray(loops["reason"]) == "search budget"
    assert cut.any() and not np.asarray(loops["accepted"])[cut].astype(bool).any()
    assert s["counts"]["loops_rejected"] >= int(cut.sum())


def test_submaps_off_keeps_the_single_map_and_says_nothing_of_submaps(sim_log, tmp_path):
    s = run_cli(sim_log, tmp_path / "out", "submaps.enabled=false")
    traj = read_csv(tmp_path / "out" / "trajectory.csv")
    for a in ("x", "y", "theta"):
        assert np.array_equal(traj[a], traj[f"online_{a}"])
    assert set(np.asarray(traj["submap"]).astype(int).tolist()) == {0}
    assert not (tmp_path / "out" / "loops.csv").exists()
    assert "submaps" not in s["counts"] and "t_loop" not in s["timing"]


def test_the_map_before_any_submap_closed_is_the_open_ones_with_columns_of_one_length(sim_log):
    """Before the first submap closes the map is the open submap's (its frame is the global one):
    every column as long as the others, ``submap`` 0 and ``linked_to`` -1 on every row."""
    cfg = config_from({}, ["submaps.enabled=true", "loops.enabled=false"])
    src = open_input(sim_log, cfg)
    hs = HierarchicalSlam(cfg, src.laser2base)
    for k, frame in enumerate(frames(src, cfg)):
        hs.step(frame)
        if k == 5:
            break
    assert not hs.closed
    table = hs.landmark_table()
    n = len(table["id"])
    assert n > 0 and {len(v) for v in table.values()} == {n}
    assert np.all(table["submap"] == 0) and np.all(table["linked_to"] == -1)
    assert set(MAP_COLUMNS) <= set(table)  # every map.csv column


class FakeVerifier:
    """Stands in for graph/loops.py: answers every candidate pair with the graph's own prediction
    moved by ``offset`` (per earlier submap a, or for all), accepted, so the gate alone decides."""

    def __init__(self, offsets):
        self.offsets = offsets
        self.hs: HierarchicalSlam | None = None
        self.calls = 0

    def __call__(self, a, b, cfg, associate, icp, maps=None):
        self.calls += 1
        pred, _ = self.hs.graph.relative(a.index, b.index)
        off = self.offsets(a.index) if callable(self.offsets) else self.offsets
        pose = compose(pred, off)
        return LoopMatch(pose, np.diag([1e-4, 1e-4, 1e-5]), 6, 0.9, True, "")


def run_with_verifier(sim_log, monkeypatch, verifier, *sets):
    monkeypatch.setattr(hierarchy, "match_submaps", verifier)
    cfg = config_from({}, ["submaps.enabled=true", "submaps.max_steps=6", "loops.min_gap=2", *sets])
    src = open_input(sim_log, cfg)
    hs = HierarchicalSlam(cfg, src.laser2base)
    verifier.hs = hs
    for frame in frames(src, cfg):
        hs.step(frame)
    hs.finish()
    return hs


def test_a_closure_that_agrees_with_the_graph_is_accepted_and_one_far_off_is_gated(sim_log, monkeypatch):
    good = run_with_verifier(sim_log, monkeypatch, FakeVerifier(np.array([0.01, 0.0, 0.001])))
    assert good.loops and all(r.accepted for r in good.loops)
    # wrong by a different amount for each earlier submap: no two of them agree on where b is
    bad = run_with_verifier(sim_log, monkeypatch, FakeVerifier(lambda a: np.array([4.0 + 3.0 * a, 0.0, 0.5])))
    assert bad.loops and not any(r.accepted for r in bad.loops)
    assert all(r.reason.startswith("disagrees with the graph") for r in bad.loops)
    rows = bad.loop_rows()
    assert all(row["inlier"] == "" and row["accepted"] is False for row in rows)


def test_closures_that_agree_with_each_other_against_the_graph_enter_it(sim_log, monkeypatch):
    # every candidate places b 1 m from where the graph has it, all at the same place: the graph is
    # what is wrong (as after an earlier false closure); two or more such closures are accepted
    hs = run_with_verifier(
        sim_log, monkeypatch, FakeVerifier(np.array([1.0, 0.0, 0.0])), "loops.gate=1", "loops.group_gate=1e9"
    )
    several = Counter(r.submap_to for r in hs.loops)
    for r in hs.loops:
        if several[r.submap_to] >= 2:
            assert r.accepted and "agree against the graph" in r.reason, r
        else:
            assert not r.accepted and r.reason.startswith("disagrees with the graph"), r
    assert any(n >= 2 for n in several.values()) and any(n == 1 for n in several.values())


def test_closures_found_on_points_are_no_evidence_against_the_graph(sim_log, monkeypatch):
    # the same agreeing closures 1 m off, but found on points around the graph's own prediction: they
    # may not outvote the graph (the group rule is for corner-verified closures only)
    def corners(a, b, cfg, associate, icp, maps=None):
        return LoopMatch(np.full(3, np.nan), np.full((3, 3), np.nan), 1, 0.0, False, "few corners")

    def points(a, b, prior, prior_cov, cfg, icp, maps=None):
        return LoopMatch(compose(prior, (1.0, 0.0, 0.0)), np.diag([1e-4, 1e-4, 1e-5]), 0, 0.9, True, "")

    monkeypatch.setattr(hierarchy, "match_points", points)
    hs = run_with_verifier(
        sim_log, monkeypatch, corners, "loops.gate=1", "loops.group_gate=1e9", "loops.point_searches=1000"
    )
    several = Counter(r.submap_to for r in hs.loops)
    assert any(n >= 2 for n in several.values()), "the fixture should give some submap two candidates"
    assert hs.loops and all(r.on_points and not r.accepted for r in hs.loops)
    assert all(r.reason.startswith("disagrees with the graph") for r in hs.loops)


def test_closures_that_agree_with_each_other_far_beyond_the_graph_are_refused(sim_log, monkeypatch):
    # a symmetric place seen from elsewhere: every candidate agrees on a pose turned by π and 20 m off
    # (aces did this); far beyond group_gate, so the agreement does not let them in
    hs = run_with_verifier(sim_log, monkeypatch, FakeVerifier(np.array([20.0, 0.0, np.pi])))
    assert hs.loops and not any(r.accepted for r in hs.loops)
    assert all(r.chi2 > hs.cfg.loops.group_gate for r in hs.loops)


def test_closures_of_one_submap_that_disagree_are_all_refused(sim_log, monkeypatch):
    # every candidate passes the gate (a loose gate), but the even ones place the submap 2 m away
    # from where the odd ones do: an aliased place; none may enter the graph
    verifier = FakeVerifier(lambda a: np.array([2.0 * (a % 2), 0.0, 0.0]))
    hs = run_with_verifier(sim_log, monkeypatch, verifier, "loops.gate=1e9")
    several = Counter(r.submap_to for r in hs.loops)
    mixed = [b for b, n in several.items() if n > 1]
    assert mixed, "the fixture should give some submap two candidates"
    for r in hs.loops:
        if r.submap_to in mixed:
            assert not r.accepted and "disagree" in r.reason


def test_agree_is_about_position_and_heading():
    p = np.zeros(3)
    assert agree([p]) and agree([p, p + [0.3, 0.0, 0.1]])
    assert not agree([p, p + [0.6, 0.0, 0.0]]) and not agree([p, p + [0.0, 0.0, 0.3]])


def test_the_pose_two_closures_imply_against_monte_carlo():
    # a1→a2 = m1 ∘ m2⁻¹ of two closures of one submap (m1: a1→b, m2: a2→b), its first-order covariance
    rng = np.random.default_rng(4)
    m1, c1 = np.array([3.0, -1.0, 0.4]), np.diag([4e-4, 1e-4, 2e-4])
    m2, c2 = np.array([-2.0, 2.5, -1.1]), np.diag([1e-4, 3e-4, 1e-4])
    pose, cov = compose_inverse_cov(m1, c1, m2, c2)
    np.testing.assert_allclose(pose, compose(m1, inverse(m2)), atol=1e-12)
    d1 = rng.multivariate_normal(m1, c1, 20000)
    d2 = rng.multivariate_normal(m2, c2, 20000)
    z = np.array([compose(p, inverse(q)) for p, q in zip(d1, d2, strict=True)])
    z[:, 2] = wrap_angle(z[:, 2] - pose[2])
    z[:, :2] -= pose[:2]
    np.testing.assert_allclose(np.cov(z.T), cov, rtol=0.05, atol=2e-6)


class _Graph:
    """A pose graph stand-in: a1 at the origin, a2 10 m ahead turned 90°; a1→a2 known to ``sigma`` m
    across and along, 0.01 rad."""

    def __init__(self, sigma):
        self.sigma = sigma

    def pose(self, i):
        return np.array([10.0 * i, 0.0, i * np.pi / 2])

    def relative(self, i, j):
        return relative(self.pose(i), self.pose(j)), np.diag([self.sigma**2, self.sigma**2, 1e-4])


@pytest.mark.parametrize(
    ("sigma", "closure_sigma", "consistent"),
    [(1.0, 0.01, True), (0.05, 0.01, False), (0.05, 1.0, True)],
)
def test_closures_placing_a_submap_apart_agree_within_the_uncertainty_between_their_submaps(
    sigma, closure_sigma, consistent
):
    # b is truly 5 m past a1 and (the graph puts a2 0.8 m too far along a1's x) the two right closures
    # place b 0.8 m apart. Consistent while the graph does not know a1→a2 better than that (or the
    # closures themselves are that uncertain); aliasing when both are sure
    true_a2 = np.array([9.2, 0.0, np.pi / 2])
    b = np.array([5.0, 1.0, 0.3])
    cov = np.diag([closure_sigma**2, closure_sigma**2, 1e-5])
    rows = [
        LoopRecord(
            9,
            a,
            5,
            LoopMatch(relative(origin, b), cov, 6, 0.9, True, ""),
            True,
            "",
            origin_cov=cov,
            a_side_cov=cov,
        )
        for a, origin in ((0, np.zeros(3)), (1, true_a2))
    ]
    hs = HierarchicalSlam.__new__(HierarchicalSlam)
    hs.graph, hs.cfg = _Graph(sigma), config_from({}, [])
    hs.closed = [SimpleNamespace(node=k) for k in range(2)]  # (a1's and a2's origins: nodes 0, 1)
    assert not agree([hs.placed(r) for r in rows])
    assert hs.consistent(rows) == consistent
    assert hs.consistent(rows + rows[:1]) == consistent  # a third closure agreeing with the first


def test_closures_carry_the_front_ends_learnt_scale_of_fit_covariances(sim_log, monkeypatch):
    # an ICP fit's covariance misses what makes real matches wrong; the front end learns by how much
    # (motion/fusion.py's s) and a closure, an ICP fit between two submaps, is weighed with the same scale
    verifier = FakeVerifier(np.array([0.01, 0.0, 0.001]))
    monkeypatch.setattr(hierarchy, "match_submaps", verifier)
    cfg = config_from({}, ["submaps.enabled=true", "submaps.max_steps=6", "loops.min_gap=2"])
    src = open_input(sim_log, cfg)
    hs = HierarchicalSlam(cfg, src.laser2base)
    verifier.hs = hs
    scale = []
    for frame in frames(src, cfg):
        hs.step(frame)
        scale.append(frame.match_scale)
    hs.finish()
    assert hs.loops and max(scale) > 2.0  # learnt: this log's fits are too confident
    for r in hs.loops:
        np.testing.assert_allclose(r.match.cov, np.diag([1e-4, 1e-4, 1e-5]) * scale[r.step])
    off = run_with_verifier(sim_log, monkeypatch, FakeVerifier(np.zeros(3)), "scan_match.enabled=false")
    assert off.loops and all(np.allclose(r.match.cov, np.diag([1e-4, 1e-4, 1e-5])) for r in off.loops)


@pytest.mark.parametrize(
    "corner_reason, on_points",
    [("few corners", True), ("no hypothesis", True), ("low fitness", True), ("ambiguous", False)],
)
def test_pairs_the_corners_cannot_verify_are_verified_on_points(
    sim_log, monkeypatch, corner_reason, on_points
):
    # too few corners seen from both (a corridor driven the other way) is no evidence either way, nor is a
    # corner pose the points refute (a constellation repeated elsewhere): the points decide, around the
    # graph's prediction; an ambiguous corner match (two poses fit) stays refused
    def corners(a, b, cfg, associate, icp, maps=None):
        return LoopMatch(np.full(3, np.nan), np.full((3, 3), np.nan), 2, 0.0, False, corner_reason)

    priors, current = [], []

    def points(a, b, prior, prior_cov, cfg, icp, maps=None):
        # the prior is the graph's own prediction of b's origin in a's frame, with its covariance
        want, want_cov = current[0].graph.relative(a.index, b.index)
        np.testing.assert_allclose(prior, want)
        np.testing.assert_allclose(prior_cov, want_cov)
        priors.append((a.index, b.index))
        return LoopMatch(compose(prior, (0.01, 0.0, 0.0)), np.diag([1e-4, 1e-4, 1e-5]), 0, 0.9, True, "")

    monkeypatch.setattr(hierarchy, "match_submaps", corners)
    monkeypatch.setattr(hierarchy, "match_points", points)
    for enabled in (True, False):
        priors.clear()
        cfg = config_from(
            {},
            [
                "submaps.enabled=true",
                "submaps.max_steps=6",
                f"loops.point_search={str(enabled).lower()}",
                "loops.point_searches=1000",
            ],
        )
        src = open_input(sim_log, cfg)
        hs = HierarchicalSlam(cfg, src.laser2base)
        current[:] = [hs]
        for frame in frames(src, cfg):
            hs.step(frame)
        hs.finish()
        assert hs.loops
        if enabled and on_points:
            assert priors and all(r.accepted and r.reason == "verified on points" for r in hs.loops)
            # the corners' count is kept for loops.csv, unless the points refuted the corners' pose
            kept = 0 if corner_reason == "low fitness" else 2
            assert all(r.match.n_corners == kept for r in hs.loops)
        else:
            assert not priors and not any(r.accepted for r in hs.loops)
            assert all(r.reason == corner_reason for r in hs.loops)


def test_verification_stops_once_max_closures_are_accepted(sim_log, monkeypatch):
    # on ground revisited many times every close has max_candidates candidates; once max_closures of
    # them (nearest first) passed the gate, the rest are not verified
    many = run_with_verifier(sim_log, monkeypatch, FakeVerifier(np.zeros(3)), "loops.max_closures=1000")
    per_submap = Counter(r.submap_to for r in many.loops)
    assert max(per_submap.values()) >= 3, "the fixture should give some submap three closures or more"
    verifier = FakeVerifier(np.zeros(3))
    capped = run_with_verifier(sim_log, monkeypatch, verifier, "loops.max_closures=2")
    per_submap = Counter(r.submap_to for r in capped.loops)
    assert max(per_submap.values()) == 2 and all(r.accepted for r in capped.loops)
    assert verifier.calls == len(capped.loops) < len(many.loops)


def test_points_are_searched_for_the_nearest_candidates_only(sim_log, monkeypatch):
    # each search costs a correlative search or two: at most loops.point_searches per closed submap
    def corners(a, b, cfg, associate, icp, maps=None):
        return LoopMatch(np.full(3, np.nan), np.full((3, 3), np.nan), 2, 0.0, False, "few corners")

    def points(a, b, prior, prior_cov, cfg, icp, maps=None):
        return LoopMatch(
            compose(prior, (0.5, 0.0, 0.0)), np.diag([1e-4, 1e-4, 1e-5]), 0, 0.9, False, "ambiguous"
        )

    monkeypatch.setattr(hierarchy, "match_submaps", corners)
    monkeypatch.setattr(hierarchy, "match_points", points)
    cfg = config_from({}, ["submaps.enabled=true", "submaps.max_steps=6", "loops.point_searches=1"])
    src = open_input(sim_log, cfg)
    hs = HierarchicalSlam(cfg, src.laser2base)
    for frame in frames(src, cfg):
        hs.step(frame)
    hs.finish()
    searched = Counter(r.submap_to for r in hs.loops if r.reason == "ambiguous")
    per_submap = Counter(r.submap_to for r in hs.loops)
    assert any(n >= 2 for n in per_submap.values()), "the fixture should give some submap two candidates"
    assert all(searched[b] == 1 for b in per_submap)
    for b in per_submap:  # the nearest (first) candidate was the one searched
        assert next(r for r in hs.loops if r.submap_to == b).reason == "ambiguous"


def test_a_step_in_the_global_frame_carries_the_lever_arm_of_its_origins_heading():
    """globalise's covariance against Monte Carlo: the origin drawn from its marginal, the local pose
    from its own (x–θ, y–θ uncorrelated, as the step record holds them), composed 200,000 times. A pose
    8 m from its origin, whose heading σ is 2°: the lever arm more than doubles the xy spread."""
    from cornerslam_cli.geometry import compose, wrap_angle
    from cornerslam_cli.slam import StepRecord, globalise

    rng = np.random.default_rng(3)
    origin, local = np.array([2.0, -1.0, 0.7]), np.array([6.0, 5.0, -0.4])
    origin_cov = np.diag([0.02**2, 0.03**2, np.radians(2.0) ** 2])
    origin_cov[0, 1] = origin_cov[1, 0] = 0.3 * 0.02 * 0.03
    local_var, local_cxy = np.array([0.05**2, 0.04**2, 0.01**2]), 0.5 * 0.05 * 0.04
    r = StepRecord(
        0, 0.0, local, local_var, np.zeros(3), np.zeros(3), 0, 0, 0, 0, 0, 0, 0, 0.0, 0.0, 0.0, 0.0,
        np.zeros((0, 4)), cov_xy=local_cxy,
    )  # fmt: skip
    g = globalise(r, origin, origin_cov, 3, 0.0)
    n = 200_000
    lc = np.diag(local_var)
    lc[0, 1] = lc[1, 0] = local_cxy
    o = rng.multivariate_normal(origin, origin_cov, n)
    loc = rng.multivariate_normal(local, lc, n)
    p = compose(o, loc)
    d = p - compose(origin, local)
    d[:, 2] = wrap_angle(d[:, 2])
    mc = np.cov(d.T)
    assert g.submap == 3 and np.allclose(g.pose, compose(origin, local))
    assert np.allclose(g.pose_var, np.diag(mc), rtol=0.03)
    assert g.cov_xy == pytest.approx(mc[0, 1], rel=0.05)
    assert g.pose_var[:2].sum() > 2 * (np.trace(origin_cov[:2, :2]) + local_var[:2].sum())
