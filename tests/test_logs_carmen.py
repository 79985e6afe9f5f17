"""CARMEN specifics: line formats, comments/PARAMs, malformed lines, angle convention."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
from _log_fixtures import split
from click.testing import CliRunner

from cornerslam_cli.cli import cli
from cornerslam_cli.errors import LogError
from cornerslam_cli.logs import open_log
from cornerslam_cli.logs.carmen import flaser_increment


def flaser(n, t, r=2.0, pose=(0, 0, 0)):
    p = " ".join(map(str, pose))
    return f"FLASER {n} {' '.join([str(r)] * n)} {p} {p} {t} host {t}\n"


def test_flaser_increments_follow_carmen():
    assert flaser_increment(180) == flaser_increment(181) == pytest.approx(math.radians(1))
    assert flaser_increment(361) == pytest.approx(math.radians(0.5))
    assert flaser_increment(401) == pytest.approx(math.radians(0.25))
    assert flaser_increment(91) == pytest.approx(math.pi / 90)


def test_comments_params_malformed_and_max_range(tmp_path, caplog):
    text = (
        "# a comment\nPARAM robot_front_laser_max 50.0\n"
        + flaser(181, 1.0)
        + "FLASER 181 1 2 3\n"  # malformed: too short
        + "ODOM 1 2 0.5 0 0 0 1.5 host 1.5\n"
        + "ODOM x y z 0 0 0 1.6 host 1.6\n"  # malformed number
        + flaser(181, 2.0, r=50.0)  # all at max range: all no-return
        + "SONAR 1 2 3\n"  # unknown tag: ignored
    )
    p = tmp_path / "a.clf"
    p.write_text(text)
    with caplog.at_level(logging.WARNING, logger="cornerslam.logs"):
        log = open_log(p)
        scans, odoms = split(log.messages())
    assert len(scans) == 2 and len(odoms) == 1 and log.stats.decode_failed == 2
    assert "malformed" in caplog.text
    assert scans[0].n_beams == 181 and scans[0].angles[-1] == pytest.approx(math.pi / 2)
    assert scans[1].range_max == 50.0 and len(scans[1].ranges) == 0 and scans[1].n_invalid == 181
    assert (odoms[0].stamp, odoms[0].x, odoms[0].theta) == (1.5, 1.0, 0.5)
    assert {t.name: t.count for t in log.info().topics} == {"FLASER": 3, "ODOM": 2, "SONAR": 1}


def test_robotlaser1_fields_and_offset(tmp_path):
    n = 5
    ranges = " ".join(["1.0", "2.0", "9.9", "inf", "3.0"])
    line = (
        f"ROBOTLASER1 0 -0.5 1.0 0.25 9.9 0.01 0 {n} {ranges} 0 1.1 2.0 0.0 1.0 2.0 0.0 0 0 0 0 0 7.5 h 7.5\n"
    )
    p = tmp_path / "r.log"
    p.write_text(line)
    log = open_log(p)
    (scan,), (odom,) = split(log.messages())
    np.testing.assert_array_equal(scan.beam_index, [0, 1, 4])
    np.testing.assert_allclose(scan.angles, [-0.5, -0.25, 0.5])
    assert scan.range_max == 9.9 and scan.stamp == 7.5
    assert (odom.stamp, odom.x, odom.y) == (7.5, 1.0, 2.0)  # robot pose fields, no ODOM lines
    assert log.laser_to_base() == pytest.approx((0.1, 0.0, 0.0))


def test_rlaser_selected_explicitly_and_missing_tag(tmp_path):
    p = tmp_path / "x.log"
    p.write_text(flaser(180, 1.0) + flaser(180, 1.0).replace("FLASER", "RLASER"))
    assert open_log(p).scan_topic == "FLASER"
    assert open_log(p, scan_topic="RLASER").scan_topic == "RLASER"
    with pytest.raises(LogError, match="no 'ROBOTLASER1' lines"):
        open_log(p, scan_topic="ROBOTLASER1").messages()
    with pytest.raises(LogError, match="no 'ODOM' lines"):
        open_log(p, odom_topic="ODOM").messages()
    # a tag the log has, but not a laser's: not "has no 'ODOM' lines" (a hostile-user probe)
    q = tmp_path / "o.log"
    q.write_text(p.read_text() + "ODOM 1 2 0.1 0 0 0 7.5 host 7.5\n")
    with pytest.raises(LogError, match=r"o.log': its 'ODOM' lines are not laser lines \(laser lines: FLASER"):
        open_log(q, scan_topic="ODOM").messages()


def test_odom_only_log_has_no_laser(tmp_path):
    p = tmp_path / "o.log"
    p.write_text("ODOM 1 2 0.5 0 0 0 1.5 host 1.5\n")
    with pytest.raises(LogError, match="no laser lines"):
        open_log(p).messages()


def test_cut_gzip_yields_prefix_with_warning(tmp_path, caplog):
    import gzip

    rng = np.random.default_rng(0)
    text = "".join(flaser(180, float(i), r=round(rng.uniform(1, 5), 3)) for i in range(200))
    data = gzip.compress(text.encode())
    p = tmp_path / "x.log.gz"
    p.write_bytes(data[: len(data) // 2])
    with caplog.at_level(logging.WARNING, logger="cornerslam.logs"):
        scans, _ = split(open_log(p).messages())
    assert 0 < len(scans) < 200 and [s.stamp for s in scans] == list(range(len(scans)))
    assert "ends early" in caplog.text


@pytest.mark.parametrize(
    ("head", "said"),
    [(b"", "damaged before its first line"), (b"PARAM a 1\n" * 20, "damaged after 20 lines")],
)
def test_gzip_damaged_before_any_laser_line_says_so(tmp_path, head, said):
    """gzip data damaged at its start was an internal error (zlib.error escaped the compressed-log check)
    and, damaged after a few PARAM lines, "not a CARMEN log": now the error says the gzip is damaged."""
    import gzip

    rng = np.random.default_rng(0)
    text = head + "".join(flaser(180, float(i), r=round(rng.uniform(1, 5), 3)) for i in range(200)).encode()
    body = bytearray(gzip.compress(text[len(head) :], mtime=0))  # a second gzip member after the head's
    body[20:60] = bytes(b ^ 0xFF for b in body[20:60])  # its deflate data damaged
    p = tmp_path / "x.log.gz"
    p.write_bytes((gzip.compress(head, mtime=0) if head else b"") + bytes(body))
    with pytest.raises(LogError, match=f"its gzip data is {said}, before any laser") as err:
        open_log(p).messages()
    assert "gzip -t" in err.value.hint


@pytest.mark.parametrize("bom", ["", "\ufeff"])
def test_a_line_after_nul_padding_is_read_with_a_warning(tmp_path, caplog, bom):
    """NUL bytes before a line (a crash's padding) made its tag '\\x00…FLASER', the line lost in silence;
    padding is block-aligned, so it usually starts mid-line: the line after it was glued to the cut one
    before and lost with it (a review's case). A run of NULs now ends a line; a BOM before them goes too."""
    lines = [flaser(180, float(i), r=2.0 + 0.01 * i) for i in range(6)]
    clean, padded, glued = tmp_path / "a.log", tmp_path / "b.log", tmp_path / "c.log"
    clean.write_text("".join(lines))
    padded.write_text(
        bom + "\x00" * 300 + "".join(lines).replace("\nFLASER", "\n" + "\x00" * 300 + "FLASER", 1)
    )
    glued.write_text("".join(lines[:2]) + lines[2][:40] + "\x00" * 500 + "".join(lines[3:]))  # line 2 cut
    with caplog.at_level(logging.WARNING, logger="cornerslam.logs"):
        got, _ = split(open_log(padded).messages())
        cut, _ = split(open_log(glued).messages())
    want, _ = split(open_log(clean).messages())
    assert [s.stamp for s in got] == [s.stamp for s in want] == [0, 1, 2, 3, 4, 5]
    assert all(np.array_equal(a.ranges, b.ranges) for a, b in zip(got, want, strict=True))
    assert [s.stamp for s in cut] == [0, 1, 3, 4, 5]  # (the cut line 2 is malformed, skipped and said)
    assert (
        "NUL bytes in 2 lines (a crash's padding?): dropped, a run of them before a tag read as a line break"
        in caplog.text
    )
    assert "malformed FLASER line skipped" in caplog.text
    inside = tmp_path / "d.log"  # a NUL inside a field (the hostname): dropped, the line read
    inside.write_text("".join(lines).replace(" host ", " ho\x00st ", 3))
    assert inside.read_text().count("\x00") == 3
    assert [s.stamp for s in split(open_log(inside).messages())[0]] == [0, 1, 2, 3, 4, 5]
    assert {t.name for t in open_log(inside).info().topics} == {"FLASER"}  # no phantom tag


@pytest.mark.parametrize("gz", [False, True])
def test_tab_separated_lines_read_as_space_separated(tmp_path, gz):
    """Fields separated by tabs (or mixed whitespace) are fields: the same messages as with spaces."""
    from _log_fixtures import make_odoms, make_scans

    from cornerslam_cli.logs.writers import write_carmen

    suffix = ".clf.gz" if gz else ".clf"
    spaces = write_carmen(tmp_path / f"s{suffix}", make_scans(), make_odoms(), gzip=gz)
    tabs = write_carmen(tmp_path / f"t{suffix}", make_scans(), make_odoms(), gzip=gz, sep="\t")
    with open_log(spaces) as a, open_log(tabs) as b:
        want, got = list(a.messages()), list(b.messages())
        assert b.info().topics == a.info().topics and b.stats.warnings == []
    assert [m.stamp for m in got] == [m.stamp for m in want] and len(got) == 24
    for m, n in zip(got, want, strict=True):
        assert type(m) is type(n)
        if hasattr(m, "ranges"):
            np.testing.assert_array_equal(m.ranges, n.ranges)


@pytest.mark.parametrize("name", ["b.clf", "b.clf.gz", "b"])
def test_a_utf8_byte_order_mark_is_not_part_of_the_first_tag(tmp_path, name):
    """A log saved as 'UTF-8 with BOM' reads as without it, gzipped or with no extension too (its first
    line was lost without a word: the tag 'ï»¿ROBOTLASER1' a topic of its own, and no format detected)."""
    import gzip

    from _log_fixtures import make_odoms, make_scans

    from cornerslam_cli.logs.writers import write_carmen

    plain = write_carmen(tmp_path / "p.clf", make_scans(), make_odoms(), odom_lines=False)
    text = "".join(line for line in plain.read_text().splitlines(True) if not line.startswith("#"))
    assert text.startswith("ROBOTLASER1 ")  # the mark sits on a line with data (the first scan)
    plain.write_text(text)
    data = "\ufeff".encode() + text.encode()
    (tmp_path / name).write_bytes(gzip.compress(data) if name.endswith(".gz") else data)
    with open_log(plain) as a, open_log(tmp_path / name) as b:
        want, got = list(a.messages()), list(b.messages())
        assert b.info().topics == a.info().topics and b.stats.warnings == []
    assert [(type(m), m.stamp) for m in got] == [(type(m), m.stamp) for m in want] and len(got) == 24


def _odom_line(t, x):
    return f"ODOM {x} 0 0 0 0 0 {t} host {t}\n"


def _flaser_odom(t, laser_x, odom_x):
    """A FLASER line whose laser pose and odometry pose fields differ (the reader must take the latter)."""
    return f"FLASER 3 1 1 1 {laser_x} 0 0 {odom_x} 0 0 {t} host {t}\n"


@pytest.mark.parametrize(
    ("odom_times", "want"),
    [
        (range(0, 31), "ODOM"),  # the scans' 30 s covered
        (range(0, 10), "FLASER"),  # ODOM lines stop at 9 s (cut, or unreadable from there): 2/3 left out
        (range(20, 31), "ODOM"),  # ... not ODOM lines starting late: the laser lines' odometry fields may
        # hold placeholders until the odometry starts (0 0 0: taken as poses, a jump of metres; a review)
        (range(0, 30), "ODOM"),  # the last second left out: under a tenth (the last scan is dropped)
    ],
)
def test_odometry_from_laser_poses_when_odom_lines_stop_early(tmp_path, odom_times, want):
    """ODOM lines that stop early (a probe: intel_cut with the ODOM lines after line 200 deleted, or
    written with decimal commas past a point) made a run drop two thirds of the scans, exit 0, while the
    FLASER lines carried odometry for all of them."""
    lines = [_odom_line(float(t), 10.0 * t) for t in odom_times]
    lines += [_flaser_odom(t + 0.5, laser_x=t, odom_x=t) for t in range(30)]
    p = tmp_path / "o.log"
    p.write_text("".join(sorted(lines, key=lambda line: float(line.split()[-1]))))
    info = open_log(p).info()
    assert info.odom_topic == want
    if want == "FLASER":  # (ODOM to 9 s: the FLASER lines from 10.5 s on, 20 of 30)
        assert info.odom_source.endswith(
            "; the whole ODOM lines end at 9.000 s, before 20 of the 30 FLASER lines"
        )
    assert open_log(p, odom_topic="ODOM").info().odom_topic == "ODOM"  # the user's choice is kept


def _robotlaser(t, laser_x, robot_x):
    poses = f"{laser_x} 0 0 {robot_x} 0 0"
    return f"ROBOTLASER1 0 -0.5 1.0 0.25 9.9 0.01 0 3 1 1 1 0 {poses} 0 0 0 0 0 {t} h {t}\n"


@pytest.mark.parametrize(
    ("odom_times", "laser_times", "odom_moves", "want"),
    [
        ((1.0, 2.0, 3.0), (1.0, 2.0, 3.0), True, "ODOM"),  # a clean ODOM series: kept
        ((1.0, 3.0, 2.0), (1.0, 2.0, 3.0), True, "FLASER"),  # out of order: the scans' own poses
        ((1.0, 3.0, 2.0), (1.0, 2.0, 3.0), False, "ODOM"),  # ... unless those never move
        ((1.0, 3.0, 2.0), (1.0, 3.0, 2.0), True, "ODOM"),  # ... or the scans go back as often
    ],
)
def test_odometry_from_laser_poses_when_odom_lines_go_back_in_time(
    tmp_path, odom_times, laser_times, odom_moves, want
):
    # the laser pose fields move in every case, the odometry fields only when odom_moves: the reader
    # must look at the odometry fields (odom_x …), not the laser's
    lines = [_odom_line(t, 10 * t) for t in odom_times]
    lines += [_flaser_odom(t + 0.5, laser_x=t, odom_x=t if odom_moves else 0) for t in laser_times]
    p = tmp_path / "o.log"
    p.write_text("".join(lines))
    log = open_log(p)
    info = log.info()
    assert info.odom_topic == want
    assert ("go back in time: 1 of 3" in info.odom_source) == (want == "FLASER")
    _, odoms = split(log.messages())
    want_x = [float(t) for t in laser_times] if want == "FLASER" else [10 * t for t in odom_times]
    assert [o.x for o in odoms] == want_x
    assert open_log(p, odom_topic="ODOM").info().odom_topic == "ODOM"  # the user's choice is kept


@pytest.mark.parametrize("robot_moves", [True, False])
def test_robotlaser_robot_pose_decides_the_switch(tmp_path, robot_moves):
    # ROBOTLASER1: the robot pose fields (not the laser's) must move for the reader to prefer them
    lines = [_odom_line(t, 10 * t) for t in (1.0, 3.0, 2.0)]
    lines += [_robotlaser(t + 0.5, laser_x=t, robot_x=t if robot_moves else 0) for t in (1.0, 2.0, 3.0)]
    p = tmp_path / "r.log"
    p.write_text("".join(lines))
    assert open_log(p).info().odom_topic == ("ROBOTLASER1" if robot_moves else "ODOM")


def test_malformed_laser_lines_do_not_count_as_moving(tmp_path):
    # "-0.0" and "0" are the same pose; a truncated line is skipped, not taken for a moving robot
    lines = [_odom_line(t, 10 * t) for t in (1.0, 3.0, 2.0)]
    lines += [_flaser_odom(1.5, 1, "0"), _flaser_odom(2.5, 2, "-0.0"), "FLASER 3 1 1\n"]
    p = tmp_path / "m.log"
    p.write_text("".join(lines))
    assert open_log(p).info().odom_topic == "ODOM"


def test_a_damaged_line_of_a_preferred_tag_does_not_choose_it(tmp_path):
    """One damaged ROBOTLASER1 / ODOM line among whole FLASER lines: the tag was chosen for its name
    (ROBOTLASER1 before FLASER, ODOM lines before the lasers' odometry fields), and the log could not
    be run ("has no complete laser line", exit 2; a damaged ODOM line: "no scan could be processed")."""
    lines = [_flaser_odom(t, laser_x=t, odom_x=t) for t in (1.0, 2.0, 3.0)]
    p = tmp_path / "d.log"
    p.write_text("".join(lines[:2] + ["ROBOTLASER1 1 2\n", "ODOM 1 2\n"] + lines[2:]))
    log = open_log(p)
    info = log.info()
    assert (info.scan_topic, info.odom_topic) == ("FLASER", "FLASER")
    assert info.odom_source == "FLASER odometry fields; no ODOM line is whole: 1 skipped"
    scans, odoms = split(log.messages())
    assert len(scans) == len(odoms) == 3
    assert open_log(p, scan_topic="ROBOTLASER1").info().scan_topic == "ROBOTLASER1"  # asked for: kept


def test_odometry_from_another_laser_tag_yields_no_scans_of_it(tmp_path):
    # --odom-topic RLASER with --scan-topic FLASER: the RLASER lines give odometry only, not scans
    lines = [
        flaser(180, t, pose=(t, 0, 0)) + f"RLASER 3 5 5 5 0 0 0 {t} 0 0 {t + 0.01} h {t}\n" for t in (1, 2)
    ]
    p = tmp_path / "two.log"
    p.write_text("".join(lines))
    scans, odoms = split(open_log(p, scan_topic="FLASER", odom_topic="RLASER").messages())
    assert [(s.stamp, s.n_beams) for s in scans] == [(1.0, 180), (2.0, 180)]
    assert [(o.stamp, o.x) for o in odoms] == [(1.01, 1.0), (2.01, 2.0)]


@pytest.mark.parametrize(
    "cut",
    [
        "ODOM 6 0 0 0 0 0 1006.0 ho",  # its accel field (0) would be the stamp
        "FLASER 3 1 1 1 6 0 0 6 0 0",  # a reading or pose field would be the stamp
        _robotlaser(1006.5, 6, 6)[:-12],  # ... its turn_axis field (0)
        "FLASER -5 1 1 1 0",  # a negative reading count: as many fields as it implies, still not whole
    ],
)
def test_a_line_cut_by_the_recorder_gives_no_stamp_or_pose(tmp_path, cut):
    # the last line of a log whose recorder stopped mid-line: no stamp 0 for the time span, no ODOM line
    # going back in time that would switch the odometry to the laser lines' fields
    lines = [_odom_line(1000.0 + i, i) + _flaser_odom(1000.5 + i, i, i) for i in range(1, 6)]
    p = tmp_path / "cut.log"
    p.write_text("".join(lines) + cut)
    info = open_log(p).info()
    assert (info.start, info.end) == (1001.0, 1005.5)
    assert (info.odom_topic, info.odom_source) == ("ODOM", "ODOM lines")


_PYTHON_WORDS = ("index", "unpack", "convert", "literal", "expected")  # IndexError, ValueError texts


@pytest.mark.parametrize(
    ("line", "why"),
    [
        ("FLASER", "a FLASER line needs at least 10 fields after its tag, has 0"),
        ("FLASER 3 1 2", "a FLASER line of 3 readings needs 13 fields after its tag, has 3"),
        (
            "FLASER 1 1 0 0 0 0 0 0 0 5 h 5 6",
            "a FLASER line of 1 reading needs 11 fields after its tag, has 13",
        ),
        ("FLASER x 1 2", "its reading count 'x' is not a whole number >= 0"),
        ("FLASER -2 1", "its reading count '-2' is not a whole number >= 0"),
        ("FLASER 2 1 y 0 0 0 0 0 0 5 h 5", "its reading 2 'y' is not a number"),
        ("FLASER 1 1 0 0 0 z 0 0 5 h 5", "its odom_x 'z' is not a number"),
        ("FLASER 1 1 0 0 0 0 0 0 t h 5", "its timestamp 't' is not a number"),
        ("ROBOTLASER1 1 2", "a ROBOTLASER1 line needs at least 23 fields after its tag, has 2"),
        (
            "ROBOTLASER1 0 a b c d e f 2 1 1",
            "a ROBOTLASER1 line of 2 readings needs at least 25 fields after",
        ),
        (
            _robotlaser(5, 0, 0).replace(" 3 1 1 1 0 ", " 3 1 1 1 2 "),
            "a ROBOTLASER1 line of 3 readings and 2 remissions needs 28 fields after its tag, has 26",
        ),
        (_robotlaser(5, 0, 0).replace("-0.5", "a"), "its start_angle 'a' is not a number"),
        (_robotlaser(5, 0, "r"), "its robot_x 'r' is not a number"),
    ],
)
def test_a_malformed_laser_line_is_named_in_the_words_of_its_format(tmp_path, caplog, line, why):
    """The warning and the error said what Python's parsing raised ("list index out of range", "not
    enough values to unpack (expected 4, got 1)"): they say what the line lacks, counting the fields
    after its tag, or which field is not a number."""
    p = tmp_path / "bad.clf"
    p.write_text(f"{line.strip()}\n")
    with caplog.at_level(logging.WARNING, logger="cornerslam.logs"), pytest.raises(LogError) as e:
        split(open_log(p).messages())
    assert f"(line 1: {why}" in str(e.value)
    assert f"bad.clf:1: malformed {line.split()[0]} line skipped ({why}" in caplog.text
    assert not any(w in str(e.value) + caplog.text for w in _PYTHON_WORDS), caplog.text


@pytest.mark.parametrize(
    ("line", "why"),
    [
        ("ODOM", "an ODOM line needs 9 fields after its tag, has 0"),
        ("ODOM 1 2 3 4 5 6 7 h 8 9", "an ODOM line needs 9 fields after its tag, has 10"),
        ("ODOM x 0 0 0 0 0 7 h 7", "its x 'x' is not a number"),
        ("ODOM 0 0 0 0 0 0 t h 7", "its timestamp 't' is not a number"),
    ],
)
def test_a_malformed_odom_line_is_named_in_the_words_of_its_format(tmp_path, caplog, line, why):
    p = tmp_path / "bad.clf"
    p.write_text(flaser(3, 1.0) + _odom_line(0.5, 0) + f"{line}\n" + _odom_line(1.5, 0))
    with caplog.at_level(logging.WARNING, logger="cornerslam.logs"):
        split(open_log(p, odom_topic="ODOM").messages())
    assert f"bad.clf:3: malformed ODOM line skipped ({why})" in caplog.text
    assert not any(w in caplog.text for w in _PYTHON_WORDS), caplog.text


@pytest.mark.parametrize("command", ["run", "info"])
def test_the_probes_damaged_lines_are_refused_in_the_words_of_the_format(tmp_path, command):
    """`printf 'FLASER\\nODOM\\n' > t.clf; cornerslam run t.clf` ended its one line with "(line 1: list
    index out of range)"; info's error is run's."""
    from click.testing import CliRunner
    from fault_corpus import check_error_line

    from cornerslam_cli.cli import cli

    p = tmp_path / "t.clf"
    p.write_text("FLASER\nODOM\n")
    args = [command, str(p), "-q"] + (["--out", str(tmp_path / "out")] if command == "run" else [])
    res = CliRunner().invoke(cli, args, catch_exceptions=False)
    check_error_line(res, ("its only FLASER line cannot be read (line 1: a FLASER line needs at least 10",))
    assert "index" not in res.stderr


def _read(p, **kw):
    log = open_log(p, **kw)
    scans, odoms = split(log.messages())
    poses = [(o.stamp, o.x, o.y, o.theta) for o in odoms]
    return log, [(s.stamp, tuple(s.angles), tuple(s.ranges)) for s in scans], poses


@pytest.mark.parametrize("tail", [0, 1])
def test_lines_ending_at_their_timestamp_or_hostname_read_as_the_standard_ones(tmp_path, tail):
    """Logs written by older CARMEN versions or by converters end each line with its timestamp (and
    hostname), without the logger timestamp: each tag's layout is the one most of its lines have, so
    they give the scans and odometry of the same log with whole lines (they were refused, and ODOM lines
    so written silently left the run on the laser lines' pose fields); a line with more fields than
    the standard's stays malformed (a reading count short of its readings, likelier than extra fields)."""

    def cut(line):
        tok = line.split()
        return " ".join(tok[: len(tok) - 2 + tail]) + "\n"

    lines = []
    for i in range(1, 6):
        t = 1000.0 + i
        lines += [
            _odom_line(t, 0.1 * i),
            _flaser_odom(t + 0.5, 9, 0.1 * i),
            # (2 remissions; the poses' y apart from their x: each field read where it belongs)
            f"ROBOTLASER1 0 -0.5 1.0 0.25 9.9 0.01 0 3 1 1 1 2 7 7 {0.1 * i + 0.2} 0.5 0 {0.1 * i} 0.5 0 "
            f"0 0 0 0 0 {t + 0.7} h {t + 0.7}\n",
        ]
    whole, short = tmp_path / "whole.log", tmp_path / "short.log"
    whole.write_text("".join(lines))
    short.write_text("".join(map(cut, lines)))
    for topic in ("FLASER", "ROBOTLASER1"):
        for odom in ("", topic):  # ODOM lines, and the laser lines' own robot pose fields
            log, scans, odoms = _read(short, scan_topic=topic, odom_topic=odom)
            assert (scans, odoms) == _read(whole, scan_topic=topic, odom_topic=odom)[1:]
            assert len(scans) == len(odoms) == 5 and log.stats.decode_failed == 0
            assert log.info().odom_source == ("ODOM lines" if not odom else f"{topic} odometry fields")
            y = 0.5 if odom == "ROBOTLASER1" else 0.0
            want = [(0.1 * i, y, 0.0) for i in range(1, 6)]
            np.testing.assert_allclose([o[1:] for o in odoms], want, atol=1e-12)
    assert open_log(short, scan_topic="ROBOTLASER1").laser_to_base() == pytest.approx((0.2, 0.0, 0.0))
    # as many lines of each layout: the standard one
    mixed = tmp_path / "mixed.log"
    mixed.write_text("".join(lines[:6] + [cut(x) for x in lines[6:12]]))
    assert [scan[0] for scan in _read(mixed, scan_topic="FLASER")[1]] == [1001.5, 1002.5]
    extra = tmp_path / "extra.log"
    extra.write_text("".join(line.replace(" h ", " h x ").replace(" host ", " host x ") for line in lines))
    with pytest.raises(LogError, match="needs 13 fields after its tag, has 14"):
        list(open_log(extra, scan_topic="FLASER").messages())


def test_the_laser_tag_with_a_few_lines_beside_many_is_not_chosen(tmp_path):
    """ROBOTLASER1 is preferred (it carries the mount), but not with 3 lines beside 150 FLASER lines: the
    run had 3 steps; of as many (or at least half as many) it still is."""
    many = "".join(_flaser_odom(1000.0 + i, 0, 0.1 * i) for i in range(150))
    few = "".join(_robotlaser(1000.2 + i, 0.1 * i + 0.2, 0.1 * i) for i in range(3))
    p = tmp_path / "mixed.log"
    p.write_text(many + few)
    assert open_log(p).info().scan_topic == "FLASER"
    half = "".join(_robotlaser(1000.2 + i, 0.1 * i + 0.2, 0.1 * i) for i in range(75))
    p.write_text(many + half)
    assert open_log(p).info().scan_topic == "ROBOTLASER1"


def test_odometry_from_laser_fields_for_want_of_odom_lines_or_never_moving_is_warned(tmp_path, caplog):
    p = tmp_path / "a.log"
    p.write_text("".join(_flaser_odom(1000.0 + i, 0, 0.1 * i) + f"ODOM 1 2 {i}\n" for i in range(4)))
    with caplog.at_level(logging.WARNING, logger="cornerslam.logs"):
        log, scans, odoms = _read(p)
    assert log.info().odom_topic == "FLASER" and len(odoms) == 4
    assert "none of its 4 ODOM lines is whole" in caplog.text and "never move" not in caplog.text
    caplog.clear()
    p.write_text("".join(_flaser_odom(1000.0 + i, 0, 0) for i in range(4)))
    with caplog.at_level(logging.WARNING, logger="cornerslam.logs"):
        _read(p)
    assert (
        "pose fields of its FLASER lines never move: the run takes the robot as standing still" in caplog.text
    )


def _rl(t, laser, robot):
    """A ROBOTLASER1 line with whole laser and robot poses (x, y, theta)."""
    poses = " ".join(f"{v:.6f}" for v in (*laser, *robot))
    return f"ROBOTLASER1 0 -0.5 1.0 0.25 9.9 0.01 0 3 1 1 1 0 {poses} 0 0 0 0 0 {t} h {t}\n"


def test_robotlaser_poses_that_are_not_one_place_on_the_robot_give_no_mount(tmp_path):
    """ROBOTLASER1 lines whose laser pose fields hold another trajectory (corrected poses, another origin)
    than their robot pose fields: their offsets spread over metres, so no mount is taken from them (it
    was their mean, 4.6 m off, with no word) and the reason is kept for the run's warning; so too when
    only their headings drift apart. A fixed mount on a turning robot, printed to 6 digits, is one, and
    a line with a glitched pose does not undo it."""
    from cornerslam_cli.geometry import compose

    mount = np.array([0.3, 0.1, 0.2])
    robots = [np.array([0.5 * i, 0.2 * i, 0.1 * i]) for i in range(60)]
    lasers = [compose(r, mount) for r in robots]
    p = tmp_path / "a.log"

    def mount_of(lasers):
        p.write_text(
            "".join(_rl(1000.0 + i, la, r) for i, (la, r) in enumerate(zip(lasers, robots, strict=True)))
        )
        log = open_log(p)
        return log.laser_to_base(), log.mount_problem

    got, problem = mount_of(lasers)
    np.testing.assert_allclose(got, mount, atol=1e-5)
    assert not problem
    glitch = [la + (3.0, 0, 0) if i == 7 else la for i, la in enumerate(lasers)]
    np.testing.assert_allclose(mount_of(glitch)[0], mount, atol=1e-5)
    corrected = [np.array([0.55 * i + 4.0, 0.2 * i, 0.1 * i]) for i in range(60)]  # another trajectory
    got, problem = mount_of(corrected)
    assert got is None and "laser poses are not at one place on the robot" in problem
    res = CliRunner().invoke(cli, ["info", str(p)])  # info says why, beside the laser's line
    assert res.exit_code == 0 and "note:      the log gives no laser mount: its ROBOTLASER1" in res.output
    turned = [la + (0, 0, 0.01 * i) for i, la in enumerate(lasers)]  # their headings drift apart only
    got, problem = mount_of(turned)
    assert got is None and "spread over 0.00 m and" in problem


def test_raw_laser_lines_are_said_to_be_unread_not_absent(tmp_path):
    """RAWLASER1 + ODOM (a raw CARMEN log): "no laser lines (FLASER/ROBOTLASER1)" and, asked for by name,
    "its 'RAWLASER1' lines are not laser lines (laser lines: none) (choose one of them …)" — false and
    impossible to follow; now both say cornerslam does not read raw laser lines."""
    p = tmp_path / "raw.log"
    p.write_text(
        "".join(
            _odom_line(1000.0 + i, 0.1 * i)
            + f"RAWLASER1 0 -1.57 3.14 0.0175 80 0.01 0 3 1 1 1 {1000.0 + i} h {1000.0 + i}\n"
            for i in range(3)
        )
    )
    unread = r"its RAWLASER1 lines are raw laser lines, which cornerslam does not read"
    with pytest.raises(LogError, match=r"has no laser lines \(FLASER/ROBOTLASER1\) \(" + unread):
        open_log(p).check()
    with pytest.raises(LogError, match=r"its 'RAWLASER1' lines are raw .* \(give a log with laser lines\)"):
        open_log(p, scan_topic="RAWLASER1").check()


def test_info_names_the_laser_lines_a_run_leaves_unused(tmp_path):
    """FLASER and RLASER (a front and a rear laser): the run reads FLASER; info said nothing of RLASER."""
    p = tmp_path / "two.log"
    p.write_text(
        "".join(
            flaser(180, 1000.0 + i) + f"RLASER 3 5 5 5 0 0 0 0 0 0 {1000.0 + i} h {1000.0 + i}\n"
            for i in range(3)
        )
    )
    info = open_log(p).info()
    assert info.scan_topic == "FLASER"
    assert info.notes == ("its RLASER lines (3) are not used (--scan-topic RLASER reads them instead)",)
    assert open_log(p, scan_topic="RLASER").info().notes == (
        "its FLASER lines (3) are not used (--scan-topic FLASER reads them instead)",
    )
    one = tmp_path / "one.log"
    one.write_text("".join(flaser(180, 1000.0 + i) for i in range(3)))
    assert open_log(one).info().notes == ()


def test_info_says_how_many_of_the_runs_lines_it_skips(tmp_path):
    """info's topic counts hold a tag's cut and malformed lines; a run skips them, which it did not say."""
    p = tmp_path / "cut.log"
    odom = "".join(f"ODOM {0.1 * i} 0 0 0 0 0 {1000.0 + i} h {1000.0 + i}\n" for i in range(4))
    p.write_text("".join(flaser(180, 1000.0 + i) for i in range(4)) + flaser(180, 1010.0)[:40] + "\n" + odom)
    assert open_log(p).info().notes == ("1 of its 5 FLASER lines is cut or malformed: a run skips them",)
    q = tmp_path / "cut_odom.log"
    q.write_text("".join(flaser(180, 1000.0 + i) for i in range(4)) + odom + "ODOM 1 2\n")
    assert open_log(q).info().notes == ("1 of its 5 ODOM lines is cut or malformed: a run skips them",)


@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-be"])
def test_a_utf16_log_is_named_so_with_the_command_that_converts_it(tmp_path, encoding):
    """A CARMEN log saved as UTF-16 by a Windows editor was "not a CARMEN log", after warning that every
    line began with NUL bytes; now the error says what it is and how to convert it (which reads)."""
    import codecs
    import subprocess

    text = "".join(flaser(180, float(i), r=2.0 + 0.01 * i) for i in range(5))
    bom = codecs.BOM_UTF16_BE if encoding.endswith("be") else b""
    p = tmp_path / "x.log"
    p.write_bytes(bom + text.encode(encoding))
    with pytest.raises(LogError, match="log 'x.log' is UTF-16 text") as err:
        open_log(p)
    command = err.value.hint.split("first: ", 1)[1]
    assert command == f"iconv -f UTF-16 -t UTF-8 {p} > {tmp_path / 'x-utf8.log'}"
    subprocess.run(command, shell=True, check=True)
    scans, _ = split(open_log(tmp_path / "x-utf8.log").messages())
    assert [s.stamp for s in scans] == [0, 1, 2, 3, 4]


def test_a_log_whose_timestamps_never_change_is_read_on_its_logger_timestamps(tmp_path, caplog):
    """A converter that wrote 0 for every line's timestamp, with the logger's beside it: every scan but the
    first was dropped as going back in time (exit 2 "check that the laser driver fills the header
    stamps"); now the logger timestamps are read, every tag alike, warned. One tag whose timestamps move
    keeps the message timestamps for all (two clocks are never mixed)."""

    def lines(stamp_of):
        out = ""
        for i in range(6):
            t = 100.0 + 0.5 * i
            pose = (0.1 * i, 0, 0)
            odom = " ".join(map(str, pose))
            out += f"ODOM {odom} 0 0 0 {stamp_of('ODOM', t)} host {t}\n"
            out += flaser(181, t, pose=pose).replace(f" {t} host", f" {stamp_of('FLASER', t)} host")
        return out

    zero = tmp_path / "zero.log"
    zero.write_text(lines(lambda tag, t: 0.0))
    with caplog.at_level(logging.WARNING):
        scans, odoms = split(open_log(zero).messages())
    assert [s.stamp for s in scans] == [o.stamp for o in odoms] == [100.0 + 0.5 * i for i in range(6)]
    said = "the timestamps of its FLASER and ODOM lines never change: read on their logger timestamps"
    assert said in caplog.text
    info = open_log(zero).info()
    assert (info.start, info.duration) == (100.0, 2.5)
    half = tmp_path / "half.log"  # the laser's timestamps move, 1 s from the logger's: the laser's clock kept
    half.write_text(lines(lambda tag, t: t + 1.0 if tag == "FLASER" else 0.0))
    scans, _ = split(open_log(half).messages())
    assert [s.stamp for s in scans] == [101.0 + 0.5 * i for i in range(6)]
    laser_zero = tmp_path / "laser_zero.log"  # the odometry moves: not read on the logger; refused
    laser_zero.write_text(lines(lambda tag, t: 0.0 if tag == "FLASER" else t))
    res = CliRunner().invoke(cli, ["run", str(laser_zero), "--out", str(tmp_path / "o"), "-q"])
    assert res.exit_code == 2, res.output
    assert "their timestamps increase" in res.stderr and "header" not in res.stderr
    alone = tmp_path / "alone.log"  # no ODOM lines: the laser lines' own odometry, their stamps all 0
    flasers = [line.rsplit(" ", 1)[0] for line in lines(lambda tag, t: 0.0).splitlines() if "FLASER" in line]
    alone.write_text("".join(f"{line} 0.0\n" for line in flasers))  # (the logger's too)
    res = CliRunner().invoke(cli, ["run", str(alone), "--out", str(tmp_path / "o"), "-q"])
    assert res.exit_code == 2 and "the timestamps of the other 5 repeated or went backwards" in res.stderr
    assert "check the laser lines' timestamp field" in res.stderr and "header" not in res.stderr
    back = tmp_path / "back.log"  # read on logger timestamps that go back: the hint names them
    flasers = [line.rsplit(" ", 1)[0] for line in lines(lambda tag, t: 0.0).splitlines() if "FLASER" in line]
    back.write_text("".join(f"{line} {51.5 if k == 0 else 50.0}\n" for k, line in enumerate(flasers)))
    res = CliRunner().invoke(cli, ["run", str(back), "--out", str(tmp_path / "o"), "-q"])
    assert (
        res.exit_code == 2
        and "check the laser lines' logger timestamps (their timestamps never" in res.stderr
    )


def test_a_laser_line_of_no_readings_is_warned_and_unusable_scans_are_named_in_carmen_words(tmp_path, caplog):
    """A `FLASER 0 …` line was counted as an unusable scan ("see the warnings") but no warning named it;
    a log whose every ROBOTLASER1 line gives its angles in degrees was told to check the LaserScans'
    angle_min/angle_increment, ROS fields a CARMEN log does not have (probes)."""
    p = tmp_path / "zero.log"
    p.write_text(flaser(181, 1.0) + "FLASER 0 0 0 0 0 0 0 2.0 host 2.0\n" + flaser(181, 3.0))
    with caplog.at_level(logging.WARNING, logger="cornerslam"):
        scans, _ = split(open_log(p).messages())
    assert len(scans) == 2 and "zero.log:2: scan at 2.000 has no beams: skipped" in caplog.text
    degrees = tmp_path / "deg.log"  # fov 180 and resolution 0.5: degrees, 361 readings over 28 turns
    poses, readings = "0 0 0 0 0 0", " ".join(["1"] * 361)
    degrees.write_text(
        "".join(
            f"ROBOTLASER1 0 -90 180 0.5 9.9 0.01 0 361 {readings} 0 {poses} 0 0 0 0 0 {t} h {t}\n"
            for t in (1, 2)
        )
    )
    with pytest.raises(LogError) as e:
        split(open_log(degrees).messages())
    assert "ROBOTLASER1 lines' start_angle/angular_resolution, in radians" in e.value.hint
    assert "LaserScan" not in e.value.hint
