"""Scan matching (motion/icp.py) against known poses in ray-cast worlds."""

import math

import numpy as np
import pytest

from cornerslam_cli.config import load_config
from cornerslam_cli.errors import ConfigError
from cornerslam_cli.geometry import matrix_from_pose, pose_from_matrix, transform_points, wrap_angle
from cornerslam_cli.motion import ScanMatchConfig, ScanMatcher
from cornerslam_cli.motion.icp import LocalMap, register, voxel_thin
from cornerslam_cli.simworld import OFFICE_LOOP, make_world, office_world, path_poses, polyline, raycast

ANGLES = np.radians(np.arange(-90.0, 90.5, 1.0))  # SICK-like: 181 beams, 1°


def scan_points(world, pose, rng=None, sigma=0.0, angles=ANGLES):
    r = raycast(world, pose, angles, max_range=30.0)
    ok = np.isfinite(r)
    r, a = r[ok], angles[ok]
    if rng is not None:
        r = r + rng.normal(0.0, sigma, r.shape)
    return np.column_stack((r * np.cos(a), r * np.sin(a)))


def pose_error(a, b):
    return math.hypot(a[0] - b[0], a[1] - b[1]), abs(wrap_angle(a[2] - b[2]))


@pytest.fixture(scope="module")
def office():
    return office_world()


def test_register_recovers_a_known_pose(office):
    rng = np.random.default_rng(1)
    ref_pose, true_pose = np.array([6.0, 5.0, 0.1]), np.array([6.6, 5.2, 0.45])
    local = LocalMap.build(transform_points(scan_points(office, ref_pose, rng, 0.01), ref_pose))
    points = scan_points(office, true_pose, rng, 0.01)
    guess = true_pose + [0.15, -0.1, math.radians(4.0)]
    pose, fit = register(points, local, guess, ScanMatchConfig())
    d, a = pose_error(pose, true_pose)
    assert d < 0.02 and a < math.radians(0.3)
    assert fit > 0.8


def test_heading_retry_rescues_a_bad_odometry_turn(office):
    """A 15° odometry heading error: plain ICP from the guess falls into a wrong minimum or a poor fit;
    the retries around the guess find the true pose."""
    rng = np.random.default_rng(2)
    cfg = ScanMatchConfig()
    poses = [np.array([6.0, 5.0, 0.0]), np.array([6.5, 5.1, 0.4])]
    m = ScanMatcher(cfg)
    m.step(scan_points(office, poses[0], rng, 0.01), poses[0])
    bad_odom = poses[1] + [0.0, 0.0, math.radians(15.0)]
    res = m.step(scan_points(office, poses[1], rng, 0.01), bad_odom)
    d, a = pose_error(res.pose, poses[1])
    assert res.matched and d < 0.03 and a < math.radians(0.5)


def test_corridor_keeps_the_wheel_guess_along_its_axis():
    """Two long parallel walls, nothing else in view: ICP cannot tell motion along the corridor, the
    prior keeps the wheel estimate there while the cross-track offset and heading are corrected."""
    world = make_world([polyline([(-50, -1), (50, -1)]), polyline([(-50, 1), (50, 1)])], "corridor")
    rng = np.random.default_rng(3)
    ref_pose, true_pose = np.array([0.0, 0.0, 0.0]), np.array([0.5, 0.1, 0.03])
    local = LocalMap.build(scan_points(world, ref_pose, rng, 0.005))
    guess = true_pose + [0.07, 0.08, 0.03]  # 7 cm along the axis (unobservable), 8 cm across, 1.7°
    pose, _ = register(scan_points(world, true_pose, rng, 0.005), local, guess, ScanMatchConfig())
    assert abs(pose[0] - guess[0]) < 0.035  # along: stays near the guess, not pulled 7 cm to truth
    assert abs(pose[1] - true_pose[1]) < 0.01 and abs(pose[2] - true_pose[2]) < math.radians(0.3)


def test_nothing_in_common_falls_back_to_the_wheel_increment(office):
    cfg = ScanMatchConfig()
    m = ScanMatcher(cfg)
    p0 = np.array([6.0, 5.0, 0.0])
    m.step(scan_points(office, p0), p0)
    far = np.random.default_rng(4).uniform(40.0, 60.0, (150, 2))  # points nowhere near the map
    odom = np.array([6.3, 5.0, 0.1])
    res = m.step(far, odom)
    assert not res.matched and res.fit < cfg.min_fit
    np.testing.assert_allclose(res.pose, odom, atol=1e-12)  # previous refined pose = odometry here
    assert m.n_fallback == 1


def test_refined_chain_beats_drifting_odometry_on_a_loop(office):
    """Once around the simulator's office loop (60 m) with 3 %-scale, heading-drifting wheel odometry:
    the refined chain stays a fraction of the odometry's error from the truth."""
    rng = np.random.default_rng(5)
    truth = path_poses(OFFICE_LOOP, 0.6)
    odom = [truth[0]]
    for k in range(1, len(truth)):
        inc = pose_from_matrix(np.linalg.inv(matrix_from_pose(truth[k - 1])) @ matrix_from_pose(truth[k]))
        inc = inc * [1.03, 1.03, 1.0] + [0.0, 0.0, 0.01 + rng.normal(0, 0.02)]
        odom.append(pose_from_matrix(matrix_from_pose(odom[-1]) @ matrix_from_pose(inc)))
    m = ScanMatcher(ScanMatchConfig())
    refined = [m.step(scan_points(office, p, rng, 0.01), o).pose for p, o in zip(truth, odom, strict=True)]
    err_odom = max(pose_error(o, p)[0] for o, p in zip(odom, truth, strict=True))
    err_icp = max(pose_error(r, p)[0] for r, p in zip(refined, truth, strict=True))
    assert err_odom > 1.0
    assert err_icp < 0.1 * err_odom
    assert m.n_matched == len(truth) - 1 and m.n_fallback == 0


def test_voxel_thin_matches_a_brute_force_cell_count():
    pts = np.random.default_rng(6).uniform(-2, 2, (500, 2)) + [-1e4, 3e4]  # negative and large cells
    thin = pts[voxel_thin(pts, 0.5)]
    cells = {(math.floor(x / 0.5), math.floor(y / 0.5)) for x, y in pts}
    assert len(thin) == len(cells)
    assert {(math.floor(x / 0.5), math.floor(y / 0.5)) for x, y in thin} == cells
    np.testing.assert_array_equal(voxel_thin(pts, 0.0), np.arange(len(pts)))


@pytest.mark.parametrize(
    "key,value",
    [("window", "0"), ("min_fit", "1.5"), ("robust_scale", "0"), ("alpha1", "-1"), ("voxl", "0.1")],
)
def test_bad_scan_match_keys_are_config_errors(key, value):
    with pytest.raises(ConfigError, match=f"scan_match.{key}"):
        load_config(None, [f"scan_match.{key}={value}"])


def test_closed_form_normals_match_eigh():
    from scipy.spatial import cKDTree

    from cornerslam_cli.motion.icp import line_normals

    rng = np.random.default_rng(7)
    t = rng.uniform(0, 3, 200)
    pts = np.column_stack((t, 0.4 * t + rng.normal(0, 0.002, t.size)))  # a noisy line
    pts = np.vstack((pts, rng.uniform(5, 9, (60, 2))))  # and clutter
    tree = cKDTree(pts)
    normals, ok = line_normals(pts, tree)
    _, idx = tree.query(pts, 5)
    nb = pts[idx] - pts[idx].mean(axis=1, keepdims=True)
    w, v = np.linalg.eigh(np.einsum("nki,nkj->nij", nb, nb))
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", normals, v[:, :, 0])), 1.0, atol=1e-6)
    assert ok[:200].mean() > 0.9 and ok[200:].mean() < 0.3


def test_run_reports_the_scan_matched_odometry_and_it_beats_the_wheels(sim_log, tmp_path):
    from cornerslam_cli.pipeline import run
    from cornerslam_cli.report.tables import read_csv

    s = run(sim_log, load_config(None), out=tmp_path / "on")
    acc = s.accuracy
    assert acc.scan_odom_ate.rmse < 0.5 * acc.odom_ate.rmse
    assert s.counts.scans_matched == s.counts.steps - 1 and s.counts.scans_match_fallback == 0
    traj = read_csv(tmp_path / "on" / "trajectory.csv")
    assert not np.allclose(traj["scan_odom_x"], traj["odom_x"])
    off = run(sim_log, load_config(None, ["scan_match.enabled=false"]), out=tmp_path / "off")
    assert off.accuracy.scan_odom_ate is None and off.counts.scans_matched is None and not off.scan_matching
    traj = read_csv(tmp_path / "off" / "trajectory.csv")
    np.testing.assert_array_equal(traj["scan_odom_x"], traj["odom_x"])


def test_normals_do_not_depend_on_which_tied_neighbour_is_fifth():
    """A point whose 5th and 6th neighbours are equidistant (beams either side of a point with equal
    quantised ranges): one would make the neighbourhood a line, the other not. A last-bit nudge of either,
    or another point order, must not change the normal or whether there is one (it did: the Intel
    figures then depended on the CPU's BLAS kernels, docs/results/intel_spread.md)."""
    from scipy.spatial import cKDTree

    from cornerslam_cli.motion.icp import line_normals

    centre, on_line = [0.0, 0.0], [[0.05, 0.0], [-0.05, 0.0], [0.1, 0.0]]
    a, b = np.array([-0.15, 0.0]), np.array([0.0, 0.15])  # both exactly 0.15 m from the centre
    seen = set()
    for nudge_a, nudge_b in [(0, 0), (-1, 0), (1, 0), (0, -1), (0, 1)]:
        pa, pb = a.copy(), b.copy()
        pa[0] = np.nextafter(pa[0], pa[0] + nudge_a) if nudge_a else pa[0]  # one ulp nearer or farther
        pb[1] = np.nextafter(pb[1], pb[1] + nudge_b) if nudge_b else pb[1]
        for order in ([0, 1, 2, 3, 4, 5], [5, 4, 3, 2, 1, 0], [0, 5, 1, 4, 2, 3]):
            pts = np.array([centre, *on_line, pa, pb])[order]
            normals, ok = line_normals(pts, cKDTree(pts))
            i = order.index(0)
            seen.add((bool(ok[i]), *np.round(np.abs(normals[i]), 12)))
    assert len(seen) == 1, seen
