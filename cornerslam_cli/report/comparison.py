"""The tables and figures of ``cornerslam compare`` (the runs themselves: ``cornerslam_cli/compare.py``):
``comparison.csv``, one row per associator's run summary, then the figures and report.html."""

from __future__ import annotations

from pathlib import Path

from .tables import COMPARISON_COLUMNS, CsvTable


def comparison_row(s: dict) -> list:
    acc = s.get("accuracy") or {}
    t = s["timing"]
    nan = float("nan")
    return [
        s["assoc"],
        s["counts"]["steps"],
        s["counts"]["landmarks"],
        s["counts"]["matched_total"],
        t["t_match"],
        t["t_match_max"],
        t["t_total"],
        acc.get("ate", {}).get("rmse", nan),
        acc.get("odom_ate", {}).get("rmse", nan),
        acc.get("rpe_per_m", nan),
        t["wall_time"],
        s["counts"]["budget_hits"],
        acc.get("relations", {}).get("trans_mean", nan),
        acc.get("relations", {}).get("trans_std", nan),
        acc.get("relations", {}).get("rot_mean_deg", nan),
        acc.get("odom_relations", {}).get("trans_mean", nan),
        acc.get("scan_odom_ate", {}).get("rmse", nan),  # the motion input, the same for every associator
        acc.get("scan_odom_relations", {}).get("trans_mean", nan),
    ]


def write_comparison(
    out_dir: Path, summaries: list[dict], plots: bool = True, ground_truth: str | Path | None = None
) -> None:
    """``out_dir``/comparison.csv from the run ``summaries`` (one per associator, in order) and, with
    ``plots``, the comparison figures and report.html drawn from the runs in ``out_dir`` (with the
    ``ground_truth`` TUM file the runs read, if any)."""
    with CsvTable(out_dir / "comparison.csv", COMPARISON_COLUMNS) as table:
        for s in summaries:
            table.row(*comparison_row(s))
    if plots:
        from .html import write_report
        from .plots import plot_compare

        plot_compare(out_dir, ground_truth)
        write_report(out_dir)
