"""open_log and topic selection: every user problem is a LogError naming the file/topic + a hint."""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path

import numpy as np
import pytest
from _log_fixtures import (
    make_odoms,
    make_scans,
    odom_messages,
    scan_messages,
    split,
    write_log,
    write_messages_mcap,
)
from click.testing import CliRunner

from cornerslam_cli.cli import cli
from cornerslam_cli.errors import ConfigError, LogError
from cornerslam_cli.logs import READERS, detect_format, open_log
from cornerslam_cli.logs.base import ReadStats, make_scan
from cornerslam_cli.logs.writers import RawScan, RosSerializer, write_mcap
from cornerslam_cli.textfile import read_text


def test_readers_table_covers_formats(tmp_path):
    assert set(READERS) == {"mcap", "rosbag1", "rosbag2", "carmen"}
    for fmt, name in [
        ("mcap-cdr", "mcap"),
        ("rosbag1", "rosbag1"),
        ("rosbag2-sqlite3", "rosbag2"),
        ("carmen", "carmen"),
    ]:
        d = tmp_path / fmt
        d.mkdir()
        assert detect_format(write_log(fmt, d)) == name


def test_content_sniffed_before_extension(tmp_path):
    p = write_log("mcap-cdr", tmp_path)
    renamed = p.rename(tmp_path / "recording.dat")
    assert detect_format(renamed) == "mcap"
    carmen = write_log("carmen", tmp_path).rename(tmp_path / "intel.txt")
    assert detect_format(carmen) == "carmen"


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda d: d / "missing.mcap", "does not exist"),
        (lambda d: (d / "e.mcap").write_bytes(b"") and None or d / "e.mcap", "is empty"),
        (lambda d: (d / "e.log").write_bytes(b"") and None or d / "e.log", "is empty"),
        (lambda d: d, "not a ROS 2 bag"),
        (
            lambda d: (d / "x.pcd").write_bytes(b"\x00\x01binary") and None or d / "x.pcd",
            "unsupported log 'x.pcd'",
        ),
        (
            lambda d: (d / "x.mcap").write_bytes(b"not an mcap at all") and None or d / "x.mcap",
            "not a valid .mcap",
        ),
        (lambda d: (d / "x.bag").write_bytes(b"not a bag") and None or d / "x.bag", "not a valid .bag"),
        (lambda d: (d / "x.log").write_text("hello world\n") and None or d / "x.log", "not a CARMEN log"),
        (lambda d: (d / "x.db3").write_bytes(b"SQLite format 3") and None or d / "x.db3", "not a valid .db3"),
        (  # another SQLite file than a bag's .db3 (review: sent to the bag reader, "Unrecognized storage")
            lambda d: (
                (d / "x.sqlite").write_bytes(b"SQLite format 3\x00" + bytes(84)) and None or d / "x.sqlite"
            ),
            "unsupported log 'x.sqlite'",
        ),
    ],
)
def test_bad_paths(tmp_path, make, match):
    with pytest.raises(LogError, match=match) as err:
        open_log(make(tmp_path))
    assert err.value.hint


def test_log_in_a_directory_we_may_not_search(tmp_path, monkeypatch):
    """stat() failing with EACCES (a directory on the path without x permission; simulated, as the
    tests may run as root): a LogError naming the log, not a PermissionError from Path.exists()."""
    import errno
    import os
    import re

    p = write_log("mcap-cdr", tmp_path)
    real_stat = os.stat

    def stat(path, *args, **kwargs):
        if str(path) == str(p):
            raise PermissionError(errno.EACCES, "Permission denied", str(path))
        return real_stat(path, *args, **kwargs)

    monkeypatch.setattr(os, "stat", stat)
    with pytest.raises(LogError, match=re.escape(f"cannot read log '{p}': Permission denied")) as err:
        open_log(p)
    assert "permissions" in err.value.hint


def test_log_that_is_a_symlink_loop(tmp_path):
    """A log path that is a symlink loop (a -> b -> a): Path.exists() is False on ELOOP, so the error
    said "log 'a.mcap' does not exist", of a name ls shows; a dangling symlink still does not exist."""
    (tmp_path / "a.mcap").symlink_to(tmp_path / "b.mcap")
    (tmp_path / "b.mcap").symlink_to(tmp_path / "a.mcap")
    with pytest.raises(LogError, match="cannot read log '.*a.mcap': a symlink loop"):
        open_log(tmp_path / "a.mcap")
    (tmp_path / "d").symlink_to(tmp_path / "e")  # a loop on the way to it
    (tmp_path / "e").symlink_to(tmp_path / "d")
    with pytest.raises(LogError, match="cannot read log '.*d/x.mcap': a symlink loop"):
        open_log(tmp_path / "d" / "x.mcap")
    (tmp_path / "c.mcap").symlink_to(tmp_path / "missing.mcap")
    with pytest.raises(LogError, match="log '.*c.mcap' does not exist"):
        open_log(tmp_path / "c.mcap")


def test_log_name_too_long(tmp_path):
    """A name longer than the file system allows (a pasted command line): a LogError, not the OSError
    ENAMETOOLONG of Path.exists()."""
    with pytest.raises(LogError, match="cannot read log .*: File name too long") as err:
        open_log(tmp_path / ("x" * 300 + ".mcap"))
    assert "check the path" in err.value.hint


@pytest.mark.parametrize(
    "fmt, name, compress, match, hint",
    [
        ("mcap-cdr", "x.mcap.gz", "gzip", "'x.mcap.gz' is a gzip-compressed MCAP", "gunzip -k"),
        ("rosbag1", "x.bag.gz", "gzip", "'x.bag.gz' is a gzip-compressed ROS 1 bag", "gunzip -k"),
        ("carmen", "x.clf", "bz2", "'x.clf' is compressed with bzip2", "gzip"),
        ("carmen", "x.clf.bz2", "bz2", "'x.clf.bz2' is compressed with bzip2", "gzip"),
    ],
)
def test_a_compressed_log_cornerslam_does_not_read_is_named_as_such(
    tmp_path, fmt, name, compress, match, hint
):
    """A gzipped MCAP or bag was "not a CARMEN log: no FLASER/… lines" (.gz is read as a gzipped CARMEN
    log), a bzip2'd CARMEN log "not a CARMEN log" or "unsupported log": the file is what it is,
    compressed; the hint says to decompress it (or gzip a CARMEN log, which is read as it is)."""
    import bz2
    import gzip

    raw = write_log(fmt, tmp_path).read_bytes()
    p = tmp_path / name
    p.write_bytes(gzip.compress(raw) if compress == "gzip" else bz2.compress(raw))
    with pytest.raises(LogError, match=match) as err:
        open_log(p)
    assert hint in err.value.hint


@pytest.mark.parametrize(
    "name, compress, command",
    [
        ("x.mcap", "gzip", "gunzip -c {p} > {d}/x-decompressed.mcap"),
        ("x.clf", "bz2", "bunzip2 -c {p} > {d}/x-decompressed.clf"),
        ("x.clf.bz2", "bz2", "bunzip2 -k {p}"),
        ("x.clf", "xz", "unxz -c {p} > {d}/x-decompressed.clf"),
        ("x.mcap.zst", "zstd", "unzstd -k {p}"),
        # a compression suffix the tool may not know: the output named without it (it kept it: a probe's
        # log.mcap.zstd gave "> log.mcap-decompressed.zstd"), as for one in capitals, which only gunzip knows
        ("x.mcap.zstd", "zstd", "unzstd -c {p} > {d}/x.mcap"),
        ("x.zstd", "zstd", "unzstd -c {p} > {d}/x"),
        ("X.MCAP.ZST", "zstd", "unzstd -c {p} > {d}/X.MCAP"),
        ("X.CLF.XZ", "xz", "unxz -c {p} > {d}/X.CLF"),
        ("x.clf.bz", "bz2", "bunzip2 -c {p} > {d}/x.clf"),
        ("x.mcap", "zstd", "unzstd -c {p} > {d}/x-decompressed.mcap"),
    ],
)
def test_the_decompress_command_works_whatever_the_name(tmp_path, name, compress, command):
    """The hint's command must work as given: gunzip -k / unxz -k / unzstd on a name without their
    suffix (a gzipped MCAP named x.mcap, a bzip2'd x.clf) refuse it ("unknown suffix -- ignored")
    or, bunzip2, write 'x.clf.out': such a file is decompressed to stdout, into a named file. Where the
    tool is installed, the command is run and must give the log back."""
    import bz2
    import gzip
    import lzma
    import shutil
    import subprocess

    import zstandard

    raw = write_log("mcap-cdr" if "mcap" in name.lower() else "carmen", tmp_path).read_bytes()
    p = tmp_path / name
    compressors = {"gzip": gzip.compress, "bz2": bz2.compress, "xz": lzma.compress}
    p.write_bytes(zstandard.compress(raw) if compress == "zstd" else compressors[compress](raw))
    with pytest.raises(LogError) as err:
        open_log(p)
    given = command.format(p=p, d=tmp_path)
    assert err.value.hint.split("decompress it first: ")[1].split(" (a CARMEN")[0] == given, err.value.hint
    if shutil.which(given.split()[0]):
        subprocess.run(given, shell=True, check=True, cwd=tmp_path, capture_output=True)
        out = given.split("> ")[1] if "> " in given else str(p.with_suffix(""))
        assert Path(out).read_bytes() == raw


def test_no_laserscan(tmp_path):
    p = write_mcap(tmp_path / "odom_only.mcap", [], make_odoms())
    log = open_log(p)
    info = log.info()  # info never raises for selection problems: it reports them
    assert info.scan_topic == "" and "no sensor_msgs/LaserScan" in info.problems[0]
    with pytest.raises(LogError, match="'odom_only.mcap' has no sensor_msgs/LaserScan"):
        log.messages()
    with pytest.raises(LogError):
        log.laser_to_base()


def test_several_laserscans_listed(tmp_path):
    p = write_messages_mcap(
        tmp_path / "two.mcap", scan_messages("/scan") + scan_messages("/scan2") + odom_messages()
    )
    with pytest.raises(LogError, match=r"2 LaserScan topics: /scan, /scan2 \(choose") as err:
        open_log(p).messages()
    assert "--scan-topic" in err.value.hint
    scans, odoms = split(open_log(p, scan_topic="/scan2").messages())
    assert len(scans) == 5 and len(odoms) == 5
    # info: no scan topic chosen, so no laser mount looked up yet ("not on tf" was said of a tf that may
    # hold it: a ROS-user probe)
    res = CliRunner().invoke(cli, ["info", str(p)])
    assert res.exit_code == 2 and "2 LaserScan topics" in res.stderr
    assert "  laser     - (no scan topic chosen)" in res.stdout.splitlines() and "not on tf" not in res.stdout


def test_a_laserscan_topic_declared_but_never_published_gives_way(tmp_path):
    """`ros2 bag record -a` declares every topic, a laser that never published too: the one LaserScan
    topic with messages is taken, and info says why (it asked for --scan-topic: a ROS-user probe)."""
    empty = [("/scan_rear", "sensor_msgs/msg/LaserScan")]
    p = write_messages_mcap(tmp_path / "rec.mcap", scan_messages("/scan") + odom_messages(), declared=empty)
    log = open_log(p)
    scans, odoms = split(log.messages())
    assert len(scans) == 5 and log.scan_topic == "/scan"
    assert "/scan_rear has no messages: LaserScan topic /scan taken" in log.info().notes
    # two with messages: the user chooses, and the empty one is named apart
    p = write_messages_mcap(
        tmp_path / "two.mcap",
        scan_messages("/scan") + scan_messages("/scan2") + odom_messages(),
        declared=empty,
    )
    with pytest.raises(
        LogError, match=r"2 LaserScan topics: /scan, /scan2 \(and /scan_rear with no messages\)"
    ):
        open_log(p).messages()


def test_a_bags_metadata_file_is_told_to_give_its_directory(tmp_path):
    """A ROS 2 bag's metadata.yaml given as the log: "unsupported log" said nothing of the directory."""
    bag = write_log("rosbag2-sqlite3", tmp_path)
    with pytest.raises(LogError, match="is the metadata of a ROS 2 bag") as err:
        detect_format(bag / "metadata.yaml")
    assert err.value.hint == f"give the bag's directory, '{bag}'"
    assert detect_format(bag) == "rosbag2"


def test_no_odometry_hint_names_option(tmp_path):
    p = write_mcap(tmp_path / "scans.mcap", make_scans(), [])
    with pytest.raises(LogError, match="no odometry") as err:
        open_log(p).messages()
    assert "--odom-topic" in err.value.hint


def test_requested_topics_missing_or_wrong_type(tmp_path):
    p = write_log("mcap-cdr", tmp_path)
    with pytest.raises(LogError, match=r"no topic '/laser' \(LaserScan topics: /scan\)"):
        open_log(p, scan_topic="/laser").messages()
    with pytest.raises(LogError, match=r"no topic '/wheel_odom' \(Odometry topics: /odom"):
        open_log(p, odom_topic="/wheel_odom").messages()
    with pytest.raises(LogError, match="is nav_msgs/Odometry, not sensor_msgs/LaserScan"):
        open_log(p, scan_topic="/odom").messages()
    with pytest.raises(LogError, match="not nav_msgs/Odometry or tf2_msgs/TFMessage"):
        open_log(p, odom_topic="/scan").messages()


def test_several_odometry_topics(tmp_path):
    both = scan_messages() + odom_messages("/odom") + odom_messages("/odometry/filtered")
    assert open_log(write_messages_mcap(tmp_path / "a.mcap", both)).odom_topic == "/odom"
    neither = scan_messages() + odom_messages("/wheel") + odom_messages("/ekf")
    with pytest.raises(LogError, match="2 Odometry topics: /ekf, /wheel") as err:
        open_log(write_messages_mcap(tmp_path / "b.mcap", neither)).messages()
    assert "--odom-topic" in err.value.hint
    assert open_log(tmp_path / "b.mcap", odom_topic="/ekf").odom_topic == "/ekf"


def test_info_on_several_odometry_topics_says_which_and_why(tmp_path):
    """``info`` with two Odometry topics, none /odom: the odometry line says so and names --odom-topic
    (a probe: it said "none found" above an error naming both); with /odom among them: /odom is taken,
    a note and an info-level log line (-v) naming the others and --odom-topic (a probe: nothing said so)."""
    neither = scan_messages() + odom_messages("/wheel") + odom_messages("/ekf")
    res = CliRunner().invoke(cli, ["info", str(write_messages_mcap(tmp_path / "b.mcap", neither))])
    assert res.exit_code == 2 and "error: log 'b.mcap' has 2 Odometry topics: /ekf, /wheel" in res.output
    lines = res.output.splitlines()
    assert "  odometry  - (2 nav_msgs/Odometry topics: choose one with --odom-topic)" in lines
    both = scan_messages() + odom_messages("/odom") + odom_messages("/odometry/filtered")
    res = CliRunner().invoke(cli, ["info", "-v", str(write_messages_mcap(tmp_path / "a.mcap", both))])
    assert res.exit_code == 0, res.output
    note = "2 Odometry topics: /odom taken, not /odometry/filtered (choose one with --odom-topic)"
    assert f"note:      {note}" in res.stdout.splitlines()
    assert f"log 'a.mcap': {note}" in res.stderr


def _scan(ranges, **kw):
    args = dict(stamp=100.0, angle_min=-1.0, angle_increment=0.01, range_min=0.1, range_max=10.0)
    args.update(kw)
    return RawScan(ranges=np.asarray(ranges, dtype=float), **args)


def test_invalid_beams_dropped_and_counted(tmp_path):
    r = [1.0, np.nan, np.inf, -np.inf, 0.05, 10.0, 11.0, 0.0, 2.0]
    p = write_mcap(tmp_path / "b.mcap", [_scan(r)], make_odoms(1, t0=99.0))
    log = open_log(p)
    (scan,), _ = split(log.messages())
    np.testing.assert_array_equal(scan.beam_index, [0, 8])
    np.testing.assert_allclose(scan.ranges, [1.0, 2.0])
    np.testing.assert_allclose(scan.angles, [-1.0, -0.92])
    assert scan.n_beams == 9 and scan.n_invalid == 7
    assert log.stats.beams == 9 and log.stats.beams_dropped == 7


def test_size_mismatch_and_bad_increment(tmp_path, caplog):
    ros = RosSerializer("cdr")
    good = _scan(np.ones(10))
    T = ros._T
    msgs = []
    for i, (a_max, inc) in enumerate([(5.0, 0.01), (-1.0 + 9 * 0.01, 0.0), (0.0, math.nan), (-1.09, -0.01)]):
        m = T["sensor_msgs/msg/LaserScan"](
            header=ros.header(100.0 + i, "laser"), angle_min=-1.0, angle_max=a_max, angle_increment=inc,
            time_increment=0.0, scan_time=0.0, range_min=0.1, range_max=10.0,
            ranges=np.ones(10, dtype=np.float32), intensities=np.zeros(0, dtype=np.float32),
        )  # fmt: skip
        msgs.append(
            (
                "/scan",
                "sensor_msgs/msg/LaserScan",
                int((100 + i) * 1e9),
                ros.serialize(m, "sensor_msgs/msg/LaserScan"),
            )
        )
    msgs += [("/scan", "sensor_msgs/msg/LaserScan", int(104e9), ros.laserscan(good))]
    msgs += odom_messages()
    log = open_log(write_messages_mcap(tmp_path / "m.mcap", msgs))
    with caplog.at_level(logging.WARNING, logger="cornerslam.logs"):
        scans, _ = split(log.messages())
    assert len(scans) == 3  # the mismatched one (10 beams from angle_min), the clockwise one, the good one
    np.testing.assert_allclose(scans[0].angles, -1.0 + 0.01 * np.arange(10), atol=1e-6)
    # beams clockwise (a negative increment): read in increasing bearing order, beam_index decreasing
    np.testing.assert_allclose(scans[1].angles, -1.0 - 0.01 * np.arange(10)[::-1], atol=1e-6)
    assert scans[1].beam_index.tolist() == list(range(9, -1, -1)) and scans[1].angle_increment > 0
    assert log.stats.size_mismatch == 1 and log.stats.scans_skipped == 2
    assert "imply" in caplog.text and "angle_increment" in caplog.text


def test_size_mismatch_of_clockwise_beams_counts_the_beams_the_angles_imply():
    """A clockwise scan (a negative angle_increment) whose angle_max disagrees with its ranges is
    warned with the number of beams its angles imply, as its counter-clockwise twin is, never a
    negative count ('imply -146'); an angle_max on the other side of angle_min from where the beams
    turn says so; a NaN angle_max is named, not counted as -1 beams; a denormal increment is warned
    about, not an OverflowError."""

    def warned(angle_min, angle_max, increment):
        stats = ReadStats()
        scan = make_scan(stats, "t", 1.0, angle_min, angle_max, increment, 0.1, 30.0, np.ones(10))
        assert scan is not None and scan.n_beams == 10
        assert stats.size_mismatch == len(stats.warnings)
        return [w.removeprefix("t: scan at 1.000 has 10 ranges but ") for w in stats.warnings]

    using = ": using 10 beams from angle_min"
    assert warned(0.5, 0.5 - 9 * 0.01, -0.01) == warned(0.41, 0.5, 0.01) == []  # 10 beams either way
    assert (
        warned(0.5, -0.96, -0.01)
        == warned(-0.96, 0.5, 0.01)
        == [  # 146 steps of 0.01 rad
            f"angle_min/max/increment imply 147{using}"
        ]
    )
    assert warned(-1.0, 0.47, -0.01) == [  # from -1 up to 0.47, but the beams turn clockwise
        "angle_min/max/increment imply 148 (angle_max is counter-clockwise of angle_min, angle_increment "
        f"clockwise){using}"
    ]
    assert warned(0.5, -0.5, 0.01) == [
        "angle_min/max/increment imply 101 (angle_max is clockwise of angle_min, angle_increment "
        f"counter-clockwise){using}"
    ]
    assert warned(0.5, 0.41, 0.01) == [  # the count agrees, the direction not: no "10 ranges but imply 10"
        f"angle_max is clockwise of angle_min, angle_increment counter-clockwise{using}"
    ]
    assert warned(-1.0, math.nan, -0.01) == [f"angle_max is nan{using}"]
    assert warned(0.0, 1.0, 1e-320) == [f"angle_min/max/increment imply inf{using}"]


def test_undecodable_message_skipped_and_counted(tmp_path, caplog):
    msgs = scan_messages(n=3) + [
        ("/scan", "sensor_msgs/msg/LaserScan", int(1.7e18) + 10**9, b"\x00\x01\x00\x00garbage")
    ]
    msgs += odom_messages(n=3) + [
        ("/odom", "nav_msgs/msg/Odometry", int(1.7e18) + 10**9, b"\x00\x01\x00\x00xx")
    ]
    log = open_log(write_messages_mcap(tmp_path / "g.mcap", sorted(msgs, key=lambda m: m[2])))
    with caplog.at_level(logging.WARNING, logger="cornerslam.logs"):
        scans, odoms = split(log.messages())
    assert len(scans) == 3 and len(odoms) == 3 and log.stats.decode_failed == 2
    assert "cannot decode" in caplog.text


def test_info_fields(tmp_path):
    p = write_log("mcap-cdr", tmp_path, tf_static=(0.1, 0.0, 0.0))
    info = open_log(p).info()
    assert info.format == "mcap" and info.path == str(p)
    topics = {t.name: t for t in info.topics}
    assert topics["/scan"].msgtype == "sensor_msgs/LaserScan" and topics["/scan"].count == 12
    assert topics["/scan"].rate_hz == pytest.approx(10.0)  # 12 scans 0.1 s apart: over their own span
    assert topics["/tf_static"].count == 1
    assert (info.scan_topic, info.odom_topic, info.odom_source) == ("/scan", "/odom", "nav_msgs/Odometry")
    assert info.n_messages == 25 and info.problems == ()


def test_a_text_file_that_is_a_symlink_loop_is_named_so(tmp_path):
    """A config, ground truth or trajectory path that is a symlink loop said "… does not exist" (the
    name is right there in ls); logs already said "a symlink loop"."""
    (tmp_path / "a").symlink_to(tmp_path / "b")
    (tmp_path / "b").symlink_to(tmp_path / "a")
    with pytest.raises(ConfigError, match="config file '.*a': a symlink loop"):
        read_text(tmp_path / "a", "config file", ConfigError, "a YAML file")
    res = CliRunner().invoke(cli, ["evaluate", str(tmp_path / "a"), "--ground-truth", str(tmp_path / "b")])
    assert res.exit_code == 2 and "a symlink loop" in res.output and "does not exist" not in res.output
    (tmp_path / "c").symlink_to(tmp_path / "missing")  # a dangling link still does not exist
    with pytest.raises(ConfigError, match="does not exist"):
        read_text(tmp_path / "c", "config file", ConfigError, "a YAML file")


def test_a_log_whose_scans_were_none_of_them_read_says_so_not_that_the_stamps_are_wrong():
    """A ROS 2 bag whose metadata.yaml names a scan topic its storage lacks, or a ROS 1 bag whose index
    points past its end, gave "0 scans read … check that the topics overlap in time" (a hostile-user
    probe): not one scan was read, so the reader's first warning is the line's reason, or with none that the
    reader found none of the messages its index lists (reindex it)."""
    from types import SimpleNamespace

    from cornerslam_cli.frontend import check_processed
    from cornerslam_cli.logs.sync import SyncStats

    def error(warnings: list[str]) -> str:
        rs = ReadStats(warnings=list(warnings))
        src = SimpleNamespace(
            path=Path("x.bag"), stats=SyncStats(), reader=SimpleNamespace(stats=rs, format="rosbag1")
        )
        with pytest.raises(LogError) as e:
            check_processed(src, 0, 0)
        return str(e.value)

    damaged = error(["x.bag: read stopped, the bag is damaged: Header could not be read"])
    assert damaged.startswith("log 'x.bag' has no scan that could be read, so no scan could be processed")
    assert "its first warning: x.bag: read stopped, the bag is damaged" in damaged
    none = error([])
    assert "found none of the scan messages its index lists: reindex it" in none
    assert "overlap in time" not in none


@pytest.mark.parametrize("encoding", ["ros1", "cdr"])
def test_a_modified_copy_of_a_standard_message_is_named_as_one(encoding):
    """The definitions the writers record (rosbags' standard ones) say nothing; a vendor's LaserScan with a
    field added, one left out or ranges as float64, and an Odometry without twist, are named."""
    from cornerslam_cli.logs.base import Channel
    from cornerslam_cli.logs.cdr import definition_note

    fmt = "ros1msg" if encoding == "ros1" else "ros2msg"
    ros = RosSerializer(encoding)
    scan_def, odom_def = (ros.msgdef(f"{t}") for t in ("sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry"))

    def note(msgdef, msgtype="sensor_msgs/LaserScan", fmt=fmt):
        return definition_note(Channel("/scan", msgtype, encoding, None, msgdef, fmt))

    assert note(scan_def) == "" and note(odom_def, "nav_msgs/Odometry") == ""
    assert note("") == "" and note("garbage {", fmt="ros2idl") == ""  # nothing recorded, or IDL: no verdict
    added = scan_def.replace("float32 range_max", "float32 range_max\nuint8 quality  # 0-255")
    assert "is not the standard message: fields added: 'quality'" in note(added)
    assert "missing: 'intensities'" in note(scan_def.replace("float32[] intensities", "# gone"))
    assert "'ranges' is float64[]" in note(scan_def.replace("float32[] ranges", "float64[] ranges"))
    assert "missing: 'twist'" in note(
        odom_def.replace("TwistWithCovariance twist", "# none"), "nav_msgs/Odometry"
    )
    for const in ("uint8 FRONT=1", "uint8 FRONT =1", "uint8 FRONT = 1"):
        assert note(scan_def.replace("float32 angle_min", f"{const}\nfloat32 angle_min")) == ""  # no field
    assert note(scan_def.replace("float32[] ranges", "float32[<=2048] ranges")) == ""  # a bounded sequence


def test_a_bag_of_a_modified_laserscan_says_so(tmp_path):
    """A ROS 1 bag whose LaserScan connection records a vendor's copy with a field added (its md5 not the
    standard's): every scan fails to decode; the error said "ranges overrun the message", now also why."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ros = RosSerializer("ros1")
    scan_def = ros.msgdef("sensor_msgs/msg/LaserScan")
    custom = scan_def.replace("float32 range_max", "float32 range_max\nuint8 quality")
    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg(custom, "sensor_msgs/msg/LaserScan"))
    scans, odoms = make_scans(6), make_odoms(7)
    path = tmp_path / "2021-06-14-10-22-33_warehouse_run3.bag"  # (a long name and topic: the note kept whole)
    with Writer(path) as w:
        conn = w.add_connection(
            "/sensors/lidar/front/scan", "sensor_msgs/msg/LaserScan", msgdef=custom, md5sum="0" * 32
        )
        odom = w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=ros.store)
        for s in scans:
            t = store.types
            sec, nsec = int(s.stamp), int(round((s.stamp % 1) * 1e9))
            header = t["std_msgs/msg/Header"](
                seq=0, stamp=t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id="laser"
            )
            msg = t["sensor_msgs/msg/LaserScan"](
                header=header, angle_min=s.angle_min, angle_max=s.angle_max,
                angle_increment=s.angle_increment, time_increment=0.0, scan_time=0.1, range_min=0.1,
                range_max=30.0, quality=1,
                ranges=np.asarray(s.ranges, dtype=np.float32), intensities=np.zeros(0, np.float32),
            )  # fmt: skip
            w.write(conn, int(s.stamp * 1e9), store.serialize_ros1(msg, "sensor_msgs/msg/LaserScan"))
        for o in odoms:
            w.write(odom, int(o.stamp * 1e9), ros.odometry(o, "odom", "base_link"))
    res = CliRunner().invoke(cli, ["run", str(path), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2
    said = "(its recorded sensor_msgs/LaserScan is not the standard message: fields added: 'quality')"
    assert said in res.stderr.splitlines()[-1]


def scans_changed(**fields) -> list:
    """make_scans(12)'s LaserScan messages on /scan, each with ``fields`` changed, logged at its stamp."""
    from dataclasses import replace

    ros = RosSerializer("cdr")
    return [
        ("/scan", "sensor_msgs/msg/LaserScan", int(s.stamp * 1e9), ros.laserscan(replace(s, **fields)))
        for s in make_scans(12)
    ]


def test_scans_whose_driver_leaves_every_header_stamp_at_0_are_named_so(tmp_path):
    """Every LaserScan stamped 0 (a driver that does not fill the header), the odometry fine: info said
    the headers were 1.7e9 s "behind" the record times and a run blamed two clocks and use_sim_time (a
    ROS-user probe). Both now say the scans' stamps are all the same, and whose they are to fill."""
    p = write_messages_mcap(tmp_path / "zero.mcap", scans_changed(stamp=0.0) + odom_messages(n=12))
    res = CliRunner().invoke(cli, ["info", str(p)])
    assert "the header stamp of its first 12 scans is 0.000 s, every one: the laser driver" in res.stdout
    assert "behind its record times" not in res.stdout
    res = CliRunner().invoke(cli, ["run", str(p), "--out", str(tmp_path / "out"), "-q"])
    assert res.exit_code == 2 and not (tmp_path / "out" / "summary.json").exists()
    assert "no scan could be processed: every one of its 12 scans is stamped 0.000 s" in res.stderr
    assert "make the laser driver fill each scan's header stamp" in res.stderr
    assert "use_sim_time" not in res.stderr


def test_a_range_max_at_or_below_range_min_is_named(tmp_path):
    """LaserScan range_max 0 (a driver's parameter left unset): every beam is invalid, and the error said
    "check … input.max_range", a key that can only lower range_max (a ROS-user probe). It now names
    the two limits and whose they are; info marks them."""
    p = write_messages_mcap(tmp_path / "r0.mcap", scans_changed(range_max=0.0) + odom_messages(n=12))
    res = CliRunner().invoke(cli, ["info", str(p)])
    assert "range_max at or below range_min: every reading counts as no return" in res.stdout
    res = CliRunner().invoke(cli, ["run", str(p), "--out", str(tmp_path / "out"), "-q"])
    assert res.exit_code == 2 and "\n" not in res.stderr.strip()
    assert "its scans' range_max (0.000 m) is at or below their range_min" in res.stderr
    assert "set the laser driver's range_max" in res.stderr


def test_a_log_with_poses_but_no_odometry_names_the_pose_topics(tmp_path):
    """A log whose robot pose is a geometry_msgs/PoseStamped topic: "no nav_msgs/Odometry topic and no
    tf topic" said nothing of it (a ROS-user probe)."""
    ros = RosSerializer("cdr")
    T, kind = ros.store.types, "geometry_msgs/msg/PoseStamped"
    still = T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
        orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
    )
    poses = [
        (
            "/robot_pose",
            kind,
            int(t * 1e9),
            ros.serialize(T[kind](header=ros.header(t, "map"), pose=still), kind),
        )
        for t in 1_700_000_000.0 + 0.1 * np.arange(5)
    ]
    nav2 = [("/goal_pose", kind), ("/initialpose", "geometry_msgs/msg/PoseWithCovarianceStamped")]
    p = write_messages_mcap(tmp_path / "poses.mcap", scan_messages("/scan") + poses, declared=nav2)
    with pytest.raises(
        LogError, match=r"no tf topic \(/robot_pose: geometry_msgs poses, not read as odometry\)"
    ):
        open_log(p).messages()  # (nav2's goal and initial pose, in every `record -a`, not named)
    # with /tf_static beside them: "no tf topic" was said of it (a ROS-user probe)
    static = [("/tf_static", "tf2_msgs/msg/TFMessage", int(1_700_000_000.0 * 1e9),
               ros.tf(1_700_000_000.0, "base_link", "laser", 0.1, 0.0, 0.0))]  # fmt: skip
    p = write_messages_mcap(tmp_path / "static.mcap", scan_messages("/scan") + static)
    with pytest.raises(
        LogError, match=r"no nav_msgs/Odometry topic and only /tf_static, whose transforms are fixed"
    ):
        open_log(p).messages()


def test_a_laser_frame_named_unlike_the_tfs_is_hinted_at(tmp_path):
    """Scans in frame 'laser_link', the tf's mount to 'laser': the default-mount warning said nothing of
    the frame named alike (a ROS-user probe). It now names it."""
    ros = RosSerializer("cdr")
    t0 = 1_700_000_000.0  # (make_scans' first stamp less 0.05 s)
    mount = [
        (
            "/tf_static",
            "tf2_msgs/msg/TFMessage",
            int(t0 * 1e9),
            ros.tf(t0, "base_link", "laser", 0.1, 0.0, 0.0),
        )
    ]
    p = write_messages_mcap(
        tmp_path / "f.mcap", mount + scans_changed(frame_id="laser_link") + odom_messages(n=12)
    )
    res = CliRunner().invoke(cli, ["run", str(p), "--out", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    assert (
        "has no tf base_link→laser_link (its tf has 'laser': the scans' frame_id 'laser_link' misnamed?)"
        in res.stderr
    )


def test_a_laser_under_another_robot_frame_is_hinted_at(tmp_path):
    """A laser mounted on 'base_footprint' (nav2's robot frame) in a log with no base_link, run on its scans
    alone (no odometry names the robot's frame): the default-mount warning and info name input.base_frame,
    and with it the tf's mount is taken."""
    ros = RosSerializer("cdr")
    t0 = 1_700_000_000.0
    mount = [("/tf_static", "tf2_msgs/msg/TFMessage", int(t0 * 1e9),
              ros.tf(t0, "base_footprint", "laser", 0.1, 0.0, 0.3))]  # fmt: skip
    p = write_messages_mcap(tmp_path / "f.mcap", mount + scans_changed(frame_id="laser"))
    alone = ["--set", "input.odometry=scans"]
    hint = "its tf places 'laser' under 'base_footprint': if that is the robot's frame, --set "
    hint += "input.base_frame="
    res = CliRunner().invoke(cli, ["run", str(p), "--out", str(tmp_path / "a"), *alone])
    assert res.exit_code == 0, res.output
    assert f"has no tf base_link→laser ({hint}" in res.stderr
    info = CliRunner().invoke(cli, ["info", str(p), *alone])
    assert info.exit_code == 0, info.output
    assert f"note:      {hint}base_footprint" in info.stdout
    told = ["--set", "input.base_frame=base_footprint"]
    res = CliRunner().invoke(cli, ["run", str(p), "--out", str(tmp_path / "b"), *alone, *told])
    assert res.exit_code == 0 and "has no tf" not in res.stderr
    mount = json.loads((tmp_path / "b" / "summary.json").read_text())["input"]["laser_to_base"]
    assert mount == pytest.approx([0.1, 0.0, 0.3])


def test_tf_root_climbs_to_the_top_and_stops_on_a_loop():
    from cornerslam_cli.logs.ros import tf_root

    e = np.eye(4)
    edges = {("base_footprint", "base_link"): e, ("base_link", "laser_mount"): e, ("laser_mount", "laser"): e}
    static = dict.fromkeys(edges, "/tf_static")
    assert tf_root(edges, "laser", static) == tf_root(edges, "base_footprint", static) == "base_footprint"
    loop = {("a", "b"): e, ("b", "a"): e}
    assert tf_root(loop, "a", dict.fromkeys(loop, "/tf_static")) in (
        "a",
        "b",
    )  # (tf2 refuses a loop: no hang)
    # a review: the robot's pose in its odometry frame (dynamic), or a mount on a world frame, is no robot
    moving = {**edges, ("odom_combined", "base_footprint"): e}
    assert (
        tf_root(moving, "laser", {**static, ("odom_combined", "base_footprint"): "/tf"}) == "base_footprint"
    )
    assert tf_root({("map", "laser"): e}, "laser", {("map", "laser"): "/tf_static"}) == "laser"
    assert tf_root({("robot1/map", "laser"): e}, "laser", {("robot1/map", "laser"): "/tf_static"}) == "laser"
    assert tf_root(edges, "laser", dict.fromkeys(edges, "/robot1/tf")) == "laser"


def test_alike_frames_take_a_prefix_too():
    """Scans in 'base_laser', the tf's 'laser': no hint was given (a ROS-user probe); a prefix is alike."""
    from cornerslam_cli.logs.ros import _alike_frames

    assert _alike_frames("base_laser", "laser") and _alike_frames("laser", "laser_link")
    assert _alike_frames("/robot1/front_laser", "laser")
    assert not _alike_frames("laser", "laser") and not _alike_frames("laserscan", "laser")
