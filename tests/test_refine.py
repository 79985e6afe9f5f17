"""graph.refine (graph/refine.py): the nodes registered against, against a brute-force enumeration; one
registration against the poses the scans were cast from; the points kept per place; a whole run against
the simulated truth."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial import cKDTree

from cornerslam_cli import simworld as sw
from cornerslam_cli.cli import cli
from cornerslam_cli.config import config_from
from cornerslam_cli.evaluate import ate
from cornerslam_cli.frontend import frames, open_input
from cornerslam_cli.geometry import compose, relative, transform_points, wrap_angle
from cornerslam_cli.graph.params import GraphConfig
from cornerslam_cli.graph.posegraph import PoseGraph
from cornerslam_cli.graph.refine import KEEP, MIN_POINTS, Refinement, nearest
from cornerslam_cli.graph.submap import OpenSubmap, keyframe_nodes
from cornerslam_cli.hierarchy import HierarchicalSlam
from cornerslam_cli.motion.params import ScanMatchConfig
from cornerslam_cli.simulate import simulate_log


def brute_nearest(poses: np.ndarray, radius: float, min_path: float, most: int) -> list[tuple[int, int]]:
    out = []
    for i in range(len(poses)):
        found = []
        for j in range(i):
            path = sum(math.dist(poses[k, :2], poses[k + 1, :2]) for k in range(j, i))
            d = math.dist(poses[i, :2], poses[j, :2])
            if d <= radius and path >= min_path:
                found.append((d, j))
        out.extend((j, i) for j in sorted(j for _, j in sorted(found)[:most]))
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_nodes_registered_against_are_the_nearest_earlier_ones_far_enough_back_along_the_path(seed):
    rng = np.random.default_rng(seed)
    steps = rng.normal(0.0, 0.6, (80, 2))
    poses = np.column_stack((np.cumsum(steps, axis=0), rng.uniform(-np.pi, np.pi, 80)))
    paths = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(poses[:, :2], axis=0).T))))
    cfg = GraphConfig(refine_radius=2.0, refine_min_path=3.0, refine_neighbours=2)
    got = [(int(j), i) for i in range(80) for j in nearest(poses[i], paths[i], poses[:i], paths[:i], cfg)]
    assert got == brute_nearest(poses, 2.0, 3.0, 2)
    assert got  # the walk comes back near itself


def room_scan(pose) -> np.ndarray:
    """Points (robot frame) of a 270° scan of a room with a pillar and a niche, from ``pose``."""
    world = sw.make_world(
        [
            sw.room(0.0, 0.0, 10.0, 7.0),
            sw.rectangle(6.5, 4.5, 1.0, 1.5),
            sw.polyline([(2, 7), (2, 5.5), (3.5, 5.5), (3.5, 7)]),
        ]
    )
    angles = np.linspace(-0.75 * np.pi, 0.75 * np.pi, 1081)
    scan = sw.simulate_scan(world, pose, angles, sigma_range=0.005, rng=np.random.default_rng(3))
    return scan.points().astype(float)


TRUE_A, TRUE_B = np.array([3.0, 2.5, 0.2]), np.array([5.5, 3.0, 0.5])
ERROR = np.array([0.12, -0.08, 0.03])  # the chain's error between A and B (B's frame)


def closing(index: int, node: int, points: list[np.ndarray]) -> OpenSubmap:
    """Submap ``index`` from node ``node`` with its steps' ``points`` (its frame), as it closes."""
    sub = OpenSubmap(index, 0, node, keep_steps=True)
    sub.step_points = points
    return sub


def registered(
    scans: list[np.ndarray], guesses: np.ndarray, cfg: GraphConfig, end: bool = True
) -> Refinement:
    """One closed submap whose origin is node 0 and whose steps are nodes 0, 1, … at ``guesses`` (the
    estimate, global) with ``scans`` (robot frame, cast from elsewhere), registered (``end``: the run
    ends there; else the last node waits for a next submap)."""
    r = Refinement(cfg, ScanMatchConfig())
    local = relative(guesses[0], guesses)
    points = [transform_points(s, p) for s, p in zip(scans, local, strict=True)]
    r.add_submap(closing(0, 0, points), local[1:], np.arange(len(scans)), local)
    if end:
        r.complete(guesses[:1])
    else:
        r.register(guesses[:1])
    return r


def two_node_graph(error: np.ndarray) -> PoseGraph:
    """Nodes at A and B, the chain between them off by ``error`` (B's frame) with a loose covariance."""
    g = PoseGraph(GraphConfig(solver="lm"), TRUE_A)
    rel = relative(TRUE_A, TRUE_B)
    g.add_sequential(rel + error, np.diag([0.3**2, 0.3**2, 0.1**2]))
    g.optimize()
    return g


def test_a_registration_brings_two_nodes_to_the_poses_their_scans_were_cast_from():
    g = two_node_graph(ERROR)
    cfg = GraphConfig(refine_min_path=0.0)
    r = registered([room_scan(TRUE_A), room_scan(TRUE_B)], g.poses(), cfg)
    assert (r.tried, [(s.j, s.i) for s in r.found]) == (1, [(0, 1)])
    assert r.apply(g, 1.0) == 1
    e = relative(relative(TRUE_A, TRUE_B), relative(g.pose(0), g.pose(1)))
    assert np.hypot(e[0], e[1]) < 0.01 and abs(wrap_angle(e[2])) < math.radians(0.2)


def test_a_registration_that_moves_the_pair_too_far_from_the_solved_graph_is_not_added():
    g = two_node_graph(ERROR)
    before = g.poses()
    cfg = GraphConfig(refine_min_path=0.0, refine_max_theta=0.02)  # ICP turns it by ~0.03 rad
    r = registered([room_scan(TRUE_A), room_scan(TRUE_B)], before, cfg)
    assert len(r.found) == 1 and r.apply(g, 1.0) == 0
    np.testing.assert_array_equal(g.poses(), before)
    too_far = replace(cfg, refine_max_theta=0.05, refine_radius=1.0)  # B is 2.5 m from A: not a pair
    assert registered([room_scan(TRUE_A), room_scan(TRUE_B)], before, too_far).tried == 0


def test_the_earlier_nodes_map_takes_its_chain_neighbours_points_placed_with_the_estimate():
    """Node 0 has too few points for a map of its own; its neighbour node 1 (0.5 m behind it, on the
    chain) has the room: node 2 registers against node 1's points placed in node 0's frame."""
    a1 = np.array([2.5, 2.5, 0.1])
    g = PoseGraph(GraphConfig(solver="lm"), TRUE_A)
    g.add_sequential(relative(TRUE_A, a1), np.diag([1e-6, 1e-6, 1e-8]))
    g.add_sequential(relative(a1, TRUE_B) + ERROR, np.diag([0.3**2, 0.3**2, 0.1**2]))
    g.optimize()
    cfg = GraphConfig(refine_min_path=0.0, refine_neighbours=1)
    scans = [room_scan(TRUE_A)[::300], room_scan(a1), room_scan(TRUE_B)]
    assert len(scans[0]) < MIN_POINTS
    r = registered(scans, g.poses(), cfg)
    # node 1's nearest is node 0 alone (too few points: not tried); node 2's is node 0, with node 1's points
    assert (r.tried, [(s.j, s.i) for s in r.found]) == (1, [(0, 2)])
    assert r.apply(g, 1.0) == 1
    e = relative(relative(TRUE_A, TRUE_B), relative(g.pose(0), g.pose(2)))
    assert np.hypot(e[0], e[1]) < 0.01 and abs(wrap_angle(e[2])) < math.radians(0.2)


def test_a_solve_with_the_pairs_stopped_at_its_step_limit_is_warned_about_as_the_refinements(monkeypatch):
    from cornerslam_cli.graph import posegraph

    r = registered(
        [room_scan(TRUE_A), room_scan(TRUE_B)],
        two_node_graph(ERROR).poses(),
        GraphConfig(refine_min_path=0.0),
    )
    assert r.solver_warning() is None  # nothing solved yet
    g = two_node_graph(ERROR)
    monkeypatch.setattr(posegraph, "LM_MAX_ITERATIONS", 1)  # the pair moves B by 0.1 m: more than 1 step
    assert r.apply(g, 1.0) == 1 and not g.converged
    assert "the dense refinement's 1 scan pairs stopped at its step limit" in r.solver_warning()
    monkeypatch.setattr(posegraph, "LM_MAX_ITERATIONS", 100)
    r.added = 0
    assert r.apply(two_node_graph(ERROR), 1.0) == 1 and r.solver_warning() is None


def test_a_pair_whose_scans_do_not_fit_is_not_kept():
    """Node 1's scan is of another room: whatever ICP makes of it, it fits below refine_min_fitness."""
    other = sw.make_world([sw.room(0.0, 0.0, 4.0, 12.0), sw.rectangle(2.0, 8.0, 0.5, 0.5)])
    angles = np.linspace(-0.75 * np.pi, 0.75 * np.pi, 1081)
    elsewhere = sw.simulate_scan(other, (2.0, 3.0, 1.2), angles, sigma_range=0.005).points().astype(float)
    scans, guesses = [room_scan(TRUE_A), elsewhere], two_node_graph(np.zeros(3)).poses()
    anything = GraphConfig(refine_min_path=0.0, refine_max_xy=100.0, refine_max_theta=3.0)
    r = registered(scans, guesses, anything)
    assert (r.tried, r.found) == (1, [])
    no_fit = registered(scans, guesses, replace(anything, refine_min_fitness=0.0))
    assert no_fit.apply(two_node_graph(np.zeros(3)), 1.0) == 1


def test_a_place_passed_again_and_again_keeps_the_first_nodes_points_and_registers_the_rest_against_them():
    """Twelve nodes alternating between P and Q (6 m apart, beyond the radius): the first KEEP at each
    are kept as targets, the later ones registered against them and dropped; the last node, left
    waiting for a next submap that never comes, is registered when the run ends."""
    P, Q = np.array([3.0, 2.5, 0.2]), np.array([9.0, 2.0, 0.5])
    guesses = np.array([P if k % 2 == 0 else Q for k in range(12)])
    scans = [room_scan(p) for p in guesses]
    r = registered(scans, guesses, GraphConfig(), end=False)
    assert r.kept == list(range(2 * KEEP)) and 11 not in r.kept
    r.complete(guesses[:1])
    assert {s.i for s in r.found} == set(range(2, 12))  # nodes 0 and 1 have no earlier node at their place
    assert all(s.j in r.kept for s in r.found) and len(r.nodes) == 2 * KEEP
    assert all(np.abs(s.pose).max() < 0.02 for s in r.found)  # each at its own place again


def test_each_node_holds_the_points_of_the_steps_that_hang_from_it_across_submap_boundaries():
    """A walk cut into three submaps as hierarchy.py cuts them (each origin the previous submap's last
    step, a node per metre or half radian): every node's points, placed by its submap's origin ∘ its pose,
    cover every scan of the steps that hang from it — the node that ends a submap has the next one's
    first steps too — and nothing else; each node's path is the chain's length to it."""
    t = np.linspace(0.0, 1.0, 40)
    walk = np.column_stack((2 + 6 * t, 2 + 3 * np.sin(3 * t), 0.3 + 2 * t))
    scans = [room_scan(p) for p in walk]
    r = Refinement(GraphConfig(refine=True), ScanMatchConfig())
    origins, origin_node, n_nodes = [walk[0]], 0, 1
    holds: dict[int, list[np.ndarray]] = {}  # node → the global points of the steps hanging from it
    for a, b in [(0, 13), (13, 27), (27, 40)]:
        poses = relative(origins[-1], walk[a:b])
        nodes = keyframe_nodes(poses, 1.0, 0.5)
        before = np.searchsorted(nodes, np.arange(len(poses)), side="right") - 1
        step_nodes = np.where(before >= 0, n_nodes + before, origin_node)
        anchors = np.where((before >= 0)[:, None], poses[nodes[before.clip(0)]], 0.0)
        points = [transform_points(s, p) for s, p in zip(scans[a:b], poses, strict=True)]
        r.add_submap(closing(len(origins) - 1, origin_node, points), poses[nodes], step_nodes, anchors)
        for n, s, p in zip(step_nodes, scans[a:b], walk[a:b], strict=True):
            holds.setdefault(int(n), []).append(transform_points(s, p))
        n_nodes += len(nodes)
        origin_node = n_nodes - 1
        origins.append(compose(origins[-1], poses[-1]))
    assert r.waiting == list(range(n_nodes - 1)) and isinstance(r.nodes[n_nodes - 1].points, list)
    r._complete([n_nodes - 1])  # (complete() would register too)
    everything = cKDTree(np.vstack([transform_points(s, p) for s, p in zip(scans, walk, strict=True)]))
    placed = {n: compose(origins[v.submap], v.pose) for n, v in r.nodes.items()}
    assert sorted(holds) == sorted(r.nodes) == list(range(n_nodes))
    for n, v in r.nodes.items():
        cloud = transform_points(v.points, placed[n])
        assert everything.query(cloud)[0].max() < 1e-9  # only scan points
        own = np.vstack(holds[n])
        assert cKDTree(cloud).query(own)[0].max() <= 0.05 * math.sqrt(2) + 1e-9  # all of its steps'
        assert len(cloud) < len(own)  # thinned
    path = np.concatenate(
        ([0.0], np.cumsum(np.hypot(*np.diff(np.array([placed[n] for n in range(n_nodes)])[:, :2], axis=0).T)))
    )
    np.testing.assert_allclose([r.nodes[n].path for n in range(n_nodes)], path, atol=1e-9)


def test_a_run_counts_its_scan_pairs_and_says_so(sim_log, tmp_path):
    runner = CliRunner()
    res = runner.invoke(
        cli, ["run", str(sim_log), "--out", str(tmp_path / "on"), "--set", "graph.refine=true"]
    )
    assert res.exit_code == 0, res.output
    counts = json.loads((tmp_path / "on" / "summary.json").read_text())["counts"]
    assert counts["refine_factors"] > 0
    assert counts["refine_registered"] >= counts["refine_fit"] >= counts["refine_factors"]
    said = (
        f"refinement {counts['refine_factors']} scan pairs (of {counts['refine_registered']} registered, "
        f"{counts['refine_fit']} fit)"
    )
    assert said in res.output, res.output
    res = runner.invoke(cli, ["run", str(sim_log), "--out", str(tmp_path / "off")])
    off = json.loads((tmp_path / "off" / "summary.json").read_text())["counts"]
    assert not {"refine_factors", "refine_registered", "refine_fit"} & set(off)
    assert "refinement" not in res.output
    args = ["run", str(sim_log), "--out", str(tmp_path / "single"), "--set", "graph.refine=true"]
    res = runner.invoke(cli, [*args, "--set", "submaps.enabled=false"])
    summary = json.loads((tmp_path / "single" / "summary.json").read_text())
    assert any("graph.refine=true is ignored" in w for w in summary["warnings"])
    assert "refine_factors" not in summary["counts"]


@pytest.fixture(scope="module")
def noisy_laps(tmp_path_factory):
    """Two laps of the office with drifting odometry: revisits the keyframe graph can use."""
    out = tmp_path_factory.mktemp("refine") / "laps.mcap"
    simulate_log(
        out, seed=4, laps=2, rate=2.0, beams=541, odometry={"odom_drift": 0.02, "odom_sigma_rot": 0.02}
    )
    return out


def smoothed(log, *overrides) -> tuple[np.ndarray, np.ndarray, HierarchicalSlam]:
    cfg = config_from({}, list(overrides))
    src = open_input(log, cfg)
    hs = HierarchicalSlam(cfg, src.laser2base)
    stamps = [f.stamp for f in frames(src, cfg) if hs.step(f) is not None]
    hs.finish()
    return np.array(stamps), hs.final_poses(), hs


def test_a_run_with_refinement_is_nearer_the_truth(noisy_laps):
    gt = np.loadtxt(noisy_laps.with_suffix(".gt.tum"))
    t, off, _ = smoothed(noisy_laps)
    t_on, on, hs = smoothed(noisy_laps, "graph.refine=true")
    # the pairs' points line up (most registrations move a pair by less than the limits)
    assert 0.8 * hs.refinement.tried <= hs.refinement.added <= len(hs.refinement.found)
    truth = (gt[:, 0], np.column_stack((gt[:, 1], gt[:, 2], np.zeros(len(gt)))))
    e_off, e_on = ate(t, off, *truth).rmse, ate(t_on, on, *truth).rmse
    assert e_on < e_off, (e_on, e_off)  # 12.1 against 15.5 mm
