"""Odometry from the scans alone (input.odometry: scans, motion/scan_odometry.py): against the known poses of
ray-cast worlds, and end to end on a log without odometry."""

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner
from mcap.reader import make_reader

from cornerslam_cli.cli import cli
from cornerslam_cli.config import load_config
from cornerslam_cli.evaluate import align_se2
from cornerslam_cli.geometry import compose, relative, wrap_angle
from cornerslam_cli.logs.writers.mcap import copy_mcap_without
from cornerslam_cli.motion.scan_odometry import ScanOdometry, with_scan_odometry
from cornerslam_cli.report.plots import _accuracy_note
from cornerslam_cli.results import RunSummary
from cornerslam_cli.simworld import OFFICE_LOOP, office_world, path_poses, raycast
from cornerslam_cli.types import OdomSample, Scan

ANGLES = np.radians(np.arange(-90.0, 90.5, 1.0))  # SICK-like: 181 beams, 1°


def scan_points(world, pose, rng, sigma=0.01):
    r = raycast(world, pose, ANGLES, max_range=30.0)
    ok = np.isfinite(r)
    r = r[ok] + rng.normal(0.0, sigma, int(ok.sum()))
    return np.column_stack((r * np.cos(ANGLES[ok]), r * np.sin(ANGLES[ok])))


def step_errors(poses: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each increment's position (m) and heading (rad) error against the truth's."""
    e = np.array(
        [relative(poses[k - 1], poses[k]) - relative(truth[k - 1], truth[k]) for k in range(1, len(poses))]
    )
    return np.hypot(e[:, 0], e[:, 1]), np.abs(wrap_angle(e[:, 2]))


def smooth_headings(poses: np.ndarray, width: int) -> np.ndarray:
    """The poses with their headings averaged over ``width`` neighbours: a robot turns over a metre or
    two, not at a polyline's corner in one step."""
    th = np.unwrap(poses[:, 2])
    k = np.ones(width) / width
    padded = np.concatenate((np.full(width, th[0]), th, np.full(width, th[-1])))
    return np.column_stack((poses[:, :2], np.convolve(padded, k, mode="same")[width:-width]))


def odometry_of(world, truth: np.ndarray, seed: int = 3) -> tuple[ScanOdometry, np.ndarray]:
    rng = np.random.default_rng(seed)
    odo = ScanOdometry(load_config().scan_match)
    poses = np.array([odo.step(scan_points(world, p, rng), 0.1 * k) for k, p in enumerate(truth)])
    return odo, poses


def test_a_lap_of_dense_scans_follows_the_true_motion():
    """A lap of the office, a scan every 10 cm, no odometry: every increment right to 2 cm and 0.3°, the
    lap's drift under 10 cm after alignment (the truth's frame is not the odometry's: it starts at 0)."""
    world = office_world()
    truth = smooth_headings(path_poses(OFFICE_LOOP, 0.1), 15)
    odo, poses = odometry_of(world, truth)
    d, a = step_errors(poses, truth)
    assert d.max() < 0.02 and a.max() < math.radians(0.3), (d.max(), math.degrees(a.max()))
    ang, t = align_se2(poses[:, :2], truth[:, :2])
    R = np.array([[math.cos(ang), -math.sin(ang)], [math.sin(ang), math.cos(ang)]])
    assert np.sqrt(np.mean(np.sum((poses[:, :2] @ R.T + t - truth[:, :2]) ** 2, axis=1))) < 0.1
    assert odo.scans == len(truth) and odo.coasted == 0
    assert odo.searched <= 3  # small steps: ICP from the guess (the first scans are searched)


def test_searched_counts_scans_once():
    """Two searches run on a scan far from the last (around the guess and around the robot standing
    still): a scan counts once, whichever won."""
    truth = [np.array([2.0, 2.0, 0.0])]
    for k in range(7):
        truth.append(compose(truth[-1], np.array([0.8, 0.0, 0.5 * (-1) ** k])))
    odo, _ = odometry_of(office_world(), np.array(truth), seed=5)
    assert 0 < odo.searched <= odo.scans - 1


def test_sparse_scans_that_turn_back_are_found_by_the_search_around_the_robot_standing_still():
    """Scans 0.4–0.8 m apart turning +0.5 rad then −0.5 rad in turn (a log thinned by distance, as the
    radish ones): the constant-velocity guess is 1 rad off at each reversal, beyond the search window
    around it (0.6 rad); the search around the robot standing still finds each (without it: 0.6 m off).
    Every increment right to 5 cm and 1°."""
    world = office_world()
    truth = [np.array([2.0, 2.0, 0.0])]
    for k in range(7):
        truth.append(compose(truth[-1], np.array([0.8 if k % 3 != 1 else 0.4, 0.0, 0.5 * (-1) ** k])))
    truth = np.array(truth)
    _, poses = odometry_of(world, truth, seed=5)
    d, a = step_errors(poses, truth)
    assert d.max() < 0.05 and a.max() < math.radians(1.0), (d, np.degrees(a))


def test_steps_larger_than_icps_basin_are_searched_even_where_icp_from_the_guess_fits():
    """Scans 1 m apart turning ±0.3 rad in turn: ICP from the constant-velocity guess (0.6 rad off at
    each reversal) fits above min_fit at a wrong pose, so searching only when it fits under min_fit is
    not enough (then: 0.2 m and 23° off); the last step being beyond ICP's basin starts the search."""
    truth = [np.array([2.0, 2.0, 0.0])]
    for k in range(7):
        truth.append(compose(truth[-1], np.array([1.0, 0.0, 0.3 * (-1) ** k])))
    _, poses = odometry_of(office_world(), np.array(truth), seed=5)
    d, a = step_errors(poses, np.array(truth))
    assert d.max() < 0.05 and a.max() < math.radians(1.0), (d, np.degrees(a))


def test_the_laser_mount_is_applied_once():
    """Scans taken by a laser 0.5 m ahead, 0.2 m left and turned 90° on the robot: the samples are the
    base's poses (its increments right to 2 cm and 0.3°), not the laser's."""
    world, rng = office_world(), np.random.default_rng(4)
    mount = (0.5, 0.2, math.pi / 2)
    truth = smooth_headings(path_poses(OFFICE_LOOP, 0.1), 15)[:80]
    msgs = []
    for k, base in enumerate(truth):
        p = scan_points(world, compose(base, np.array(mount)), rng)
        msgs.append(scan_message(1.0 + 0.1 * k, p))
    out = with_scan_odometry(msgs, ScanOdometry(load_config().scan_match), mount)
    poses = np.array([[m.x, m.y, m.theta] for m in out if isinstance(m, OdomSample)])
    d, a = step_errors(poses, truth)
    assert d.max() < 0.02 and a.max() < math.radians(0.3), (d.max(), math.degrees(a.max()))


def scan_message(stamp: float, points: np.ndarray) -> Scan:
    """A Scan of ``points`` (sensor frame), beams in increasing bearing order."""
    r, a = np.hypot(points[:, 0], points[:, 1]), np.arctan2(points[:, 1], points[:, 0])
    order = np.argsort(a)
    n = len(r)
    return Scan(stamp, r[order], a[order], np.arange(n), n, 0.1, 30.0, math.radians(1.0))


def test_a_beam_20_km_away_does_not_blow_up_the_search():
    """The correlative search's grid spans the points it places: one beam at 20 km (a driver's range_max
    of 1e5) asked for 42 GiB. It takes the points within scan_match.search_range, as the front end's
    matcher does; the first scans, always searched, register as before."""
    world, rng = office_world(), np.random.default_rng(7)
    odo = ScanOdometry(load_config().scan_match)
    truth = np.array([[2.0 + 0.3 * k, 2.0, 0.0] for k in range(4)])
    poses = np.array(
        [odo.step(np.vstack((scan_points(world, p, rng), [[2e4, 0.0]])), k) for k, p in enumerate(truth)]
    )
    d, a = step_errors(poses, truth)
    assert d.max() < 0.02 and a.max() < math.radians(0.3)


def test_a_gap_in_the_scans_is_counted():
    """Ten scans dropped from a run at 10 Hz: the scan after them is counted as after a gap, with its
    stamp and how long the gap was; the scans before it are not."""
    world, rng = office_world(), np.random.default_rng(6)
    truth = smooth_headings(path_poses(OFFICE_LOOP, 0.05), 15)[:60]
    odo = ScanOdometry(load_config().scan_match)
    for k, p in enumerate(truth):
        if not 40 <= k < 50:
            odo.step(scan_points(world, p, rng), 0.1 * k)
    assert odo.gaps == [(pytest.approx(5.0), pytest.approx(1.1))]
    assert odo.stats().gaps == 1
    # scans thinned by distance (a radish log's): seconds apart when the robot went slowly — no gap
    odo, t = ScanOdometry(load_config().scan_match), 0.0
    for k, p in enumerate(truth):
        t += 0.5 if k % 7 else 6.0
        odo.step(scan_points(world, p, rng), t)
    assert odo.gaps == []


def test_a_scan_with_no_points_coasts_on_the_last_increment():
    """No registration without points: the pose is the last one moved by the last increment, counted."""
    world, rng = office_world(), np.random.default_rng(1)
    truth = np.array([[2.0 + 0.1 * k, 2.0, 0.0] for k in range(4)])
    odo = ScanOdometry(load_config().scan_match)
    poses = [odo.step(scan_points(world, p, rng), 0.1 * k) for k, p in enumerate(truth)]
    coasted = odo.step(np.zeros((0, 2)), 0.4)
    assert odo.coasted == 1
    np.testing.assert_allclose(coasted, compose(poses[-1], relative(poses[-2], poses[-1])), atol=1e-12)


def test_stamps_that_do_not_advance_get_no_odometry_sample():
    """A scan stamped at or before the previous one (the synchroniser skips it as going backwards) and
    one with a stamp that is not finite get no sample; the log's own odometry samples are left out."""
    world, rng = office_world(), np.random.default_rng(2)

    def scan(t, x):
        return scan_message(t, scan_points(world, np.array([x, 2.0, 0.0]), rng))

    msgs = [
        scan(1.0, 2.0),
        OdomSample(1.0, 5.0, 5.0, 1.0),
        scan(1.1, 2.05),
        scan(1.1, 2.1),
        scan(math.nan, 2.1),
    ]
    out = list(with_scan_odometry(msgs, ScanOdometry(load_config().scan_match), (0.0, 0.0, 0.0)))
    kinds = [type(m).__name__ for m in out]
    assert kinds == ["Scan", "OdomSample", "Scan", "OdomSample", "Scan", "Scan"]
    assert [m.stamp for m in out if isinstance(m, OdomSample)] == [1.0, 1.1]
    assert out[1].x == 0.0 and abs(out[3].x - 0.05) < 0.01  # its own frame, from the first scan


# ---------------------------------------------------------------- end to end: a log without odometry


@pytest.fixture(scope="module")
def scans_only(sim_log, tmp_path_factory):
    log = copy_mcap_without(sim_log, tmp_path_factory.mktemp("alone") / "alone.mcap", {"/odom"})
    log.with_suffix(".gt.tum").write_bytes(sim_log.with_suffix(".gt.tum").read_bytes())
    return log


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False, prog_name="cornerslam")


def test_a_log_without_odometry_is_refused_with_the_way_to_run_it_on_its_scans(scans_only, tmp_path):
    res = invoke("run", scans_only, "--out", tmp_path / "o", "-q")
    assert res.exit_code == 2 and "has no odometry" in res.stderr
    assert "--set input.odometry=scans" in res.stderr and "\n" not in res.stderr.strip()
    assert not (tmp_path / "o").exists()


def test_a_log_without_odometry_runs_on_its_scans(scans_only, tmp_path):
    """The simulated office loop without its odometry: within 10 cm of the truth (its wheel odometry
    alone is off by metres), the scan odometry's counts and time in summary.json and timing.csv, and
    the printed lines say where the odometry came from."""
    res = invoke("run", scans_only, "--out", tmp_path / "o", "--set", "input.odometry=scans", "--plot")
    assert res.exit_code == 0, res.output
    html = (tmp_path / "o" / "report.html").read_text()
    assert "scan odometry time [s]" in html and "scans: searched, coasted, after a gap" in html
    assert '<td class="name">scan odometry</td>' in html and "scan matching time" not in html
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert s["accuracy"]["ate"]["rmse"] < 0.10
    assert s["input"]["odom_source"] == "the scans (input.odometry=scans)" and s["input"]["odom_topic"] == ""
    assert list(s)[-1] == "scan_odometry"  # appended after every other key
    assert s["accuracy"]["odom_ate"]["rmse"] < 0.05  # the scan odometry itself
    odo = s["scan_odometry"]
    assert odo["scans"] == s["counts"]["scans_in"] and odo["coasted"] == 0
    assert s["counts"].get("scans_matched") is None  # no second matching of the same scans
    assert s["timing"]["t_scan_match"] == pytest.approx(odo["seconds"], abs=1e-5)
    assert "odometry from the scans (input.odometry=scans)" in res.stdout
    assert "(scan odometry " in res.stdout
    info = invoke("info", scans_only, "--set", "input.odometry=scans")
    assert info.exit_code == 0, info.output
    assert "odometry  from the scans (input.odometry=scans)" in info.stdout
    assert "base_link→laser" in info.stdout  # the mount from the tf, without odometry to name the robot


def test_compare_on_the_scans_alone_names_the_scan_odometry(scans_only, tmp_path):
    """compare's table, report.html and the maps' titles say that the odometry scored is the scans'."""
    out = tmp_path / "c"
    alone = ("--set", "input.odometry=scans", "--end", "#150")
    res = invoke("compare", scans_only, "--assoc", "pca", "--out", out, *alone)
    assert res.exit_code == 0, res.output
    assert " scan odom ATE m" in res.stdout.splitlines()[0]
    assert "The odom_* columns score the scans' own odometry" in (out / "report.html").read_text()
    assert "(scan odometry " in _accuracy_note(RunSummary.read(out / "pca"))


def test_an_odometry_topic_beside_the_scans_alone_is_refused(sim_log, tmp_path):
    for command in ("run", "info"):
        args = ["--odom-topic", "/odom", "--set", "input.odometry=scans"]
        res = invoke(command, sim_log, *args, *(["--out", tmp_path / "o"] if command == "run" else []))
        assert res.exit_code == 2, res.output
        assert "input.odom_topic '/odom' is given, but input.odometry=scans" in res.stderr


def test_a_carmen_log_runs_on_its_scans(tmp_path):
    """A CARMEN log's laser lines carry odometry: on the scans alone it is not read."""
    res = invoke(
        "run", "sample_logs/intel_cut.clf", "--out", tmp_path / "o", "-q", "--set", "input.odometry=scans"
    )
    assert res.exit_code == 0, res.output
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert s["scan_odometry"]["scans"] == s["counts"]["scans_in"]
    odom = np.loadtxt(tmp_path / "o" / "odometry.tum")
    np.testing.assert_allclose(odom[0, 1:4], 0.0, atol=1e-12)  # the scans' own frame, not the log's


def test_a_log_with_tf_odometry_on_the_scans_alone_keeps_its_tf_tree(sim_log, tmp_path):
    """A log whose odometry is on /tf, run on its scans alone with a results MCAP: summary.json says the
    log's tf carries odom → base_link, the results MCAP publishes no second one beside it (map → odom is
    built on the log's tf, as with wheel odometry), and does not warn that the two odometries differ
    (they always do here)."""
    import math

    from _log_fixtures import write_messages_mcap

    from cornerslam_cli.logs.writers import RosSerializer

    ros = RosSerializer("cdr")
    msgs = []
    with open(sim_log, "rb") as f:
        for schema, channel, m in make_reader(f).iter_messages():
            if channel.topic != "/odom":
                msgs.append((channel.topic, schema.name, m.log_time, m.data))
                continue
            o = ros.store.deserialize_cdr(m.data, "nav_msgs/msg/Odometry")
            p, q = o.pose.pose.position, o.pose.pose.orientation
            tf = ros.tf(m.log_time * 1e-9, "odom", "base_link", p.x, p.y, 2 * math.atan2(q.z, q.w))
            msgs.append(("/tf", "tf2_msgs/msg/TFMessage", m.log_time, tf))
    log = write_messages_mcap(tmp_path / "tf.mcap", sorted(msgs, key=lambda x: x[2]))
    out, results = tmp_path / "o", tmp_path / "r.mcap"
    res = invoke("run", log, "--out", out, "--mcap-out", results, "-q", "--set", "input.odometry=scans")
    assert res.exit_code == 0, res.output
    s = json.loads((out / "summary.json").read_text())
    assert s["input"]["odom_on_tf"] is True
    assert not any("differs from the odometry the run used" in w for w in s["warnings"])
    with open(results, "rb") as f:
        topics = {c.topic for c in make_reader(f).get_summary().channels.values()}
    assert "/cornerslam/tf" in topics and "/cornerslam/odom_tf" not in topics


def test_a_carmen_log_whose_pose_fields_never_move_is_not_warned_of_on_the_scans_alone(tmp_path):
    """The log a run on the scans alone is for: laser lines with still pose fields and no ODOM lines.
    With its odometry it is warned of (and told of the mode); on the scans alone, not."""
    lines = []
    for line in open("sample_logs/intel_cut.clf"):
        tok = line.split()
        if not tok or tok[0] == "ODOM":
            continue
        if tok[0] == "FLASER":
            n = int(tok[1])
            tok[2 + n : 2 + n + 6] = ["0"] * 6  # its laser and robot poses: still
        lines.append(" ".join(tok))
    log = tmp_path / "still.clf"
    log.write_text("\n".join(lines) + "\n")
    still = "odometry pose fields of its FLASER lines never move"
    res = invoke("run", log, "--out", tmp_path / "a", "-q")
    warnings = json.loads((tmp_path / "a" / "summary.json").read_text())["warnings"]
    assert res.exit_code == 0 and any(still in w and "--set input.odometry=scans" in w for w in warnings)
    res = invoke("run", log, "--out", tmp_path / "b", "-q", "--set", "input.odometry=scans")
    warnings = json.loads((tmp_path / "b" / "summary.json").read_text())["warnings"]
    assert res.exit_code == 0 and not any(still in w for w in warnings), warnings
    assert still in invoke("info", log).stderr  # info reads its first scan as a run reads the log (a review)
    assert still not in invoke("info", log, "--set", "input.odometry=scans").stderr


def test_on_the_scans_alone_a_carmen_logs_odom_lines_need_no_logger_timestamps(tmp_path):
    """input.stamps=receive reads the logger timestamps of the lines a run reads: on the scans alone the
    ODOM lines are not read, and their missing logger timestamps do not refuse the log (a review)."""
    lines = []
    for line in open("sample_logs/intel_cut.clf"):
        tok = line.split()
        lines.append(" ".join(tok[:-2] if tok and tok[0] == "ODOM" else tok))  # (no hostname, logger stamp)
    log = tmp_path / "odom_short.clf"
    log.write_text("\n".join(lines) + "\n")
    receive = ["--set", "input.stamps=receive"]
    res = invoke("run", log, "--out", tmp_path / "a", "-q", *receive)
    assert res.exit_code == 2 and "ODOM lines do not all carry" in res.stderr
    res = invoke("run", log, "--out", tmp_path / "b", "-q", *receive, "--set", "input.odometry=scans")
    assert res.exit_code == 0, res.output


def test_on_the_scans_alone_a_mirrored_run_is_not_scored_and_both_causes_are_named(scans_only, tmp_path):
    """A laser taken upside down when it is upright mirrors the scans' odometry as a ground truth in a
    z-down frame would: not blamed on the ground truth alone (a review), and not scored either — a mirror's
    ATE means nothing (a probe: 5.8 m, no word)."""
    flip = [
        "--set",
        "input.laser.from_tf=false",
        "--set",
        "input.laser.x=0.1",
        "--set",
        "input.laser.upside_down=true",
    ]
    res = invoke("run", scans_only, "--out", tmp_path / "o", "-q", "--set", "input.odometry=scans", *flip)
    assert res.exit_code == 0, res.output
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert s["accuracy"] is None or s["accuracy"].get("ate") is None
    (warning,) = [w for w in s["warnings"] if "mirrored" in w]
    assert "and the scans' odometry are mirrored (a laser upside down taken as upright" in warning
    assert "z-down frame" in warning and warning.endswith("no ATE/RPE")


def test_on_the_scans_alone_a_ground_truth_in_millimetres_is_not_scored(scans_only, tmp_path):
    """A ground truth in mm beside a log run on its scans alone: not scored, said so (a probe: ATE 9 km)."""
    log = tmp_path / "mm.mcap"
    log.write_bytes(scans_only.read_bytes())
    gt = np.loadtxt(scans_only.with_suffix(".gt.tum"))
    gt[:, 1:4] *= 1000.0
    np.savetxt(log.with_suffix(".gt.tum"), gt)
    res = invoke("run", log, "--out", tmp_path / "o", "-q", "--set", "input.odometry=scans")
    assert res.exit_code == 0, res.output
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert s["accuracy"] is None or s["accuracy"].get("ate") is None
    assert any(
        "the scans' odometry are in different units" in w and "millimetres" in w for w in s["warnings"]
    )
