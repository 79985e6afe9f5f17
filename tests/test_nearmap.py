"""The scan matcher's local map with older map scans near the robot (scan_match.near_*, issue 15):
which scans join, and a sparse revisit in a ray-cast world where they make the match better than the
last-N map alone."""

import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from test_scanmatch import matcher, noisy_odometry, pose_error, scan_points

from cornerslam_cli.cli import cli
from cornerslam_cli.config import load_config
from cornerslam_cli.errors import ConfigError
from cornerslam_cli.motion.icp import MapScan, near_scans, voxel_thin
from cornerslam_cli.simworld import OFFICE_LOOP, office_world, path_poses

SAMPLES = Path(__file__).resolve().parents[1] / "sample_logs"
NEAR = ["scan_match.window=2", "scan_match.near_history=5", "scan_match.near_radius=1.5"]


@pytest.fixture(scope="module")
def office():
    return office_world()


def test_near_scans_keeps_the_poses_within_the_radius_and_the_angle():
    poses = np.array(
        [
            [0.0, 0.0, 0.0],  # the robot's own place
            [1.9, 0.0, 0.0],  # within 2 m
            [2.1, 0.0, 0.0],  # beyond
            [0.0, -1.5, 3.0],  # near, facing the other way
            [1.0, 1.0, -0.3],  # near, heading 0.3 off
        ]
    )
    robot = np.array([0.0, 0.0, 0.1])
    np.testing.assert_array_equal(near_scans(poses, robot, 2.0, math.pi, 10), [0, 1, 3, 4])
    np.testing.assert_array_equal(near_scans(poses, robot, 2.0, 0.5, 10), [0, 1, 4])
    np.testing.assert_array_equal(near_scans(poses, robot, 2.0, 0.2, 10), [0, 1])
    # headings compared across ±π: 3.1 and −3.1 are 0.08 apart
    assert near_scans(np.array([[0.0, 0.0, -3.1]]), np.array([0.0, 0.0, 3.1]), 1.0, 0.1, 1).tolist() == [0]
    assert near_scans(poses[2:3], robot, 2.0, math.pi, 10).size == 0


def test_near_scans_of_more_than_the_most_are_the_nearest_in_their_order():
    poses = np.array([[d, 0.0, 0.0] for d in (1.5, 0.5, 1.0, 0.2, 0.5, 1.8)])
    np.testing.assert_array_equal(near_scans(poses, np.zeros(3), 2.0, math.pi, 3), [1, 3, 4])
    np.testing.assert_array_equal(near_scans(poses, np.zeros(3), 2.0, math.pi, 2), [1, 3])  # tie: the older


def _out_and_back(office, overrides):
    """A matcher fed exact odometry along the office corridor, 1 m a scan from (6, 5) to (10, 5), then
    back near the start at (6.2, 5): with a window of 2 the last-N map holds the scans at 10 and 6.2."""
    m = matcher(overrides=overrides)
    rng = np.random.default_rng(3)
    for pose in [*([6.0 + i, 5.0, 0.0] for i in range(5)), [6.2, 5.0, 0.0]]:
        m.step(scan_points(office, pose, rng, 0.01), np.array(pose))
    return m


def test_scans_leaving_the_window_are_kept_and_the_near_ones_join_the_map(office):
    m = _out_and_back(office, NEAR)
    assert [round(s.pose[0]) for s in m.scans] == [10, 6]
    assert [round(s.pose[0]) for s in m.history] == [6, 7, 8, 9]
    # the window's scans first (their points win a voxel), then the history's within 1.5 m: 6 and 7
    pts = np.concatenate([*(s.points for s in m.scans), m.history[0].points, m.history[1].points])
    np.testing.assert_array_equal(m.local.points, pts[voxel_thin(pts, m.cfg.voxel)])
    off = _out_and_back(office, [NEAR[0], "scan_match.near_history=0"])
    assert not off.history and len(off.local.points) < len(m.local.points)


def test_a_near_scan_placed_off_the_window_is_refused_with_near_min_fit(office):
    m = _out_and_back(office, [*NEAR, "scan_match.near_min_fit=0.5"])
    window = np.concatenate([s.points for s in m.scans])
    here = m.scans[-1].pose
    assert [round(s.pose[0]) for s in m._near(here, window)] == [6, 7]
    first = m.history[0]
    m.history[0] = MapScan(first.pose, first.points + [0.0, 0.3])  # placed 0.3 m off: double walls
    assert [round(s.pose[0]) for s in m._near(here, window)] == [7]


def test_a_sparse_revisit_matches_the_near_scans_better_than_the_last_n_map(office):
    """Once around the office loop and on (scans 0.8 m apart, 3 %-scale and heading-drifting odometry,
    a window of 3): back at the start the chain has drifted ~0.5 m; the last-N map holds only the
    drifted scans just before, the near scans the start's, so the revisit is matched onto them."""
    rng = np.random.default_rng(5)
    lap = path_poses(OFFICE_LOOP, 0.8)
    truth = np.vstack((lap, lap[:12]))
    odom = noisy_odometry(truth, rng, scale=1.03, drift=0.02, sigma=0.03)
    scans = [scan_points(office, p, rng, 0.01) for p in truth]
    revisit = {}
    for name, extra in (("last_n", ["scan_match.near_history=0"]), ("near", ["scan_match.near_history=200"])):
        m = matcher(overrides=["scan_match.window=3", *extra])
        steps = [m.step(s, o) for s, o in zip(scans, odom, strict=True)][len(lap) :]
        errors = [pose_error(r.pose, p)[0] for r, p in zip(steps, truth[len(lap) :], strict=True)]
        revisit[name] = (np.mean(errors), np.mean([r.fit for r in steps]))
    (err_n, fit_n), (err_near, fit_near) = revisit["last_n"], revisit["near"]
    assert err_n > 0.3 and err_near < 0.1 * err_n
    assert fit_near > 0.95 > fit_n + 0.1


def _run(tmp_path: Path, name: str, sets: list[str]) -> Path:
    out = tmp_path / name
    args = ["run", str(SAMPLES / "intel_cut.clf"), "--max-scans", "120", "--out", str(out), "-q"]
    res = CliRunner().invoke(cli, [*args, *(x for s in sets for x in ("--set", f"scan_match.{s}"))])
    assert res.exit_code == 0, res.output
    return out


def test_near_history_0_turns_it_off_byte_for_byte(tmp_path):
    """Through the CLI on the shipped Intel cut: with near_history=0 the other near_* keys are not read
    (moving them all leaves the outputs byte for byte), and the default (near scans on) differs from
    it (the option is wired, and on by default)."""
    off = _run(tmp_path, "off", ["near_history=0"])
    moved = _run(tmp_path, "moved", ["near_history=0", "near_radius=9", "near_angle=0.5", "near_max=3",
                                     "near_min_fit=0.5"])  # fmt: skip
    default = _run(tmp_path, "default", [])
    for table in ("trajectory.csv", "map.csv", "lines.csv"):
        assert (moved / table).read_bytes() == (off / table).read_bytes(), table
    assert (default / "trajectory.csv").read_bytes() != (off / "trajectory.csv").read_bytes()


@pytest.mark.parametrize(
    "key,value",
    [("near_history", "-1"), ("near_radius", "-0.5"), ("near_angle", "4"), ("near_max", "0"),
     ("near_min_fit", "1.5"), ("near_history", "many")],
)  # fmt: skip
def test_bad_near_keys_are_config_errors(key, value, tmp_path):
    with pytest.raises(ConfigError, match=f"scan_match.{key}"):
        load_config(None, [f"scan_match.{key}={value}"])
    res = CliRunner().invoke(
        cli,
        ["run", str(SAMPLES / "intel_cut.clf"), "--out", str(tmp_path), "--set", f"scan_match.{key}={value}"],
    )
    assert res.exit_code == 2 and f"scan_match.{key}" in res.output
    assert res.output.strip().count("\n") == 0 and res.output.startswith("error: ")
