"""The CLI through click's CliRunner: every command, exit codes, and the bad-input table."""

import dataclasses
import json
import math
import re
import tempfile
from pathlib import Path

import click
import numpy as np
import pytest
from _log_fixtures import write_log
from click.testing import CliRunner

from cornerslam_cli.cli import cli
from cornerslam_cli.errors import ConfigError
from cornerslam_cli.logs.writers import RawScan, write_mcap
from cornerslam_cli.options import parse_assocs
from cornerslam_cli.report.html import MAIN_COLUMNS
from cornerslam_cli.report.ownership import MARKER
from cornerslam_cli.report.tables import TIMING_COLUMNS, TRAJECTORY_COLUMNS, best_cells, read_csv
from cornerslam_cli.types import OdomSample

T0 = 1_700_000_000.0


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False, prog_name="cornerslam")


DAMAGED = "the file is damaged: copy it again from its source, or salvage its intact parts"


def one_line_error(result, *fragments):
    """Exit 2, one line on stderr starting with 'error:', no traceback, naming what it must."""
    assert result.exit_code == 2, result.output
    err = result.stderr.strip()
    assert err.startswith("error:") and "\n" not in err and "Traceback" not in result.output, err
    for f in fragments:
        assert f in err, err


def small_log(path, n=20, ranges=None, scan_topic="/scan", **kw):
    r = np.full(181, 5.0) if ranges is None else ranges
    scans = [RawScan(T0 + 0.1 * i + 0.05, -math.pi / 2, math.pi / 180, r, 0.1, 30.0) for i in range(n)]
    odoms = [OdomSample(T0 + 0.1 * i, 0.05 * i, 0.0, 0.0) for i in range(n + 1)]
    return write_mcap(path, scans, odoms, scan_topic=scan_topic, **kw)


# ---------------------------------------------------------------------------- run, end to end
def test_run_writes_every_table_with_the_interface_columns(sim_log, tmp_path):
    out = tmp_path / "out"
    res = invoke("run", sim_log, "--out", out, "-q")
    assert res.exit_code == 0, res.output
    files = ["trajectory.tum", "trajectory.csv", "map.csv", "lines.csv", "timing.csv", "summary.json"]
    files += ["odometry.tum", "scan_matched.tum", "map.pgm", "map.yaml", "map_grid.png"]  # issue 17
    files += ["loops.csv"]  # issue 16: submaps are on by default
    assert sorted(p.name for p in out.iterdir()) == sorted([*files, MARKER])
    assert json.loads((out / MARKER).read_text())["files"] == sorted(files)  # what it replaces next time
    traj = read_csv(out / "trajectory.csv")
    timing = read_csv(out / "timing.csv")
    assert list(traj) == TRAJECTORY_COLUMNS and list(timing) == TIMING_COLUMNS
    summary = json.loads((out / "summary.json").read_text())
    steps = summary["counts"]["steps"]
    assert len(traj["step"]) == len(timing["step"]) == steps > 100
    assert summary["mode"] == "slam" and summary["assoc"] == "pca"
    assert summary["config"]["association"]["pca"]["group_size"] == 3
    # ground truth was found beside the log: the estimate beats odometry by far
    acc = summary["accuracy"]
    assert acc["ate"]["rmse"] < 0.25 and acc["ate"]["rmse"] < acc["odom_ate"]["rmse"] / 5
    lm = read_csv(out / "map.csv")
    assert len(lm["id"]) == summary["counts"]["landmarks"] > 10
    assert np.all(lm["n_obs"] >= 1) and np.all(lm["last_step"] >= lm["first_step"])
    tum = np.loadtxt(out / "trajectory.tum")
    assert tum.shape == (steps, 8) and np.allclose(tum[:, 1], traj["x"])


def test_run_overrides_reach_the_resolved_config(sim_log, tmp_path):
    res = invoke(
        "run",
        sim_log,
        "--out",
        tmp_path / "o",
        "-q",
        "--assoc",
        "icnn",
        "--set",
        "keyframes.linear_update=0.5",
    )
    assert res.exit_code == 0, res.output
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert s["assoc"] == "icnn" and s["config"]["keyframes"]["linear_update"] == 0.5
    assert s["counts"]["keyframes_skipped"] > 0


def test_run_plot_and_mcap_out(sim_log, tmp_path):
    out, mc = tmp_path / "out", tmp_path / "res.mcap"
    res = invoke("run", sim_log, "--out", out, "--plot", "--mcap-out", mc, "-q")
    assert res.exit_code == 0, res.output
    for name in ("map.png", "segments.png", "timing.png", "corners.png", "report.html"):
        assert (out / name).stat().st_size > 1000, name
    assert mc.read_bytes()[:8] == b"\x89MCAP0\r\n"
    # a name of another format: refused before any work (a probe: an MCAP written as res.bag)
    res = invoke("run", sim_log, "--out", tmp_path / "o2", "--mcap-out", tmp_path / "res.BAG", "-q")
    assert (
        res.exit_code == 2 and "names a ROS 1 bag, but it is written as MCAP: name it res.mcap" in res.stderr
    )
    assert not (tmp_path / "o2").exists() and not (tmp_path / "res.BAG").exists()


def test_evaluate_reports_ate(sim_log, tmp_path):
    out = tmp_path / "out"
    assert invoke("run", sim_log, "--out", out, "-q").exit_code == 0
    res = invoke("evaluate", out, "--ground-truth", sim_log.with_suffix(".gt.tum"))
    assert res.exit_code == 0 and "ATE  rmse" in res.output
    # its trajectory.tum cut at a line since (a copy interrupted): refused, not scored as the whole run
    traj = out / "trajectory.tum"
    lines = traj.read_text().splitlines(keepends=True)
    traj.write_text("".join(lines[: len(lines) // 3]))
    res = invoke("evaluate", out, "--ground-truth", sim_log.with_suffix(".gt.tum"))
    one_line_error(res, "trajectory.tum' holds", "but its run wrote", "cut short or changed since")
    # ... but the file itself, named, is scored as it is
    res = invoke("evaluate", traj, "--ground-truth", sim_log.with_suffix(".gt.tum"))
    assert res.exit_code == 0 and "ATE  rmse" in res.output
    # a link to a part in its place is followed: refused too (a review: it was scored as the whole)
    short = tmp_path / "short.tum"
    traj.rename(short)
    traj.symlink_to(short)
    one_line_error(invoke("evaluate", out, "--ground-truth", sim_log.with_suffix(".gt.tum")), "cut short")
    # a copy without its marker (no sizes): its poses against the steps summary.json counts
    (out / MARKER).unlink()
    res = invoke("evaluate", out, "--ground-truth", sim_log.with_suffix(".gt.tum"))
    one_line_error(res, "poses, but its run's summary.json counts", "steps: it was cut short")
    traj.unlink()
    short.rename(traj)
    traj.write_text("".join(lines))  # whole again: scored
    assert invoke("evaluate", out, "--ground-truth", sim_log.with_suffix(".gt.tum")).exit_code == 0


def test_evaluate_of_a_directory_that_does_not_exist_says_so(tmp_path):
    """A mistyped run directory was answered "give --ground-truth FILE.tum or --relations FILE" (a probe)."""
    res = invoke("evaluate", tmp_path / "nonexist")
    assert res.exit_code == 2
    want = f"error: '{tmp_path / 'nonexist'}' does not exist"
    assert res.stderr.strip() == f"{want} (give a run's output directory or a trajectory file)"


def test_evaluate_correct_scale_reports_the_scale_and_needs_ground_truth(tmp_path):
    t = np.arange(40.0)
    gt = np.column_stack((np.cos(t / 6) * 8, np.sin(t / 4) * 5, t / 6))

    def rows(poses):  # TUM: stamp x y z qx qy qz qw
        return "".join(
            f"{s} {x} {y} 0 0 0 {np.sin(a / 2)} {np.cos(a / 2)}\n"
            for s, (x, y, a) in zip(t, poses, strict=True)
        )

    (tmp_path / "gt.tum").write_text(rows(gt))
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "trajectory.tum").write_text(rows(gt * [1.002, 1.002, 1.0]))
    res = invoke("evaluate", tmp_path / "run", "--ground-truth", tmp_path / "gt.tum", "--correct-scale")
    assert res.exit_code == 0, res.output
    assert "ATE  rmse 0.0000 m" in res.output and "scale corrected ×0.99800" in res.output
    res = invoke("evaluate", tmp_path / "run", "--ground-truth", tmp_path / "gt.tum")
    assert res.exit_code == 0 and "scale corrected" not in res.output and "ATE  rmse 0.0000" not in res.output
    res = invoke("evaluate", tmp_path / "run", "--relations", tmp_path / "gt.tum", "--correct-scale")
    assert res.exit_code == 2 and "--correct-scale" in res.output


def test_info_names_the_topics_run_would_use(sim_log):
    res = invoke("info", sim_log)
    assert res.exit_code == 0, res.output
    assert "/scan" in res.output and "sensor_msgs/LaserScan" in res.output
    assert "scans     /scan" in res.output and "odometry  /odom" in res.output


def test_info_notes_the_ground_truth_a_run_would_score_against(sim_log, tmp_path, monkeypatch):
    """run and compare score against LOG.gt.tum unasked; info said nothing of it (an evo-user probe)."""
    res = invoke("info", sim_log)
    gt = sim_log.with_suffix(".gt.tum")
    assert f"ground truth {gt} beside it: run and compare score against it" in res.stdout
    alone = tmp_path / "alone.mcap"
    alone.write_bytes(sim_log.read_bytes())
    assert "ground truth" not in invoke("info", alone).stdout
    # one run refuses: said so, not "score against it" (a probe)
    (tmp_path / "alone.gt.tum").write_text("1 2 3\n")
    res = invoke("info", alone)
    assert res.exit_code == 0 and "score against it" not in res.stdout
    assert "note:      run and compare exit 2 on the ground truth beside it: ground truth " in res.stdout
    assert "line 1 has 3 values" in res.stdout
    # one over INFO_GT_BYTES is not read (a review: 122 MB took info 16 s): said as before, run checks it
    import cornerslam_cli.cli as cli_module

    monkeypatch.setattr(cli_module, "INFO_GT_BYTES", 5)
    assert (
        "run and compare score against it (its 0 MiB not read here: run checks them)"
        in invoke("info", alone).stdout
    )


def test_a_log_whose_name_leaves_no_room_for_gt_tum_is_read(sim_log, tmp_path):
    """A log named with 249 bytes: LOG.mcap.gt.tum is longer than a file name may be, and looking for it
    raised ENAMETOOLONG — info and run exited 1, internal error (a review). No ground truth then."""
    log = tmp_path / ("x" * 244 + ".mcap")
    log.write_bytes(sim_log.read_bytes())
    res = invoke("info", log)
    assert res.exit_code == 0, res.output
    assert "ground truth" not in res.stdout


def test_info_shows_the_first_scans_beams_preset_and_beam_times(sim_log, tmp_path):
    """The simulated log: 541 beams over 270° (no preset has them), no time_increment (scans as
    recorded); 181 SICK-like beams with time_increment: the SICK preset, the beam times and sweep."""
    res = invoke("info", sim_log)
    assert res.exit_code == 0, res.output
    assert "  beams     541 over 270.0° (0.500° apart), 0.050–30.000 m: no laser preset matches" in res.output
    assert "  beam times not in the log: scans used as recorded (input.beam_time to deskew)" in res.output
    r = np.full(181, 5.0)
    scans = [
        RawScan(T0 + 0.1 * i, -math.pi / 2, math.pi / 180, r, 0.1, 30.0, time_increment=1e-4)
        for i in range(3)
    ]
    odoms = [OdomSample(T0 + 0.1 * i, 0.0, 0.0, 0.0) for i in range(4)]
    res = invoke("info", write_mcap(tmp_path / "ti.mcap", scans, odoms))
    assert res.exit_code == 0, res.output
    assert "  beams     181 over 180.0° (1.000° apart), 0.100–30.000 m: preset sick_lms_1deg" in res.output
    assert "  beam times 100.00 µs apart (the log's time_increment, 18.0 ms a sweep): deskewed" in res.output
    # as a run would use them under the config (a probe: info said "deskewed" under input.deskew=false)
    res = invoke("info", tmp_path / "ti.mcap", "--set", "input.deskew=false")
    assert "(the log's time_increment, 18.0 ms a sweep): not deskewed (input.deskew=false)" in res.output
    res = invoke("info", sim_log, "--set", "input.beam_time=-2e-5")
    assert "  beam times 20.00 µs apart (not in the log: input.beam_time, 10.8 ms a sweep): deskewed" in (
        res.output
    )
    res = invoke("info", sim_log, "--set", "input.deskew=false")
    assert "  beam times not in the log: scans used as recorded (input.deskew=false)" in res.output
    one = [RawScan(T0 + 0.1 * i, 0.0, 0.01, np.array([5.0]), 0.1, 30.0) for i in range(3)]
    res = invoke("info", write_mcap(tmp_path / "one.mcap", one, odoms))
    assert res.exit_code == 0, res.output
    assert "  beams     1 (a single beam), 0.100–30.000 m: " in res.output  # (was: "1 over 0.0°")


def test_info_lists_the_topics_of_a_log_whose_first_scan_cannot_be_read(tmp_path):
    """A CARMEN log whose only laser line is cut: info still lists the topics, then refuses the log as
    run does (it exited 0 with the reason as a problem line, while run exits 2)."""
    log = tmp_path / "cut.clf"
    log.write_text("ODOM 0 0 0 0 0 0 1.0 host 1.0\nFLASER 180 1.0 1.0 1.0\n")
    res = invoke("info", log, "-q")
    why = "CARMEN log 'cut.clf' has no complete laser line: its only FLASER line cannot be read"
    one_line_error(res, why)
    assert "FLASER" in res.stdout and "  beams " not in res.stdout and "problem:" not in res.stdout
    one_line_error(invoke("run", log, "--out", tmp_path / "out"), why)


def test_info_refuses_a_log_with_no_readable_scan_as_run_does(tmp_path):
    """Every chunk corrupt: info listed /scan with the summary's count and exited 0, only its warnings
    saying that nothing was read, while run exits 2. It lists the topics, then exits 2."""
    from fault_corpus import corrupt_chunk

    log = small_log(tmp_path / "s.mcap", n=3)
    corrupt_chunk(log, log, which=0)
    res = invoke("info", log, "-q")
    why = f"log '{log}': no scan could be read, so run has none to process (0 scans usable); 1 damaged part"
    one_line_error(res, why, DAMAGED)
    assert "/scan" in res.stdout and "  scans     /scan" in res.stdout and "  beams " not in res.stdout
    assert invoke("run", log, "--out", tmp_path / "out", "-q").exit_code == 2


def test_run_on_a_log_with_every_chunk_damaged_names_the_damage(tmp_path):
    """Every chunk corrupt: run said "no scan could be processed (0 scans read, 0 before the first …)"
    and told the user to check that the topics overlap in time; it names the damage and what to do."""
    from fault_corpus import corrupt_chunk

    log = small_log(tmp_path / "s.mcap", n=3)
    corrupt_chunk(log, log, which=0)
    res = invoke("run", log, "--out", tmp_path / "out", "-q")
    why = f"log '{log}': no scan could be processed (0 scans and 0 odometry samples usable); 1 damaged part"
    one_line_error(res, why, DAMAGED)
    assert "overlap in time" not in res.stderr and not (tmp_path / "out").exists()


@pytest.mark.parametrize("command", ["run", "info", "extract"])
@pytest.mark.parametrize("damaged", ["first", "every"])
def test_a_log_without_summary_whose_chunks_are_damaged_names_the_damage(tmp_path, command, damaged):
    """Without a summary an MCAP's channel definitions sit in its chunks: with its first chunk damaged
    (or every one) a topic was missing, and the error said to record the laser as LaserScan (or that
    there was no odometry topic). It names the damage instead."""
    from fault_corpus import mcap_records

    log = small_log(tmp_path / "s.mcap", n=10, chunk_size=1, summary=False)
    data = bytearray(log.read_bytes())
    chunks = [(start, n) for op, start, n in mcap_records(bytes(data)) if op == 0x06]
    for start, n in chunks[:1] if damaged == "first" else chunks:
        data[start + n // 2 : start + n // 2 + 8] = bytes(8)  # inside the compressed records
    log.write_bytes(bytes(data))
    extra = {"run": ["--out", tmp_path / "out"], "extract": ["--step", 0], "info": []}[command]
    res = invoke(command, log, *extra, "-q")
    if damaged == "first" and command == "extract":  # the odometry's chunk: extract needs none
        assert res.exit_code == 0 and res.stdout.startswith("scan 0 at "), res.output
        return
    n_damaged = 1 if damaged == "first" else len(chunks)
    why = f"topic in its readable parts; {n_damaged} damaged part"
    one_line_error(res, f"log '{log.name}': no ", why, DAMAGED)
    assert "record the laser" not in res.stderr and not (tmp_path / "out").exists()


def test_a_log_in_an_unsupported_compression_says_so(tmp_path):
    """A chunk compression this reader lacks is not damage: re-copying the file would not help."""
    data = bytearray(small_log(tmp_path / "s.mcap", n=3, compression="lz4").read_bytes())
    data = data.replace(b"\x03\x00\x00\x00lz4", b"\x03\x00\x00\x00bz3")
    log = tmp_path / "b.mcap"
    log.write_bytes(bytes(data))
    res = invoke("run", log, "--out", tmp_path / "out", "-q")
    one_line_error(res, "in a compression this reader does not support", "write the log with zstd, lz4")
    assert "damaged" not in res.stderr


def test_info_lists_the_topics_of_a_log_run_refuses(tmp_path):
    """A log with odometry and no LaserScan (or scans and no odometry): info printed nothing but the
    error, whose hint is "`cornerslam info LOG` lists the topics". It lists them, then exits 2 with
    the error run gives."""
    t0 = 1_700_000_000.0
    odoms = [OdomSample(t0 + 0.1 * i, 0.1 * i, 0.0, 0.0) for i in range(5)]
    res = invoke("info", write_mcap(tmp_path / "odom_only.mcap", [], odoms))
    one_line_error(res, "has no sensor_msgs/LaserScan topic")
    assert "/odom" in res.stdout and "nav_msgs/Odometry" in res.stdout and "  scans     -" in res.stdout
    r = np.full(181, 5.0)
    scans = [RawScan(t0 + 0.1 * i, -math.pi / 2, math.pi / 180, r, 0.1, 30.0) for i in range(3)]
    res = invoke("info", write_mcap(tmp_path / "scans_only.mcap", scans, []))
    one_line_error(res, "has no odometry")
    assert "/scan" in res.stdout and "  odometry  - (none found)" in res.stdout
    # its first scan is read all the same, as extract reads it (dd82047: "info also shows the first scan")
    assert "  beams     181 over 180.0° (1.000° apart)" in res.stdout, res.stdout


def test_info_lists_the_topics_of_a_log_whose_scan_topic_has_no_message(tmp_path):
    """/scan declared, nothing recorded on it: info printed only the error, whose hint is "`cornerslam
    info LOG` shows the counts". It shows them (0 on /scan), then exits 2 as run does (found by a
    hostile-user probe)."""
    from fault_corpus import _empty_topics_mcap

    log = _empty_topics_mcap(tmp_path / "e.mcap", True)
    res = invoke("info", log)
    one_line_error(res, "topic '/scan' of log 'e.mcap' has no messages")
    assert "  /scan " in res.stdout and " 0 msgs" in res.stdout and "run would use:" in res.stdout


def test_run_line_counts_the_scans_the_reader_could_not_use(tmp_path):
    """Half the scans with angle_increment 0: the run line said "30 steps (30 scans, 0 skipped, …)",
    the 30 others only in capped warnings and summary.json (found by a hostile-user probe)."""
    t0, r = 1_700_000_000.0, np.full(181, 5.0)
    inc = [math.pi / 180 * (i % 2) for i in range(40)]  # every other scan's angle_increment 0
    scans = [RawScan(t0 + 0.1 * i + 0.05, -math.pi / 2, inc[i], r, 0.1, 30.0) for i in range(40)]
    odoms = [OdomSample(t0 + 0.1 * i, 0.05 * i, 0.0, 0.0) for i in range(41)]
    res = invoke("run", write_mcap(tmp_path / "h.mcap", scans, odoms), "--out", tmp_path / "o")
    assert res.exit_code == 0, res.output
    assert "(20 scans, 0 skipped, " in res.stdout
    assert "; 20 more scans unusable, not read: see the warnings)" in res.stdout


def test_extract_refuses_a_wrong_odometry_topic_as_run_does(sim_log):
    """extract needs no odometry, but an --odom-topic given wrong was ignored on ROS logs (exit 0) while
    a CARMEN log refused it (a hostile-user probe)."""
    res = invoke("extract", sim_log, "--odom-topic", "/nope")
    assert res.exit_code == 2 and "has no topic '/nope'" in res.output, res.output
    res = invoke("extract", sim_log, "--odom-topic", "/scan")
    assert res.exit_code == 2 and "not nav_msgs/Odometry" in res.output, res.output
    assert invoke("extract", sim_log, "--odom-topic", "/odom").exit_code == 0


def test_extract_prints_and_plots(sim_log, tmp_path):
    png = tmp_path / "scan.png"
    res = invoke("extract", sim_log, "--step", 3, "--plot", png)
    assert res.exit_code == 0, res.output
    assert png.stat().st_size > 10_000


def test_extract_plot_cut_short_keeps_the_earlier_figure_and_leaves_no_part(sim_log, tmp_path, monkeypatch):
    """The figure is written beside its target and renamed onto it: a write cut short (a kill, a full
    disk: here an error after half the bytes) leaves the earlier figure whole and no partial file."""
    from cornerslam_cli.report import extract_plot

    svg = tmp_path / "scan.svg"
    assert invoke("extract", sim_log, "--step", 3, "--plot", svg).exit_code == 0
    before = svg.read_bytes()
    draw = extract_plot.plot_extraction

    def cut_short(scan, segments, corners, path, title="", fmt=None):
        draw(scan, segments, corners, path, title, fmt)
        Path(path).write_bytes(Path(path).read_bytes()[: len(before) // 2])
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(extract_plot, "plot_extraction", cut_short)
    res = invoke("extract", sim_log, "--step", 4, "--plot", svg)
    assert res.exit_code == 2 and "no space left on device" in res.stderr, res.output
    assert svg.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["scan.svg"]


def test_extract_plot_to_a_place_it_cannot_write_is_refused_before_the_scan_is_printed(
    sim_log, tmp_path, monkeypatch
):
    """A read-only mount (os.access says so: root passes permission bits) was found out only after the
    scan's table had been printed (a probe): refused first, naming the nearest existing directory."""
    import os

    real = os.access
    monkeypatch.setattr(os, "access", lambda p, mode: False if Path(p) == tmp_path else real(p, mode))
    res = invoke("extract", sim_log, "--step", 3, "--plot", tmp_path / "figs" / "scan.png")
    assert res.exit_code == 2 and not res.stdout and f"'{tmp_path}' is not writable" in res.stderr, res.output
    assert not (tmp_path / "figs").exists()


@pytest.mark.parametrize("name", ["scan.gif", "scan.webp", "scan.pgf", "scan.svgz"])
def test_extract_plot_refuses_formats_whose_files_it_could_not_recognise_later(sim_log, tmp_path, name):
    """Only formats whose file can name cornerslam as its creator: an extract figure in any other could
    not be replaced by the next --plot (nor told from a user's file), and .pgf needs LaTeX (an internal
    error after the work); refused before any work, no directory made."""
    res = invoke("extract", sim_log, "--plot", tmp_path / "new" / name)
    assert res.exit_code == 2 and "does not end in a figure format (" in res.stderr, res.output
    formats = res.stderr.split("figure format (", 1)[1]
    assert ".png, " in formats and ".gif" not in formats and not (tmp_path / "new").exists()


def test_extract_step_is_the_steps_scan_and_its_features(tmp_path):
    """extract_step counts scans from 0 and extracts them as the filter's front end does; a step
    past the end is a ConfigError naming the valid range, and the CLI prints it as one line."""
    from cornerslam_cli.config import load_config
    from cornerslam_cli.extract import extract_step
    from cornerslam_cli.features import extract

    room = np.concatenate([np.full(91, 3.0), np.linspace(3.0, 1.5, 90)])  # a wall meeting a slanted one
    log = small_log(tmp_path / "s.mcap", n=6, ranges=room)
    cfg = load_config(None, [])
    _, scan, segments, corners = extract_step(log, 4, cfg)
    assert scan.stamp == pytest.approx(T0 + 0.45)
    ref_segments, ref_corners = extract(scan, cfg.sensor, cfg.lines, cfg.corners)
    assert len(segments) == len(ref_segments) > 0 and np.array_equal(corners.z, ref_corners.z)
    with pytest.raises(ConfigError) as e:
        extract_step(log, 6, cfg)
    assert str(e.value) == f"--step 6 is past the end of '{log}' (6 scans) (use 0..5)"
    res = invoke("extract", log, "--step", 4)
    assert res.stdout.startswith("scan 4 at 1700000000.450 s: 181 valid of 181 beams\n")
    # written '#4' too, as run's --start '#4' takes a scan index (a probe: '#10' was refused)
    assert invoke("extract", log, "--step", "#4").stdout == res.stdout
    assert invoke("extract", log, "--step", "#x").exit_code == 2
    assert invoke("extract", log, "--step", 9).stderr == (
        f"error: --step 9 is past the end of '{log}' (6 scans) (use 0..5)\n"
    )


def test_extract_at_a_stamp_is_a_runs_step(tmp_path):
    """A run's step numbers skip scans (between keyframes, before the odometry, a stamp that went back):
    `extract --step 295` showed the scan the run skipped, not its step 295 (an evo-user probe). --at takes
    a stamp of trajectory.csv and shows that scan, with its index in the log; a stamp no scan has names
    the scans' span; --at with --step is a usage error."""
    log = small_log(tmp_path / "s.mcap", n=6)
    res = invoke("extract", log, "--at", f"{T0 + 0.4505:.4f}")  # (within 1 ms of the 5th scan's)
    assert res.exit_code == 0 and res.stdout.startswith("scan 4 at 1700000000.450 s:"), res.output
    res = invoke("extract", log, "--at", "12.5")
    assert res.exit_code == 2 and "no scan of" in res.stderr and "is stamped --at 12.500000" in res.stderr
    assert "trajectory.csv stamp column" in res.stderr
    res = invoke("extract", log, "--at", f"{T0 + 0.45}", "--step", "1")
    assert res.exit_code == 2 and "contradict each other" in res.stderr


def test_extract_from_a_log_with_no_readable_scan_names_no_range(tmp_path):
    """Every chunk corrupt: extract said "--step 0 is past the end of 'LOG' (0 scans) (use 0..0)",
    offering a step the log does not have."""
    from fault_corpus import corrupt_chunk

    log = small_log(tmp_path / "s.mcap", n=3)
    corrupt_chunk(log, log, which=0)
    res = invoke("extract", log, "--step", 0, "-q")
    one_line_error(res, f"log '{log}': no scan could be read, so none to extract", DAMAGED)
    assert "0..0" not in res.stderr


def test_a_gzipped_carmen_log_finds_its_ground_truth(tmp_path):
    """NAME.log.gz beside NAME.gt.tum: the ground truth is found (before: only NAME.log.gz.gt.tum and
    NAME.log.gt.tum were looked for, so a gzipped radish log was run unscored, nothing said)."""
    from cornerslam_cli.report.run_writer import find_ground_truth

    log = tmp_path / "orebro.log.gz"
    log.write_bytes(b"")
    assert find_ground_truth(log) is None
    for name in ("orebro.gt.tum", "orebro.log.gt.tum", "orebro.log.gz.gt.tum"):  # the later, the nearer
        (tmp_path / name).write_text("0 0 0 0 0 0 0 1\n")
        assert find_ground_truth(log) == tmp_path / name
    assert find_ground_truth(tmp_path / "orebro.log") == tmp_path / "orebro.log.gt.tum"


@pytest.mark.parametrize("command", ["run", "compare", "batch"])
def test_a_damaged_ground_truth_beside_the_log_says_why_it_was_read(command, tmp_path):
    """LOG.gt.tum beside the log, not readable: the error named a file the user had not given, without
    saying why it was read or how to run without it (batch too, which had no --no-ground-truth)."""
    log = small_log(tmp_path / "s.mcap", n=6)
    gt = tmp_path / "s.gt.tum"
    gt.write_text("garbage line\n")
    jobs = ("--jobs", 1) if command == "batch" else ()
    res = invoke(command, log, "--out", tmp_path / "o", *jobs)
    error = (
        f"ground truth '{gt}' line 1 is not a TUM pose (expected: stamp x y z qx qy qz qw; read as the "
        "log's ground truth for lying beside it: fix it, or run without it: --no-ground-truth)"
    )
    if command == "batch":  # its row failed (the batch goes on), the line in batch.csv
        assert res.exit_code == 2
        (row,) = read_csv(tmp_path / "o" / "batch.csv")["error"]
        assert row == error
        res = invoke(command, log, "--out", tmp_path / "o", "--no-ground-truth", "-q", *jobs)
        assert res.exit_code == 0, res.output
        summary = next((tmp_path / "o").rglob("summary.json"))
        assert json.loads(summary.read_text())["accuracy"] is None
        return
    one_line_error(res, error)
    res = invoke(command, log, "--out", tmp_path / "o", "--ground-truth", gt)  # given: no such note
    one_line_error(res, "line 1 is not a TUM pose")
    assert res.stderr.endswith("(expected: stamp x y z qx qy qz qw)\n")
    assert not (tmp_path / "o").exists()
    # --no-ground-truth: scored against none (the folder may be read-only: an evo-user probe)
    res = invoke(command, log, "--out", tmp_path / "o", "--no-ground-truth", "-q")
    assert res.exit_code == 0, res.output
    summary = next((tmp_path / "o").rglob("summary.json"))
    assert json.loads(summary.read_text())["accuracy"] is None
    res = invoke(command, log, "--out", tmp_path / "o2", "--no-ground-truth", "--ground-truth", gt)
    assert res.exit_code == 2 and "--ground-truth and --no-ground-truth contradict each other" in res.stderr


def test_extract_keeps_the_beams_a_run_keeps(tmp_path):
    """input.skip_beams_* and input.max_range (in --set or --config) apply to extract's scan as to a
    run's (before: ignored, exit 0 with the features of beams the run never sees); skipping every beam
    is the run's exit 2 naming both keys."""
    room = np.concatenate([np.full(91, 3.0), np.linspace(3.0, 1.5, 90)])
    log = small_log(tmp_path / "s.mcap", n=3, ranges=room)
    res = invoke("extract", log, "--step", 1, "--set", "input.skip_beams_start=100")
    assert res.exit_code == 0, res.output
    assert res.stdout.startswith("scan 1 at 1700000000.150 s: 81 valid of 181 beams\n"), res.stdout
    res = invoke("extract", log, "--step", 1, "--set", "input.max_range=2.5")
    assert res.stdout.startswith("scan 1 at 1700000000.150 s: 60 valid of 181 beams\n"), res.stdout
    res = invoke("extract", log, "--set", "input.skip_beams_start=100", "--set", "input.skip_beams_end=81")
    one_line_error(res, "input.skip_beams_start=100 and input.skip_beams_end=81 skip all 181 beams")
    # info lists the log, then exits 2 as run would (a probe: exit 0, not a word)
    res = invoke("info", log, "--set", "input.skip_beams_start=100", "--set", "input.skip_beams_end=81")
    assert res.exit_code == 2 and "  beams     181 over 180.0°" in res.stdout
    assert res.stderr.startswith("error: input.skip_beams_start=100 and input.skip_beams_end=81 skip all 181")


@pytest.mark.parametrize("fmt", ["mcap-cdr", "rosbag1", "rosbag2-sqlite3"])
def test_extract_reads_a_log_without_odometry(fmt, tmp_path):
    """One scan's features need no odometry: extract serves a log of scans alone (run refuses it)."""
    log = write_log(fmt, tmp_path, odoms=[])
    res = invoke("extract", log, "--step", 2)
    assert res.exit_code == 0, res.output
    assert res.stdout.startswith("scan 2 at ")
    one_line_error(invoke("run", log, "--out", tmp_path / "out"), "has no odometry")
    assert not (tmp_path / "out").exists()


def test_an_option_and_a_set_of_its_key_must_agree(sim_log, tmp_path):
    """--assoc icnn with --set association.method=jcbb ran icnn without a word (likewise the topics):
    a usage error naming both; the same value given twice is no conflict."""
    res = invoke(
        "run", sim_log, "--assoc", "icnn", "--set", "association.method=jcbb", "--out", tmp_path / "a"
    )
    assert res.exit_code == 2 and "--assoc icnn and --set 'association.method=jcbb' disagree" in res.stderr
    assert not (tmp_path / "a").exists()
    res = invoke("extract", sim_log, "--scan-topic", "/scan", "--set", "input.scan_topic=/other")
    assert (
        res.exit_code == 2 and "--scan-topic /scan and --set 'input.scan_topic=/other' disagree" in res.stderr
    )
    res = invoke("extract", sim_log, "--odom-topic", "/odom", "--set", "input.odom_topic=/odom")
    assert res.exit_code == 0, res.output


def test_an_option_and_a_set_of_a_mapping_with_its_key_must_agree(sim_log):
    """--set 'input={scan_topic: /other}' (a mapping, merged key by key) sets the same key as
    --set input.scan_topic=/other: with --scan-topic /scan it is the same conflict, not a silent win."""
    res = invoke("extract", sim_log, "--scan-topic", "/scan", "--set", "input={scan_topic: /other}")
    assert res.exit_code == 2 and "--scan-topic /scan and --set 'input={scan_topic: /other}' disagree" in (
        res.stderr
    )
    res = invoke("extract", sim_log, "--scan-topic", "/scan", "--set", "input={scan_topic: /scan}")
    assert res.exit_code == 0, res.output


def test_config_preset_and_a_set_of_the_preset_key_must_agree(sim_log):
    """`config --preset none --set input.laser_preset=hokuyo_270deg` printed `laser_preset: none`, the
    --set dropped without a word (found by a hostile-user probe): a usage error naming both, as for
    --assoc; the same preset given twice is no conflict."""
    res = invoke("config", sim_log, "--preset", "none", "--set", "input.laser_preset=hokuyo_270deg")
    assert res.exit_code == 2 and "--preset none and --set 'input.laser_preset=hokuyo_270deg' disagree" in (
        res.stderr
    )
    res = invoke("config", sim_log, "--preset", "none", "--set", "input={laser_preset: none}")
    assert res.exit_code == 0 and "laser_preset: none" in res.stdout, res.output


def test_simulate_is_reproducible(tmp_path):
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    for p in (a, b):
        assert invoke("simulate", p, "--seed", 3, "--rate", 1, "--beams", 91, "-q").exit_code == 0
    assert a.read_bytes() == b.read_bytes()
    assert a.with_suffix(".gt.tum").read_text() == b.with_suffix(".gt.tum").read_text()


def test_a_simulated_logs_static_tf_is_offered_latched(sim_log):
    """ros2 bag play offers each topic with the QoS the bag recorded: simulate recorded none, so /tf_static
    was played volatile and a listener started after the first message never got the laser's mount (a
    probe). It is offered transient local, keep last 1, as tf2's static broadcaster does; the rest as
    before, the default."""
    from rosbags.rosbag2 import Reader

    with Reader(sim_log) as reader:
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
    (static,) = qos["/tf_static"]
    assert static.durability.name == "TRANSIENT_LOCAL" and static.depth == 1
    assert qos["/scan"] == [] and qos["/odom"] == []


def test_simulates_help_gives_the_ranges_it_accepts():
    """The ranges were said only by the errors of values outside them (a probe): --help gives them, the
    same as simulate.RANGES."""
    from cornerslam_cli.simulate import RANGES

    text = " ".join(invoke("simulate", "--help").stdout.split())
    for option, lo, hi in RANGES:
        said = text.split(option, 1)[1].split(" --", 1)[0]
        assert f"{lo:g}–{hi:g}." in said.replace(",", ""), (option, said)


# ---------------------------------------------------------------------------- bad input: exit 2, one line
def test_nonexistent_log(tmp_path):
    one_line_error(invoke("run", tmp_path / "nope.mcap", "--out", tmp_path / "o"), "nope.mcap")
    assert not (tmp_path / "o").exists()


def test_empty_and_unsupported_files(tmp_path):
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    one_line_error(invoke("run", empty, "--out", tmp_path / "o"), "empty.mcap")
    txt = tmp_path / "notes.txt"
    txt.write_text("hello")
    one_line_error(invoke("info", txt), "notes.txt")
    assert not (tmp_path / "o").exists()


def test_log_without_laserscan(tmp_path):
    log = tmp_path / "odom_only.mcap"
    write_mcap(log, [], [OdomSample(T0 + i, i, 0, 0) for i in range(5)])
    one_line_error(invoke("run", log, "--out", tmp_path / "o"), "LaserScan")


def test_log_without_odometry_says_how_to_choose(tmp_path):
    log = tmp_path / "scan_only.mcap"
    r = np.full(181, 5.0)
    write_mcap(log, [RawScan(T0 + i, -1.5, 0.01, r) for i in range(5)], [])
    one_line_error(invoke("run", log, "--out", tmp_path / "o"), "--odom-topic")


def test_several_scan_topics_and_none_chosen(tmp_path):
    log = tmp_path / "two.mcap"
    _two_scan_topics(log)
    one_line_error(invoke("run", log, "--out", tmp_path / "o"), "/front", "/rear", "--scan-topic")
    assert invoke("run", log, "--scan-topic", "/rear", "--out", tmp_path / "o", "-q").exit_code == 0


def _two_scan_topics(path: Path) -> None:
    """An MCAP with two LaserScan topics (/front, /rear) and /odom, built with the writers' serializer."""
    from mcap.writer import Writer

    from cornerslam_cli.logs.writers.ros import RosSerializer, RosTopics, ros_messages

    ros = RosSerializer("cdr")
    r = np.full(181, 5.0)
    scans = [RawScan(T0 + 0.1 * i + 0.05, -math.pi / 2, math.pi / 180, r) for i in range(10)]
    odoms = [OdomSample(T0 + 0.1 * i, 0.0, 0.0, 0.0) for i in range(11)]
    msgs = list(ros_messages(ros, scans, odoms, RosTopics(scan_topic="/front")))
    msgs += list(ros_messages(ros, scans, [], RosTopics(scan_topic="/rear")))
    msgs.sort(key=lambda m: m[2])
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="test")
        chans = {}
        for topic, typename, t, data in msgs:
            if topic not in chans:
                sid = w.register_schema(name=typename, encoding="ros2msg", data=ros.msgdef(typename).encode())
                chans[topic] = w.register_channel(topic=topic, message_encoding="cdr", schema_id=sid)
            w.add_message(channel_id=chans[topic], log_time=t, data=data, publish_time=t)
        w.finish()


def test_all_beams_invalid_is_a_clear_error(tmp_path):
    log = small_log(tmp_path / "blind.mcap", ranges=np.full(181, np.nan))
    one_line_error(invoke("run", log, "--out", tmp_path / "o"), "blind.mcap", "valid")
    assert not (tmp_path / "o").exists()


def test_time_going_backwards_is_skipped_counted_and_warned(tmp_path):
    log = tmp_path / "back.mcap"
    r = np.full(181, 5.0)
    stamps = [0.05, 0.15, 0.25, 0.15, 0.35, 0.35, 0.45]
    scans = [RawScan(T0 + s, -math.pi / 2, math.pi / 180, r) for s in stamps]
    write_mcap(log, scans, [OdomSample(T0 + 0.1 * i, 0.05 * i, 0, 0) for i in range(6)])
    res = invoke("run", log, "--out", tmp_path / "o")
    assert res.exit_code == 0, res.output
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert s["counts"]["scan_time_backwards"] == 2 and s["counts"]["steps"] == 5
    assert "went backwards or repeated" in res.stderr


def test_invalid_yaml_and_unknown_key(tmp_path, sim_log):
    bad = tmp_path / "bad.yaml"
    bad.write_text("association: [\n")
    one_line_error(invoke("run", sim_log, "--config", bad, "--out", tmp_path / "o"), "bad.yaml")
    one_line_error(
        invoke("run", sim_log, "--set", "association.pca.grup_size=3", "--out", tmp_path / "o"),
        "association.pca.grup_size",
        "group_size",
    )
    one_line_error(invoke("run", sim_log, "--assoc", "jbcc", "--out", tmp_path / "o"), "jbcc", "jcbb")
    assert not (tmp_path / "o").exists()


def test_bad_ground_truth_fails_before_the_run(tmp_path, sim_log):
    gt = tmp_path / "gt.tum"
    gt.write_text("1 2 3\n")
    one_line_error(invoke("run", sim_log, "--ground-truth", gt, "--out", tmp_path / "o"), "gt.tum")
    assert not (tmp_path / "o").exists()


def test_truncated_mcap_processes_what_is_readable(sim_log, tmp_path):
    data = sim_log.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    res = invoke("run", cut, "--out", tmp_path / "o", "--ground-truth", sim_log.with_suffix(".gt.tum"))
    assert res.exit_code == 0, res.output
    assert "truncated" in res.stderr.lower() or "warning" in res.stderr.lower()
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert 10 < s["counts"]["steps"] < 200


def test_an_internal_error_exits_1_with_the_traceback_saved(tmp_path, sim_log, monkeypatch):
    from cornerslam_cli.slam import Slam

    def boom(*a, **k):
        raise ZeroDivisionError("synthetic bug")

    monkeypatch.setattr(Slam, "step", boom)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # not a file left in the system's /tmp
    res = invoke("run", sim_log, "--out", tmp_path / "o")
    assert res.exit_code == 1
    assert "internal error: ZeroDivisionError" in res.stderr and "traceback saved to" in res.stderr
    saved = res.stderr.split("traceback saved to ")[1].strip().rstrip(")")
    assert Path(saved).parent == tmp_path and "synthetic bug" in Path(saved).read_text()
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("where", ["no temporary directory", "a full disk"])
def test_an_internal_error_whose_traceback_cannot_be_saved_is_still_one_line(
    where, tmp_path, sim_log, monkeypatch
):
    """No writable temporary directory (TMPDIR and /tmp read-only) or a full disk: the OSError of
    saving the traceback escaped, a Python traceback printed after the bug's."""
    import errno
    import os
    import tempfile

    from cornerslam_cli.slam import Slam

    def boom(*a, **k):
        raise ZeroDivisionError("synthetic bug")

    def no_dir(*a, **k):
        raise FileNotFoundError(errno.ENOENT, "No usable temporary directory found")

    def full(*a, **k):
        return os.open("/dev/full", os.O_WRONLY), str(tmp_path / "crash.txt")

    monkeypatch.setattr(Slam, "step", boom)
    monkeypatch.setattr(tempfile, "mkstemp", no_dir if where.startswith("no") else full)
    res = invoke("run", sim_log, "--out", tmp_path / "o")
    assert res.exit_code == 1 and "Traceback" not in res.output
    reason = "No usable temporary directory found" if where.startswith("no") else "No space left on device"
    assert res.stderr.startswith("internal error: ZeroDivisionError: synthetic bug (traceback not saved")
    assert res.stderr.endswith(f"{reason}; set TMPDIR to a writable directory to keep it)\n")
    assert not (tmp_path / "o").exists()


def test_compare_runs_every_associator_on_the_same_frames(sim_log, tmp_path):
    out = tmp_path / "cmp"
    res = invoke("compare", sim_log, "--assoc", "icnn,pca", "--out", out, "--jobs", 2)
    assert res.exit_code == 0, res.output
    rows = read_csv(out / "comparison.csv")
    assert list(rows["assoc"]) == ["icnn", "pca"]
    assert rows["steps"][0] == rows["steps"][1] > 100
    for a in ("icnn", "pca"):
        s = json.loads((out / a / "summary.json").read_text())
        assert s["assoc"] == a
    # the same frames: identical extraction columns in both timing tables
    t1, t2 = read_csv(out / "icnn" / "timing.csv"), read_csv(out / "pca" / "timing.csv")
    assert np.array_equal(t1["n_corners"], t2["n_corners"]) and np.array_equal(
        t1["t_extract"], t2["t_extract"]
    )
    assert "ATE m" in res.output and "icnn" in res.output
    # scan matching ran once for both: the same motion input, scored once on the summary line
    assert rows["scan_odom_ate_rmse"][0] == rows["scan_odom_ate_rmse"][1] < rows["odom_ate_rmse"][0]
    assert np.array_equal(t1["t_scan_match"], t2["t_scan_match"])
    assert "scan-matched odometry (the filter's motion input): ATE" in res.output
    for name in ("report.html", "compare_matching.png", "compare_maps.png", "icnn/map.png", "pca/timing.png"):
        assert (out / name).stat().st_size > 1000, name
    # two filters ran at once: their times include waiting for the CPU — recorded, said, not ranked
    for a in ("icnn", "pca"):
        assert json.loads((out / a / "summary.json").read_text())["timing"]["concurrent_filters"] == 2
    assert res.stderr.count("timings: 2 filters ran at once (--jobs 2, ") == 1, res.stderr
    assert "times: the filters ran 2 at a time" in res.stdout  # under the table (the warning scrolled away)
    page = (out / "report.html").read_text()
    assert "The 2 filters ran 2 at a time" in page
    main_table = page.split("<h2>Comparison</h2>", 1)[1].split("<h", 1)[0]
    assert main_table.count('best"') == len(best_cells(rows, 2, MAIN_COLUMNS, timed=False))  # no time ranked
    loop_table = page.split("<h3>Loop closing</h3>", 1)[1].split("<h", 1)[0]  # nor loop closing's t_loop
    names = re.findall(r"<th[^>]*>([^<]*)</th>", loop_table)
    assert "t_loop" in names and loop_table.count('best"') == len(best_cells(rows, 2, names, timed=False))
    assert best_cells(rows, 2, MAIN_COLUMNS) - best_cells(rows, 2, MAIN_COLUMNS, timed=False)  # (there were)


def test_times_are_not_ranked_when_the_runs_shared_the_cpu():
    cols = {"assoc": np.array(["icnn", "pca"], dtype=object), "t_total": np.array([2.0, 1.0]),
            "ate_rmse": np.array([0.2, 0.1]), "wall_time": np.array([3.0, 4.0])}  # fmt: skip
    names = ["assoc", "t_total", "ate_rmse", "wall_time"]
    assert best_cells(cols, 2, names) == {(1, 1), (1, 2), (0, 3)}
    assert best_cells(cols, 2, names, timed=False) == {(1, 2)}


def test_the_most_matches_are_not_called_best_and_the_relation_metric_is_ranked():
    """An associator that takes wrong matches matches most: matched_total is shown, not ranked; the
    relation metric (--relations: Intel's accuracy figure) is ranked as the ATE is."""
    cols = {"matched_total": np.array([900.0, 700.0]), "ate_rmse": np.array([0.5, 0.1]),
            "rel_trans_mean": np.array([0.0909, 0.0908]), "rel_rot_mean_deg": np.array([2.0, 3])}  # fmt: skip
    names = ["matched_total", "ate_rmse", "rel_trans_mean", "rel_rot_mean_deg"]
    assert best_cells(cols, 2, names) == {(1, 1), (1, 2), (0, 3)}


def test_compare_one_job_records_no_concurrency_and_ranks_the_times(sim_log, tmp_path):
    out = tmp_path / "cmp"
    res = invoke("compare", sim_log, "--assoc", "icnn,pca", "--out", out, "--max-scans", "60")
    assert res.exit_code == 0, res.output
    for a in ("icnn", "pca"):
        assert "concurrent_filters" not in json.loads((out / a / "summary.json").read_text())["timing"]
    assert "filters ran at once" not in res.stderr and "at a time" not in res.output
    assert "at a time" not in (out / "report.html").read_text()


def test_compare_gives_each_associator_only_its_own_runs_warnings(sim_log, tmp_path, monkeypatch):
    """With --jobs 1 the associators run one after another in one process, on one input: a warning one
    run gives (a stand-in naming its associator, given where a run warns of the laser mount; a real
    one: the occupancy grid coarsened, its size the run's own) is in that run's summary.json only, as
    with --jobs 2, where each run has its own process; the extraction's warnings are in every one."""
    import cornerslam_cli.pipeline as pipeline
    from cornerslam_cli.compare import compare
    from cornerslam_cli.config import load_config
    from cornerslam_cli.span import Span

    monkeypatch.setattr(
        pipeline,
        "warn_mount",
        lambda src, cfg: src.reader.stats.warn(f"ran {cfg.association.method}"),
    )
    compare(sim_log, load_config(), ["icnn", "jcbb"], tmp_path / "cmp", span=Span(max_scans=20))
    for a, other in (("icnn", "jcbb"), ("jcbb", "icnn")):
        warnings = json.loads((tmp_path / "cmp" / a / "summary.json").read_text())["warnings"]
        assert f"ran {a}" in warnings and f"ran {other}" not in warnings


def test_compare_refuses_a_set_of_association_method(sim_log, tmp_path):
    """compare runs each associator of --assoc: a --set of association.method (alone or in a mapping)
    would be ignored without a word, so it is a usage error naming --assoc, before any work."""
    for given in ("association.method=jcbb", "association={method: jcbb}"):
        res = invoke("compare", sim_log, "--set", given, "--out", tmp_path / "c")
        assert res.exit_code == 2 and "--assoc" in res.output and given in res.output, res.output
        assert "drop the --set" in res.output  # jcbb is one of the default --assoc (it said: give it)
        assert not (tmp_path / "c").exists()
    res = invoke(
        "compare", sim_log, "--assoc", "pca,icnn", "--set", "association.method=jcbb", "--out", tmp_path / "c"
    )
    assert res.exit_code == 2 and "give --assoc jcbb instead" in res.output, res.output


@pytest.mark.parametrize(
    "args, said",
    [
        (
            ["simulate", "{tmp}/s.mcap/"],
            "'{tmp}/s.mcap/' names a directory (give a file name ending in .mcap)",
        ),
        (["simulate", "{tmp}/s.mcap/."], "'{tmp}/s.mcap/.' names a directory"),
        (["simulate", "{tmp}/.mcap"], "'{tmp}/.mcap' has no name before .mcap"),
        (["run", "{log}", "--config", "{tmp}/list.yaml"], "not list (write 'section:' lines with their keys"),
    ],
)
def test_small_mistakes_say_what_to_do(args, said, sim_log, tmp_path):
    """Found by a hostile-user probe: `simulate a.mcap/` wrote the file a.mcap; `simulate .mcap` was told
    to end in .mcap; a config that is a list said what was wrong but not what to write."""
    (tmp_path / "list.yaml").write_text("- a\n- b\n")
    res = invoke(*(a.format(tmp=tmp_path, log=sim_log) for a in args))
    assert res.exit_code == 2 and said.format(tmp=tmp_path) in res.output, res.output
    assert not (tmp_path / "s.mcap").exists()


def test_help_lists_every_exit_code():
    res = invoke("--help")  # 130/143/141 were missing
    said = " ".join(res.output.split())
    assert res.exit_code == 0 and "130 Ctrl-C, 143 SIGTERM, 141 output pipe closed" in said


def test_compare_warns_that_a_config_file_s_association_method_is_ignored(sim_log, tmp_path):
    """A --config file that sets association.method (a shared one may) is no error for compare, which
    runs each associator of --assoc: one warning line says the file's method is ignored; a file that
    does not set it, or sets it to one of --assoc's (configs/default.yaml's pca), gives no such line."""
    team, other = tmp_path / "team.yaml", tmp_path / "other.yaml"
    team.write_text("association:\n  alpha: 0.05\n  method: jcbb\n")
    other.write_text("association:\n  alpha: 0.05\n")
    res = invoke(
        "compare", sim_log, "--config", team, "--assoc", "icnn,pca", "--max-scans", 6, "--out", tmp_path / "a"
    )
    assert res.exit_code == 0, res.output
    assert [line for line in res.stderr.splitlines() if "association.method" in line] == [
        f"WARNING: config file '{team}' line 3: config key 'association.method' = 'jcbb' is ignored: "
        "compare runs each associator of --assoc (icnn,pca)"
    ]
    for a in ("icnn", "pca"):
        assert json.loads((tmp_path / "a" / a / "summary.json").read_text())["assoc"] == a
    for i, config in enumerate((other, Path(__file__).resolve().parents[1] / "configs" / "default.yaml")):
        res = invoke(
            "compare", sim_log, "--config", config, "--assoc", "icnn,pca", "--max-scans", 6,
            "--out", tmp_path / f"b{i}",
        )  # fmt: skip
        assert res.exit_code == 0 and "association.method" not in res.stderr, res.output


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_compare_says_a_ground_truth_note_once_and_keeps_it_in_every_summary(sim_log, tmp_path, jobs):
    """A ground truth covering part of the run: compare's runs share one input, so the note was printed
    once per associator (once per worker process with --jobs); it is printed once and still in each
    associator's summary.json. A real process: the workers' stderr is the terminal's, not CliRunner's."""
    import subprocess
    import sys

    gt = tmp_path / "half.tum"
    rows = sim_log.with_suffix(".gt.tum").read_text().splitlines()
    gt.write_text("\n".join(rows[: len(rows) // 8]) + "\n")
    res = subprocess.run(
        [sys.executable, "-m", "cornerslam_cli", "compare", str(sim_log), "--assoc", "icnn,jcbb,pca",
         "--ground-truth", str(gt), "--max-scans", "40", "--out", str(tmp_path / "c"), "--jobs", jobs],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert res.stderr.count("ATE/RPE are over those") == 1, res.stderr
    for a in ("icnn", "jcbb", "pca"):
        warnings = json.loads((tmp_path / "c" / a / "summary.json").read_text())["warnings"]
        assert sum("ATE/RPE are over those" in w for w in warnings) == 1, (a, warnings)


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_compare_warns_of_the_default_laser_mount_once(tmp_path, jobs):
    """A log without tf for the laser: the built-in mount is the input's warning, printed once however
    many associators run (it was once per associator) and in each one's summary.json."""
    from fault_corpus import make_odoms, make_scans

    log = write_mcap(tmp_path / "notf.mcap", make_scans(), make_odoms())
    res = invoke("compare", log, "--assoc", "icnn,pca", "--out", tmp_path / "c", "--jobs", jobs)
    assert res.exit_code == 0, res.output
    assert res.stderr.count("has no tf base_link→laser") == 1, res.stderr
    for a in ("icnn", "pca"):
        warnings = json.loads((tmp_path / "c" / a / "summary.json").read_text())["warnings"]
        assert sum("has no tf base_link→laser" in w for w in warnings) == 1, warnings


@pytest.mark.parametrize("command", ["run", "compare"])
def test_a_log_whose_every_beam_is_invalid_gives_its_error_without_the_mount_warning(tmp_path, command):
    """A log without tf whose every beam is NaN: its one error, not the default laser mount's warning
    first (a run warns of the mount after check_processed; compare warned once it had frames, whatever
    their beams)."""
    from fault_corpus import make_odoms, make_scans

    scans = make_scans(ranges=lambda i, r: np.full_like(r, np.nan))
    log = write_mcap(tmp_path / "nan.mcap", scans, make_odoms())
    res = invoke(command, log, "--out", tmp_path / "o")
    one_line_error(res, "every beam of every scan is invalid")


def test_compare_rejects_unknown_and_repeated_associators(sim_log, tmp_path):
    one_line_error(
        invoke("compare", sim_log, "--assoc", "icnn,jbcc", "--out", tmp_path / "c"), "jbcc", "jcbb"
    )
    res = invoke("compare", sim_log, "--assoc", "pca,pca", "--out", tmp_path / "c")
    assert res.exit_code == 2 and "distinct" in res.output
    assert not (tmp_path / "c").exists()


@pytest.mark.parametrize("allow_many", [True, False])
def test_parse_assocs_names_separated_by_spaces_are_told_to_use_commas(allow_many):
    """`--assoc 'icnn jcbb'` was answered "did you mean 'jcbb'?" (an evo-user probe); run, which takes
    one, is pointed at compare, and an unknown word among them is named with the closest (a review)."""
    with pytest.raises(ConfigError) as e:
        parse_assocs("icnn jcbb", allow_many=allow_many, log_path="a b.mcap")
    hint = (
        "separate them with commas: icnn,jcbb"
        if allow_many
        else "run takes one; cornerslam compare 'a b.mcap' --assoc icnn,jcbb runs several"
    )
    assert str(e.value) == f"--assoc: 'icnn jcbb' is not an associator ({hint})"
    with pytest.raises(ConfigError) as e:
        parse_assocs("icnn jbcc", allow_many=allow_many)
    assert str(e.value).startswith("--assoc: unknown associator 'jbcc' (did you mean 'jcbb'?")


def test_parse_assocs_good_names():
    assert parse_assocs("icnn,jcbb,pca", allow_many=True) == ["icnn", "jcbb", "pca"]
    assert parse_assocs(" pca , icnn", allow_many=True) == ["pca", "icnn"]  # spaces dropped
    assert parse_assocs(" jcbb", allow_many=False) == ["jcbb"]
    assert parse_assocs(None, allow_many=True) == parse_assocs(None, allow_many=False) == []
    with pytest.raises(click.BadParameter):  # run's default is None, the config's; '' names none
        parse_assocs("", allow_many=False)


@pytest.mark.parametrize("text", ["pca,pca", " icnn,icnn "])
def test_parse_assocs_repeated_list_is_a_usage_error(text):
    with pytest.raises(click.BadParameter) as e:
        parse_assocs(text, allow_many=True)
    assert e.value.format_message() == (
        f"Invalid value for --assoc: '{text}' must list distinct associators, e.g. icnn,jcbb,pca"
    )


@pytest.mark.parametrize("text", ["pca,,icnn", " pca , icnn,,", "pca,", ",pca"])
def test_parse_assocs_empty_name_in_a_list_is_a_usage_error(text):
    """An empty name between commas was dropped silently, while --sweep refuses an empty value as one
    lost in typing (a hostile-user probe)."""
    with pytest.raises(click.BadParameter) as e:
        parse_assocs(text, allow_many=True)
    assert e.value.format_message().startswith(
        f"Invalid value for --assoc: '{text}' has an empty name between its commas: give the associators "
        "without empty ones, e.g. pca"
    )


@pytest.mark.parametrize("text", ["", ",", " , "])
def test_parse_assocs_empty_list_is_a_usage_error(text):
    with pytest.raises(click.BadParameter) as e:
        parse_assocs(text, allow_many=True)
    assert e.value.format_message() == (
        f"Invalid value for --assoc: '{text}' names no associator: give e.g. icnn,jcbb,pca"
    )


@pytest.mark.parametrize(
    ("args", "line"),
    [
        (["run"], "error: missing argument 'LOG' (see 'cornerslam run --help')"),
        (
            ["run", "x.log", "--bogus"],
            "error: no such option '--bogus' (did you mean one of: '--out', '--verbose'?) "
            "(see 'cornerslam run --help')",
        ),
        (
            ["simulate", "x.mcap", "--seed", "q"],
            "error: invalid value for '--seed': 'q' is not a valid integer "
            "(see 'cornerslam simulate --help')",
        ),
        (
            ["run", "x.log", "-q", "-v"],
            "error: -q (only errors) and -v (more log output) contradict each other: give one "
            "(see 'cornerslam run --help')",
        ),
        (["bogus"], "error: no such command 'bogus' (see 'cornerslam --help')"),
        (["--bogus"], "error: no such option '--bogus' (see 'cornerslam --help')"),
    ],
)
def test_a_usage_error_is_one_line_naming_the_help(args, line, tmp_path, monkeypatch):
    """Click's own usage errors read as ours: one line, exit 2 — not usage, hint and message on four."""
    monkeypatch.chdir(tmp_path)
    res = invoke(*args)
    assert res.exit_code == 2 and res.stderr == line + "\n"
    assert not list(tmp_path.iterdir())  # nothing written


@pytest.mark.parametrize(
    ("text", "allow_many", "line"),
    [
        (
            "icnn,jbcc",
            True,
            "--assoc: unknown associator 'jbcc' (did you mean 'jcbb'? Choices: icnn, jcbb, pca)",
        ),
        ("icnn,qqqq", True, "--assoc: unknown associator 'qqqq' (choose one of: icnn, jcbb, pca)"),
        ("jbcc", False, "--assoc: unknown associator 'jbcc' (did you mean 'jcbb'? Choices: icnn, jcbb, pca)"),
        (
            "pca,",
            False,
            "--assoc: unknown associator 'pca,' (did you mean 'pca'? Choices: icnn, jcbb, pca)",
        ),  # one name
        ("PCA", False, "--assoc: unknown associator 'PCA' (did you mean 'pca'? Choices: icnn, jcbb, pca)"),
    ],
)
def test_parse_assocs_unknown_name_names_the_closest(text, allow_many, line, monkeypatch):
    import cornerslam_cli.association as association

    def never(*args):
        raise AssertionError("an associator was built to check a name")

    for name in association.ASSOCIATORS:
        monkeypatch.setitem(association.ASSOCIATORS, name, never)
    with pytest.raises(ConfigError) as e:
        parse_assocs(text, allow_many)
    assert str(e.value) == line


@pytest.mark.parametrize("text", ["", "  "])
def test_run_assoc_naming_none_is_a_usage_error(text, sim_log, tmp_path):
    """`run --assoc "$A"` with A unset ran the config's associator, exit 0, without a word (and
    `--assoc ' '` said "unknown associator ''")."""
    res = invoke("run", sim_log, "--assoc", text, "--out", tmp_path / "o")
    one_line_error(res, "invalid value for --assoc: '", "' names no associator: give e.g. pca")
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("command", ["run", "compare", "batch"])
def test_every_command_reports_a_bad_assoc_in_the_same_words(command, sim_log, tmp_path):
    out = ["--out", tmp_path / "o"]
    res = invoke(command, sim_log, "--assoc", "icnn,jbcc" if command != "run" else "jbcc", *out)
    assert (
        res.stderr
        == "error: --assoc: unknown associator 'jbcc' (did you mean 'jcbb'? Choices: icnn, jcbb, pca)\n"
    )
    assert res.exit_code == 2 and not (tmp_path / "o").exists()
    if command != "run":
        res = invoke(command, sim_log, "--assoc", "pca,pca", *out)
        assert res.exit_code == 2 and res.stderr == (
            "error: invalid value for --assoc: 'pca,pca' must list distinct associators, e.g. icnn,jcbb,pca "
            f"(see 'cornerslam {command} --help')\n"
        )
    res = invoke(command, sim_log, "--set", "association.method=pcaa", *out)
    assert res.stderr == (
        "error: --set 'association.method=pcaa': config key 'association.method' = 'pcaa' is not an "
        "associator (did you mean 'pca'? Choices: icnn, jcbb, pca)\n"
    )


def test_run_given_several_associators_points_to_compare(sim_log, tmp_path):
    """`run --assoc pca,icnn`: run takes one associator; the usage error says so and gives the compare
    command that runs the list (it suggested 'icnn' for the unknown name 'pca,icnn')."""
    res = invoke("run", sim_log, "--assoc", "pca, icnn", "--out", tmp_path / "o")
    assert res.exit_code == 2 and not (tmp_path / "o").exists()
    assert res.stderr == (
        "error: invalid value for --assoc: 'pca, icnn' lists 2 associators, but run takes one; to run "
        f"several side by side: cornerslam compare {sim_log} --assoc pca,icnn (see 'cornerslam run --help')\n"
    )
    with pytest.raises(click.BadParameter, match="cornerslam compare 'my log.bag' --assoc icnn,jcbb,pca"):
        parse_assocs("icnn,jcbb,pca", allow_many=False, log_path="my log.bag")
    with pytest.raises(click.BadParameter, match="cornerslam compare LOG --assoc icnn,jcbb"):
        parse_assocs("icnn,jcbb", allow_many=False)
    assert parse_assocs(" jcbb ", allow_many=False) == ["jcbb"]


def test_relations_are_scored_in_run_and_compare(sim_log, tmp_path):
    """Relations built from the simulator's ground truth (offset by a made-up clock difference): the
    estimate must score far better than odometry, and compare tabulates the metric per associator."""
    from cornerslam_cli.geometry import relative
    from cornerslam_cli.report.tables import read_tum

    t, gt = read_tum(sim_log.with_suffix(".gt.tum"))
    i = np.arange(0, len(t) - 10, 7)
    rel = relative(gt[i], gt[i + 10])
    offset = 1000.0
    lines = [
        f"{t[a] + offset:.6f} {t[a + 10] + offset:.6f} {x:.6f} {y:.6f} 0 0 0 {th:.6f}"
        for a, (x, y, th) in zip(i, rel, strict=True)
    ]
    rel_file = tmp_path / "sim.relations"
    rel_file.write_text("\n".join(lines) + "\n")
    args = ["--relations", rel_file, "--time-offset", offset]
    res = invoke("run", sim_log, "--out", tmp_path / "r", *args)
    assert res.exit_code == 0, res.output
    acc = json.loads((tmp_path / "r" / "summary.json").read_text())["accuracy"]
    assert acc["relations"]["n"] == len(i)
    assert acc["relations"]["trans_mean"] < 0.05 < acc["odom_relations"]["trans_mean"]
    assert "relations: translation" in res.output
    res = invoke("compare", sim_log, "--assoc", "icnn,pca", "--out", tmp_path / "c", *args)
    assert res.exit_code == 0, res.output
    rows = read_csv(tmp_path / "c" / "comparison.csv")
    assert np.all(rows["rel_trans_mean"] < rows["odom_rel_trans_mean"])


def test_output_columns_extend_the_interface_and_never_change_it():
    """INTERFACE.md's columns come first and in order; ours are appended after them (every CSV it
    names: loops.csv's were once written under names of our own)."""
    from cornerslam_cli.report.tables import (
        LINES_COLUMNS,
        LOOP_COLUMNS,
        MAP_COLUMNS,
        TIMING_COLUMNS,
        TRAJECTORY_COLUMNS,
    )

    interface = {
        "step,stamp,x,y,theta,odom_x,odom_y,odom_theta,var_x,var_y,var_theta": TRAJECTORY_COLUMNS,
        "id,x,y,phi,var_x,var_y,cov_xy,var_phi,first_step,last_step,n_obs": MAP_COLUMNS,
        "step,x1,y1,x2,y2": LINES_COLUMNS,
        "step,stamp,n_points,n_lines,n_corners,n_candidates,n_matched,n_new,n_landmarks,"
        "t_extract,t_predict,t_match,t_update,t_total": TIMING_COLUMNS,
        "step,submap,other_submap,dx,dy,dtheta,n_corners,fitness,accepted": LOOP_COLUMNS,
    }
    for given, ours in interface.items():
        names = given.split(",")
        assert list(ours[: len(names)]) == names, given


# ---------------------------------------------------------------------------- config
@pytest.mark.parametrize("preset", ["none", "sick_lms_1deg", "auto"])
def test_config_of_a_log_that_does_not_exist_exits_2(preset, tmp_path):
    """With --preset none the LOG was never opened, so a wrong path printed a config, exit 0."""
    res = invoke("config", tmp_path / "nope.mcap", "--preset", preset)
    assert res.exit_code == 2 and f"log '{tmp_path / 'nope.mcap'}' does not exist" in res.output, res.output


def test_config_prints_the_resolved_config_that_run_uses(tmp_path):
    """`cornerslam config LOG --set ...` prints what `run LOG --set ...` resolves (preset chosen from
    the log's scans); fed back as --config it gives the same config (the same hash), and without a
    log it is configs/default.yaml without its first comments (the keys a laser preset sets commented
    out: as --config it leaves each log its preset)."""
    import yaml

    from cornerslam_cli.config import Config, dump_config

    log = Path(__file__).resolve().parents[1] / "sample_logs" / "intel_cut.clf"
    res = invoke("config", log, "--set", "ekf.alpha1=0.07")
    assert res.exit_code == 0, res.output
    printed = yaml.safe_load(res.stdout)
    assert printed["ekf"]["alpha1"] == 0.07 and printed["input"]["laser_preset"] == "sick_lms_1deg"
    (tmp_path / "c.yaml").write_text(res.stdout)
    direct = invoke("run", log, "--set", "ekf.alpha1=0.07", "--out", tmp_path / "a", "-q")
    via_file = invoke("run", log, "--config", tmp_path / "c.yaml", "--out", tmp_path / "b", "-q")
    assert direct.exit_code == 0 and via_file.exit_code == 0, (direct.output, via_file.output)
    hashes = [json.loads((tmp_path / d / "summary.json").read_text())["hashes"]["config"] for d in "ab"]
    assert hashes[0] == hashes[1]
    default = (Path(__file__).resolve().parents[1] / "configs" / "default.yaml").read_text()
    assert default.endswith(invoke("config").stdout)
    assert "\n  # model: piecewise\n" in default and yaml.safe_load(default)["sensor"] is None
    assert invoke("config", "--set", "sensor.model=linear").stdout.count("\n  model: linear\n") == 1
    given = invoke("config", "--set", "sensor.model=piecewise", "--set", "lines.min_points=6").stdout
    assert "\n  model: piecewise\n" in given and "\n  min_points: 6\n" in given  # given: kept, if defaults
    assert "\n  # a: 0.01\n" in given
    # a --config file's keys are kept as the --set's; the preset's others stay commented out (a probe: `config
    # --config FILE` pinned the built-in sensor model, which as --config then replaced every log's preset's)
    (tmp_path / "mine.yaml").write_text("sensor:\n  sigma_r_rel: 0.02\nekf:\n  alpha1: 0.07\n")
    mine = invoke("config", "--config", tmp_path / "mine.yaml").stdout
    assert "\n  sigma_r_rel: 0.02\n" in mine and "\n  # model: piecewise\n" in mine and "alpha1: 0.07" in mine
    assert invoke("config", "--config", "/dev/null").stdout == invoke("config").stdout
    none = Config(input=dataclasses.replace(Config().input, laser_preset="none"))
    assert invoke("config", "--preset", "none").stdout == dump_config(none)  # (no preset: every key)
    res = invoke("config", "--preset", "hokuyo_urg04lx")
    assert yaml.safe_load(res.stdout)["input"]["laser_preset"] == "hokuyo_urg04lx"
    one_line_error(
        invoke("config", "--preset", "hokuyo"),
        "invalid value for '--preset': 'hokuyo' is not a laser preset",
        "hokuyo_urg04lx",
    )
    one_line_error(invoke("config", "--set", "ekf.alpha1=nan"), "ekf.alpha1")


def test_config_errors_say_where_the_key_was_given_and_topic_options_are_names(tmp_path):
    log = small_log(tmp_path / "a.mcap")
    cfg = tmp_path / "mine.yaml"
    cfg.write_text("ekf:\n  alpha1: 0.1\nscan_match:\n  window: -2\n")
    one_line_error(
        invoke("run", log, "--config", cfg, "--out", tmp_path / "o1"), f"'{cfg}' line 4:", "scan_match.window"
    )
    one_line_error(
        invoke("run", log, "--set", "ekf.alpha1=x", "--out", tmp_path / "o2"), "--set 'ekf.alpha1=x':"
    )
    # a topic option's text is a name, not YAML: 'yes' is a topic (not the boolean), and it is missing
    one_line_error(invoke("run", log, "--scan-topic", "yes", "--out", tmp_path / "o3"), "no topic 'yes'")
    # a bad --sweep value is named once, as the --sweep it is
    r = invoke("batch", log, "--sweep", "scan_match.window=10,ab", "--out", tmp_path / "o4")
    one_line_error(r, "--sweep scan_match.window=ab: config key 'scan_match.window' must be an integer")
    assert "--set" not in r.stderr
    assert not any((tmp_path / f"o{i}").exists() for i in range(1, 5))


def test_a_topic_option_past_u_ffff(tmp_path):
    # --scan-topic reaches the config as YAML: a character past U+FFFF is one character, not two halves
    log = small_log(tmp_path / "a.mcap", scan_topic="/\U0001f600")
    assert invoke("run", log, "--scan-topic", "/\U0001f600", "--out", tmp_path / "o", "-q").exit_code == 0


@pytest.mark.parametrize(
    ("log", "key", "hint"),
    [
        ("sim_office.mcap", "input.scan_topic", "check --set input.scan_topic=TOPIC; `cornerslam info LOG`"),
        ("intel_cut.clf", "input.scan_topic", "choose one of them with --set input.scan_topic=TOPIC)"),
        ("intel_cut.clf", "input.odom_topic", "choose one with --set input.odom_topic=TOPIC: ODOM or"),
    ],
)
def test_a_topic_hint_names_what_the_command_takes(tmp_path, log, key, hint):
    """`config --set input.scan_topic=/nope` said "check --scan-topic", an option config does not have
    (nor batch): a command without it is told the --set of its key; run keeps its option."""
    sample = Path(__file__).resolve().parents[1] / "sample_logs" / log
    r = invoke("config", sample, "--set", f"{key}=/nope")
    one_line_error(r, "no '/nope' lines" if log.endswith(".clf") else "no topic '/nope'", hint)
    assert "-topic" not in r.stderr
    r = invoke("batch", sample, "--set", f"{key}=/nope", "--out", tmp_path / "b", "-q")
    assert r.exit_code == 2 and hint in (tmp_path / "b" / "batch.csv").read_text()
    option = "--" + key.split(".")[1].replace("_", "-")
    r = invoke("run", sample, option, "/nope", "--out", tmp_path / "r")
    one_line_error(r, f"with {option}" if "choose" in hint else f"check {option};")
    assert "--set" not in r.stderr


def test_an_empty_preset_option_is_a_usage_error_naming_the_choices():
    """`config --preset ''` (an unset shell variable) printed the automatic preset's config, exit 0."""
    r = invoke("config", "--preset", "")
    one_line_error(
        r, "invalid value for '--preset': '' names no laser preset (choices: auto, none, sick_lms_1deg"
    )
    assert r.stdout == ""
    # an unknown one is --preset's too (the config named its key input.laser_preset: an evo-user probe)
    r = invoke("config", "--preset", "bogus")
    assert "(choices: auto, none," in r.stderr and "input.laser_preset" not in r.stderr
    r = invoke("config", "--preset", "hokuyo_270")  # (the closest still offered: a review)
    assert "is not a laser preset (did you mean 'hokuyo_270deg'? choices: auto, none," in r.stderr


@pytest.mark.parametrize(
    "args, option",
    [
        (["run", "LOG.mcap", "--scan-topic", ""], "--scan-topic"),
        (["compare", "LOG.mcap", "--odom-topic", ""], "--odom-topic"),
        (["info", "LOG.mcap", "--scan-topic="], "--scan-topic"),
        (["extract", "LOG.mcap", "--step", "0", "--odom-topic", ""], "--odom-topic"),
    ],
)
def test_an_empty_topic_option_is_a_usage_error(args, option, tmp_path, monkeypatch):
    """`--scan-topic "$TOPIC"` with TOPIC unset was taken as not given: the topic found by message
    type was run, exit 0, without a word."""
    monkeypatch.chdir(tmp_path)
    one_line_error(invoke(*args), f"invalid value for '{option}': '' names no topic")
    assert list(tmp_path.iterdir()) == []


def test_a_bad_preset_option_is_named_as_the_options_value_not_a_set():
    r = invoke("config", "--preset", "nope")
    one_line_error(r, "invalid value for '--preset': 'nope' is not a laser preset")
    assert "--set" not in r.stderr


@pytest.mark.parametrize(
    "args",
    [
        ["run", "LOG.mcap", "--out", "OUT"],
        ["compare", "LOG.mcap", "--out", "OUT"],
        ["evaluate", "OUT", "--ground-truth", "gt.tum"],
    ],
)
def test_time_offset_without_relations_is_a_usage_error(args, tmp_path, monkeypatch):
    """--time-offset shifts the relations' times only: with --ground-truth alone (or nothing) it was
    silently ignored, exit 0, as if the user's clock correction had been applied."""
    monkeypatch.chdir(tmp_path)
    res = invoke(*args, "--time-offset", 5)
    one_line_error(res, "--time-offset", "--relations")
    assert list(tmp_path.iterdir()) == []  # refused before any work


@pytest.mark.parametrize(
    "args, name",
    [
        (["run", ""], "'LOG'"),
        (["info", ""], "'LOG'"),
        (["batch", "LOG.mcap", "", "--out", "b"], "'LOGS...'"),
        (["evaluate", "", "--ground-truth", "gt.tum"], "'OUTDIR'"),
        (["config", "--config", ""], "'--config'"),
        (["run", "LOG.mcap", "--mcap-out", ""], "'--mcap-out'"),
        (["run", "LOG.mcap", "--ground-truth", ""], "'--ground-truth'"),
        (["simulate", ""], "'OUT.mcap'"),
    ],
)
def test_an_empty_path_is_refused_by_name(args, name, tmp_path, monkeypatch):
    """`cornerslam run "$LOG"` with LOG unset: '' was read as '.', and the error named "directory '.'"
    (the config "file '.'"); an empty --mcap-out / --ground-truth was taken as not given, silently."""
    monkeypatch.chdir(tmp_path)
    one_line_error(invoke(*args), f"invalid value for {name}: '' names no file")
    assert list(tmp_path.iterdir()) == []


def test_a_log_name_with_control_characters_reaches_the_terminal_escaped(tmp_path):
    """A file name holding a newline and an escape sequence split a warning in two and coloured the
    terminal: the warnings and the run's report print it escaped, as repr does."""
    sample = Path(__file__).resolve().parents[1] / "sample_logs" / "intel_cut.clf"
    log = tmp_path / "new\nline\x1b[31m.clf"
    log.write_bytes(sample.read_bytes())
    res = CliRunner().invoke(cli, ["run", str(log), "--max-scans", "5", "--out", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    printed = res.stdout + res.stderr
    assert "\x1b" not in printed and "line\\x1b[31m.clf" in printed
    warning = next(line for line in res.stderr.splitlines() if line.startswith("WARNING"))
    assert "new\\nline" in warning  # one line, the newline shown as \n
    report = next(line for line in res.stdout.splitlines() if "5 steps" in line)
    assert report.startswith(str(tmp_path)) and "new\\nline" in report


def test_the_configs_warnings_are_in_summary_json_too(tmp_path):
    """A pinned laser preset that is not the log's laser is warned about while the config resolves,
    before the log is opened for the run: summary.json's warnings lacked it (said on the terminal only,
    so a run read later looked clean). Now run's, each of compare's runs' and each batch combination's
    summary.json keep it, and the terminal still says it once."""
    log, pinned = (
        Path(__file__).parent.parent / "sample_logs" / "intel_cut.clf",
        "input.laser_preset=hokuyo_urg04lx",
    )
    common = ["--set", pinned, "--set", "submaps.enabled=false", "-q"]

    def mismatch(lines):
        return [w for w in lines if "input.laser_preset 'hokuyo_urg04lx' is for" in w]

    res = invoke("run", log, "--out", tmp_path / "run", "--max-scans", 15, *common[:-1])
    assert res.exit_code == 0, res.output
    assert len(mismatch(res.stderr.splitlines())) == 1
    summaries = [tmp_path / "run" / "summary.json"]
    res = invoke("compare", log, "--assoc", "icnn,pca", "--out", tmp_path / "cmp", "--max-scans", 15, *common)
    assert res.exit_code == 0, res.output
    summaries += [tmp_path / "cmp" / a / "summary.json" for a in ("icnn", "pca")]
    res = invoke("batch", log, "--assoc", "icnn", "--out", tmp_path / "batch", "--jobs", 1, *common)
    assert res.exit_code == 0, res.output
    summaries += list((tmp_path / "batch").glob("*/summary.json"))
    assert len(summaries) == 4
    for s in summaries:
        assert len(mismatch(json.loads(s.read_text())["warnings"])) == 1, s


def test_verbosity_help_says_only_what_the_command_has():
    """info, evaluate, extract and config draw no progress bar and run no filter: their -q/-v help said
    "no progress bar" and "-vv every filter step" (a new-user walkthrough)."""
    for cmd in ("info", "evaluate", "extract", "config", "simulate"):
        text = invoke(cmd, "--help").output
        assert "filter step" not in text and ("progress bar" in text) == (cmd == "simulate"), cmd
    for cmd in ("run", "compare", "batch"):
        text = invoke(cmd, "--help").output
        assert "no progress bar" in text and "every filter step" in text, cmd


def test_extract_counts_read_in_the_singular_for_one():
    """extract's text and figure title read "1 corners" (a new-user walkthrough)."""
    from cornerslam_cli.report.extract_plot import _counted

    assert [_counted(n, "corner") for n in (0, 1, 2)] == ["0 corners", "1 corner", "2 corners"]


def test_compare_and_batch_say_the_whole_path_they_wrote_as_run_does(sim_log, tmp_path, monkeypatch):
    """run printed `wrote /abs/path`, compare and batch the path as given (a new-user walkthrough)."""
    monkeypatch.chdir(tmp_path)
    res = invoke("compare", sim_log, "--assoc", "icnn", "--out", "c", "--max-scans", "8")
    assert (
        res.exit_code == 0
        and f"wrote {tmp_path / 'c'} (report: {tmp_path / 'c' / 'report.html'})" in res.output
    )
    res = invoke("batch", sim_log, "--assoc", "icnn", "--out", "b", "--jobs", "1")
    assert res.exit_code == 0 and f"wrote {tmp_path / 'b' / 'batch.csv'}" in res.output, res.output


def test_two_settings_after_one_set_are_told_to_take_a_set_each(sim_log, tmp_path):
    """`--set a.b=1 c.d=2` (as the README itself once wrote): run said only "unexpected extra arguments",
    config took c.d=2 for the LOG and said it did not exist (a probe). A real file named like a setting
    is still a log."""
    res = invoke("run", sim_log, "--set", "input.laser.x=0.1", "input.laser.y=0", "--out", tmp_path / "o")
    one_line_error(res, "got unexpected extra argument (input.laser.y=0): give --set before each KEY=VALUE")
    res = invoke("config", "--set", "scan_match.window=5", "ekf.alpha1=0.1")
    one_line_error(res, "'ekf.alpha1=0.1' is no file but a setting: give --set before each KEY=VALUE")
    res = invoke("batch", sim_log, "--sweep", "ekf.alpha1=0.1,0.2", "ekf.alpha2=0.1", "--out", tmp_path / "b")
    one_line_error(res, "'ekf.alpha2=0.1' is no file but a setting: give --set or --sweep before each")
    named = tmp_path / "ekf.alpha1=0.1"
    named.write_bytes(Path(sim_log).read_bytes())
    assert invoke("config", named).exit_code == 0
    assert not (tmp_path / "o").exists() and not (tmp_path / "b").exists()
    # outputs named like a setting are names (a review: --out scan_match.window=5 was refused)
    out = tmp_path / "scan_match.window=5"
    assert invoke("run", sim_log, "--max-scans", 5, "--out", out, "-q").exit_code == 0 and out.is_dir()


def test_a_given_out_holding_another_logs_output_says_it_is_replaced(tmp_path):
    """The default --out refuses another log's output (two logs of one stem); a given --out replaced it
    without a word (a probe). Now said once, before any work; the same log's output is no news."""
    a, b, out = small_log(tmp_path / "a.mcap", n=6), small_log(tmp_path / "b.mcap", n=6), tmp_path / "o"
    assert invoke("run", a, "--out", out, "-q").exit_code == 0
    res = invoke("run", b, "--out", out)
    assert res.exit_code == 0, res.output
    said = f"'{out}' holds the output of '{a}': it is replaced by this run's of '{b}' (give another --out"
    assert res.stderr.count(said) == 1, res.stderr
    assert json.loads((out / "summary.json").read_text())["input"]["log"] == str(b)
    assert "holds the output of" not in invoke("run", b, "--out", out).stderr


@pytest.mark.parametrize(
    ("command", "option"), [("batch", "--jobs"), ("compare", "--jobs"), ("run", "--max-scans")]
)
def test_a_count_that_is_no_number_is_said_to_be_no_integer(command, option, tmp_path):
    """click's IntRange said "'abc' is not a valid integer range" (a probe)."""
    log = Path(__file__).resolve().parents[1] / "sample_logs" / "intel_cut.clf"
    res = invoke(command, log, option, "abc", "--out", tmp_path / "o")
    one_line_error(res, f"invalid value for '{option}': 'abc' is not a valid integer (see ")


def test_a_results_mcap_name_without_the_mcap_suffix_is_written_and_warned(tmp_path):
    """rosbag2 and Foxglove choose their reader by the .mcap suffix: a name without it played nowhere
    without a word (a ROS-user probe)."""
    log = Path(__file__).resolve().parents[1] / "sample_logs" / "intel_cut.clf"
    res = invoke("run", log, "--max-scans", "5", "--out", tmp_path / "o", "--mcap-out", tmp_path / "res")
    assert res.exit_code == 0 and (tmp_path / "res").is_file(), res.output
    assert f"--mcap-out '{tmp_path / 'res'}' does not end in .mcap" in res.stderr
    res = invoke("run", log, "--max-scans", "5", "--out", tmp_path / "p", "--mcap-out", tmp_path / "r.MCAP")
    assert res.exit_code == 0 and "does not end in .mcap" not in res.stderr
