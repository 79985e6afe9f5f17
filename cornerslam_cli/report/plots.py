"""Figures of a run and of a comparison (the paper's Figs 16–20), written as PNGs beside the tables.

``plot_run(DIR)`` reads a ``cornerslam run`` output directory and writes

- ``map.png`` (Fig 16): odometry and corrected trajectories, ground truth when the summary names one,
  landmarks with 3σ covariance ellipses, the segment map drawn faintly; with submaps, the accepted
  loop closures as lines between the two submap origins;
- ``segments.png`` (Fig 20a): the segment map at the corrected poses with the landmark positions;
- ``timing.png`` (Fig 17): per-step prediction / matching / update time (and scan matching when on);
- ``corners.png`` (Fig 18): detected vs matched corners per step, and new landmarks.

``plot_compare(DIR)`` reads a ``cornerslam compare`` output directory and writes
``compare_matching.png`` (Fig 19: cumulative matching time and landmark count per associator),
``compare_maps.png`` (each associator's map side by side, its accepted loop closures counted in its
title) and ``compare_timing.png`` (per-step matching time per associator), then calls ``plot_run`` on
each associator's directory.

The directories are read back by report/run_dir.py (the trajectories in the map frame, the
landmarks' covariance ellipses).

matplotlib is imported inside the functions (Agg backend), so importing this module stays cheap.

Over 400 lines because the run's figures and the comparison's are drawn by the same helpers (Fig 16's
map on one axes with its loop closures, the binned per-step series, the accuracy note): split in two,
each half would import the other's private drawing functions.
"""

from __future__ import annotations

import logging
import math
import os
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..results import RunSummary
from .run_dir import RunData, ellipse_polygons, load_run
from .tables import COMPARISON_COLUMNS, read_csv
from .text import odometry_label

log = logging.getLogger(__name__)

DPI = 120
COLORS = {
    "corrected": "tab:blue",
    "odometry": "tab:red",
    "scan_odometry": "tab:orange",
    "ground_truth": "black",
    "landmark": "tab:green",
    "loop": "tab:purple",
}
ASSOC_COLORS = {"icnn": "tab:orange", "jcbb": "tab:purple", "pca": "tab:blue"}

MAX_STEPS_DRAWN = 600  # longer per-step series are drawn per bin of steps (median and range), not per step
STEP_BINS = 150  # bins of a longer series
MANY_LANDMARKS = 100  # more landmarks than this: their ellipses are drawn thinner and fainter
MANY_LOOPS = 30  # more loop closures than this: their lines are drawn thinner and fainter
RUN_FIGURES = ("map.png", "segments.png", "timing.png", "corners.png")
COMPARE_FIGURES = ("compare_matching.png", "compare_maps.png", "compare_timing.png")


def agg_backend() -> None:
    """matplotlib on the Agg backend (every figure here is a file). MPLBACKEND is set to it first:
    matplotlib checks that variable when it is imported, and a value it does not know (a typo, a GUI
    backend of another machine) ended ``run --plot`` after its work, though Agg is what we draw with
    whatever the variable says."""
    os.environ["MPLBACKEND"] = "agg"
    logging.getLogger("matplotlib").addFilter(_config_dir_unwritable)  # once: skips one it has
    # said once, in our words, by _note_missing_glyphs (matplotlib warns per character and figure, -q or not)
    warnings.filterwarnings("ignore", message=r"Glyph \d+ .*missing from font", category=UserWarning)
    import matplotlib

    matplotlib.use("Agg")


_CONFIG_DIR_NOTES = (
    "mkdir -p failed for path ",
    " is not a writable directory",
    "Matplotlib created a temporary",
)


def _config_dir_unwritable(record: logging.LogRecord) -> bool:
    """False for matplotlib's notes, as it is imported, that its config directory (``~/.config/
    matplotlib``: a read-only or missing HOME, a service user's) cannot be written and that it uses a
    temporary one instead: two lines printed even with ``-q``, on what the figures do not need."""
    return not any(note in record.getMessage() for note in _CONFIG_DIR_NOTES)


def pyplot():
    """matplotlib.pyplot, on Agg (:func:`agg_backend`)."""
    agg_backend()
    import matplotlib.pyplot as plt

    return plt


def _figure(*args, **kwargs):
    plt = pyplot()
    logging.getLogger("matplotlib.axes._base").addFilter(_limits_widened)  # once: skips one it has
    return plt.subplots(*args, **kwargs)


def _limits_widened(record: logging.LogRecord) -> bool:
    """False for matplotlib's warning that an equal-aspect map (``adjustable="datalim"``) widens the
    limits :func:`_frame_the_map` fixed: widening them to the aspect is what we ask for, and the
    WARNING on the user's stderr read as a fault."""
    return not record.getMessage().startswith("Ignoring fixed")


def _save(fig, path: Path) -> Path:
    import matplotlib.pyplot as plt

    _note_missing_glyphs(fig)
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


_glyphs_noted: set[str] = set()  # characters already said to be missing (a warning once per process)


def _note_missing_glyphs(fig) -> None:
    """One warning for the characters of the figure's texts none of its fonts has a glyph for (a log
    named in CJK): drawn as boxes. The fonts are those matplotlib falls back through (the family list of
    the user's matplotlibrc, where it has one). matplotlib's own warnings, one per character and figure,
    are filtered (:func:`agg_backend`)."""
    from matplotlib import font_manager
    from matplotlib.ft2font import FT2Font
    from matplotlib.text import Text

    chars = {c for t in fig.findobj(Text) for c in t.get_text() if ord(c) > 127} - _glyphs_noted
    if not chars:
        return
    props = font_manager.FontProperties()
    find = getattr(font_manager.fontManager, "_find_fonts_by_props", None)  # (matplotlib ≥ 3.6's fallback)
    paths = [os.fspath(f) for f in find(props)] if find else [font_manager.findfont(props)]
    fonts = [FT2Font(path) for path in paths]
    missing = sorted(c for c in chars if all(f.get_char_index(ord(c)) == 0 for f in fonts))
    _glyphs_noted.update(chars)
    if missing:
        log.warning(
            "the figures' font (%s) has no glyph for %s: drawn as boxes",
            ", ".join(Path(path).stem for path in paths),
            " ".join(missing[:10]) + (" …" if len(missing) > 10 else ""),
        )


def _draw_segments(ax, lines: dict[str, np.ndarray], **kwargs) -> None:
    from matplotlib.collections import LineCollection

    if len(lines.get("x1", ())) == 0:
        return
    seg = np.stack(
        (np.column_stack((lines["x1"], lines["y1"])), np.column_stack((lines["x2"], lines["y2"]))), axis=1
    )
    ax.add_collection(LineCollection(seg, rasterized=True, **kwargs))


def _draw_landmarks(ax, lm: dict[str, np.ndarray], ellipses: bool = True, label: str | None = None) -> None:
    from matplotlib.collections import PolyCollection

    n = len(lm.get("x", ()))
    if n == 0:
        return
    xy = np.column_stack((lm["x"], lm["y"]))
    if ellipses:
        cov = np.empty((n, 2, 2))
        cov[:, 0, 0], cov[:, 1, 1] = lm["var_x"], lm["var_y"]
        cov[:, 0, 1] = cov[:, 1, 0] = lm["cov_xy"]
        polys = ellipse_polygons(xy, np.nan_to_num(cov))
        thin = min(1.0, math.sqrt(MANY_LANDMARKS / n))  # 1 up to MANY_LANDMARKS, then ~ 1/sqrt(n)
        ax.add_collection(
            PolyCollection(
                polys,
                closed=True,
                facecolors="none",
                edgecolors=COLORS["landmark"],
                linewidths=0.7 * thin,
                alpha=None if thin == 1.0 else max(0.35, thin),
                zorder=2,
            )
        )
    size = 9 if n <= MANY_LANDMARKS else 4
    ax.scatter(xy[:, 0], xy[:, 1], s=size, marker="+", color=COLORS["landmark"], linewidths=0.9, label=label)


def _draw_map(ax, run: RunData, segments_alpha: float = 0.18, legend: bool = True) -> None:
    """Fig 16 contents on one axes."""
    _draw_segments(ax, run.lines, colors="0.45", linewidths=0.4, alpha=segments_alpha, zorder=1)
    if run.ground_truth is not None:
        g = run.ground_truth
        ax.plot(g[:, 0], g[:, 1], color=COLORS["ground_truth"], lw=1.1, ls=":", zorder=4,
                label="ground truth (aligned)")  # fmt: skip
    o, c = run.odometry, run.corrected
    name = odometry_label(run.summary)
    (odometry,) = ax.plot(o[:, 0], o[:, 1], color=COLORS["odometry"], lw=0.9, ls="--", label=name)
    if run.scan_odometry is not None:
        m = run.scan_odometry
        ax.plot(
            m[:, 0], m[:, 1], color=COLORS["scan_odometry"], lw=0.9, ls="-.", label="scan-matched odometry"
        )
    ax.plot(c[:, 0], c[:, 1], color=COLORS["corrected"], lw=1.2, label=corrected_label(run.summary))
    _draw_landmarks(ax, run.landmarks, label=f"landmarks ({len(run.landmarks.get('x', ()))}, 3σ)")
    _draw_loop_closures(ax, run.loop_closures())
    if len(c):
        ax.plot(*c[0, :2], "o", color="k", ms=4, zorder=5, label="start")
    _map_axes(ax)
    _frame_the_map(ax, run)
    if legend and len(o):  # (side-by-side panels share their limits: the last one's, so not said there)
        ax.apply_aspect()  # the limits as drawn: the equal aspect widens the ones framed on the map
        (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
        if not np.all((o[:, 0] >= x0) & (o[:, 0] <= x1) & (o[:, 1] >= y0) & (o[:, 1] <= y1)):
            odometry.set_label(f"{name} (runs off the plot)")  # (framed on the map, not on the drift)
    if legend:
        ax.legend(loc="best", fontsize=8, framealpha=0.85)


def corrected_label(summary: RunSummary) -> str:
    """What trajectory.tum holds: the pose graph's smoothed trajectory with the two levels, the EKF's
    with the single map (the paper's) — the name Fig 16's legend and report.html's tables give it."""
    return "corrected (EKF)" if summary.counts.submaps is None else "smoothed (pose graph)"


def _draw_loop_closures(ax, seg: np.ndarray) -> None:
    """The accepted loop closures ``seg`` (k, 2, 2): a line between the two submap origins, dots at
    the origins; one artist however many, thinner and fainter past MANY_LOOPS."""
    k = len(seg)
    if k == 0:
        return
    xy = np.concatenate((seg, np.full((k, 1, 2), np.nan)), axis=1).reshape(-1, 2)  # NaN: a break
    thin = min(1.0, math.sqrt(MANY_LOOPS / k))
    alpha = 1.0 if thin == 1.0 else max(0.25, 0.8 * thin)  # Intel's 79 read as trajectory at 0.6
    ax.plot(xy[:, 0], xy[:, 1], "-o", color=COLORS["loop"], lw=1.2 * thin, ms=3 * max(thin, 0.5),
            alpha=alpha, zorder=3, label=f"loop closures ({k} accepted)")  # fmt: skip


def _frame_the_map(ax, run: RunData, margin: float = 0.05) -> None:
    """Axes limits from the map (corrected and scan-matched trajectories, ground truth, landmarks), not
    the raw odometry: drifting 100 m off on a long real log it would shrink the map into a corner. The
    odometry is drawn where it falls inside."""
    parts = [run.corrected[:, :2]]
    parts += [a[:, :2] for a in (run.scan_odometry, run.ground_truth) if a is not None]
    lm = run.landmarks
    if len(lm.get("x", ())):
        parts.append(np.column_stack((lm["x"], lm["y"])))
    pts = np.concatenate([p for p in parts if len(p)]) if any(len(p) for p in parts) else np.zeros((0, 2))
    pts = pts[np.isfinite(pts).all(axis=1)]
    if len(pts) == 0:
        return
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = margin * max(float(np.max(hi - lo)), 1.0)
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)


def _map_axes(ax) -> None:
    # shared axes (the side-by-side maps) cannot adjust their data limits, only their box
    shared = len(ax.get_shared_x_axes().get_siblings(ax)) > 1
    ax.set_aspect("equal", adjustable="box" if shared else "datalim")
    ax.autoscale_view()
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, lw=0.3, alpha=0.5)


def _accuracy_note(summary: RunSummary) -> str:
    acc = summary.accuracy
    if acc is None or acc.ate is None or math.isnan(acc.ate.rmse):  # null in summary.json: not drawn
        return ""
    text = f"ATE RMSE {acc.ate.rmse:.3f} m"
    if acc.odom_ate is not None and not math.isnan(acc.odom_ate.rmse):
        text += f" ({odometry_label(summary)} {acc.odom_ate.rmse:.3f} m)"
    return text


def plot_map(run: RunData, path: Path) -> Path:
    fig, ax = _figure(figsize=(8, 7), layout="constrained")
    _draw_map(ax, run)
    ax.set_title(f"Trajectories and landmark map (Fig 16) — {run.title}")
    note = _accuracy_note(run.summary)
    if note:
        ax.text(0.01, 0.01, note, transform=ax.transAxes, fontsize=8, va="bottom",
                bbox=dict(fc="white", ec="0.7", alpha=0.85))  # fmt: skip
    return _save(fig, path)


def plot_segments(run: RunData, path: Path) -> Path:
    fig, ax = _figure(figsize=(8, 7), layout="constrained")
    _draw_segments(ax, run.lines, colors="0.15", linewidths=0.5, alpha=0.5, zorder=1)
    c = run.corrected
    ax.plot(c[:, 0], c[:, 1], color=COLORS["corrected"], lw=0.8, alpha=0.8, label="corrected poses")
    lm = run.landmarks
    if len(lm.get("x", ())):
        ax.scatter(lm["x"], lm["y"], s=14, color="tab:red", zorder=4, label=f"landmarks ({len(lm['x'])})")
    ax.plot([], [], color="0.15", lw=0.8, label=f"segments ({len(run.lines.get('x1', ()))})")
    _map_axes(ax)
    ax.legend(loc="best", fontsize=8, framealpha=0.85)
    ax.set_title(f"Segment map at the corrected poses (Fig 20) — {run.title}")
    return _save(fig, path)


def _positive(v: np.ndarray) -> np.ndarray:
    """Values for a log axis: zeros (not measured) become NaN gaps."""
    v = np.asarray(v, dtype=float).copy()
    v[~(v > 0)] = np.nan
    return v


def step_bins(n: int) -> int:
    """Steps per bin for a series of ``n`` steps: 1 up to MAX_STEPS_DRAWN, then enough for at most
    STEP_BINS bins."""
    return 1 if n <= MAX_STEPS_DRAWN else math.ceil(n / STEP_BINS)


def binned(step: np.ndarray, v: np.ndarray, size: int) -> tuple[np.ndarray, ...]:
    """Per bin of ``size`` consecutive steps: the middle step, and the median, minimum and maximum of
    ``v`` (NaN, a gap, where a bin has no value)."""
    n = math.ceil(len(v) / size)
    pad = np.full(n * size, np.nan)
    pad[: len(v)] = v
    bins = pad.reshape(n, size)
    mid = np.asarray(step, dtype=float)[np.minimum(np.arange(n) * size + size // 2, len(v) - 1)]
    empty = np.all(np.isnan(bins), axis=1)
    bins[empty] = 0.0  # no all-NaN warnings; put back as NaN below
    stats = [np.nanmedian(bins, axis=1), np.nanmin(bins, axis=1), np.nanmax(bins, axis=1)]
    for a in stats:
        a[empty] = np.nan
    return mid, *stats


def _plot_per_step(
    ax, step: np.ndarray, v: np.ndarray, color: str, label: str, lw: float = 0.7, **kw
) -> None:
    """A per-step series: each step when short, else per bin its median (a line) and its range (a
    light band), so a long run is not a solid band of lines."""
    size = step_bins(len(v))
    if size == 1:
        ax.plot(step, v, lw=0.7, color=color, label=label, **kw)
        return
    mid, med, lo, hi = binned(step, v, size)
    ax.fill_between(mid, lo, hi, color=color, alpha=0.18, lw=0)
    ax.plot(mid, med, lw=1.1, color=color, label=label, **kw)


def _binned_note(step: np.ndarray) -> str:
    """The axis label's note for a binned series ('' when drawn per step)."""
    size = step_bins(len(step))
    return "" if size == 1 else f"\n(median and range per {size} steps)"


def plot_timing(run: RunData, path: Path) -> Path:
    t = run.timing
    fig, (ax, ax2) = _figure(2, 1, figsize=(9, 6), sharex=True, height_ratios=(3, 1), layout="constrained")
    series = [
        ("t_predict", "prediction", "tab:gray"),
        ("t_match", "matching", "tab:orange"),
        ("t_update", "update", "tab:blue"),
    ]
    if np.any(t.get("t_scan_match", np.zeros(1)) > 0):  # our motion front end, not in the paper's figure
        series.append(("t_scan_match", "scan matching", "tab:purple"))
    for key, label, color in series:
        _plot_per_step(ax, t["step"], _positive(t[key] * 1e3), color=color, label=label)
    ax.set_yscale("log")
    ax.set_ylabel("time per step [ms]" + _binned_note(t["step"]))
    ax.legend(loc="upper left", fontsize=8, ncol=len(series))
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    ax.set_title(f"Per-step time of the filter stages and scan matching (Fig 17) — {run.title}")
    ax2.plot(t["step"], run.map_landmarks(), color=COLORS["landmark"], lw=1.0)
    ax2.set_ylabel("landmarks\nin the map")  # (one line overran the short axes)
    ax2.set_xlabel("step")
    ax2.grid(True, lw=0.3, alpha=0.5)
    return _save(fig, path)


def plot_corners(run: RunData, path: Path) -> Path:
    t = run.timing
    fig, (ax, ax2) = _figure(2, 1, figsize=(9, 6), sharex=True, height_ratios=(2, 1), layout="constrained")
    size = step_bins(len(t["step"]))
    step, detected, matched = (_bin_mean(t[k], size) for k in ("step", "n_corners", "n_matched"))
    ax.plot(step, detected, lw=0.8, color="tab:gray", label="detected corners")
    ax.plot(step, matched, lw=0.8, color="tab:blue", label="matched corners")
    ax.fill_between(step, matched, detected, color="tab:red", alpha=0.3, lw=0,
                    step=None, label="unmatched")  # fmt: skip
    ax.set_ylabel("corners per step" + ("" if size == 1 else f"\n(mean per {size} steps)"))
    ax.legend(loc="upper left", fontsize=8, ncol=3)
    ax.grid(True, lw=0.3, alpha=0.5)
    total_d, total_m = int(np.nansum(t["n_corners"])), int(np.nansum(t["n_matched"]))
    ax.set_title(
        f"Detected vs matched corners (Fig 18) — {run.title}\n"
        f"{total_m} of {total_d} detections matched ({100 * total_m / max(total_d, 1):.0f} %)",
        fontsize=10,
    )
    new = _bin_sum(t["n_new"], size)
    ax2.bar(step, new, width=size, color=COLORS["landmark"], label="new landmarks")
    ax2.set_ylabel("new landmarks" + ("" if size == 1 else f"\nper {size} steps"))
    from matplotlib.ticker import MaxNLocator

    ax2.yaxis.set_major_locator(MaxNLocator(integer=True))  # counts: no 2.5 landmarks
    ax2.set_xlabel("step")
    ax2.grid(True, lw=0.3, alpha=0.5)
    return _save(fig, path)


def _bin_sum(v: np.ndarray, size: int) -> np.ndarray:
    """Sums of ``v`` over bins of ``size`` consecutive values (the last bin may be shorter)."""
    v = np.asarray(v, dtype=float)
    return v if size == 1 else np.add.reduceat(v, np.arange(0, len(v), size))


def _bin_mean(v: np.ndarray, size: int) -> np.ndarray:
    """Means of ``v`` over bins of ``size`` consecutive values (the last bin may be shorter)."""
    counts = _bin_sum(np.ones(len(v)), size)
    return _bin_sum(v, size) / counts


def plot_run(out_dir: Path, ground_truth: str | Path | None = None) -> list[Path]:
    """Write map.png, segments.png, timing.png and corners.png into a run directory; return their
    paths. ``ground_truth`` as for :func:`load_run`."""
    out_dir = Path(out_dir)
    run = load_run(out_dir, ground_truth)
    return [
        plot_map(run, out_dir / "map.png"),
        plot_segments(run, out_dir / "segments.png"),
        plot_timing(run, out_dir / "timing.png"),
        plot_corners(run, out_dir / "corners.png"),
    ]


def compare_assocs(out_dir: Path) -> list[str]:
    """Associator names in comparison.csv order."""
    table = read_csv(Path(out_dir) / "comparison.csv")
    return [str(a) for a in table.get(COMPARISON_COLUMNS[0], [])]


def _assoc_color(assoc: str, i: int) -> str:
    return ASSOC_COLORS.get(assoc, f"C{i}")


def plot_compare(
    out_dir: Path, ground_truth: str | Path | None = None, progress: Callable[..., None] | None = None
) -> list[Path]:
    """Write the comparison figures into a compare directory and each associator's run figures
    (``ground_truth`` as for :func:`load_run`); ``progress(done, total, "figures")`` as they are drawn
    (each run's set counts as one: a few seconds on a long log)."""
    out_dir = Path(out_dir)
    runs = [load_run(out_dir / a, ground_truth) for a in compare_assocs(out_dir)]
    log_name = runs[0].log_name if runs else out_dir.name
    drawers = [
        lambda: [_plot_compare_matching(runs, log_name, out_dir / "compare_matching.png")],
        lambda: [_plot_compare_maps(runs, log_name, out_dir / "compare_maps.png")],
        lambda: [_plot_compare_timing(runs, log_name, out_dir / "compare_timing.png")],
        *(lambda run=run: plot_run(run.out_dir, ground_truth) for run in runs),
    ]
    written: list[Path] = []
    for k, draw in enumerate(drawers):
        if progress is not None:
            progress(k, len(drawers), "figures")
        written += draw()
    if progress is not None:
        progress(len(drawers), len(drawers), "figures")
    return written


def _plot_compare_matching(runs: list[RunData], log_name: str, path: Path) -> Path:
    fig, (ax, ax2) = _figure(1, 2, figsize=(12, 4.8), layout="constrained")
    for i, r in enumerate(runs):
        color = _assoc_color(r.assoc, i)
        ax.plot(r.timing["step"], np.cumsum(r.timing["t_match"]), color=color, lw=1.3, label=r.assoc)
        ax2.plot(r.timing["step"], r.map_landmarks(), color=color, lw=1.3, label=r.assoc)
    ax.set_ylabel("cumulative matching time [s]")
    ax.set_title("Cumulative matching time")
    ax2.set_ylabel("landmarks\nin the map")  # (one line overran the short axes)
    ax2.set_title("Total landmarks")
    for a in (ax, ax2):
        a.set_xlabel("step")
        a.grid(True, lw=0.3, alpha=0.5)
        a.legend(loc="upper left", fontsize=9)
    fig.suptitle(f"Associators compared (Fig 19) — {log_name}")
    return _save(fig, path)


def _plot_compare_maps(runs: list[RunData], log_name: str, path: Path) -> Path:
    n = max(len(runs), 1)
    fig, axes = _figure(
        1, n, figsize=(5.2 * n, 4.8), sharex=True, sharey=True, layout="constrained", squeeze=False
    )
    for ax, r in zip(axes[0], runs, strict=False):
        _draw_map(ax, r, legend=False)
        note = _accuracy_note(r.summary)
        n_lm = len(r.landmarks.get("x", ()))
        loops = r.summary.counts.loops_accepted
        closures = "" if loops is None else f", {loops} loop closure{'' if loops == 1 else 's'}"
        ax.set_title(f"{r.assoc}: {n_lm} landmarks{closures}" + (f"\n{note}" if note else ""), fontsize=10)
    if runs:
        _shared_legend(fig, axes[0][: len(runs)])
    fig.suptitle(f"Maps per associator (Fig 16) — {log_name}")
    return _save(fig, path)


def _shared_legend(fig, axes) -> None:
    """One legend below the panels: every label any panel has, once, without its panel's count (the
    landmarks and loop closures of one associator)."""
    seen: dict[str, object] = {}
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            if label.startswith(("landmarks", "loop closures")):
                label = label.split(" (")[0]
            seen.setdefault(label, handle)
    fig.legend(list(seen.values()), list(seen), loc="outside lower center", ncol=len(seen), fontsize=9)


def _plot_compare_timing(runs: list[RunData], log_name: str, path: Path) -> Path:
    fig, ax = _figure(figsize=(10, 4.8), layout="constrained")
    for i, r in enumerate(runs):
        t = r.timing
        label = f"{r.assoc} (max {np.nanmax(t['t_match']) * 1e3:.1f} ms)"
        _plot_per_step(
            ax, t["step"], _positive(t["t_match"] * 1e3), _assoc_color(r.assoc, i), label, alpha=0.85
        )
    ax.set_yscale("log")
    ax.set_xlabel("step")
    ax.set_ylabel("matching time per step [ms]" + (_binned_note(runs[0].timing["step"]) if runs else ""))
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    ax.legend(loc="upper left", fontsize=9)
    ax.set_title(f"Per-step matching time per associator (Fig 17) — {log_name}")
    return _save(fig, path)
