"""Loop closing in what run and compare report (issue 16): comparison.csv's appended columns and the
printed tables, the run's summary line, the accepted closures on the map, report.html's loops table.

Through the CLI on the session's sim log with small submaps (8 steps: loop closures accepted and
refused on one lap), and with submaps off (the paper's single map: no loop-closing output at all).
"""

from __future__ import annotations

import csv
import json
import logging
import re
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from _results_helpers import ate, make_summary
from click.testing import CliRunner
from test_report_html import Page, table_with_header

from cornerslam_cli.cli import cli
from cornerslam_cli.report import plots
from cornerslam_cli.report.html import ACCEPTED_REASON, loop_reason_rows
from cornerslam_cli.report.run_dir import load_run, submap_origins
from cornerslam_cli.report.tables import COMPARISON_COLUMNS, read_csv
from cornerslam_cli.report.text import comparison_lines, summary_lines
from cornerslam_cli.results import Accuracy

ASSOCS = ["icnn", "pca"]
SMALL_SUBMAPS = ["--set", "submaps.max_steps=8"]
# comparison.csv's columns before issue 16: they stay first and in this order
BEFORE = (
    "assoc,steps,landmarks,matched_total,t_match_total,t_match_max,t_total,ate_rmse,odom_ate_rmse,"
    "rpe_trans_per_m,wall_time,budget_hits,rel_trans_mean,rel_trans_std,rel_rot_mean_deg,"
    "odom_rel_trans_mean,scan_odom_ate_rmse,scan_odom_rel_trans_mean"
).split(",")
LOOPS = ["submaps", "loops_accepted", "loops_rejected", "online_ate_rmse", "refine_factors", "t_loop"]


def invoke(*args: str) -> str:
    res = CliRunner().invoke(cli, list(args))
    assert res.exit_code == 0, res.output
    return res.output


@pytest.fixture(scope="module")
def compared(tmp_path_factory, sim_log) -> tuple[Path, str]:
    """`cornerslam compare` with small submaps: (its directory, what it printed)."""
    out = tmp_path_factory.mktemp("loops") / "cmp"
    gt = str(sim_log.with_suffix(".gt.tum"))
    text = invoke("compare", str(sim_log), "--assoc", ",".join(ASSOCS), "--out", str(out),
                  "--ground-truth", gt, *SMALL_SUBMAPS)  # fmt: skip
    return out, text


@pytest.fixture(scope="module")
def single_map(tmp_path_factory, sim_log) -> tuple[Path, str]:
    """`cornerslam compare` of the paper's single map (submaps off) on the log's first 40 scans."""
    out = tmp_path_factory.mktemp("loops") / "single"
    text = invoke("compare", str(sim_log), "--assoc", ",".join(ASSOCS), "--out", str(out),
                  "--max-scans", "40", "--set", "submaps.enabled=false")  # fmt: skip
    return out, text


def summary_of(run_dir: Path) -> dict:
    return json.loads((run_dir / "summary.json").read_text())


def raw_rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_comparison_csv_appends_each_associators_loop_closing(compared):
    out, _ = compared
    header = (out / "comparison.csv").read_text().splitlines()[0].split(",")
    assert header == COMPARISON_COLUMNS == BEFORE + LOOPS
    rows = raw_rows(out / "comparison.csv")
    assert [r["assoc"] for r in rows] == ASSOCS
    for r in rows:
        s, loops = summary_of(out / r["assoc"]), read_csv(out / r["assoc"] / "loops.csv")
        c = s["counts"]
        assert (
            int(r["submaps"])
            == c["submaps"]
            == len(set(read_csv(out / r["assoc"] / "trajectory.csv")["submap"]))
        )
        assert int(r["loops_accepted"]) == c["loops_accepted"] == int(loops["accepted"].sum())
        assert int(r["loops_rejected"]) == c["loops_rejected"] == int((loops["accepted"] == 0).sum())
        assert float(r["online_ate_rmse"]) == pytest.approx(s["accuracy"]["online_ate"]["rmse"], abs=1e-9)
        assert r["refine_factors"] == "" and "refine_factors" not in c  # graph.refine off
        assert float(r["t_loop"]) == pytest.approx(s["timing"]["t_loop"], abs=1e-9)
        assert s["timing"]["t_loop"] > 0
    assert sum(int(r["loops_accepted"]) for r in rows) > 0  # something to compare
    assert all(int(r["loops_rejected"]) > 0 for r in rows)


def test_compare_prints_the_loop_closing_columns(compared):
    out, text = compared
    lines = text.splitlines()
    (head,) = [line for line in lines if line.startswith("assoc")]
    assert head.endswith(" ATE m odom ATE m submaps loops ok refused online ATE m")
    for a in ASSOCS:
        (row,) = [line for line in lines if line.startswith(f"{a} ")]
        s = summary_of(out / a)
        c, online = s["counts"], s["accuracy"]["online_ate"]["rmse"]
        assert row.split()[-4:] == [str(c["submaps"]), str(c["loops_accepted"]), str(c["loops_rejected"]),
                                    f"{online:.3f}"]  # fmt: skip
        assert len(row) == len(head)  # the cells line up under the header


def test_without_submaps_the_loop_cells_are_empty_and_nothing_is_said_of_loops(single_map):
    out, text = single_map
    rows = raw_rows(out / "comparison.csv")
    assert [r["assoc"] for r in rows] == ASSOCS
    assert all(r[k] == "" for r in rows for k in LOOPS)
    assert all(r["steps"] == "40" for r in rows)  # the other cells as before
    (head,) = [line for line in text.splitlines() if line.startswith("assoc")]
    assert head.endswith("ATE m odom ATE m") and "submaps" not in text  # the table as before issue 16
    html = (out / "report.html").read_text(encoding="utf-8")
    assert "Loop closures" not in html
    assert not any((out / a / "loops.csv").exists() for a in ASSOCS)


def test_run_prints_one_loop_closing_line_only_with_submaps(tmp_path, sim_log):
    text = invoke("run", str(sim_log), "--out", str(tmp_path / "on"), "--max-scans", "60", *SMALL_SUBMAPS)
    s = summary_of(tmp_path / "on")
    c, t_loop = s["counts"], s["timing"]["t_loop"]
    loop_lines = [line for line in text.splitlines() if line.startswith("submaps:")]
    assert loop_lines == [
        f"submaps: {c['submaps']}, loop closures {c['loops_accepted']} accepted, {c['loops_rejected']} "
        f"refused, loop time {t_loop:.2f}s"
    ]
    assert c["submaps"] == 8  # 60 steps of 8
    text = invoke("run", str(sim_log), "--out", str(tmp_path / "off"), "--max-scans", "60",
                  "--set", "submaps.enabled=false")  # fmt: skip
    assert not any(line.startswith("submaps") or "loop" in line for line in text.splitlines()[:-1])


def test_summary_and_comparison_lines_with_submaps():
    acc = Accuracy(ground_truth="gt.tum", ate=ate(0.0123), odom_ate=ate(1.4249), online_ate=ate(0.0456))
    s = make_summary(accuracy=acc, submaps=12, loops_accepted=3, loops_rejected=17)
    s = replace(s, timing=replace(s.timing, t_loop=0.4567))
    assert summary_lines(s)[4] == "submaps: 12, loop closures 3 accepted, 17 refused, loop time 0.46s"
    assert summary_lines(s)[5].startswith("ATE RMSE 0.012 m")
    single = make_summary("icnn", accuracy=replace(acc, online_ate=None))
    assert not any(line.startswith("submaps") for line in summary_lines(single))
    assert comparison_lines([single, s]) == [
        "assoc   steps landmarks  matched  t_match s   max ms  t_total s    ATE m odom ATE m"
        " submaps loops ok refused online ATE m",
        "icnn      500        88     2777      0.500     12.3       4.57    0.012      1.425"
        "       -        -       -            -",
        "pca       500        88     2777      0.500     12.3       4.57    0.012      1.425"
        "      12        3      17        0.046",
    ]
    assert comparison_lines([single])[0].endswith("ATE m odom ATE m")  # no loop columns without submaps


def expected_closures(run_dir: Path) -> np.ndarray:
    """The accepted closures' segments worked out row by row from the CSVs: submap s's origin is the
    pose at the last step of submap s − 1 (step 0 for submap 0)."""
    traj = raw_rows(run_dir / "trajectory.csv")
    origin = {0: (float(traj[0]["x"]), float(traj[0]["y"]))}
    for row, after in zip(traj, traj[1:], strict=False):
        if after["submap"] != row["submap"]:
            origin[int(after["submap"])] = (float(row["x"]), float(row["y"]))
    loops = [r for r in raw_rows(run_dir / "loops.csv") if r["accepted"] == "1"]
    return np.array([[origin[int(r["other_submap"])], origin[int(r["submap"])]] for r in loops])


def closure_line(ax):
    """The map's loop-closure artist (one Line2D: segments separated by NaN) and its label."""
    (line,) = [ln for ln in ax.get_lines() if ln.get_label().startswith("loop closures")]
    return line


def test_the_map_joins_the_submap_origins_of_each_accepted_closure(compared):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    for a in ASSOCS:
        run = load_run(compared[0] / a)
        want = expected_closures(run.out_dir)
        if len(want) == 0:
            continue
        np.testing.assert_allclose(run.loop_closures(), want, atol=1e-9)
        fig, ax = plt.subplots()
        try:
            plots._draw_map(ax, run)
            line = closure_line(ax)
            assert line.get_label() == f"loop closures ({len(want)} accepted)"
            xy = np.column_stack((line.get_xdata(), line.get_ydata())).astype(float)
            np.testing.assert_allclose(xy[~np.isnan(xy[:, 0])], want.reshape(-1, 2), atol=1e-9)
        finally:
            plt.close(fig)
    assert any(len(expected_closures(compared[0] / a)) for a in ASSOCS)


def test_submap_origins_are_the_last_pose_of_the_submap_before():
    submap = np.array([0, 0, 0, 1, 1, 2, 2, 2, 3])
    corrected = np.column_stack((np.arange(9.0), 10 + np.arange(9.0), np.zeros(9)))
    np.testing.assert_array_equal(submap_origins(submap, corrected), [[0, 10], [2, 12], [4, 14], [7, 17]])
    np.testing.assert_array_equal(submap_origins(np.zeros(3, int), corrected[:3]), [[0, 10]])
    assert submap_origins(np.zeros(0, int), corrected[:0]).shape == (0, 2)


def test_many_closures_are_one_thinner_fainter_artist():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rng = np.random.default_rng(3)
    drawn = []
    for k in (10, 1200):
        fig, ax = plt.subplots()
        try:
            plots._draw_loop_closures(ax, rng.uniform(0, 80, (k, 2, 2)))
            line = closure_line(ax)
            assert len(ax.get_lines()) == 1 and np.isnan(line.get_xdata()).sum() == k
            drawn.append((line.get_linewidth(), line.get_alpha()))
        finally:
            plt.close(fig)
    (lw_few, alpha_few), (lw_many, alpha_many) = drawn
    assert alpha_few is None or alpha_few == 1.0
    assert lw_many <= lw_few / 5 and alpha_many < 0.5


def test_closures_naming_an_unknown_submap_are_left_out_with_a_warning(compared, tmp_path, caplog):
    run_dir = tmp_path / "pca"
    shutil.copytree(compared[0] / "pca", run_dir)
    want = expected_closures(run_dir)
    text = (run_dir / "loops.csv").read_text().splitlines()
    text.append("999,5,400,0,0,0,5,0.9,1,1,0.5,")  # an edited row: submap 400 does not exist
    (run_dir / "loops.csv").write_text("\n".join(text) + "\n")
    with caplog.at_level(logging.WARNING, logger="cornerslam_cli.report.run_dir"):
        got = load_run(run_dir).loop_closures()
    np.testing.assert_allclose(got, want.reshape(-1, 2, 2), atol=1e-9)
    assert "1 accepted loop closure(s) name a submap that trajectory.csv does not have" in caplog.text


def test_closures_of_a_directory_written_before_the_interface_names_are_drawn(compared, tmp_path):
    """loops.csv was written as step,submap_from,submap_to,x,y,theta,corners,... before it took
    INTERFACE.md's names (submap = the closed one = submap_to): such a directory still draws its
    closures."""
    run_dir = tmp_path / "pca"
    shutil.copytree(compared[0] / "pca", run_dir)
    want = expected_closures(run_dir)
    rows = (run_dir / "loops.csv").read_text().splitlines()
    old = ["step,submap_from,submap_to,x,y,theta,corners,fitness,accepted,inlier,chi2,reason"]
    for line in rows[1:]:
        c = line.split(",")
        old.append(",".join([c[0], c[2], c[1], *c[3:]]))
    (run_dir / "loops.csv").write_text("\n".join(old) + "\n")
    assert len(want) > 0
    np.testing.assert_allclose(load_run(run_dir).loop_closures(), want.reshape(-1, 2, 2), atol=1e-9)


def test_compare_maps_count_each_associators_closures(compared, tmp_path, monkeypatch):
    out = tmp_path / "cmp"
    shutil.copytree(compared[0], out)
    drawn = {}

    def keep(fig, path):
        drawn[Path(path).name] = fig
        return path

    monkeypatch.setattr(plots, "_save", keep)
    plots._plot_compare_maps([load_run(out / a) for a in ASSOCS], "sim.mcap", out / "compare_maps.png")
    fig = drawn["compare_maps.png"]
    for ax, a in zip(fig.axes, ASSOCS, strict=False):
        n = summary_of(out / a)["counts"]["loops_accepted"]
        assert ax.get_title().splitlines()[0].endswith(f", {n} loop closures")
    (legend,) = fig.legends
    assert "loop closures" in [t.get_text() for t in legend.get_texts()]  # once, without a count


def test_report_counts_the_candidates_by_reason(compared):
    out, _ = compared
    page = Page((out / "report.html").read_text(encoding="utf-8"))
    tables = [t for t in page.tables if t and t[0][0][0] == "outcome"]
    assert len(tables) == len(ASSOCS)  # one per associator's section, in order
    for a, table in zip(ASSOCS, tables, strict=True):
        loops, c = read_csv(out / a / "loops.csv"), summary_of(out / a)["counts"]
        rows = [(r[0][0], r[1][0], int(r[2][0])) for r in table[1:]]
        assert sum(n for _, _, n in rows) == len(loops["step"])
        assert sum(n for o, _, n in rows if o == "accepted") == c["loops_accepted"]
        assert sum(n for o, _, n in rows if o == "refused") == c["loops_rejected"]
        assert all(not re.search(r"\d", reason) for _, reason, _ in rows)
    facts = {r[0][0]: r[1][0] for t in page.tables for r in t if len(r) == 2}
    assert facts["loop closures accepted"] == str(summary_of(out / ASSOCS[-1])["counts"]["loops_accepted"])
    rows = table_with_header(page, "outcome")
    assert [c[0] for c in rows[0]] == ["outcome", "reason", "candidates"]


def test_loop_reasons_count_together_without_their_figures():
    loops = {
        "accepted": np.array([1.0, 0, 0, 1, 0, 1, 0, 0]),
        "reason": np.array(["", "few corners", "disagrees with the graph (chi2 12.5)", "",
                            "disagrees with the graph (chi2 6839543.0)", "2 closures agree against the graph",
                            "closures of this submap disagree on where it is (aliasing)", "few corners"],
                           dtype=object),
    }  # fmt: skip
    assert loop_reason_rows(loops) == [
        ["accepted", ACCEPTED_REASON, 2],
        ["accepted", "closures agree against the graph", 1],
        ["refused", "disagrees with the graph", 2],
        ["refused", "few corners", 2],
        ["refused", "closures of this submap disagree on where it is (aliasing)", 1],
    ]
    empty = {"accepted": np.zeros(0), "reason": np.zeros(0)}  # loops.csv with its header only
    assert loop_reason_rows(empty) == []


def test_a_run_directory_from_before_submaps_is_drawn_and_reported_without_loops(compared, tmp_path):
    """Written before issue 16: no trajectory.csv submap column, no loops.csv, no loop counts."""
    from cornerslam_cli.report.html import write_report

    run_dir = tmp_path / "old"
    shutil.copytree(compared[0] / "pca", run_dir, ignore=shutil.ignore_patterns("*.png", "report.html"))
    (run_dir / "loops.csv").unlink()
    rows = raw_rows(run_dir / "trajectory.csv")
    columns = [c for c in rows[0] if c not in ("online_x", "online_y", "online_theta", "submap")]
    lines = [",".join(columns)] + [",".join(r[c] for c in columns) for r in rows]
    (run_dir / "trajectory.csv").write_text("\n".join(lines) + "\n")
    s = summary_of(run_dir)
    for key in ("submaps", "loops_accepted", "loops_rejected"):
        del s["counts"][key]
    del s["timing"]["t_loop"], s["accuracy"]["online_ate"]
    (run_dir / "summary.json").write_text(json.dumps(s))
    run = load_run(run_dir)
    assert run.submap is None and run.loops is None and run.loop_closures().shape == (0, 2, 2)
    text = write_report(run_dir).read_text(encoding="utf-8")
    assert "Loop closures" not in text and (run_dir / "map.png").is_file()


def test_a_missing_loops_csv_is_said_not_taken_for_no_candidate(compared, tmp_path):
    from cornerslam_cli.report.html import write_report

    run_dir = tmp_path / "pca"
    shutil.copytree(compared[0] / "pca", run_dir, ignore=shutil.ignore_patterns("report.html"))
    (run_dir / "loops.csv").unlink()
    text = write_report(run_dir).read_text(encoding="utf-8")
    assert "Loop closures" in text and "no loops.csv" in text and "no loop-closure candidate" not in text
    assert load_run(run_dir).loop_closures().shape == (0, 2, 2)


def test_a_run_without_loop_candidates_says_so(tmp_path, sim_log):
    out = tmp_path / "short"
    text = invoke("run", str(sim_log), "--out", str(out), "--max-scans", "12", "--plot", *SMALL_SUBMAPS)
    c = summary_of(out)["counts"]
    assert (c["submaps"], c["loops_accepted"], c["loops_rejected"]) == (2, 0, 0)
    assert "submaps: 2, loop closures 0 accepted, 0 refused" in text
    assert len(raw_rows(out / "loops.csv")) == 0
    html = (out / "report.html").read_text(encoding="utf-8")
    assert "Loop closures" in html and "no loop-closure candidate" in html
    assert load_run(out).loop_closures().shape == (0, 2, 2)


def test_report_compares_the_associators_on_loop_closing_in_a_table_of_its_own(compared, single_map):
    out, _ = compared
    page = Page((out / "report.html").read_text(encoding="utf-8"))
    main, loops = [t for t in page.tables if t and t[0] and t[0][0][0] == "assoc"]
    assert [c[0] for c in main[0]] == BEFORE
    assert [c[0] for c in loops[0]] == ["assoc", *LOOPS[:4], "t_loop"]  # refine_factors: empty without refine
    cells = raw_rows(out / "comparison.csv")
    for row, r in zip(loops[1:], cells, strict=True):
        assert [c[0] for c in row[:4]] == [r["assoc"], r["submaps"], r["loops_accepted"], r["loops_rejected"]]
        assert float(row[4][0]) == pytest.approx(float(r["online_ate_rmse"]), rel=1e-3)
        assert float(row[5][0]) == pytest.approx(float(r["t_loop"]), rel=1e-3, abs=1e-6)
    for col, name in ((4, "online_ate_rmse"), (5, "t_loop")):  # (t_loop ranked: the runs took turns)
        values = [float(r[name]) for r in cells]
        marked = [i for i, row in enumerate(loops[1:]) if "best" in row[col][1]]
        assert marked == ([] if len(set(values)) < 2 else [values.index(min(values))]), name
    page = Page((single_map[0] / "report.html").read_text(encoding="utf-8"))
    (main,) = [t for t in page.tables if t and t[0] and t[0][0][0] == "assoc"]  # no loop-closing table
    assert [c[0] for c in main[0]] == BEFORE


def test_the_landmark_curves_count_the_whole_map_not_the_open_submap(compared, single_map):
    """Fig 17's and Fig 19's landmark curves: timing.csv's n_landmarks counts the open submap's, so
    they drew a sawtooth ending at the last submap's count (24 on the simulated office against 177 in
    map.csv); each closed submap's count is now added to the steps after it — at the end map.csv's rows
    (each run of a comparison, and a single map's curve as it was)."""
    for a in ASSOCS:
        run = load_run(compared[0] / a)
        total = run.map_landmarks()
        assert total[-1] == len(run.landmarks["id"]) and np.all(np.diff(total) >= -1)  # (a landmark may go)
        assert len(np.unique(run.submap)) > 1 and total[-1] > run.timing["n_landmarks"][-1]
        closes = np.flatnonzero(np.diff(run.submap)) + 1  # first steps of each later submap
        want = run.timing["n_landmarks"].copy()
        for c in closes:  # by hand: a closed submap's last count carried on
            want[c:] += run.timing["n_landmarks"][c - 1]
        np.testing.assert_array_equal(total, want)
    run = load_run(single_map[0] / ASSOCS[0])
    np.testing.assert_array_equal(run.map_landmarks(), run.timing["n_landmarks"])
    assert run.map_landmarks()[-1] == len(run.landmarks["id"])
