"""The tables and figures of ``cornerslam compare`` (the runs themselves: ``cornerslam_cli/compare.py``):
``comparison.csv``, one row per associator's run summary, then the figures and report.html."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from ..results import Accuracy, Ate, RelationError, RunSummary
from .tables import COMPARISON_COLUMNS, COMPARISON_LOOP_COLUMNS, CsvTable

NAN = float("nan")


def comparison_row(s: RunSummary) -> list:
    """One row of comparison.csv (``COMPARISON_COLUMNS``); NaN for what the run did not measure, empty
    loop-closing cells without submaps."""
    c, t, acc = s.counts, s.timing, s.accuracy or Accuracy()
    return [
        s.assoc,
        c.steps,
        c.landmarks,
        c.matched_total,
        t.t_match,
        t.t_match_max,
        t.t_total,
        _or_nan(acc.ate, "rmse"),
        _or_nan(acc.odom_ate, "rmse"),
        NAN if acc.rpe_per_m is None else acc.rpe_per_m,
        t.wall_time,
        c.budget_hits,
        _or_nan(acc.relations, "trans_mean"),
        _or_nan(acc.relations, "trans_std"),
        _or_nan(acc.relations, "rot_mean_deg"),
        _or_nan(acc.odom_relations, "trans_mean"),
        _or_nan(acc.scan_odom_ate, "rmse"),  # the motion input, the same for every associator
        _or_nan(acc.scan_odom_relations, "trans_mean"),
        *loop_cells(s),
    ]


# batch.csv's figures (cornerslam_cli/batch.py): comparison.csv's cells of the same names (t_match: its
# t_match_total); then, appended after out_dir (2026-12-05), the scan-matched odometry's ATE and the
# loop-closing cells, as comparison.csv has them
BATCH_FIGURES = "steps,landmarks,matched_total,t_match,t_total,wall_time,ate_rmse,odom_ate_rmse".split(",")
# (``n_submaps``: batch.csv's ``submaps`` would take the name of a swept ``submaps`` section's column)
BATCH_MORE_FIGURES = ["scan_odom_ate_rmse", "n_submaps"]  # (no relation error: batch takes no relations)
BATCH_MORE_FIGURES += COMPARISON_LOOP_COLUMNS[1:]


def batch_figures(s: RunSummary) -> dict:
    """The batch.csv figures of one run's summary (returned by the run or read from summary.json)."""
    cells = dict(zip(COMPARISON_COLUMNS, comparison_row(s), strict=True))
    cells["t_match"], cells["n_submaps"] = cells["t_match_total"], cells["submaps"]
    return {k: cells[k] for k in BATCH_FIGURES + BATCH_MORE_FIGURES}


def loop_cells(s: RunSummary) -> list:
    """comparison.csv's loop-closing cells: submaps, closures accepted and refused, the online
    (causal) estimate's ATE RMSE (NaN without ground truth), the dense refinement's factors (empty
    without graph.refine), the loop-closing time; empty cells when the run had no submaps."""
    c, acc, t = s.counts, s.accuracy or Accuracy(), s.timing
    if c.submaps is None:
        return [""] * len(COMPARISON_LOOP_COLUMNS)
    refine = "" if c.refine_factors is None else c.refine_factors
    t_loop = NAN if t.t_loop is None else t.t_loop
    return [c.submaps, c.loops_accepted, c.loops_rejected, _or_nan(acc.online_ate, "rmse"), refine, t_loop]


def _or_nan(result: Ate | RelationError | None, name: str) -> float:
    """A figure of an accuracy result, NaN when there is no result or it lacks the figure."""
    value = None if result is None else getattr(result, name)
    return NAN if value is None else value


def write_comparison(
    out_dir: Path,
    summaries: list[RunSummary],
    plots: bool = True,
    ground_truth: str | Path | None = None,
    progress: Callable[..., None] | None = None,
) -> None:
    """``out_dir``/comparison.csv from the run ``summaries`` (one per associator, in order) and, with
    ``plots``, the comparison figures and report.html drawn from the runs in ``out_dir`` (with the
    ``ground_truth`` TUM file the runs read, if any), the figures reported to ``progress``."""
    with CsvTable(out_dir / "comparison.csv", COMPARISON_COLUMNS) as table:
        for s in summaries:
            table.row(*comparison_row(s))
    if plots:
        from .html import write_report
        from .plots import plot_compare

        plot_compare(out_dir, ground_truth, progress)
        write_report(out_dir)
