"""The commands' printed text (report/text.py), line by line, from hand-made results."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import replace

import numpy as np
from _results_helpers import NO_REL, REL, ate, make_summary

from cornerslam_cli.logs.base import LogInfo, TopicInfo
from cornerslam_cli.report.text import (
    batch_counts,
    batch_lines,
    comparison_lines,
    evaluation_lines,
    info_lines,
    mean_std,
    relation_text,
    scan_heading,
    summary_lines,
)
from cornerslam_cli.results import Accuracy, Ate, RelationError, ScanOdometryStats
from cornerslam_cli.types import Scan


def summary(assoc="pca", accuracy=None, t_match=0.5, t_match_max=0.0123):
    return make_summary(assoc, accuracy, t_match, t_match_max)


def accuracy(scan_odom_relations: RelationError | None) -> Accuracy:
    """A summary's accuracy section with ground truth and relations."""
    return Accuracy(
        ground_truth="gt.tum",
        ate=ate(0.0123),
        odom_ate=ate(1.4249),
        scan_odom_ate=ate(0.0816),
        relations=REL,
        odom_relations=NO_REL,
        scan_odom_relations=scan_odom_relations,
    )


def test_relation_text_and_mean_std():
    assert mean_std(REL) == "0.123 ± 0.046"
    assert mean_std(NO_REL) == "-"
    assert relation_text(REL) == "translation 0.123 ± 0.046 m, rotation 1.23 ± 0.50 deg (3/4 relations)"
    assert relation_text(NO_REL) == (
        "no relation falls inside the trajectory's time span (check --time-offset)"
    )


def test_summary_lines_without_reference():
    s = make_summary(t_scan_match=None)  # a summary written before scan matching existed
    assert summary_lines(s) == [
        "logs/office.mcap: 500 steps (502 scans, 2 skipped, 7 between keyframes), 88 landmarks, "
        "2777 matches with pca",
        "topics: scans /scan, odometry /odom (odometry)",
        "laser mount: x=0.000 m y=0.000 m yaw=0.000 rad (the built-in default: not on the log's tf, "
        "not in the config)",
        "time: extract 1.23s scan match 0.00s predict 0.04s match 0.50s update 0.38s (118 steps/s), "
        "wall 4.6s",
        "wrote out/office_pca",
    ]
    tf = replace(s, input=replace(s.input, laser_to_base=(0.1, 0.0, 0.0), laser_to_base_source="tf"))
    assert summary_lines(tf)[2] == "laser mount: x=0.100 m y=0.000 m yaw=0.000 rad (from the log's tf)"
    skewed = replace(s, input=replace(s.input, beam_times="log", beam_time=0.1 / 1024))
    assert summary_lines(skewed)[3] == "deskewed: beams 97.66 µs apart (the log's time_increment)"
    for no in ("none", "off"):  # nothing said when the scans were used as recorded
        assert summary_lines(replace(s, input=replace(s.input, beam_times=no))) == summary_lines(s)
    for preset, line in (
        ("sick_lms_1deg", "sick_lms_1deg (its sensor model and extraction settings, under the config)"),
        ("auto", "none matches the scans (the config's sensor model)"),
        ("none", "none (input.laser_preset: none; the config's sensor model)"),
    ):
        config = {**s.config, "input": {"laser_preset": preset}}
        assert summary_lines(replace(s, config=config))[3] == f"laser preset: {line}"


def test_mount_line_names_the_upside_down_flag_s_own_source():
    """The position and the upside-down flag each say where they came from: the flag set by
    input.laser.upside_down is not the built-in default's, nor the log's on a CARMEN log whose
    ROBOTLASER1 laser pose gave the position; one source is named once."""
    s = make_summary()
    at = "laser mount: x=0.100 m y=0.000 m yaw=0.000 rad"
    by_config = "upside down (from the config's input.laser.upside_down)"

    def line(position: str, flag: str | None, fmt: str = "mcap", down: bool = True) -> str:
        inp = replace(
            s.input,
            format=fmt,
            laser_to_base=(0.1, 0.0, 0.0),
            laser_to_base_source=position,
            laser_upside_down=down,
            laser_upside_down_source=flag,
        )
        return summary_lines(replace(s, input=inp))[2]

    assert line("default", "config") == (
        f"{at} (the built-in default: not on the log's tf, not in the config), {by_config}"
    )
    assert line("tf", "config", "carmen") == f"{at} (from the log's ROBOTLASER1 laser pose), {by_config}"
    assert line("preset", "config") == f"{at} (from the laser preset), {by_config}"
    assert line("tf", "tf") == f"{at}, upside down (from the log's tf)"
    assert line("config", "config") == f"{at}, upside down (from the config's input.laser)"
    assert line("tf", "config", down=False) == f"{at} (from the log's tf)"
    assert line("tf", None) == f"{at} (from the log's tf), upside down"  # a summary without the flag's source


def test_summary_lines_with_ground_truth_and_relations():
    acc = accuracy(scan_odom_relations=REL)
    lines = summary_lines(summary(accuracy=acc))
    assert lines[4:] == [
        "ATE RMSE 0.012 m (odometry 1.425 m, scan-matched 0.082 m) against gt.tum",
        "relations: translation 0.123 ± 0.046 m, rotation 1.23 ± 0.50 deg (3/4 relations)",
        "  odometry: no relation falls inside the trajectory's time span (check --time-offset)",
        "  scan-matched odometry: translation 0.123 ± 0.046 m, rotation 1.23 ± 0.50 deg (3/4 relations)",
        "wrote out/office_pca",
    ]
    acc = dataclasses.replace(acc, scan_odom_ate=None, scan_odom_relations=None)
    lines = summary_lines(summary(accuracy=acc))
    assert lines[4] == "ATE RMSE 0.012 m (odometry 1.425 m) against gt.tum"
    assert not any("scan-matched" in line for line in lines)
    # a ground truth of part of the run: the line says over how many poses (a warning alone said it)
    part = dataclasses.replace(acc, ate=dataclasses.replace(acc.ate, n=200, in_holes=7))
    lines = summary_lines(summary(accuracy=part))
    assert lines[4] == (
        "ATE RMSE 0.012 m (odometry 1.425 m) against gt.tum, over 200 of the 500 poses "
        "(7 in its gaps not scored)"
    )


def test_comparison_lines_columns_follow_the_references():
    plain = [summary("icnn"), summary("jcbb", t_match=12.3456, t_match_max=0.1)]
    assert comparison_lines(plain) == [
        "assoc   steps landmarks  matched  t_match s   max ms  t_total s",
        "icnn      500        88     2777      0.500     12.3       4.57",
        "jcbb      500        88     2777     12.346    100.0       4.57",
    ]
    acc = accuracy(scan_odom_relations=NO_REL)
    assert comparison_lines([summary("pca", acc)]) == [
        "assoc   steps landmarks  matched  t_match s   max ms  t_total s    ATE m odom ATE m"
        "      relations m   odom relations m",
        "pca       500        88     2777      0.500     12.3       4.57    0.012      1.425"
        "    0.123 ± 0.046                  -",
        "scan-matched odometry (the filter's motion input): ATE 0.082 m, relations - m",
    ]
    assert comparison_lines([]) == comparison_lines(plain)[:1]  # the header alone


def test_comparison_lines_name_the_scan_odometry_on_the_scans_alone():
    """input.odometry=scans: the odometry columns are the scans' own odometry, and say so, aligned."""
    acc = replace(accuracy(scan_odom_relations=None), scan_odom_ate=None)  # (no second matching)
    stats = ScanOdometryStats(scans=9, searched=1, coasted=0, gaps=0, seconds=0.1)
    alone = replace(summary("pca", acc), scan_odometry=stats)
    assert comparison_lines([alone]) == [
        "assoc   steps landmarks  matched  t_match s   max ms  t_total s    ATE m scan odom ATE m"
        "      relations m scan odom relations m",
        "pca       500        88     2777      0.500     12.3       4.57    0.012           1.425"
        "    0.123 ± 0.046                     -",
    ]


def test_batch_lines_table_failures_and_totals():
    def row(log, assoc, size, status, steps=None, landmarks=None, ate=None, error=""):
        return {
            "log": log,
            "assoc": assoc,
            "association.pca.group_size": size,
            "status": status,
            "steps": steps,
            "landmarks": landmarks,
            "ate_rmse": ate,
            "error": error,
        }

    rows = [
        row("/data/office.mcap", "pca", 3, "ok", 501, 88, 0.01234),
        row("/data/office.mcap", "icnn", 5, "skipped", 501, 85, math.nan),
        row("/data/bad.bag", "pca", 3, "failed", error="no scans (check --scan-topic)"),
        row("/data/bad.bag", "icnn", 5, "failed", error="no scans (check --scan-topic)"),
    ]
    assert batch_counts(rows) == (2, 1)
    assert batch_lines(rows, ["association.pca.group_size"]) == [
        "log          assoc  group_size  status   steps  landmarks  ATE m",
        "office.mcap  pca    3           ok       501    88         0.012",
        "office.mcap  icnn   5           skipped  501    85         -",  # no ATE (was: nan)
        "bad.bag      pca    3           failed   -      -          -",
        "bad.bag      icnn   5           failed   -      -          -",
        "failed (2x): /data/bad.bag: no scans (check --scan-topic)",
        "4 combinations: 1 ran, 1 skipped (complete), 2 failed",
    ]
    assert batch_lines(rows[:1], [])[-1] == "1 combination: 1 ran, 0 skipped (complete), 0 failed"
    # two folders' logs of one name: told apart by their paths (both were "office.mcap")
    twins = [rows[0], {**rows[1], "log": "/other/office.mcap"}]
    assert [line.split()[0] for line in batch_lines(twins, ["association.pca.group_size"])[1:3]] == [
        "/data/office.mcap",
        "/other/office.mcap",
    ]
    # two swept keys of one last part: the columns named whole (both were "max_distance")
    keys = ["submaps.max_distance", "scan_match.max_distance"]
    swept = [{**r, keys[0]: 10, keys[1]: 1} for r in rows[:1]]
    assert batch_lines(swept, keys)[0].split()[2:4] == keys
    assert batch_lines(swept, keys[:1] + ["association.pca.group_size"])[0].split()[2:4] == [
        "max_distance",
        "group_size",
    ]


def test_info_lines():
    info = LogInfo(
        format="mcap",
        path="office.mcap",
        start=1700000000.0061,
        end=1700000050.0,
        duration=49.9939,
        n_messages=1503,
        topics=(
            TopicInfo("/scan", "sensor_msgs/LaserScan", 501, 10.0, "cdr"),
            TopicInfo("/tf", "tf2_msgs/TFMessage", None, None, "protobuf"),
        ),
        scan_topic="/scan",
        odom_topic="",
        odom_source="",
        problems=("no odometry",),
        notes=("a note",),
    )
    assert info_lines("office.mcap", info, (0.1, -0.02, math.pi / 2)) == [
        "file:      office.mcap",
        "format:    mcap",
        "messages:  1503",
        "start:     1700000000.006 s",
        "duration:  49.99 s",
        "topics:",
        "  /scan                        sensor_msgs/LaserScan               501 msgs    10.00 Hz",
        "  /tf                          tf2_msgs/TFMessage                    ? msgs "
        " [protobuf: not readable]",
        "run would use:",
        "  scans     /scan",
        "  odometry  - (none found)",
        "  laser     x=0.100 m y=-0.020 m yaw=1.571 rad (from tf)",
        "problem:   no odometry",
        "note:      a note",
    ]
    named = info_lines("office.mcap", info, (0.1, -0.02, math.pi / 2), tf_frames=("base_footprint", "laser"))
    assert "  laser     x=0.100 m y=-0.020 m yaw=1.571 rad (from tf base_footprint→laser)" in named
    empty = LogInfo("carmen", "x.clf", None, None, 0.0, 0, (), "", "", "")
    assert info_lines("x.clf", empty, None) == [
        "file:      x.clf",
        "format:    carmen",
        "messages:  0",
        "topics:",
        "run would use:",
        "  scans     -",
        "  odometry  - (none found)",
        "  laser     not in its laser lines: from the config's input.laser (built-in default x=0 y=0 yaw=0)",
    ]


def test_info_lines_escape_control_characters_of_names_from_the_log():
    """A topic (a CARMEN tag, an MCAP channel) named with control characters (garbage bytes, a terminal
    escape sequence): info printed them raw to the terminal."""
    odd = "\x1b]0;owned\x07/scan\x00"
    info = LogInfo("mcap", "x.mcap", None, None, 0.0, 1, (TopicInfo(odd, odd, 1, None, "cdr"),), odd, "", "")
    lines = info_lines("x.mcap", info, None)
    assert not any(c in line for line in lines for c in "\x00\x07\x1b")
    assert lines[4].split() == ["\\x1b]0;owned\\x07/scan\\x00"] * 2 + ["1", "msgs"]
    assert lines[6] == "  scans     \\x1b]0;owned\\x07/scan\\x00"


def test_evaluation_lines():
    res = Accuracy(
        ate=Ate(rmse=0.01234, mean=0.01, max=0.05, n=501),
        rpe_step_rmse=0.00321,
        rpe_step_rot_rmse=0.001,
        rpe_per_m=0.0456,
        relations=REL,
    )
    assert evaluation_lines(res) == [
        "ATE  rmse 0.0123 m  mean 0.0100 m  max 0.0500 m  (n=501)",
        "RPE  per step 0.0032 m  per metre 0.0456 m/m",
        "relations: translation 0.123 ± 0.046 m, rotation 1.23 ± 0.50 deg (3/4 relations)",
    ]
    res = dataclasses.replace(res, rpe_per_m=math.nan, relations=None)  # a path shorter than 1 m
    assert evaluation_lines(res)[1] == "RPE  per step 0.0032 m  per metre - m/m"
    assert evaluation_lines(Accuracy()) == []


def test_scan_heading():
    k = 170
    scan = Scan(1700000000.4567, np.full(k, 2.0), np.zeros(k), np.arange(k), 181, 0.1, 30.0, 0.01)
    assert scan_heading(40, scan) == "scan 40 at 1700000000.457 s: 170 valid of 181 beams"


def test_a_dumb_terminals_status_line_is_erased_without_escape_codes(monkeypatch):
    """TERM=dumb (Emacs's shell, some CI log viewers) shows ANSI erase-line as garbage: spaces between
    two carriage returns there (a hostile-user probe), the escape code elsewhere."""
    from cornerslam_cli.report import progress

    monkeypatch.setenv("TERM", "dumb")
    dumb = progress._erase()
    assert "\033" not in dumb and dumb.startswith("\r") and dumb.endswith("\r") and dumb.strip() == ""
    monkeypatch.setenv("TERM", "xterm-256color")
    assert progress._erase() == "\r\033[K"


def test_the_run_says_what_it_read_of_the_log():
    """Which scan topic and odometry the run took was said only with -v (info says it; run chose among
    several by rules a ROS user may not expect): a line of the summary now."""
    s = make_summary()
    tf = replace(s.input, odom_topic="/tf", odom_source="tf odom→base_footprint")
    assert (
        summary_lines(replace(s, input=tf))[1] == "topics: scans /scan, odometry /tf (tf odom→base_footprint)"
    )
    carmen = replace(
        s.input, format="carmen", scan_topic="FLASER", odom_topic="ODOM", odom_source="ODOM lines"
    )
    assert summary_lines(replace(s, input=carmen))[1] == "read: FLASER lines, odometry from ODOM lines"
    none = replace(s.input, odom_topic="", odom_source="")
    assert summary_lines(replace(s, input=none))[1] == "topics: scans /scan, odometry -"


def test_the_run_says_how_well_its_map_agrees_with_itself():
    """A figure that needs no ground truth (summary.json `consistency`) was only in summary.json and
    report.html: on a log without a reference (the Mines bags) the run printed no quality figure (a
    new-user probe)."""
    from cornerslam_cli.results import MapConsistency

    c = MapConsistency(
        cell=0.05, scans=304, points=83688, occupied_cells=5868, odom_occupied_cells=8808,
        cells_vs_odom=0.6662, revisit_mean=0.0861, revisit_share=0.42, odom_revisit_mean=0.1134,
        odom_revisit_share=0.35,
    )  # fmt: skip
    s = make_summary()
    assert summary_lines(replace(s, consistency=c))[-2] == (
        "map consistency: revisit misalignment 8.6 cm on 42 % of points (odometry 11.3 cm on 35 %), "
        "map cells 0.67× the odometry's"
    )
    never = replace(c, revisit_mean=None, revisit_share=0.0, odom_revisit_mean=None, odom_revisit_share=0.0)
    assert summary_lines(replace(s, consistency=never))[-2] == (
        "map consistency: map cells 0.67× the odometry's; the run never comes back to a place (no revisit "
        "misalignment)"
    )
    assert not any(line.startswith("map consistency") for line in summary_lines(s))


def test_comparison_lines_with_one_run_scored_and_another_not():
    """A review: a compare whose runs got different verdicts on the ground truth (one scored, one not)
    failed on the unscored one's accuracy (None) after every run had finished: '-' cells instead."""
    lines = comparison_lines([summary("pca", accuracy(scan_odom_relations=REL)), summary("icnn")])
    assert "0.012" in lines[1] and "1.425" in lines[1]
    assert lines[2].split()[-4:] == ["-", "-", "-", "-"], lines
