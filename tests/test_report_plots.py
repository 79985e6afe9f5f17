"""Figures of a run and a comparison (report/plots.py), drawn from a real small run of the sim log."""

from __future__ import annotations

import dataclasses
import logging
import math
import shutil
import struct
from pathlib import Path

import numpy as np
import pytest

from cornerslam_cli.compare import compare
from cornerslam_cli.config import load_config
from cornerslam_cli.geometry import relative
from cornerslam_cli.report.plots import (
    COMPARE_FIGURES,
    MAX_STEPS_DRAWN,
    RUN_FIGURES,
    STEP_BINS,
    binned,
    plot_compare,
    plot_run,
    step_bins,
)
from cornerslam_cli.report.run_dir import ellipse_polygons, load_run, odom_in_map

ASSOCS = ["icnn", "pca"]
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def make_report_outputs(tmp_path_factory, sim_log: Path) -> tuple[Path, Path]:
    """(run dir, compare dir) on the session's sim log, computed once per session and shared by the
    report tests (cached under the session's base temp dir). Copy them before writing into them.

    The run directory is a copy of the compare's ``pca`` run: the same files ``cornerslam run`` writes.
    """
    base = tmp_path_factory.getbasetemp() / "report_outputs"
    run_dir, cmp_dir = base / "run", base / "cmp"
    if not (base / "done").exists():
        compare(sim_log, load_config(), ASSOCS, cmp_dir, plots=False)  # the tests draw them
        shutil.copytree(cmp_dir / "pca", run_dir)
        (base / "done").touch()
    return run_dir, cmp_dir


def png_size(path: Path) -> tuple[int, int]:
    """(width, height) from a PNG's IHDR chunk; asserts the file is a PNG."""
    data = Path(path).read_bytes()
    assert data[:8] == PNG_SIGNATURE, f"{path} is not a PNG"
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


@pytest.fixture(scope="module")
def outputs(tmp_path_factory, sim_log):
    run_dir, cmp_dir = make_report_outputs(tmp_path_factory, sim_log)
    mine = tmp_path_factory.mktemp("plots")
    shutil.copytree(run_dir, mine / "run")
    shutil.copytree(cmp_dir, mine / "cmp")
    return mine / "run", mine / "cmp"


@pytest.fixture(scope="module")
def run_pngs(outputs):
    return plot_run(outputs[0])


COMPARE_PROGRESS: list[tuple[int, int, str]] = []  # what plot_compare reported while drawing


@pytest.fixture(scope="module")
def compare_pngs(outputs):
    return plot_compare(outputs[1], progress=lambda *a: COMPARE_PROGRESS.append(a))


def check_png(path: Path) -> None:
    assert path.is_file(), path
    w, h = png_size(path)
    assert 500 <= w <= 4000 and 300 <= h <= 4000, (path, w, h)
    assert path.stat().st_size > 10_000, f"{path} is suspiciously small (empty figure?)"


def test_plot_run_writes_every_figure(outputs, run_pngs):
    assert [p.name for p in run_pngs] == list(RUN_FIGURES)
    assert all(p.parent == outputs[0] for p in run_pngs)
    for p in run_pngs:
        check_png(p)


def test_plot_compare_writes_comparison_and_each_run(outputs, compare_pngs):
    cmp_dir = outputs[1]
    expected = [cmp_dir / n for n in COMPARE_FIGURES] + [cmp_dir / a / n for a in ASSOCS for n in RUN_FIGURES]
    assert sorted(compare_pngs) == sorted(expected)
    for p in expected:
        check_png(p)
    # its progress (compare's figures took 8–14 s on a long log with no line): one step per comparison
    # figure and per run's set, from 0 to all of them
    n = len(COMPARE_FIGURES) + len(ASSOCS)
    assert COMPARE_PROGRESS == [(k, n, "figures") for k in range(n)] + [(n, n, "figures")]
    # the side-by-side maps are wider than tall, one panel per associator
    w, h = png_size(cmp_dir / "compare_maps.png")
    assert w > 1.5 * h


def test_figures_leave_no_matplotlib_warning_on_stderr(outputs, tmp_path, caplog):
    """The maps' equal aspect widens the limits _frame_the_map fixed, as asked: matplotlib's "Ignoring
    fixed y limits to fulfill fixed data aspect" WARNING reached the user's stderr twice per `run --plot`
    (five times per `compare`), read as a fault."""
    import logging

    run_dir = tmp_path / "run"
    shutil.copytree(outputs[0], run_dir)
    with caplog.at_level(logging.WARNING):
        plot_run(run_dir)
    assert [r.getMessage() for r in caplog.records if r.name.startswith("matplotlib")] == []


def test_map_draws_every_landmark_ellipse_and_trajectory(outputs):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection, PolyCollection

    from cornerslam_cli.report.plots import _draw_map

    run = load_run(outputs[0])
    fig, ax = plt.subplots()
    try:
        _draw_map(ax, run)
        polys = [c for c in ax.collections if isinstance(c, PolyCollection)]
        segs = [c for c in ax.collections if isinstance(c, LineCollection)]
        assert len(polys) == 1 and len(polys[0].get_paths()) == len(run.landmarks["id"]) > 0
        assert len(segs) == 1 and len(segs[0].get_segments()) == len(run.lines["step"]) > 0
        labels = [line.get_label() for line in ax.get_lines()]
        # trajectory.tum's trajectory named as what it is: the pose graph's with the two levels (the
        # default), the EKF's with the single map (the legend said "corrected (EKF)" for both)
        assert run.summary.counts.submaps is not None
        assert {"odometry", "smoothed (pose graph)", "ground truth (aligned)"} <= set(labels)
        assert "corrected (EKF)" not in labels
        single = dataclasses.replace(
            run,
            summary=dataclasses.replace(
                run.summary, counts=dataclasses.replace(run.summary.counts, submaps=None)
            ),
        )
        ax.clear()
        _draw_map(ax, single)
        assert "corrected (EKF)" in [line.get_label() for line in ax.get_lines()]
        assert ax.get_xlabel() == "x [m]" and ax.get_ylabel() == "y [m]"
    finally:
        plt.close(fig)


def test_ground_truth_is_aligned_onto_the_corrected_trajectory(outputs):
    run = load_run(outputs[0])
    assert run.ground_truth is not None  # the sim log has sim.gt.tum beside it
    # the sim's ground truth starts at (5, 5); aligned, it must lie on the corrected trajectory
    d = np.linalg.norm(run.ground_truth[:, None, :2] - run.corrected[None, :, :2], axis=2).min(axis=1)
    assert np.max(d) < 0.5


def test_odometry_is_anchored_on_the_first_corrected_pose():
    rng = np.random.default_rng(3)
    odom = np.cumsum(rng.normal(0, 0.3, (20, 3)), axis=0) + [5.0, 5.0, 1.0]
    corrected = np.column_stack((rng.normal(0, 1, (20, 2)), rng.normal(0, 1, 20)))
    out = odom_in_map(odom, corrected)
    np.testing.assert_allclose(out[0], corrected[0], atol=1e-12)
    # a rigid motion: relative poses between steps are unchanged
    np.testing.assert_allclose(relative(out[:-1], out[1:]), relative(odom[:-1], odom[1:]), atol=1e-12)


def test_ellipse_polygons_lie_on_the_n_sigma_contour():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(5, 2, 2))
    cov = a @ a.transpose(0, 2, 1) + 0.01 * np.eye(2)
    xy = rng.normal(size=(5, 2))
    polys = ellipse_polygons(xy, cov, n_sigma=3.0, k=16)
    assert polys.shape == (5, 16, 2)
    for p, c, m in zip(polys, cov, xy, strict=True):
        d = p - m
        mahal = np.einsum("ki,ij,kj->k", d, np.linalg.inv(c), d)
        np.testing.assert_allclose(mahal, 9.0, rtol=1e-9)
    # axis-aligned: semi-axes 3σ = 6 m along x, 3 m along y
    box = ellipse_polygons(np.zeros((1, 2)), np.diag([4.0, 1.0])[None], k=64)[0]
    np.testing.assert_allclose(np.abs(box).max(axis=0), [6.0, 3.0], rtol=1e-3)


def test_binned_gives_each_bins_median_and_range():
    step = np.arange(10)
    v = np.array([1, 5, 3, np.nan, np.nan, np.nan, 2, 8, 4, 9], dtype=float)
    mid, med, lo, hi = binned(step, v, 3)
    np.testing.assert_array_equal(mid, [1, 4, 7, 9])
    np.testing.assert_array_equal(med, [3, np.nan, 4, 9])  # an all-NaN bin stays a gap
    np.testing.assert_array_equal(lo, [1, np.nan, 2, 9])
    np.testing.assert_array_equal(hi, [5, np.nan, 8, 9])
    assert step_bins(MAX_STEPS_DRAWN) == 1 and step_bins(MAX_STEPS_DRAWN + 1) == 5
    assert math.ceil(4800 / step_bins(4800)) <= STEP_BINS


def long_run(outputs, tmp_path: Path, n: int = 4800) -> Path:
    """The sim run stretched to ``n`` steps: timing.csv's rows repeated with fresh step numbers."""
    run = tmp_path / "long"
    shutil.copytree(outputs[0], run, ignore=shutil.ignore_patterns("*.png", "report.html"))
    lines = (run / "timing.csv").read_text().splitlines()
    body = [row.split(",", 1)[1] for row in lines[1:]]
    rows = [f"{i},{body[i % len(body)]}" for i in range(n)]
    (run / "timing.csv").write_text("\n".join([lines[0], *rows]) + "\n")
    return run


def test_long_runs_are_drawn_per_bin_not_as_a_solid_band(outputs, tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    from cornerslam_cli.report.plots import _plot_per_step

    run = long_run(outputs, tmp_path)
    t = load_run(run).timing
    assert len(t["step"]) == 4800
    fig, ax = plt.subplots()
    try:
        _plot_per_step(ax, t["step"], t["t_match"], "tab:orange", "matching")
        (line,) = ax.get_lines()
        assert len(line.get_xdata()) <= STEP_BINS  # medians, not 4,800 zig-zags
        band = [c for c in ax.collections if isinstance(c, PolyCollection)]
        assert len(band) == 1  # the range of each bin, drawn faintly
        size = step_bins(4800)
        np.testing.assert_allclose(line.get_ydata()[0], np.median(t["t_match"][:size]))
    finally:
        plt.close(fig)
    for path in plot_run(run):
        check_png(path)


def test_many_landmarks_get_thin_ellipses_all_still_drawn():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    from cornerslam_cli.report.plots import _draw_landmarks

    rng = np.random.default_rng(1)
    widths = []
    for n in (50, 900):
        lm = {"x": rng.uniform(0, 50, n), "y": rng.uniform(0, 50, n), "var_x": np.full(n, 0.04),
              "var_y": np.full(n, 0.01), "cov_xy": np.zeros(n)}  # fmt: skip
        fig, ax = plt.subplots()
        try:
            _draw_landmarks(ax, lm)
            (polys,) = [c for c in ax.collections if isinstance(c, PolyCollection)]
            assert len(polys.get_paths()) == n
            widths.append(float(polys.get_linewidths()[0]))
        finally:
            plt.close(fig)
    assert widths[0] == 0.7 and widths[1] <= 0.7 / 3


def test_the_map_is_framed_on_the_estimate_not_on_drifting_odometry():
    """Fig 16 of a long real log: odometry 300 m off must not shrink the map into a corner."""
    from types import SimpleNamespace

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cornerslam_cli.report.plots import _frame_the_map

    t = np.linspace(0, 2 * np.pi, 50)
    corrected = np.column_stack((10 * np.cos(t), 10 * np.sin(t), t))
    run = SimpleNamespace(corrected=corrected, scan_odometry=None, ground_truth=None,
                          landmarks={"x": np.array([12.0]), "y": np.array([0.0])})  # fmt: skip
    fig, ax = plt.subplots()
    ax.plot(corrected[:, 0] - 300, corrected[:, 1] - 300)  # the drifting odometry, drawn first
    _frame_the_map(ax, run)
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    plt.close(fig)
    assert -12 < x0 < -10 and 12 < x1 < 14 and -12 < y0 < -10 and 10 < y1 < 12


def test_odometry_that_runs_off_the_map_says_so_in_the_legend(outputs):
    """The map is framed on the estimate, so a drifting odometry was cut at the axes with no sign of it
    (orebro's left the top: a new-user walkthrough); its legend entry now says it runs off the plot."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cornerslam_cli.report.plots import _draw_map

    run = load_run(outputs[0])
    labels = {}
    for name, shift in (("inside", 0.0), ("off", 300.0)):
        odometry = run.odometry.copy()
        odometry[len(odometry) // 2 :, 0] += shift  # its second half 300 m off
        fig, ax = plt.subplots()
        try:
            _draw_map(ax, dataclasses.replace(run, odometry=odometry))
            labels[name] = [t for t in (line.get_label() for line in ax.get_lines()) if t.startswith("odom")]
        finally:
            plt.close(fig)
    assert labels == {"inside": ["odometry"], "off": ["odometry (runs off the plot)"]}


def test_an_unknown_mplbackend_does_not_end_a_plot(sim_log, tmp_path):
    # matplotlib refuses a backend it does not know when it is imported; we draw files with Agg anyway
    import os
    import subprocess
    import sys

    env = {**os.environ, "MPLBACKEND": "bogus", "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    png = tmp_path / "scan.png"
    cmd = [sys.executable, "-m", "cornerslam_cli", "extract", str(sim_log), "--plot", str(png), "-q"]
    res = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert png.stat().st_size > 0


def test_characters_the_font_lacks_are_one_warning_in_our_words(tmp_path, caplog):
    """A log named in CJK: matplotlib warned once per character and figure (UserWarning, shown under
    -q too); now one warning names them, once per process."""
    import warnings

    from cornerslam_cli.report import plots

    caplog.set_level(logging.WARNING, logger=plots.log.name)  # (an earlier test's -q set it higher)
    plt = plots.pyplot()
    plots._glyphs_noted.clear()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        plots.agg_backend()  # (its filter, as the commands install it)
        for i in range(2):
            fig, ax = plt.subplots()
            ax.set_title("办公室.mcap · é")
            plots._save(fig, tmp_path / f"f{i}.png")
    assert not [w for w in caught if "Glyph" in str(w.message)]
    said = [r.getMessage() for r in caplog.records if "glyph" in r.getMessage()]
    assert said == ["the figures' font (DejaVuSans) has no glyph for 公 办 室: drawn as boxes"]


def test_a_character_a_fallback_font_has_is_not_said_to_be_missing(caplog, monkeypatch):
    """matplotlib falls back through the fonts of the family list (a matplotlibrc naming a CJK font after
    DejaVu Sans): only the first was asked, and CJK drawn by the second was said to be boxes (a review)."""
    import matplotlib.ft2font
    from matplotlib import font_manager

    from cornerslam_cli.report import plots

    class Font:  # the second font has every glyph, the first none
        def __init__(self, path):
            self.path = str(path)

        def get_char_index(self, code):
            return 1 if self.path.endswith("second.ttf") else 0

    caplog.set_level(logging.WARNING, logger=plots.log.name)
    plt = plots.pyplot()
    plots._glyphs_noted.clear()
    monkeypatch.setattr(matplotlib.ft2font, "FT2Font", Font)
    monkeypatch.setattr(
        font_manager.fontManager, "_find_fonts_by_props", lambda props: ["a/first.ttf", "b/second.ttf"]
    )
    fig, ax = plt.subplots()
    ax.set_title("办公室")
    plots._note_missing_glyphs(fig)
    plt.close(fig)
    assert not [r for r in caplog.records if "glyph" in r.getMessage()]
