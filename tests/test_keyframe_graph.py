"""The pose graph's keyframe nodes (graph/submap.py, hierarchy.py): which steps become nodes, the chain
of factors a closed submap enters as (poses and covariances against an independent propagation), and a
run's smoothed trajectory read from the nodes."""

from __future__ import annotations

import copy
import csv
import json
from types import SimpleNamespace

import numpy as np
import pytest

from cornerslam_cli.config import config_from
from cornerslam_cli.frontend import frames, open_input
from cornerslam_cli.geometry import chain, compose, relative, wrap_angle
from cornerslam_cli.graph.smooth import recalibrated
from cornerslam_cli.graph.submap import det3, keyframe_factors, keyframe_nodes, propagate
from cornerslam_cli.hierarchy import HierarchicalSlam
from cornerslam_cli.motion.fusion import bias_matrices


def arc(n: int = 12, step: float = 0.4, turn: float = 0.15) -> tuple[np.ndarray, np.ndarray]:
    """n steps of ``step`` m and ``turn`` rad each: (increments (n, 3), poses (n, 3) from the origin)."""
    inc = np.tile([step, 0.0, turn], (n, 1))
    poses = [inc[0]]
    for d in inc[1:]:
        poses.append(compose(poses[-1], d))
    return inc, np.array(poses)


def test_nodes_every_spacing_metres_or_angle_and_at_the_last_step():
    _, poses = arc(12, 0.4, 0.0)  # straight: 0.4, 0.8, 1.2 … m from the origin
    assert keyframe_nodes(poses, 1.0, 0.5).tolist() == [2, 5, 8, 11]  # 1.2 m, then 1.2 m more, …, last
    assert keyframe_nodes(poses, 0.0, 0.5).tolist() == list(range(12))  # every keyframe
    turn = np.column_stack((np.zeros(6), np.zeros(6), 0.2 * np.arange(1, 7)))  # turning in place
    assert keyframe_nodes(turn, 1.0, 0.5).tolist() == [2, 5]


def test_factors_chain_back_to_the_poses_and_carry_the_propagated_covariance():
    inc, poses = arc(12)
    rng = np.random.default_rng(7)
    covs = np.array([np.diag(rng.uniform(1e-4, 4e-4, 2).tolist() + [rng.uniform(1e-5, 4e-5)]) for _ in inc])
    nodes = keyframe_nodes(poses, 1.0, 0.5)
    # the filter as sure of the last pose as the motion alone: no scaling
    mc = monte_carlo(inc, covs, 20000, rng)
    rel, cov = keyframe_factors(poses, covs, np.cov(last_errors(mc, poses).T), nodes)
    chained = [rel[0]]
    for r in rel[1:]:
        chained.append(compose(chained[-1], r))
    np.testing.assert_allclose(chained, poses[nodes], atol=1e-12)
    # each factor's covariance: the steps' noise between its two nodes, in the first node's frame
    a, b = nodes[0], nodes[1]
    seg = monte_carlo(inc[a + 1 : b + 1], covs[a + 1 : b + 1], 20000, rng)
    seg_err = seg[:, -1] - rel[1]
    seg_err[:, 2] = wrap_angle(seg_err[:, 2])
    np.testing.assert_allclose(cov[1], np.cov(seg_err.T), rtol=0.15, atol=2e-6)
    # a filter twice as sure of the end (its corners): every factor's covariance scaled to match
    end = np.cov(last_errors(mc, poses).T)
    _, half = keyframe_factors(poses, covs, end / 2, nodes)
    np.testing.assert_allclose(half / cov, 0.5, rtol=0.1)


def keyframe_factors_step_by_step(poses, covs, end_cov, nodes):
    """keyframe_factors as it was written before its terms were computed for all steps at once: one
    :func:`propagate` of each chain per step (the reference its bits must equal)."""
    prev = np.vstack((np.zeros(3), poses[:-1]))
    total, part, ref, parts = np.zeros((3, 3)), np.zeros((3, 3)), np.zeros(3), []
    is_node = np.zeros(len(poses), dtype=bool)
    is_node[nodes] = True
    for k, (p0, p1, c) in enumerate(zip(prev, poses, covs, strict=True)):
        total = propagate(total, p0, p1, c)
        part = propagate(part, relative(ref, p0), relative(ref, p1), c)
        if is_node[k]:
            parts.append(part)
            part, ref = np.zeros((3, 3)), p1
    scale = 1.0
    if det3(total) > 0 and det3(end_cov) > 0:
        scale = float(np.cbrt(det3(end_cov) / det3(total)))
    anchors = np.vstack((np.zeros(3), poses[nodes[:-1]]))
    return relative(anchors, poses[nodes]), np.array(parts) * scale


@pytest.mark.parametrize("seed", range(4))
def test_factors_are_the_step_by_step_propagations_bit_for_bit(seed):
    """Random walks (turns past ±π, nodes every step or far apart, a single step): the same bits as
    the step-by-step computation."""
    rng = np.random.default_rng(seed)
    for n, spacing in ((1, 1.0), (2, 0.0), (40, 0.0), (300, 1.0), (300, 5.0)):
        inc = np.column_stack((rng.uniform(0.0, 0.5, n), rng.normal(0.0, 0.05, n), rng.normal(0.0, 0.4, n)))
        poses = [rng.normal(0.0, 0.1, 3)]
        for d in inc[1:]:
            poses.append(compose(poses[-1], d))
        poses = np.array(poses)
        A = rng.normal(0.0, 0.02, (n, 3, 3))
        covs = A @ A.transpose(0, 2, 1) + 1e-6 * np.eye(3)
        nodes = keyframe_nodes(poses, spacing, 0.5)
        end = np.diag(rng.uniform(1e-4, 1e-2, 3))
        rel, cov = keyframe_factors(poses, covs, end, nodes)
        ref_rel, ref_cov = keyframe_factors_step_by_step(poses, covs, end, nodes)
        assert rel.tobytes() == ref_rel.tobytes() and cov.tobytes() == ref_cov.tobytes()


def monte_carlo(inc: np.ndarray, covs: np.ndarray, n: int, rng) -> np.ndarray:
    """(n, s, 3) poses from chaining ``inc`` with Gaussian noise of ``covs`` (each in its start frame)."""
    out = np.zeros((n, len(inc), 3))
    pose = np.zeros((n, 3))
    for k, (d, c) in enumerate(zip(inc, covs, strict=True)):
        pose = compose(pose, d + rng.multivariate_normal(np.zeros(3), c, n))
        out[:, k] = pose
    return out


def last_errors(mc: np.ndarray, poses: np.ndarray) -> np.ndarray:
    e = mc[:, -1] - poses[-1]
    e[:, 2] = wrap_angle(e[:, 2])
    return e


@pytest.mark.parametrize("spacing", [0.0, 1.0])
def test_a_runs_smoothed_poses_hang_from_the_nodes(sim_log, spacing):
    """Without loop closing the keyframe graph is a chain: its smoothed trajectory is the filter's own
    (each submap's steps at its origin), whatever the node spacing; each step's node is at or before it."""
    cfg = config_from({}, ["submaps.max_steps=6", "loops.enabled=false", f"graph.node_spacing={spacing}"])
    src = open_input(sim_log, cfg)
    hs = HierarchicalSlam(cfg, src.laser2base)
    online = [hs.step(f).pose for f in frames(src, cfg)]
    hs.finish()
    np.testing.assert_allclose(hs.final_poses(), online, atol=1e-6)
    nodes = np.concatenate([s.step_nodes for s in hs.closed])
    assert np.all(np.diff(nodes) >= 0) and nodes[-1] == len(hs.smoothed) - 1
    if spacing == 0.0:
        assert len(hs.smoothed) == hs.n_steps + 1  # a node per keyframe and the first origin


def test_chain_composes_the_increments_one_after_another():
    rng = np.random.default_rng(5)
    inc = np.column_stack((rng.uniform(-0.2, 0.6, 40), rng.normal(0, 0.05, 40), rng.normal(0, 0.6, 40)))
    want = [inc[0]]
    for d in inc[1:]:
        want.append(compose(want[-1], d))
    np.testing.assert_allclose(chain(inc), np.array(want), atol=1e-12)


def test_a_recalibrated_chain_is_the_filter_chain_moved_by_each_steps_shift():
    """recalibrated (graph/smooth.py): with no shift, the submap's own keyframe chain (keyframe_factors'
    rel) and each step's offset from its node (as final_poses reads it from the filter); with a shift, the
    chain of the filter's step increments each moved by its shift, independently composed."""
    inc, poses = arc(12)
    nodes = keyframe_nodes(poses, 1.0, 0.5)
    before = np.searchsorted(nodes, np.arange(len(poses)), side="right") - 1
    anchors = np.where((before >= 0)[:, None], poses[nodes[before.clip(0)]], 0.0)
    sub = SimpleNamespace(poses=poses)
    rel, at, offsets = recalibrated(sub, np.zeros((12, 3)), nodes)
    np.testing.assert_allclose(
        rel, keyframe_factors(poses, np.tile(np.eye(3), (12, 1, 1)), np.eye(3), nodes)[0]
    )
    np.testing.assert_allclose(at, poses[nodes], atol=1e-12)
    np.testing.assert_allclose(offsets, relative(anchors, poses), atol=1e-12)
    shift = np.random.default_rng(2).normal(0, [0.01, 0.01, 0.003], (12, 3))
    moved = [inc[0] + shift[0]]
    for d, s in zip(inc[1:], shift[1:], strict=True):
        moved.append(compose(moved[-1], d + s))
    moved = np.array(moved)
    rel, at, offsets = recalibrated(sub, shift, nodes)
    np.testing.assert_allclose(at, moved[nodes], atol=1e-12)
    chained = [rel[0]]
    for r in rel[1:]:
        chained.append(compose(chained[-1], r))
    np.testing.assert_allclose(chained, moved[nodes], atol=1e-12)
    hang = np.where((before >= 0)[:, None], moved[nodes[before.clip(0)]], 0.0)
    np.testing.assert_allclose(compose(hang, offsets), moved, atol=1e-12)


def moved_to(c: np.ndarray):
    """A stand-in for OdometryFusion.carry_back: every step moved as if it had the bias ``c`` (scale,
    drift) taken out as well, −keep·B(o)·c, from its BiasTaken row."""

    def recalibration(rows: np.ndarray) -> np.ndarray:
        keep = rows[:, 3:].reshape(-1, 3, 3)
        return -np.einsum("nij,nj->ni", keep, bias_matrices(rows[:, :3], False) @ c)

    return recalibration


def test_a_runs_recalibrated_poses_are_its_steps_moved_by_their_shifts(sim_log):
    """Without loop closing the keyframe graph is a chain: finished with a bias carried back (here a
    stand-in: 1 % scale, 0.01 rad/m added to every step), the smoothed trajectory is the filter's step
    increments each moved by its shift (from its frame's BiasTaken), composed from the first pose; across
    submaps too."""
    cfg = config_from({}, ["submaps.max_steps=6", "loops.enabled=false", "graph.recalibrate=true"])
    src = open_input(sim_log, cfg)
    hs = HierarchicalSlam(cfg, src.laser2base)
    fs = list(frames(src, cfg))
    online = np.array([hs.step(f).pose for f in fs])
    assert sum(f.bias_taken is not None for f in fs) == len(fs) - 1  # all but the first
    rows = np.array([[0.0] * 12 if f.bias_taken is None else f.bias_taken.row() for f in fs])

    recalibration = moved_to(np.array([0.01, 0.01]))
    shift = recalibration(rows)
    assert np.abs(shift).max() > 1e-4
    hs.finish(recalibration)
    moved = compose(online[0], chain(relative(online[:-1], online[1:]) + shift[1:]))
    np.testing.assert_allclose(hs.final_poses()[1:], moved, atol=1e-6)


def test_recalibrated_landmarks_keep_their_place_relative_to_the_robot_that_last_saw_them(sim_log):
    """map.csv once recalibrated (finish with a bias): each landmark where the smoothed pose of the step
    that last observed it puts it — relative to that pose, where the filter had it relative to its own
    pose then (landmark_frames), as lines.csv's segments move with the smoothed poses."""
    cfg = config_from({}, ["submaps.max_steps=6", "loops.enabled=false"])
    src = open_input(sim_log, cfg)
    hs = HierarchicalSlam(cfg, src.laser2base)
    for f in frames(src, cfg):
        hs.step(f)
    hs.finish(moved_to(np.array([0.02, 0.02])))
    table, poses = hs.landmark_table(), hs.final_poses()
    assert len(table["id"]) > 0
    for s, t in zip(hs.closed, hs.tables, strict=True):
        k = t["last_step"]
        seen = np.column_stack((t["x"], t["y"], np.zeros(len(k))))
        want = relative(s.poses[k - s.first_step], seen)[:, :2]
        rows = np.isin(table["id"], t["id"])
        placed = np.column_stack((table["x"][rows], table["y"][rows], np.zeros(rows.sum())))
        np.testing.assert_allclose(relative(poses[k], placed)[:, :2], want, atol=1e-9)


@pytest.mark.parametrize(
    "overrides, learnt",
    [
        (["graph.recalibrate=true"], True),
        ([], False),
        (["graph.recalibrate=true", "scan_match.enabled=false"], False),
    ],
)
def test_a_run_recalibrates_with_its_front_ends_bias_only_when_it_matched_scans_and_is_asked_to(
    sim_log, tmp_path, monkeypatch, overrides, learnt
):
    """pipeline.run_filter's wiring of graph.recalibrate: finish gets the scan matcher's fusion's
    carry_back (the bias it fits on the whole run, carried back) with graph.recalibrate=true, None by
    default (off) or without scan matching."""
    from cornerslam_cli.motion.fusion import OdometryFusion
    from cornerslam_cli.pipeline import run
    from cornerslam_cli.span import Span

    got = []
    finish = HierarchicalSlam.finish
    monkeypatch.setattr(HierarchicalSlam, "finish", lambda self, r=None: (got.append(r), finish(self, r)))
    cfg = config_from({}, ["submaps.max_steps=20", "loops.enabled=false", *overrides])
    run(sim_log, cfg, tmp_path / "out", span=Span(max_scans=60))
    assert len(got) == 1
    model = json.loads((tmp_path / "out" / "summary.json").read_text()).get("odometry_model") or {}
    whole = ("whole_run_scale_error", "whole_run_heading_drift_per_m")
    if learnt:
        assert isinstance(got[0].__self__, OdometryFusion) and got[0].__func__ is OdometryFusion.carry_back
        fusion = got[0].__self__  # (the run's: every sample kept, all of them under the window here)
        assert len(fusion.every_sample) == 24 * len(fusion.samples) > 0
        # summary.json says which bias was carried back: the whole run's fit
        assert [model[k] for k in whole] == pytest.approx(list(fusion.whole_run_fit[0]), abs=0.0)
    else:
        assert got[0] is None and not any(k in model for k in whole)


@pytest.mark.parametrize(
    "overrides, ignored",
    [
        ([], None),
        (["submaps.enabled=false"], "submaps.enabled=false"),
        (["scan_match.enabled=false"], "scan_match.enabled=false"),
    ],
)
def test_graph_recalibrate_says_when_it_has_nothing_to_do(sim_log, tmp_path, overrides, ignored):
    """graph.recalibrate=true on a run without the keyframe graph or without scan matching warns that it is
    ignored and why (as graph.refine does), and not otherwise."""
    from cornerslam_cli.pipeline import run
    from cornerslam_cli.span import Span

    cfg = config_from({}, ["graph.recalibrate=true", "loops.enabled=false", *overrides])
    summary = run(sim_log, cfg, tmp_path / "out", span=Span(max_scans=30))
    said = [w for w in summary.warnings if "graph.recalibrate=true is ignored" in w]
    assert len(said) == (ignored is not None) and all(ignored in w for w in said)


def written_poses(out, columns: tuple[str, str, str] = ("x", "y", "theta")) -> np.ndarray:
    """(n, 3) the ``columns`` of the trajectory.csv a run wrote into ``out``."""
    with open(out / "trajectory.csv", newline="") as f:
        return np.array([[float(row[c]) for c in columns] for row in csv.DictReader(f)])


def test_a_run_writes_its_steps_moved_by_the_bias_its_own_fusion_carries_back(sim_log, tmp_path, monkeypatch):
    """End to end, the real OdometryFusion.carry_back on a run's own BiasTaken rows (sim_log's odometry:
    2 % long, 0.01 rad/m drift, which the learner takes out only after some steps): row k of the
    hierarchy's ``taken`` is trajectory step k (its odometry increment and the bias the fusion had then);
    each term carried moves the steps before the one that first took it and none from it on; and without
    loop closing the trajectory the run wrote is its online steps each moved by that shift, composed from
    the first pose — with graph.recalibrate=false, the online trajectory itself."""
    from cornerslam_cli.motion.fusion import OdometryFusion
    from cornerslam_cli.pipeline import run
    from cornerslam_cli.span import Span

    seen, used = {}, []  # the hierarchy at finish; (fusion, o, c) of every increment the fusions handled
    finish, taken = HierarchicalSlam.finish, OdometryFusion.taken

    def finishing(self, shift_of=None):
        seen.update(online=self.final_poses().copy(), shift_of=shift_of)
        if shift_of is not None:
            seen.update(rows=np.frombuffer(self.taken).reshape(-1, 12).copy())
            seen.update(shift=shift_of(seen["rows"]))
        return finish(self, shift_of)

    def taking(self, o, gain):  # (after fuse or the fallback: self.c is the bias this increment had)
        used.append((self, np.array(o, dtype=float), self.c.copy()))
        return taken(self, o, gain)

    monkeypatch.setattr(HierarchicalSlam, "finish", finishing)
    monkeypatch.setattr(OdometryFusion, "taken", taking)
    sets = ["submaps.max_steps=20", "loops.enabled=false"]
    run(sim_log, config_from({}, [*sets, "graph.recalibrate=true"]), tmp_path / "on", span=Span(max_scans=60))
    fusion, rows, shift, online = seen["shift_of"].__self__, seen["rows"], seen["shift"], seen["online"]
    assert seen["shift_of"].__func__ is OdometryFusion.carry_back

    # row k is step k: row 0 (the first scan) took nothing; row k's odometry is the written odometry's
    # increment k-1 → k, and fusing it was the k-th increment the run's fusion handled
    odom = written_poses(tmp_path / "on", ("odom_x", "odom_y", "odom_theta"))
    assert len(rows) == len(shift) == len(online) == len(odom) == fusion.n_steps + 1
    assert not rows[0].any() and not shift[0].any()
    np.testing.assert_allclose(rows[1:, :3], relative(odom[:-1], odom[1:]), atol=1e-7)
    mine = [(o, c) for f, o, c in used if f is fusion]
    assert np.array_equal(np.array([o for o, _ in mine]), rows[1:, :3])
    had = np.vstack((np.zeros(2), [c for _, c in mine]))  # the bias each step's increment was fused with
    carried = [i for i in range(2) if fusion.first_taken[i] is not None and not fusion.dropped[i]]
    for i in range(2):
        first = np.flatnonzero(had[:, i])
        assert fusion.first_taken[i] == (int(first[0]) if len(first) else None)
    assert any(fusion.first_taken[i] > 1 for i in carried)  # a term the learner took only after some steps

    # each term carried moves every step before its first_taken, none from it on; together, the shift
    whole = np.zeros_like(shift)
    for i in carried:
        alone = copy.copy(fusion)
        alone.first_taken = [f if j == i else None for j, f in enumerate(fusion.first_taken)]
        part = alone.carry_back(rows)
        first = fusion.first_taken[i]
        assert not part[first:].any() and np.all(np.abs(part[1:first]).max(axis=1) > 0)
        whole += part
    np.testing.assert_allclose(shift, whole, rtol=0, atol=1e-15)
    last = max(fusion.first_taken[i] for i in carried)
    assert not shift[last:].any() and np.abs(shift[last - 1]).max() > 1e-6
    assert np.abs(shift).max() > 1e-4

    # what the run wrote: the online trajectory (as trajectory.csv's online columns place it, in the
    # odometry frame) with each increment moved by the shift, composed from the first pose
    placed = written_poses(tmp_path / "on", ("online_x", "online_y", "online_theta"))
    to_written = compose(placed[0], relative(online[0], np.zeros(3)))  # the map frame in the written one
    np.testing.assert_allclose(compose(to_written, online), placed, atol=1e-6)
    moved = compose(placed[0], chain(relative(online[:-1], online[1:]) + shift[1:]))
    written = written_poses(tmp_path / "on")
    np.testing.assert_allclose(written[0], placed[0], atol=1e-9)
    np.testing.assert_allclose(written[1:], moved, atol=1e-6)
    assert np.abs(written - placed).max() > 1e-3  # (the shift moved it: not the online one)

    # graph.recalibrate=false: no shift, the online trajectory written, the same online steps
    seen.clear()
    run(sim_log, config_from({}, sets), tmp_path / "off", span=Span(max_scans=60))
    assert seen["shift_of"] is None
    np.testing.assert_allclose(seen["online"], online, atol=1e-12)
    np.testing.assert_allclose(written_poses(tmp_path / "off"), placed, atol=1e-6)
