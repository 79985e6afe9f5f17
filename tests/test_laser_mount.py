"""Lasers as ROS robots mount them: beams running clockwise (a negative angle_increment) and a laser
mounted upside down (its tf z axis down). Checked against the same scans of an upright,
counter-clockwise laser: the run must not tell them apart."""

from __future__ import annotations

import dataclasses
import json
import logging
import math
from pathlib import Path

import numpy as np
import pytest
from _log_fixtures import make_scans, split, write_log, write_messages_mcap
from _run_helpers import run_cli

from cornerslam_cli.logs import open_log
from cornerslam_cli.logs.base import ReadStats, make_scan
from cornerslam_cli.logs.deskew import beam_times
from cornerslam_cli.logs.ros import transform_matrix
from cornerslam_cli.logs.writers import RawScan, write_carmen
from cornerslam_cli.logs.writers.ros import JsonSerializer
from cornerslam_cli.report.text import mount_line
from cornerslam_cli.results import RunSummary
from cornerslam_cli.types import Scan

SAMPLE = "sample_logs/sim_office.mcap"


def _ranges(n: int = 31, seed: int = 0) -> np.ndarray:
    r = np.random.default_rng(seed).uniform(0.5, 8.0, n)
    r[[3, 17]] = np.inf  # no return: dropped, so the beam indices have gaps
    return r


def _sorted_points(scan: Scan) -> np.ndarray:
    p = scan.points()
    return p[np.lexsort((p[:, 1], p[:, 0]))]


def test_clockwise_beams_read_as_the_same_points_in_increasing_bearing_order():
    """A message from +0.5 rad in steps of −0.01 rad is the counter-clockwise message of the same beams
    reversed: the same points, bearings increasing, each beam keeping its index in its own message
    (so its time, stamp + index · time_increment)."""
    r = _ranges()
    n = len(r)
    cw = make_scan(ReadStats(), "t", 1.0, 0.5, None, -0.01, 0.1, 30.0, r, time_increment=1e-3)
    ccw = make_scan(ReadStats(), "t", 1.0, 0.5 - 0.01 * (n - 1), None, 0.01, 0.1, 30.0, r[::-1])
    assert cw is not None and ccw is not None
    assert np.all(np.diff(cw.angles) > 0) and cw.angle_increment == pytest.approx(0.01)
    np.testing.assert_allclose(cw.angles, ccw.angles, atol=1e-12)
    np.testing.assert_array_equal(cw.ranges, ccw.ranges)
    np.testing.assert_array_equal(cw.beam_index, n - 1 - ccw.beam_index)
    # the beam at bearing 0.5 − 0.01 i is the i-th of the clockwise message: fired at i ms
    i = np.rint((0.5 - cw.angles) / 0.01)
    np.testing.assert_allclose(beam_times(cw, cw.time_increment), i * 1e-3, atol=1e-12)


def test_mirrored_scan_is_the_upright_laser_s_view():
    """Upside down, a beam at bearing φ of the laser looks at −φ in the base's plane: every point's y
    changes sign, bearings stay increasing and every range keeps its beam's index."""
    r = _ranges()
    scan = make_scan(ReadStats(), "t", 1.0, -0.3, None, 0.02, 0.1, 30.0, r)
    m = scan.mirrored()
    assert np.all(np.diff(m.angles) > 0)
    want = scan.points() * [1.0, -1.0]
    np.testing.assert_allclose(_sorted_points(m), want[np.lexsort((want[:, 1], want[:, 0]))], atol=1e-12)
    np.testing.assert_array_equal(m.ranges, r[m.beam_index])
    np.testing.assert_allclose(m.mirrored().angles, scan.angles, atol=1e-15)


def _sample_log() -> tuple[list[RawScan], list]:
    """Every beam of the first 80 scans of the shipped simulated log, and its odometry up to them."""
    with open_log(SAMPLE) as log:
        scans, odoms = split(log.messages())
        mount = log.laser_to_base()
    scans = scans[:80]
    raw = []
    for s in scans:
        r = np.full(s.n_beams, np.inf)
        r[s.beam_index] = s.ranges
        # its 0.25° and −135°, made exactly symmetric in the messages' float32 (within 0.002 % of them):
        # a run moves by 0.2 mm when the mirrored bearings are off by float32's 5e-8 rad
        inc = round(s.angle_increment * 2**21) / 2**21
        raw.append(RawScan(s.stamp, -0.5 * (s.n_beams - 1) * inc, inc, r, s.range_min, s.range_max, "laser"))
    odoms = [o for o in odoms if o.stamp <= scans[-1].stamp + 0.5]
    return raw, odoms, mount


def _tf(ser: JsonSerializer, stamp: float, mount, q, frame: str = "laser") -> bytes:
    ts = {
        "header": ser.header(stamp, "base_link"),
        "child_frame_id": frame,
        "transform": {
            "translation": {"x": mount[0], "y": mount[1], "z": 0.3},
            "rotation": dict(zip("xyzw", q, strict=True)),
        },
    }
    return json.dumps({"transforms": [ts]}).encode()


def _write(path, raw, odoms, mount, q, frame: str = "laser"):
    """An MCAP of the scans, the odometry and a /tf_static base_link→``frame`` (none when q is None)."""
    ser = JsonSerializer()
    t0 = int(min(raw[0].stamp, odoms[0].stamp) * 1e9) - 1
    tf = [] if q is None else [_tf(ser, t0 * 1e-9, mount, q, frame)]
    msgs = [("/tf_static", "tf2_msgs/msg/TFMessage", t0, m) for m in tf]
    msgs += [("/scan", "sensor_msgs/msg/LaserScan", int(s.stamp * 1e9), ser.laserscan(s)) for s in raw]
    msgs += [
        ("/odom", "nav_msgs/msg/Odometry", int(o.stamp * 1e9), ser.odometry(o, "odom", "base_link"))
        for o in odoms
    ]
    return write_messages_mcap(path, sorted(msgs, key=lambda m: m[2]), encoding="json")


def _flipped(s: RawScan) -> RawScan:
    """The scan an upside-down laser at the same place records: a symmetric field of view, so its beam
    i looks where the upright laser's beam n − 1 − i did."""
    assert s.angle_min == pytest.approx(-(s.angle_min + (len(s.ranges) - 1) * s.angle_increment), abs=1e-9)
    return RawScan(
        s.stamp, s.angle_min, s.angle_increment, s.ranges[::-1].copy(), s.range_min, s.range_max, "laser"
    )


def _yaw_q(yaw: float) -> tuple[float, float, float, float]:
    return (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))


def _upside_down_q(yaw: float) -> tuple[float, float, float, float]:
    """Rz(yaw)·Rx(π): the laser's x axis at yaw in the plane, its z axis down."""
    c, s = math.cos(yaw / 2), math.sin(yaw / 2)
    return (c, s, 0.0, 0.0)


def test_upside_down_laser_gives_the_upright_run(tmp_path):
    """The simulated office recorded by an upside-down laser (tf roll π, ranges mirrored) and by the
    upright one: trajectory and map agree; summary.json and info say which is which."""
    raw, odoms, mount = _sample_log()
    up = _write(tmp_path / "up.mcap", raw, odoms, mount, _yaw_q(mount[2]))
    down = _write(tmp_path / "down.mcap", [_flipped(s) for s in raw], odoms, mount, _upside_down_q(mount[2]))
    with open_log(down) as log:
        assert log.laser_to_base() == pytest.approx(mount, abs=1e-9) and log.laser_upside_down()
        assert not any("tilts" in w for w in log.stats.warnings)
    with open_log(up) as log:
        assert not log.laser_upside_down()
    a = run_cli(up, tmp_path / "a", "submaps.enabled=false")
    b = run_cli(down, tmp_path / "b", "submaps.enabled=false")
    assert b["input"]["laser_upside_down"] and not a["input"]["laser_upside_down"]
    assert b["input"]["laser_upside_down_source"] == a["input"]["laser_upside_down_source"] == "tf"
    ta = np.genfromtxt(tmp_path / "a" / "trajectory.csv", delimiter=",", names=True)
    tb = np.genfromtxt(tmp_path / "b" / "trajectory.csv", delimiter=",", names=True)
    assert len(ta) == len(tb) > 20
    for k in ("x", "y", "theta"):
        np.testing.assert_allclose(tb[k], ta[k], atol=1e-6)
    # read as upright (the tf ignored), the mirrored scans give another run: the test can fail
    c = run_cli(down, tmp_path / "c", "submaps.enabled=false", "input.laser.from_tf=false")
    tc = np.genfromtxt(tmp_path / "c" / "trajectory.csv", delimiter=",", names=True)
    assert not c["input"]["laser_upside_down"]
    assert np.max(np.hypot(tc["x"] - ta["x"][: len(tc)], tc["y"] - ta["y"][: len(tc)])) > 1e-3  # ≫ 1e-6


def test_config_upside_down_mirrors_a_log_without_tf(tmp_path):
    """A log without tf: ``input.laser.upside_down`` says so, as input.laser.x/y/yaw give the rest."""
    raw, odoms, mount = _sample_log()
    raw, odoms = raw[:30], [o for o in odoms if o.stamp <= raw[29].stamp + 0.5]
    up = _write(tmp_path / "up.mcap", raw, odoms, mount, _yaw_q(mount[2]))
    flipped = [_flipped(s) for s in raw]
    down = tmp_path / "down.mcap"
    ser = JsonSerializer()
    msgs = [("/scan", "sensor_msgs/msg/LaserScan", int(s.stamp * 1e9), ser.laserscan(s)) for s in flipped]
    msgs += [
        ("/odom", "nav_msgs/msg/Odometry", int(o.stamp * 1e9), ser.odometry(o, "odom", "base_link"))
        for o in odoms
    ]
    write_messages_mcap(down, sorted(msgs, key=lambda m: m[2]), encoding="json")
    sets = [f"input.laser.x={mount[0]!r}", f"input.laser.y={mount[1]!r}", f"input.laser.yaw={mount[2]!r}"]
    run_cli(up, tmp_path / "a", "submaps.enabled=false")
    b = run_cli(down, tmp_path / "b", "submaps.enabled=false", "input.laser.upside_down=true", *sets)
    assert b["input"]["laser_upside_down"] and b["input"]["laser_to_base_source"] == "config"
    ta = np.genfromtxt(tmp_path / "a" / "trajectory.csv", delimiter=",", names=True)
    tb = np.genfromtxt(tmp_path / "b" / "trajectory.csv", delimiter=",", names=True)
    np.testing.assert_allclose(
        np.c_[tb["x"], tb["y"], tb["theta"]], np.c_[ta["x"], ta["y"], ta["theta"]], atol=1e-6
    )


def test_config_upside_down_overruled_by_an_upright_tf_is_warned_about(tmp_path):
    """``input.laser.upside_down=true`` on a log whose tf mounts the laser upright: the tf decides (the
    scans are not mirrored), and the key the user set is said to be ignored, once, with the remedy.
    Not when the tf says upside down too (they agree), nor when the key is not set."""
    raw, odoms, mount = _sample_log()
    raw, odoms = raw[:20], [o for o in odoms if o.stamp <= raw[19].stamp + 0.5]
    up = _write(tmp_path / "up.mcap", raw, odoms, mount, _yaw_q(mount[2]))
    down = _write(tmp_path / "down.mcap", [_flipped(s) for s in raw], odoms, mount, _upside_down_q(mount[2]))
    sets = ("submaps.enabled=false", "input.laser.upside_down=true")

    def ignored(summary: dict) -> list[str]:
        return [w for w in summary["warnings"] if "input.laser.upside_down" in w]

    a = run_cli(up, tmp_path / "a", *sets)
    assert not a["input"]["laser_upside_down"] and a["input"]["laser_upside_down_source"] == "tf"
    (warning,) = ignored(a)
    assert "upright" in warning and "ignored" in warning and "input.laser.from_tf=false" in warning
    b = run_cli(down, tmp_path / "b", *sets)
    assert b["input"]["laser_upside_down"] and not ignored(b)
    assert not ignored(run_cli(up, tmp_path / "c", "submaps.enabled=false"))


def test_mount_warnings_name_the_log_s_laser_frame(tmp_path):
    """The warnings about the mount name the tf as the log does: base_link→hokuyo_link for scans in
    frame hokuyo_link, not a frame "laser" the log does not have."""
    raw, odoms, mount = _sample_log()
    raw = [dataclasses.replace(s, frame_id="hokuyo_link") for s in raw[:10]]
    odoms = [o for o in odoms if o.stamp <= raw[-1].stamp + 0.5]
    up = _write(tmp_path / "up.mcap", raw, odoms, mount, _yaw_q(mount[2]), frame="hokuyo_link")
    a = run_cli(up, tmp_path / "a", "submaps.enabled=false", "input.laser.upside_down=true")
    (warning,) = [w for w in a["warnings"] if "input.laser.upside_down" in w]
    assert "its tf base_link→hokuyo_link mounts the laser upright" in warning, warning
    bare = _write(tmp_path / "bare.mcap", raw, odoms, mount, None)
    warnings = run_cli(bare, tmp_path / "b", "submaps.enabled=false")["warnings"]
    assert any("has no tf base_link→hokuyo_link:" in w for w in warnings), warnings


def test_tilted_laser_is_warned_about(tmp_path, caplog):
    """A tf that tilts the laser 30° (pitch) is used as if level, with one warning naming the angle."""
    raw, odoms, mount = _sample_log()
    pitch = math.radians(30.0)
    q = (0.0, math.sin(pitch / 2), 0.0, math.cos(pitch / 2))
    path = _write(tmp_path / "tilt.mcap", raw[:5], odoms[:20], mount, q)
    with caplog.at_level(logging.WARNING, logger="cornerslam.logs"), open_log(path) as log:
        assert log.laser_to_base() is not None and not log.laser_upside_down()
    assert "tilts the laser 30° from level" in caplog.text


def test_tf_quaternion_with_a_huge_component_keeps_its_rotation(tmp_path):
    """A tf rotation (1e200, 0, 0, 1), from corrupt data, is roll π: the laser upside down. Its squared
    length overflows to inf, which must not normalise it to no rotation (read as upright)."""
    np.testing.assert_allclose(
        transform_matrix((0.0, 0.0, 0.0), (1e200, 0.0, 0.0, 1.0)), np.diag([1, -1, -1, 1]), atol=1e-15
    )
    np.testing.assert_allclose(  # π about (1, 1, 0)/√2: x and y swap, z turns down
        transform_matrix((0.0, 0.0, 0.0), (1e200, 1e200, 0.0, 0.0))[:3, :3],
        [[0, 1, 0], [1, 0, 0], [0, 0, -1]],
        atol=1e-15,
    )
    raw, odoms, mount = _sample_log()
    m = (mount[0], mount[1], 0.0)
    path = _write(tmp_path / "huge.mcap", raw[:5], odoms[:20], m, (1e200, 0.0, 0.0, 1.0))
    with open_log(path) as log:
        assert log.laser_to_base() == pytest.approx(m, abs=1e-9) and log.laser_upside_down()


def test_tf_quaternion_whose_length_overflows_hypot_keeps_its_rotation(tmp_path):
    """Two components of 1.5e308 (corrupt data): math.hypot's length is inf too (past 1.8e308), which
    must not divide every component to 0, read as no rotation (upright, level). (1, 1, 0, 0)/√2 is π
    about (1, 1, 0)/√2: x and y swap, z turns down, the laser upside down."""
    np.testing.assert_allclose(
        transform_matrix((0.0, 0.0, 0.0), (1.5e308, 1.5e308, 0.0, 0.0))[:3, :3],
        [[0, 1, 0], [1, 0, 0], [0, 0, -1]],
        atol=1e-15,
    )
    np.testing.assert_allclose(  # all four of 1.7e308: 120° about (1, 1, 1), x → y → z → x
        transform_matrix((0.0, 0.0, 0.0), (1.7e308,) * 4)[:3, :3],
        [[0, 0, 1], [1, 0, 0], [0, 1, 0]],
        atol=1e-15,
    )
    assert not np.isfinite(transform_matrix((0.0, 0.0, 0.0), (math.inf, 0.0, 0.0, 1.0))).all()
    assert not np.isfinite(transform_matrix((0.0, 0.0, 0.0), (math.nan, 0.0, 0.0, 1.0))).all()
    raw, odoms, mount = _sample_log()
    path = _write(
        tmp_path / "huge.mcap", raw[:5], odoms[:20], (mount[0], mount[1], 0.0), (1.5e308, 1.5e308, 0, 0)
    )
    with open_log(path) as log:
        assert log.laser_to_base() is not None and log.laser_upside_down()


def test_config_upside_down_mirrors_a_carmen_robotlaser_log(tmp_path):
    """A CARMEN ROBOTLASER1 log gives the laser's planar offset, which cannot say the laser is upside
    down: ``input.laser.upside_down`` does (its offset still from the log)."""
    raw, odoms, _ = _sample_log()
    raw, odoms = raw[:30], [o for o in odoms if o.stamp <= raw[29].stamp + 0.5]
    up = write_carmen(tmp_path / "up.clf", raw, odoms, laser="ROBOTLASER1")
    down = write_carmen(tmp_path / "down.clf", [_flipped(s) for s in raw], odoms, laser="ROBOTLASER1")
    a = run_cli(up, tmp_path / "a", "submaps.enabled=false")
    b = run_cli(down, tmp_path / "b", "submaps.enabled=false", "input.laser.upside_down=true")
    assert b["input"]["laser_upside_down"] and b["input"]["laser_to_base_source"] == "tf"
    assert b["input"]["laser_upside_down_source"] == "config"  # the offset from the log, the flag not
    assert mount_line(RunSummary.read(tmp_path / "b").input).endswith(
        "rad (from the log's ROBOTLASER1 laser pose), upside down (from the config's input.laser.upside_down)"
    )
    assert not a["input"]["laser_upside_down"]
    ta = np.genfromtxt(tmp_path / "a" / "trajectory.csv", delimiter=",", names=True)
    tb = np.genfromtxt(tmp_path / "b" / "trajectory.csv", delimiter=",", names=True)
    np.testing.assert_allclose(
        np.c_[tb["x"], tb["y"], tb["theta"]], np.c_[ta["x"], ta["y"], ta["theta"]], atol=1e-6
    )


def test_info_names_a_carmen_robotlaser_mount_as_run_does(tmp_path):
    """``info`` on a CARMEN ROBOTLASER1 log says the mount comes from the log's laser pose, as run's
    mount line does (there is no tf in a CARMEN log)."""
    from click.testing import CliRunner

    from cornerslam_cli.cli import cli

    raw, odoms, _ = _sample_log()
    raw, odoms = raw[:5], [o for o in odoms if o.stamp <= raw[4].stamp + 0.5]
    log = write_carmen(tmp_path / "r.clf", raw, odoms, laser="ROBOTLASER1")
    res = CliRunner().invoke(cli, ["info", str(log)])
    assert res.exit_code == 0, res.output
    (line,) = [t for t in res.output.splitlines() if t.startswith("  laser ")]
    assert line.endswith(" rad (from the log's ROBOTLASER1 laser pose)") and "tf" not in line, line


def test_info_says_whose_upside_down_it_shows_as_run_takes_it(tmp_path, sim_log):
    """A planar ROBOTLASER1 mount cannot say the laser is upside down: the config's flag is used, and info
    labelled it with the log's pose; a tf mounting the laser upright overrules the flag (run warns), and
    info said nothing (a review)."""
    from click.testing import CliRunner

    from cornerslam_cli.cli import cli

    raw, odoms, _ = _sample_log()
    raw, odoms = raw[:5], [o for o in odoms if o.stamp <= raw[4].stamp + 0.5]
    log = write_carmen(tmp_path / "r.clf", raw, odoms, laser="ROBOTLASER1")
    res = CliRunner().invoke(cli, ["info", str(log), "--set", "input.laser.upside_down=true"])
    (line,) = [t for t in res.output.splitlines() if t.startswith("  laser ")]
    assert line.endswith(
        " rad, upside down (input.laser.upside_down): scans mirrored (from the log's ROBOTLASER1 laser pose)"
    ), line
    res = CliRunner().invoke(cli, ["info", str(sim_log), "--set", "input.laser.upside_down=true"])
    assert "note:      the log's tf mounts the laser upright: input.laser.upside_down=true is ignored" in (
        res.output.splitlines()
    )
    assert "upside" not in CliRunner().invoke(cli, ["info", str(sim_log)]).output


def test_a_carmen_flaser_log_without_a_mount_is_not_said_to_lack_tf(tmp_path):
    """A FLASER log carries no laser mount and CARMEN has no tf: the warning, run's mount line and info
    say the log's laser lines give none (they said "has no tf base_link→laser … or
    input.laser.from_tf=false to keep it", advice that does not apply)."""
    from click.testing import CliRunner

    from cornerslam_cli.cli import cli

    log = Path(__file__).resolve().parents[1] / "sample_logs" / "intel_cut.clf"  # FLASER and ODOM lines
    res = CliRunner().invoke(cli, ["run", str(log), "--max-scans", "5", "--out", str(tmp_path / "a")])
    assert res.exit_code == 0, res.output
    s = json.loads((tmp_path / "a" / "summary.json").read_text())
    (warning,) = [w for w in s["warnings"] if "built-in default" in w]
    assert "gives no laser mount (its FLASER lines carry none)" in warning and "tf" not in warning, warning
    line = mount_line(RunSummary.read(tmp_path / "a").input)
    assert line.endswith("(the built-in default: not in the log's laser lines, not in the config)"), line
    res = CliRunner().invoke(cli, ["info", str(log)])
    (line,) = [t for t in res.output.splitlines() if t.startswith("  laser ")]
    assert "not in its laser lines" in line and "tf" not in line, line


def test_upside_down_alone_still_warns_of_the_default_position(tmp_path):
    """``input.laser.upside_down`` says how the laser is turned, not where it is: a log without tf
    whose config sets nothing else is still at the built-in x = y = yaw = 0, and warned about."""
    log = write_log("mcap-cdr", tmp_path)
    s = run_cli(log, tmp_path / "a", "input.laser.upside_down=true")
    assert s["input"]["laser_upside_down"] and s["input"]["laser_to_base_source"] == "default"
    assert s["input"]["laser_upside_down_source"] == "config"
    assert mount_line(RunSummary.read(tmp_path / "a").input).endswith(
        "rad (the built-in default: not on the log's tf, not in the config), "
        "upside down (from the config's input.laser.upside_down)"
    )
    assert any("built-in default" in w for w in s["warnings"])


@pytest.mark.parametrize("yaw", [0.4, 1.3])
def test_clockwise_upside_down_laser_turned_on_the_robot_with_a_sweep(tmp_path, yaw):
    """The harder case: a laser turned ``yaw`` on the robot, upside down, its beams clockwise in the
    message and fired 50 ms apart end to end (deskewed). Written twice with the same beams fired at the
    same times — upright (counter-clockwise) and upside down (the tf's z axis down, a negative
    increment) — the two runs agree: the mirrored bearings, the tf's yaw, the beams' times (by their
    index in the message) and the end beams trimmed all line up."""
    from cornerslam_cli.simulate import simulate_log

    sim = tmp_path / "sim.mcap"
    simulate_log(sim, beams=541, sweep=0.05, speed=1.0)
    with open_log(sim) as log:
        scans, odoms = split(log.messages())
        mount = log.laser_to_base()
    scans = scans[:60]
    odoms = [o for o in odoms if o.stamp <= scans[-1].stamp + 0.5]
    up, down = [], []
    for s in scans:
        r = np.full(s.n_beams, np.inf)
        r[s.beam_index] = s.ranges
        inc = round(s.angle_increment * 2**21) / 2**21  # (exact in the messages' float32, as above)
        b0 = -0.5 * (s.n_beams - 1) * inc  # bearing of beam 0 on the robot, turned by the mount's yaw
        up.append(RawScan(s.stamp, b0 - yaw, inc, r, s.range_min, s.range_max, "laser", s.time_increment))
        down.append(RawScan(s.stamp, yaw - b0, -inc, r, s.range_min, s.range_max, "laser", s.time_increment))
    assert scans[0].time_increment > 0
    m = (mount[0], mount[1], yaw)
    a_log = _write(tmp_path / "up.mcap", up, odoms, m, _yaw_q(yaw))
    b_log = _write(tmp_path / "down.mcap", down, odoms, m, _upside_down_q(yaw))
    sets = ("submaps.enabled=false", "input.skip_beams_start=40", "input.skip_beams_end=5")
    a = run_cli(a_log, tmp_path / "a", *sets)
    b = run_cli(b_log, tmp_path / "b", *sets)
    assert b["input"]["laser_upside_down"] and b["input"]["beam_times"] == a["input"]["beam_times"] == "log"
    ta = np.genfromtxt(tmp_path / "a" / "trajectory.csv", delimiter=",", names=True)
    tb = np.genfromtxt(tmp_path / "b" / "trajectory.csv", delimiter=",", names=True)
    assert len(ta) == len(tb) > 20
    for k in ("x", "y", "theta"):
        np.testing.assert_allclose(tb[k], ta[k], atol=1e-6)


@pytest.mark.parametrize("tf_static", [None, (0.2, 0.0, 0.0)])
def test_scans_with_an_empty_frame_id_are_warned_of_as_such(tmp_path, tf_static):
    """Scans whose header frame_id is empty: no tf can place the laser (a /tf_static base_link→"", which
    tf2 would ignore, is not used): the warning says so, not that the log has no tf base_link→laser (a
    probe)."""
    raw = [dataclasses.replace(s, frame_id="") for s in make_scans()]
    log = write_log("mcap-cdr", tmp_path, raw, tf_static=tf_static)
    s = run_cli(log, tmp_path / "a")
    assert s["input"]["laser_to_base_source"] == "default"
    assert (
        "log 'log.mcap' has scans on '/scan' with an empty header frame_id, so no tf can place the laser: "
        "the laser is taken at the built-in default x=0 y=0 yaw=0 on the robot (set input.laser.x/y/yaw "
        "to its mount, or input.laser.from_tf=false to keep it)"
    ) in s["warnings"]
    assert not any("has no tf" in w for w in s["warnings"])


def test_a_laser_mount_turned_the_wrong_way_is_warned_of(tmp_path):
    """The mount's yaw off by π: the scans then move against the odometry, and the front end learnt an
    odometer scale error of 180 % (a hostile-user probe) with no word; now warned."""
    raw, odoms, mount = _sample_log()
    log = _write(tmp_path / "log.mcap", raw, odoms, mount, _yaw_q(mount[2]))
    right = run_cli(log, tmp_path / "a", "submaps.enabled=false")
    assert not any("disagree on distance" in w for w in right["warnings"])
    assert abs(right["odometry_model"]["odom_scale_error"]) < 0.05
    turned = (
        f"input.laser.x={mount[0]}",
        f"input.laser.yaw={mount[2] + math.pi}",
        "input.laser.from_tf=false",
    )
    wrong = run_cli(log, tmp_path / "b", "submaps.enabled=false", *turned)
    assert abs(wrong["odometry_model"]["odom_scale_error"]) > 0.25
    (said,) = [w for w in wrong["warnings"] if "disagree on distance" in w]
    assert f"check the laser mount (yaw {mount[2] + math.pi:.3f} rad, from the config's input.laser" in said


def test_a_config_mount_the_tf_overrules_is_warned_of(tmp_path):
    """`--set input.laser.x=0.3` on a log whose tf mounts the laser at x=0.1: the tf's was used without a
    word, summary.json holding both (a probe); now warned, naming the keys and how to use them instead.
    The same values as the tf's, or none given, are no news."""
    raw, odoms, mount = _sample_log()
    log = _write(tmp_path / "log.mcap", raw[:20], odoms, mount, _yaw_q(mount[2]))
    other = run_cli(log, tmp_path / "a", "submaps.enabled=false", f"input.laser.x={mount[0] + 0.2:g}")
    (said,) = [w for w in other["warnings"] if "mounts the laser at" in w]
    assert f"x={mount[0]:.3f}" in said and f"input.laser.x={mount[0] + 0.2:g} is ignored" in said
    assert "set input.laser.from_tf=false to use the config's mount instead" in said
    turned = f"input.laser.yaw={mount[2] + 2 * math.pi!r}"  # the same yaw a turn on (a review)
    for same in ((f"input.laser.x={mount[0] + 5e-5!r}", f"input.laser.yaw={mount[2]!r}"), (turned,), ()):
        s = run_cli(log, tmp_path / f"b{len(same)}", "submaps.enabled=false", *same)
        assert not any("mounts the laser at" in w for w in s["warnings"])
