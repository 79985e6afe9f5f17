"""``info --config/--set``: what a run would use under the same config — the topics, frames and stamps it
reads the log by, the laser's mount and preset. info read the log with the built-in defaults only, so a
log a run reads under ``--set input.odom_frame=world`` was refused by info, and info could not show a log
as ``input.stamps=receive`` reads it."""

from __future__ import annotations

import json
from pathlib import Path

from _log_fixtures import make_odoms, make_scans, write_messages_mcap
from click.testing import CliRunner

from cornerslam_cli.cli import cli
from cornerslam_cli.logs.writers import serializer

SAMPLES = Path(__file__).resolve().parents[1] / "sample_logs"


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def line(output: str, start: str) -> str:
    (found,) = [t for t in output.splitlines() if t.startswith(start)]
    return found


def world_log(path: Path) -> Path:
    """Odometry on /tf as world → base_link (not the default odom → base_link), the laser 0.2 m ahead."""
    ros = serializer("cdr")
    scans, odoms = make_scans(6), make_odoms(8)
    t0 = min(scans[0].stamp, odoms[0].stamp) - 0.01
    msgs = [
        (
            "/tf_static",
            "tf2_msgs/msg/TFMessage",
            int(t0 * 1e9),
            ros.tf(t0, "base_link", "laser", 0.2, 0.0, 0.0),
        )
    ]
    msgs += [("/scan", "sensor_msgs/msg/LaserScan", int(s.stamp * 1e9), ros.laserscan(s)) for s in scans]
    msgs += [
        (
            "/tf",
            "tf2_msgs/msg/TFMessage",
            int(o.stamp * 1e9),
            ros.tf(o.stamp, "world", "base_link", o.x, o.y, o.theta),
        )
        for o in odoms
    ]
    return write_messages_mcap(path, sorted(msgs, key=lambda m: m[2]))


def test_info_reads_the_log_on_the_frames_the_set_gives_as_run_does(tmp_path):
    log = world_log(tmp_path / "world.mcap")
    refused = invoke("info", log)
    assert refused.exit_code == 2 and "--set input.odom_frame=world" in refused.stderr, refused.output
    res = invoke("info", log, "--set", "input.odom_frame=world")
    assert res.exit_code == 0, res.output
    assert line(res.stdout, "  odometry ") == "  odometry  /tf (tf world→base_link)"
    assert line(res.stdout, "  laser ").endswith(
        "x=0.200 m y=0.000 m yaw=0.000 rad (from tf base_link→laser)"
    )
    ran = invoke("run", log, "--out", tmp_path / "o", "-q", "--set", "input.odom_frame=world")
    assert ran.exit_code == 0, ran.output
    # a config file is read as run reads it
    config = tmp_path / "c.yaml"
    config.write_text("input:\n  odom_frame: world\n")
    assert invoke("info", log, "--config", config).exit_code == 0


def test_info_shows_the_mount_a_run_takes_from_the_config(tmp_path):
    """The config's mount where the log has none (a CARMEN FLASER log), and over the tf's with
    input.laser.from_tf=false: the mount the run records in summary.json."""
    clf = SAMPLES / "intel_cut.clf"
    res = invoke("info", clf, "--set", "input.laser.x=0.1")
    assert res.exit_code == 0, res.output
    mount = line(res.stdout, "  laser ")
    assert (
        mount
        == "  laser     x=0.100 m y=0.000 m yaw=0.000 rad (the config's input.laser: not in its laser lines)"
    )
    ran = invoke("run", clf, "--out", tmp_path / "o", "-q", "--max-scans", "3", "--set", "input.laser.x=0.1")
    assert ran.exit_code == 0, ran.output
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["input"]["laser_to_base"] == [0.1, 0.0, 0.0]
    log = world_log(tmp_path / "world.mcap")
    sets = [
        "--set",
        "input.odom_frame=world",
        "--set",
        "input.laser.from_tf=false",
        "--set",
        "input.laser.y=-0.05",
    ]
    res = invoke("info", log, *sets)
    assert res.exit_code == 0, res.output
    assert line(res.stdout, "  laser ") == (
        "  laser     x=0.000 m y=-0.050 m yaw=0.000 rad (the config's input.laser: input.laser.from_tf=false)"
    )


def test_info_names_the_clock_a_receive_run_reads_and_the_preset_the_config_chooses(sim_log):
    plain = invoke("info", sim_log)
    assert plain.exit_code == 0 and "  stamps " not in plain.stdout
    res = invoke("info", sim_log, "--set", "input.stamps=receive")
    assert res.exit_code == 0, res.output
    assert line(res.stdout, "  stamps ") == "  stamps    log times (input.stamps=receive)"
    clf = SAMPLES / "intel_cut.clf"
    assert line(invoke("info", clf).stdout, "  beams ").endswith(": preset sick_lms_1deg")
    res = invoke("info", clf, "--set", "input.laser_preset=none")
    assert line(res.stdout, "  beams ").endswith(
        ": no laser preset (input.laser_preset=none: the config's sensor model)"
    )


def test_info_refuses_a_bad_set_as_run_does_and_lists_a_broken_log_under_one(tmp_path):
    res = invoke("info", SAMPLES / "sim_office.mcap", "--set", "input.stampz=receive")
    assert res.exit_code == 2 and "input.stampz" in res.stderr and "Traceback" not in res.output
    assert len(res.stderr.strip().splitlines()) == 1, res.stderr
    # scans without odometry: the preset cannot be chosen as a run would (the log is refused); info lists
    # the topics under the config all the same, then refuses it as run does
    from _log_fixtures import scan_messages

    log = write_messages_mcap(tmp_path / "scans_only.mcap", scan_messages(n=3))
    res = invoke("info", log, "--set", "input.stamps=receive")
    assert res.exit_code == 2 and "has no odometry" in res.stderr, res.output
    assert "/scan" in res.stdout and "  odometry  - (none found)" in res.stdout


def test_info_shows_an_upside_down_laser_at_the_default_mount_and_warns_once(tmp_path):
    """input.laser.upside_down alone (the mount still the built-in default) was not shown, though the run
    mirrors the scans; a retired key's warning came twice (the config resolved twice) (a review)."""
    clf = SAMPLES / "intel_cut.clf"
    res = invoke("info", clf, "--set", "input.laser.upside_down=true")
    assert line(res.stdout, "  laser ").endswith(
        "(built-in default x=0 y=0 yaw=0), upside down: scans mirrored"
    )
    res = invoke("info", clf, "--set", "scan_match.retry_fit=1")
    assert res.exit_code == 0 and res.stderr.count("retry_fit") == 1, res.stderr


def test_a_results_mcap_is_read_as_a_log_under_a_set_topic_as_under_the_option(sim_log, tmp_path):
    """--set input.scan_topic=/scan described a results MCAP as results, --scan-topic /scan read it as a
    log: the same now, whichever way the topic is given (a review)."""
    results = tmp_path / "r.mcap"
    ran = invoke("run", sim_log, "--out", tmp_path / "o", "-q", "--max-scans", "5", "--mcap-out", results)
    assert ran.exit_code == 0, ran.output
    assert "It is not a log to run" in invoke("info", results).stdout
    by_option = invoke("info", results, "--scan-topic", "/scan")
    by_set = invoke("info", results, "--set", "input.scan_topic=/scan")
    assert (by_set.exit_code, by_set.stdout) == (by_option.exit_code, by_option.stdout)
    assert "It is not a log to run" not in by_set.stdout


def test_info_notes_a_config_mount_the_logs_own_overrules(sim_log):
    """The config's input.laser.x where the log's tf mounts the laser: run warns it is ignored; info said
    nothing (a review)."""
    res = invoke("info", sim_log, "--set", "input.laser.x=0.5")
    assert res.exit_code == 0, res.output
    assert (
        "note:      the log's mount is used: input.laser.x=0.5 is ignored (input.laser.from_tf=false uses "
        "the config's)" in res.stdout.splitlines()
    )
    assert "ignored" not in invoke("info", sim_log).stdout
    assert "  laser " in res.stdout and "from tf" in line(res.stdout, "  laser ")
