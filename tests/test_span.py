"""``--start``, ``--end`` and ``--max-scans`` on ``run`` and ``compare`` (span.py): the part of a log
processed, recorded in summary.json; bad values exit 2 naming the option."""

import json

import pytest
from click.testing import CliRunner

from cornerslam_cli.cli import cli
from cornerslam_cli.span import Bound, Span, parse_bound


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


def summary(out):
    return json.loads((out / "summary.json").read_text())


def stamps(out):
    return [float(line.split()[0]) for line in (out / "trajectory.tum").read_text().splitlines()]


def test_parse_bound_seconds_and_index():
    assert parse_bound("12.5") == Bound(12.5, False)
    assert parse_bound(" #40 ") == Bound(40.0, True)
    # (non-ASCII digits too; '1_0' and '٣' are 10 and 3 to Python's float: refused, found by a probe)
    for bad in ("#", "#1.5", "#-3", "-1", "nan", "inf", "ten", "#²", "#٣", "1_0", "٣", "1٣.5"):
        with pytest.raises(ValueError):
            parse_bound(bad)


def test_a_huge_scan_index_is_echoed_as_given_or_refused_in_one_short_line():
    """An index is kept an int (a float round trip turned #99999999999999999999999 into
    #99999999999999991611392 in the error); past INDEX_DIGITS digits it is refused, the message cut short
    (int() itself refuses more than 4,300 digits with a traceback-worthy ValueError)."""
    big = "9" * 23
    assert parse_bound(f"#{big}").text() == f"#{big}"
    with pytest.raises(ValueError) as e:
        parse_bound("#" + "9" * 5000)
    assert str(e.value) == "'#9999999999...' (5,000 digits) is past any scan of a log"


def test_expected_scans_for_the_progress_line():
    assert Span(Bound(10, True), Bound(30, True)).expected_scans(100, 50.0) == 20
    assert Span(Bound(5.0, False), None, 7).expected_scans(100, 50.0) == 7  # 2 scans/s
    assert Span(Bound(40.0, False)).expected_scans(100, 50.0) == 20
    assert Span(Bound(200, True)).expected_scans(100, 50.0) == 0
    # seconds past any log: clamped to the log before int() (1e308 s × 2 scans/s is inf: OverflowError)
    assert Span(Bound(1e308, False)).expected_scans(100, 50.0) == 0
    assert Span(None, Bound(1e308, False)).expected_scans(100, 50.0) == 100
    assert Span(Bound(5.0, False), Bound(1e308, False), 7).expected_scans(100, 50.0) == 7


@pytest.mark.parametrize(
    "command, span, code",
    [
        ("run", ("--start", "1e308"), 2),
        ("compare", ("--start", "1e308"), 2),
        ("run", ("--end", "1e308", "--max-scans", "5"), 0),
    ],
)
def test_seconds_past_any_log_are_no_internal_error(sim_log, tmp_path, command, span, code):
    """Any finite --start or --end behaves as 1e300 does (a probe: 1e308 exited 1 with an OverflowError
    from the progress line's estimate): a start past the log selects no scan, an end past it ends nowhere."""
    res = invoke(command, sim_log, "--out", tmp_path / "o", "-q", *span)
    assert res.exit_code == code, res.output
    if code == 2:
        assert res.stderr.startswith("error: --start 1e+308 selects no scan of log 'sim.mcap'"), res.stderr


def test_run_by_scan_index_and_count_records_the_span(sim_log, tmp_path):
    """… and says it on the run's summary and in its report (before: in summary.json only, a run over a
    slice reading like the whole log's; a probe)."""
    full, part = tmp_path / "full", tmp_path / "part"
    res = invoke("run", sim_log, "--out", full)
    assert res.exit_code == 0 and "span:" not in res.output
    res = invoke("run", sim_log, "--out", part, "--start", "#10", "--max-scans", "20", "--plot")
    assert res.exit_code == 0, res.output
    said = "--start #10 --max-scans 20: scans #10–#29 of the log, "
    assert f"\nspan: {said}" in res.stdout and "s from its first scan\n" in res.stdout
    assert f"span</th><td>{said}" in (part / "report.html").read_text()
    assert "span" not in summary(full)["input"]  # a whole-log run's summary.json is unchanged
    span = summary(part)["input"]["span"]
    assert span["options"] == "--start #10 --max-scans 20"
    assert (span["first_index"], span["last_index"], span["scans"]) == (10, 29, 20)
    t_full, t_part = stamps(full), stamps(part)
    t0 = t_full[0]  # the simulated log's first scan is its first keyframe
    assert t_part[0] == pytest.approx(t0 + span["first_time"], abs=1e-6)
    assert t_part[-1] <= t0 + span["last_time"] + 1e-6
    assert summary(part)["counts"]["steps"] < summary(full)["counts"]["steps"]


def test_run_by_seconds_keeps_scans_inside(sim_log, tmp_path):
    out = tmp_path / "out"
    res = invoke("run", sim_log, "--out", out, "-q", "--start", "5", "--end", "20")
    assert res.exit_code == 0, res.output
    span = summary(out)["input"]["span"]
    assert 5.0 <= span["first_time"] < 5.6 and 19.4 < span["last_time"] < 20.0
    assert span["scans"] == span["last_index"] - span["first_index"] + 1


def test_compare_on_part_of_the_log(sim_log, tmp_path):
    out = tmp_path / "cmp"
    res = invoke("compare", sim_log, "--assoc", "icnn,pca", "--out", out, "--end", "#25")
    assert res.exit_code == 0, res.output
    for assoc in ("icnn", "pca"):
        span = summary(out / assoc)["input"]["span"]
        assert (span["first_index"], span["last_index"], span["options"]) == (0, 24, "--end #25")
    said = "--end #25: scans #0–#24 of the log, "  # said under the table and in the report
    assert res.stdout.count(f"\nspan: {said}") == 1 and f"({said}" in (out / "report.html").read_text()


@pytest.mark.parametrize(
    "args, option",
    [
        (("--start", "ten"), "--start"),
        (("--end", "#x"), "--end"),
        (("--start", "-2"), "--start"),
        (("--max-scans", "0"), "--max-scans"),
        (("--start", "#20", "--end", "#20"), "--end"),
        (("--start", "8", "--end", "3"), "--end"),
    ],
)
@pytest.mark.parametrize("command", ["run", "compare"])
def test_bad_span_values_exit_2_naming_the_option(sim_log, tmp_path, command, args, option):
    res = invoke(command, sim_log, "--out", tmp_path / "o", *args)
    assert res.exit_code == 2 and option in res.stderr and "Traceback" not in res.output
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("end", [("0",), ("0.0",), ("#0",), ("0", "--start", "#0")])
def test_an_end_at_the_first_scan_is_refused_naming_the_option(sim_log, tmp_path, end):
    """`--end 0` holds no scan: a usage error (it read the log up to its first scan, then said the log
    held '1 scans over 0.0 s')."""
    res = invoke("run", sim_log, "--out", tmp_path / "o", "--end", *end)
    assert res.exit_code == 2, res.output
    assert "invalid value for --end" in res.stderr and "is the log's first scan" in res.stderr, res.stderr
    assert not (tmp_path / "o").exists()


def test_span_past_the_end_of_the_log_is_one_line_error(sim_log, tmp_path):
    res = invoke("run", sim_log, "--out", tmp_path / "o", "--start", "#100000")
    assert res.exit_code == 2, res.output
    err = res.stderr.strip()
    assert err.startswith("error: --start #100000 selects no scan of log 'sim.mcap'") and "\n" not in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("span", [("--start", "2", "--end", "#3"), ("--start", "#6", "--end", "1")])
def test_an_end_before_the_start_in_other_units_says_so(sim_log, tmp_path, span):
    """A start in seconds and an end as an index (or the other way round) that ends before the start:
    the error says where the start let the first scan in, not the scans read before stopping as if they
    were the log's extent ('21 scans over 5.0 s' for a 501-scan log)."""
    res = invoke("run", sim_log, "--out", tmp_path / "o", *span)
    assert res.exit_code == 2, res.output
    err = res.stderr.strip()
    assert "selects no scan of log 'sim.mcap': the first scan its start lets in (#" in err, err
    assert "is already past its end (give an end after the start)" in err and "\n" not in err
    assert not (tmp_path / "o").exists()


def test_seconds_in_errors_keep_their_digits():
    """'--start 930.86420001 selects no scan' was said as 930.864 (the last scan at 930.8642 looked let
    in), and a first scan past an --end of 907.7 as "907.7 s"."""
    from cornerslam_cli.span import Bound, seconds

    assert Bound(930.86420001, False).text() == "930.86420001" and Bound(5.0, False).text() == "5"
    assert seconds(907.6500000000001) == "907.65" and seconds(907.7000004) == "907.7"


@pytest.mark.parametrize(
    "span",
    [
        ("--start", "#5", "--max-scans", "10"),
        ("--start", "0.5", "--end", "1.5"),
        # the span is taken on the scans as read, then their stamps shifted: the odometry is read past
        # the last one's shifted stamp (else it would be "after the last odometry")
        ("--start", "#5", "--max-scans", "10", "--set", "input.scan_time_offset=0.3"),
    ],
)
def test_beam_counts_are_the_spans_scans(tmp_path, span):
    """summary.json's beams_total / beams_invalid count the scans the run processed, as scans_in does
    (a probe: they counted every scan read, the ones before --start and after --end too)."""
    from _log_fixtures import make_odoms, make_scans

    from cornerslam_cli.logs.writers import write_mcap

    raw = make_scans(30, beams=181)
    log = write_mcap(tmp_path / "log.mcap", raw, make_odoms(31))
    res = invoke("run", log, "--out", tmp_path / "o", "-q", *span)
    assert res.exit_code == 0, res.output
    kept = raw[5:15]  # #5 to #14; 0.5 s to 1.5 s from the first scan (10 Hz) is the same ten
    counts = summary(tmp_path / "o")["counts"]
    valid = [(s.ranges > 0) & (s.ranges >= 0.1) & (s.ranges < 30.0) for s in kept]  # NaN compares False
    assert counts["scans_in"] == 10
    assert counts["beams_total"] == sum(len(s.ranges) for s in kept) == 1810
    assert counts["beams_invalid"] == sum(int((~v).sum()) for v in valid) > 0


def test_a_stamp_given_for_seconds_is_shown_the_logs_first_stamp(sim_log, tmp_path):
    """`--start 1700000000` (the log's stamp, where seconds from its first scan are meant) said only that
    it selects no scan (a probe): the first scan's stamp is shown."""
    res = invoke("run", sim_log, "--start", "1700000000", "--out", tmp_path / "o")
    assert res.exit_code == 2 and "(its first scan is stamped 1700000000.006: choose a span" in res.stderr
    res = invoke("run", sim_log, "--start", "500", "--out", tmp_path / "o")
    assert res.exit_code == 2 and "stamped" not in res.stderr
