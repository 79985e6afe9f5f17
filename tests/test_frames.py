"""Every frame transform against an independent reference, with a laser that is yawed AND offset.

MOUNT puts the laser 0.2 m ahead of the base, 0.1 m to its right, turned 0.3 rad to the left. The
references are 3 × 3 homogeneous matrices written out below (``matrix``) or numbers worked out by hand,
never the code under test, so a sign flip of the laser yaw, a transposed rotation or a composition in
the wrong order fails here. The last tests run a whole log recorded by a laser with that mount (ray
cast from the true laser pose in the simulated office) and check the outputs in the world: the
trajectory, every lines.csv segment, every landmark; and map.csv's covariance columns against Σ.

Frames (types.py): sensor = laser, base = robot, map = the SLAM frame (the base at the first scan);
the outputs are written in the odometry frame (the map frame placed at the first odometry pose), which
for these logs, whose odometry is the true pose, is the world frame.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from cornerslam_cli.cli import cli
from cornerslam_cli.config import Config, from_dict, load_config
from cornerslam_cli.filter import inverse_observe, observe
from cornerslam_cli.frontend import Frame, corners_to_base, frames, odometry_noise, open_input
from cornerslam_cli.geometry import matrix_from_pose, pose_from_matrix, transform_points, yaw_from_quaternion
from cornerslam_cli.logs import open_log
from cornerslam_cli.logs.ros import chain_transform, pose2_from_matrix, transform_matrix
from cornerslam_cli.logs.sync import reanchor_odometry
from cornerslam_cli.logs.writers import RawScan, write_mcap
from cornerslam_cli.motion import ScanMatcher
from cornerslam_cli.report.tables import read_csv, write_tum
from cornerslam_cli.simulate import SimParams, drive
from cornerslam_cli.simworld import office_world, raycast, true_corners
from cornerslam_cli.slam import Slam
from cornerslam_cli.types import Corners, OdomSample, Scan, Segments

MOUNT = (0.2, -0.1, 0.3)  # laser in the base frame: x, y (m), yaw (rad)
COS, SIN = 0.955336489125606, 0.29552020666133955  # cos 0.3, sin 0.3


def matrix(x: float, y: float, yaw: float) -> np.ndarray:
    """The pose's homogeneous matrix, written out: a point p in the pose's frame is matrix @ [p, 1]."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


def pose_from(M: np.ndarray) -> np.ndarray:
    return np.array([M[0, 2], M[1, 2], math.atan2(M[1, 0], M[0, 0])])


def apply(M: np.ndarray, points) -> np.ndarray:
    """(k, 2) points moved by the homogeneous matrix M, one by one."""
    return np.array([(M @ [px, py, 1.0])[:2] for px, py in np.reshape(points, (-1, 2))])


def test_the_reference_matrix_by_hand():
    assert matrix(*MOUNT) @ [1.0, 0.5, 1.0] == pytest.approx(
        [0.2 + COS - 0.5 * SIN, -0.1 + SIN + 0.5 * COS, 1]
    )
    assert pose_from(matrix(*MOUNT) @ matrix(1.0, 0.0, -0.3)) == pytest.approx([0.2 + COS, -0.1 + SIN, 0.0])


# ----------------------------------------------------------------------------- sensor → base
def test_scan_points_are_cartesian_in_the_sensor_frame():
    scan = Scan(0.0, np.array([1.0, 2.0]), np.array([-1.0, 0.5]), np.arange(2), 2, 0.1, 10.0, 1.5)
    np.testing.assert_allclose(scan.points(), [[0.5403023058681398, -0.8414709848078965],
                                               [1.7551651237807455, 0.958851077208406]])  # fmt: skip


def test_corners_to_base_moves_the_position_and_turns_the_covariance():
    C = np.array([[0.04, 0.0, 0.003], [0.0, 0.0025, 0.0], [0.003, 0.0, 0.01]])  # long along the beam (x)
    corners = Corners(np.array([[1.0, 0.5, 1.2]]), C[None], np.ones(1, np.int8), np.zeros((1, 2), np.int64))
    z, C_base = corners_to_base(corners, MOUNT)
    # by hand: (0.2 + cos·1 − sin·0.5, −0.1 + sin·1 + cos·0.5); φ, an angle between two lines, stays
    assert z[0] == pytest.approx([1.0075763857949362, 0.6731884512241425, 1.2], abs=1e-12)
    J = np.array([[COS, -SIN, 0.0], [SIN, COS, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(C_base[0], J @ C @ J.T, atol=1e-15)
    # the uncertainty's long axis, the laser's x axis, points 0.3 rad left of the base's x axis
    w, v = np.linalg.eigh(C_base[0][:2, :2])
    assert abs(v[1, 1] / v[0, 1]) == pytest.approx(math.tan(0.3), rel=1e-9) and v[1, 1] * v[0, 1] > 0
    assert w[1] == pytest.approx(0.04) and C_base[0][:2, 2] == pytest.approx([0.003 * COS, 0.003 * SIN])


def test_scan_points_reach_the_base_frame_through_the_mount():
    """The scan matcher's input (pipeline: transform_points(scan.points(), laser2base))."""
    pts = np.array([[1.0, 0.5], [-2.0, 3.0], [0.0, -1.5]])
    np.testing.assert_allclose(transform_points(pts, MOUNT), apply(matrix(*MOUNT), pts), atol=1e-12)
    np.testing.assert_allclose(matrix_from_pose(MOUNT), matrix(*MOUNT), atol=1e-15)
    assert pose_from_matrix(matrix(*MOUNT)) == pytest.approx(MOUNT)


def test_laser_mount_from_the_config_when_the_log_has_no_tf(yawed_logs):
    overrides = [f"input.laser.{k}={v}" for k, v in zip(("x", "y", "yaw"), MOUNT, strict=True)]
    cfg = load_config(None, overrides)
    src = open_input(yawed_logs["no_tf"], cfg)
    assert (src.laser2base, src.laser_source) == (MOUNT, "config")
    src = open_input(yawed_logs["tf"], load_config(None, ["input.laser.from_tf=false"]))
    assert (src.laser2base, src.laser_source) == ((0.0, 0.0, 0.0), "config")  # tf ignored on request


# ----------------------------------------------------------------------------- the mount in the logs
def quaternion(yaw: float) -> tuple[float, float, float, float]:
    return 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)


def test_tf_chain_through_an_intermediate_frame():
    """base_link → plate → laser: the laser's pose is T(base←plate) · T(plate←laser)."""
    a, b = (0.15, 0.05, 0.1), (0.05, -0.15, 0.2)
    assert yaw_from_quaternion(*quaternion(0.3)) == pytest.approx(0.3)
    T1, T2 = (
        transform_matrix((a[0], a[1], 0.4), quaternion(a[2])),
        transform_matrix((*b[:2], 0.0), quaternion(b[2])),
    )
    np.testing.assert_allclose(T1[[0, 1, 3]][:, [0, 1, 3]], matrix(*a), atol=1e-15)
    want = pose_from(matrix(*a) @ matrix(*b))
    for edges in ({("base_link", "plate"): T1, ("plate", "laser"): T2},
                  {("base_link", "plate"): T1, ("laser", "plate"): np.linalg.inv(T2)}):  # fmt: skip
        got = pose2_from_matrix(chain_transform(edges, "base_link", "laser"))
        assert got == pytest.approx(want, abs=1e-12)
    assert want[2] == pytest.approx(0.3)


def test_carmen_robotlaser_offset_of_a_turned_robot(tmp_path):
    """ROBOTLASER1 holds the laser's and the robot's world poses; the mount is robot⁻¹ ∘ laser."""
    robot = (1.0, 2.0, 2.5)  # turned: the world offset is not the mount's
    laser = pose_from(matrix(*robot) @ matrix(*MOUNT))
    fields = " ".join(f"{v:.12f}" for v in (*laser, *robot))
    line = f"ROBOTLASER1 0 -0.5 1.0 0.25 9.9 0.01 0 3 1.0 2.0 3.0 0 {fields} 0 0 0 0 0 7.5 h 7.5\n"
    (tmp_path / "r.log").write_text(line)
    with open_log(tmp_path / "r.log") as log:
        assert log.laser_to_base() == pytest.approx(MOUNT, abs=1e-9)


# ----------------------------------------------------------------------------- poses and the map frame
def test_observation_and_landmark_initialisation_by_hand():
    pose = np.array([1.0, 2.0, 0.5])
    h, _, _ = observe(pose, np.array([[2.0, 3.0, 1.0]]))
    # R(0.5)ᵀ (1, 1): (cos + sin, cos − sin)
    assert h[0] == pytest.approx([1.3570081004945758, 0.39815702328616975, 1.0])
    np.testing.assert_allclose(h[0, :2], apply(np.linalg.inv(matrix(*pose)), [2.0, 3.0])[0], atol=1e-12)
    m, _, _ = inverse_observe(pose, np.array([[0.3, -0.7, 2.0]]))
    np.testing.assert_allclose(m[0, :2], apply(matrix(*pose), [0.3, -0.7])[0], atol=1e-12)


def test_scan_matcher_guess_puts_the_wheel_increment_on_the_refined_pose():
    """guess = refined ∘ odom_prev⁻¹ ∘ odom (returned as is when there is nothing to match against)."""
    cfg = load_config()
    matcher = ScanMatcher(cfg.scan_match, odometry_noise(cfg))
    matcher.pose, matcher.odom = np.array([1.0, 2.0, 0.5]), np.array([0.3, -0.2, 0.3])
    odom = np.array([0.8, 0.1, 0.6])
    result = matcher.step(np.zeros((2, 2)), odom)
    assert not result.matched
    want = pose_from(matrix(1.0, 2.0, 0.5) @ np.linalg.inv(matrix(0.3, -0.2, 0.3)) @ matrix(*odom))
    assert result.pose == pytest.approx(want, abs=1e-12)


def test_reanchored_odometry_continues_from_the_pose_before_the_jump():
    a, jumped, step = (1.0, 2.0, 0.5), (10.0, -3.0, 2.0), (0.1, 0.05, 0.1)
    after = pose_from(matrix(*jumped) @ matrix(*step))  # the robot moves on from where the jump put it
    msgs = [OdomSample(0.0, *a), OdomSample(0.02, *jumped), OdomSample(0.04, *after)]
    out = list(reanchor_odometry(msgs, load_config().input.odom_jump))
    got = [(o.x, o.y, o.theta) for o in out]
    assert got[1] == pytest.approx(a, abs=1e-12)
    assert got[2] == pytest.approx(pose_from(matrix(*a) @ matrix(*step)), abs=1e-12)


def test_segments_of_a_step_go_to_the_map_through_pose_and_mount():
    """lines.csv: a segment seen at filter pose p is map ← base (p) ← laser (MOUNT) of its end points."""
    slam = Slam.from_config(load_config(), MOUNT)
    p1, p2 = np.array([[1.0, 0.5]]), np.array([[2.0, -0.5]])
    one = Segments(
        np.ones(1), np.zeros(1), np.eye(2)[None], p1, p2, np.full(1, 5), np.zeros(1, int), np.ones(1, int)
    )
    none = np.zeros((0, 3))
    odom = (np.zeros(3), np.array([1.0, 2.0, 0.5]))
    for k in range(2):  # from the first pose (the map origin) to odometry (1, 2, 0.5): no corners, no update
        rec = slam.step(Frame(float(k), odom[k], 0, one, none, np.zeros((0, 3, 3)), 0.0))
    assert rec.pose == pytest.approx([1.0, 2.0, 0.5], abs=1e-12)
    M = matrix(1.0, 2.0, 0.5) @ matrix(*MOUNT)
    np.testing.assert_allclose(rec.segments_map, np.hstack((apply(M, p1), apply(M, p2))), atol=1e-12)


def test_trajectory_tum_quaternion_by_hand(tmp_path):
    write_tum(tmp_path / "t.tum", np.array([1.0]), np.array([[0.5, -0.25, 0.3]]))
    assert (
        tmp_path / "t.tum"
    ).read_text() == "1.000000000 0.500000000 -0.250000000 0 0 0 0.149438132 0.988771078\n"


# ----------------------------------------------------------------------------- a whole run, in the world
@pytest.fixture(scope="module")
def yawed_logs(tmp_path_factory) -> dict:
    """100 scans (541 beams, 270°) ray cast from the laser mounted at MOUNT, along 17 m of the office
    corridor with a 90° turn; odometry = the true base poses. Written with the mount on /tf_static and
    without it. Returns the paths and the true base poses (n, 3) in the world frame."""
    truth = drive(np.array([(12.0, 5.0), (24.5, 5.0), (24.5, 12.0)]), 1, SimParams(), 0.2)[:200:2]
    world, rng = office_world(), np.random.default_rng(3)
    angles = np.linspace(-0.75 * math.pi, 0.75 * math.pi, 541)
    scans, odoms = [], []
    for i, base in enumerate(truth):
        r = raycast(world, pose_from(matrix(*base) @ matrix(*MOUNT)), angles, 20.0)
        r = np.where(np.isfinite(r), r + rng.normal(0.0, 0.005, len(r)), np.inf)
        stamp = 1_700_000_000.0 + 0.4 * i
        scans.append(
            RawScan(stamp, angles[0], angles[1] - angles[0], r.astype(np.float32), 0.05, 20.0, "laser")
        )
        odoms.append(OdomSample(stamp, *base))
    d = tmp_path_factory.mktemp("yawed")
    return {
        "tf": write_mcap(d / "tf.mcap", scans, odoms, tf_static=MOUNT),
        "no_tf": write_mcap(d / "no_tf.mcap", scans, odoms),
        "truth": truth,
        "world": world,
    }


@pytest.fixture(scope="module")
def yawed_run(yawed_logs, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("yawed_run") / "out"
    # the single map: map.csv's covariances are replayed against one filter's Σ below
    args = ["run", str(yawed_logs["tf"]), "--out", str(out), "-q", "--set", "submaps.enabled=false"]
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 0, res.output
    return out


def distance_to_walls(points: np.ndarray, walls: np.ndarray) -> np.ndarray:
    """(k,) distance of each point to the nearest wall segment."""
    a, e = walls[:, 0], walls[:, 1] - walls[:, 0]
    t = np.clip(((points[:, None] - a) * e).sum(-1) / (e * e).sum(-1), 0.0, 1.0)
    return np.linalg.norm(points[:, None] - a - t[..., None] * e, axis=-1).min(axis=1)


def test_run_with_a_yawed_laser_puts_trajectory_segments_and_landmarks_on_the_world(yawed_logs, yawed_run):
    truth = yawed_logs["truth"]
    summary = json.loads((yawed_run / "summary.json").read_text())
    assert summary["input"]["laser_to_base"] == pytest.approx(MOUNT) and summary["counts"]["steps"] == len(
        truth
    )
    tr = read_csv(yawed_run / "trajectory.csv")  # in the odometry frame: here the world's
    est = np.column_stack((tr["x"], tr["y"], tr["theta"]))
    assert est[0] == pytest.approx(truth[0], abs=1e-8)  # the first pose is the first odometry pose
    assert np.abs(est[:, :2] - truth[:, :2]).max() < 0.05
    assert np.abs(np.angle(np.exp(1j * (est[:, 2] - truth[:, 2])))).max() < 0.02
    walls = yawed_logs["world"].walls
    ln = read_csv(yawed_run / "lines.csv")
    ends = np.column_stack((np.r_[ln["x1"], ln["x2"]], np.r_[ln["y1"], ln["y2"]]))
    d = distance_to_walls(ends, walls)
    assert len(d) > 500 and np.percentile(d, 95) < 0.05 and d.max() < 0.1
    lm = read_csv(yawed_run / "map.csv")
    xy = np.column_stack((lm["x"], lm["y"]))
    assert len(xy) > 20 and distance_to_walls(xy, walls).max() < 0.1  # corners lie on walls
    corners = true_corners(yawed_logs["world"])
    nearest = np.linalg.norm(xy[:, None] - corners[None, :, :2], axis=-1).min(axis=1)
    assert np.median(nearest) < 0.1  # most are the world's corners (the rest: ends of what was seen)


def test_map_csv_covariance_columns_are_the_landmark_blocks_of_sigma(yawed_logs, yawed_run):
    """map.csv's var_x, var_y, cov_xy, var_phi against the final Σ of the same run, replayed, moved by
    hand from the filter's map frame into the odometry frame (by the first odometry pose)."""
    summary = json.loads((yawed_run / "summary.json").read_text())
    cfg = from_dict(Config, summary["config"])  # the run's resolved config (laser preset included)
    src = open_input(yawed_logs["tf"], cfg)
    slam = Slam.from_config(cfg, src.laser2base)
    for frame in frames(src, cfg):
        slam.step(frame)
    mu, P = slam.ekf.mu, slam.ekf.P
    odom2world = matrix(*yawed_logs["truth"][0])  # the filter's map frame in the odometry (world) frame
    R = odom2world[:2, :2]
    lm = read_csv(yawed_run / "map.csv")
    assert len(lm["id"]) == summary["counts"]["landmarks"] > 20
    ratio = lm["var_x"] / lm["var_y"]
    assert np.sum((ratio > 1.5) | (ratio < 1 / 1.5)) >= 5  # var_x and var_y clearly differ: a swap fails
    for row, i in enumerate(lm["id"].astype(int)):
        block = P[3 + 3 * i : 6 + 3 * i, 3 + 3 * i : 6 + 3 * i]
        got = [lm[k][row] for k in ("var_x", "var_y", "cov_xy", "var_phi")]
        cov = R @ block[:2, :2] @ R.T
        np.testing.assert_allclose(got, [cov[0, 0], cov[1, 1], cov[0, 1], block[2, 2]], rtol=1e-6, atol=1e-9)
        got = [lm[k][row] for k in ("x", "y", "phi")]
        want = [*apply(odom2world, mu[3 + 3 * i : 5 + 3 * i])[0], mu[5 + 3 * i]]
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-8)
