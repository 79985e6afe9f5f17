"""``report.html``: one self-contained page per run or comparison.

Everything is inside the one file — figures as base64 ``data:image/png`` URIs, CSS in a ``<style>``
element, no JavaScript, no network — so it can be mailed, attached to a CI job or opened from disk.
A directory with ``comparison.csv`` is a comparison (table, Fig 19, maps, one section per
associator); any other is a run. Figures missing from the directory are drawn first (plots.py).
"""

from __future__ import annotations

import base64
import html
import json
import math
import re
from collections import Counter
from collections.abc import Callable, Iterable
from pathlib import Path

from ..results import Ate, MapConsistency, RelationError, RunSummary, to_json
from .plots import (
    COMPARE_FIGURES,
    RUN_FIGURES,
    compare_assocs,
    corrected_label,
    plot_compare,
    plot_run,
)
from .tables import COMPARISON_COLUMNS, COMPARISON_LOOP_COLUMNS, best_cells, read_csv
from .text import odometry_label, span_text

CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 2em auto; max-width: 1200px;
       padding: 0 1em; color: #222; line-height: 1.4; }
h1 { font-size: 1.5em; border-bottom: 2px solid #ccc; padding-bottom: .3em; }
h2 { font-size: 1.25em; margin-top: 2em; border-bottom: 1px solid #ddd; }
h3 { font-size: 1.05em; }
table { border-collapse: collapse; margin: .5em 0 1em; font-size: .92em; }
th, td { border: 1px solid #ccc; padding: .25em .6em; text-align: right; }
table.wide { font-size: .75em; } table.wide th, table.wide td { padding: .2em .25em; }
table.wide th { font-weight: 600; }
th { background: #f2f2f2; } td.name, th.name { text-align: left; }
td.best { background: #d9f2d9; font-weight: bold; }
figure { margin: 1em 0; } figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: .9em; color: #555; }
pre { background: #f7f7f7; padding: .8em; overflow-x: auto; font-size: .85em; }
.warn { color: #8a4b00; } .muted { color: #777; font-size: .9em; }
nav a { margin-right: 1em; }
"""

CAPTIONS = {
    "map.png": "Fig 16 — odometry (dashed), scan-matched (dash-dot) and output (solid) paths, landmarks.",
    "segments.png": "Fig 20 — segment map at the corrected poses with the landmark positions.",
    "timing.png": "Fig 17 — per-step prediction, matching, update and scan-matching time.",
    "corners.png": "Fig 18 — detected vs matched corners per step, and new landmarks.",
    "compare_matching.png": "Fig 19 — cumulative matching time and total landmarks per associator.",
    "compare_maps.png": "Fig 16 — each associator's map with odometry (and the ground truth when given).",
    "compare_timing.png": "Fig 17 — per-step matching time per associator.",
}

# summary.json's time totals as the report names them
TIME_LABELS = {
    "t_extract": "extraction time",
    "t_scan_match": "scan matching time",
    "t_predict": "prediction time",
    "t_match": "matching time",
    "t_update": "update time",
    "t_total": "filter time (all stages, summed over the steps)",
    "wall_time": "wall-clock time",
}


def esc(value) -> str:
    return html.escape(str(value), quote=True)


def fmt(value) -> str:
    """A table cell: integers plainly, floats to 4 significant digits, NaN as an em dash."""
    if isinstance(value, float):
        if math.isnan(value):
            return "—"
        if value.is_integer() and abs(value) < 1e12:
            return str(int(value))
        return f"{value:.4g}"
    return str(value)


def png_data_uri(path: Path) -> str:
    return "data:image/png;base64," + base64.b64encode(Path(path).read_bytes()).decode("ascii")


def figure(path: Path, alt: str) -> str:
    caption = CAPTIONS.get(path.name, path.name)
    return (
        f'<figure><img src="{png_data_uri(path)}" alt="{esc(alt)}">'
        f"<figcaption>{esc(caption)}</figcaption></figure>"
    )


def table(
    header: list[str], rows: list[list], name_cols: int = 1, best: set | None = None, wide: bool = False
) -> str:
    """An HTML table; ``best`` holds (row, col) cells to highlight. Everything is escaped. A ``wide``
    table (many columns named like ``rel_trans_mean``) is set smaller and its headers may break
    after each underscore, so it fits the page."""
    best = best or set()
    out = ['<table class="wide"><tr>' if wide else "<table><tr>"]
    heads = [esc(h).replace("_", "_<wbr>") if wide else esc(h) for h in header]
    out += [f'<th class="name">{h}</th>' if j < name_cols else f"<th>{h}</th>" for j, h in enumerate(heads)]
    out.append("</tr>")
    for i, row in enumerate(rows):
        cells = []
        for j, v in enumerate(row):
            cls = " ".join(
                c for c in ("name" if j < name_cols else "", "best" if (i, j) in best else "") if c
            )
            cells.append(f'<td class="{cls}">{esc(fmt(v))}</td>' if cls else f"<td>{esc(fmt(v))}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    out.append("</table>")
    return "".join(out)


def _page(title: str, body: list[str]) -> str:
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>{esc(title)}</title><style>{CSS}</style></head><body>\n"
        + "\n".join(body)
        + "\n</body></html>\n"
    )


def _kv_table(pairs: list[tuple[str, object]]) -> str:
    """A two-column table: a header cell naming each value."""
    rows = "".join(f'<tr><th class="name">{esc(k)}</th><td>{esc(fmt(v))}</td></tr>' for k, v in pairs)
    return f"<table>{rows}</table>"


def _summary_section(summary: RunSummary, run_dir: Path) -> list[str]:
    inp, counts, timing = summary.input, summary.counts, summary.timing
    pairs: list[tuple[str, object]] = [
        ("log", inp.log),
        *[("span", text) for text in [span_text(inp)] if text],
        ("format", inp.format),
        ("scan topic", inp.scan_topic),
        ("odometry", f"{inp.odom_topic} ({inp.odom_source})" if inp.odom_topic else inp.odom_source),
        ("associator", summary.assoc),
        ("steps", counts.steps),
        ("landmarks", counts.landmarks),
        ("matched corners", counts.matched_total),
    ]
    alone = summary.scan_odometry  # (input.odometry: scans)
    for key, label in TIME_LABELS.items():
        if getattr(timing, key) is not None:  # no scan matching time in a summary from before it
            label = "scan odometry time" if key == "t_scan_match" and alone is not None else label
            pairs.append((f"{label} [s]", float(getattr(timing, key))))
    if alone is not None:
        pairs.append(
            ("scans: searched, coasted, after a gap", f"{alone.searched}, {alone.coasted}, {alone.gaps}")
        )
    pairs.append(("max matching time per step [ms]", 1e3 * timing.t_match_max))
    pairs.append(("scans per second", timing.scans_per_second))
    pairs.append(("final pose x, y [m], θ [rad]", ", ".join(f"{v:.3f}" for v in summary.final_pose)))
    out = ["<h2>Summary</h2>", _kv_table(pairs)]
    out += _accuracy_section(summary)
    out += _consistency_section(summary.consistency, corrected_label(summary), odometry_label(summary))
    out += _loops_section(run_dir, summary)
    out.append("<h3>Warnings</h3>")
    if summary.warnings:
        out.append("<ul>" + "".join(f'<li class="warn">{esc(w)}</li>' for w in summary.warnings) + "</ul>")
    else:
        out.append('<p class="muted">none</p>')
    out.append("<details><summary>All counts</summary>")
    out.append(_kv_table(list(to_json(counts).items())) + "</details>")
    return out


def _accuracy_section(summary: RunSummary) -> list[str]:
    """ATE against the ground truth and the relation metric, each when the run measured it."""
    acc = summary.accuracy
    if acc is None:
        return []
    out = ["<h3>Accuracy</h3>"]
    if acc.ate is not None or acc.odom_ate is not None:
        more = (("scan-matched odometry", acc.scan_odom_ate), ("online (causal)", acc.online_ate))
        named = [(corrected_label(summary), acc.ate), (odometry_label(summary), acc.odom_ate)]
        named += [(n, a) for n, a in more if a]
        rows = [[name, *_ate_cells(a)] for name, a in named]
        out += [
            f'<p class="muted">against {esc(acc.ground_truth or "")} (SE(2)-aligned)</p>',
            table(["trajectory", "ATE RMSE [m]", "mean [m]", "max [m]", "heading RMSE [rad]", "poses"], rows),
        ]
    extra = [(k, getattr(acc, k)) for k in ("rpe_step_rmse", "rpe_step_rot_rmse", "rpe_per_m")]
    extra = [(k, v) for k, v in extra if v is not None and math.isfinite(v)]  # null in summary.json
    if extra:
        out.append(_kv_table(extra))
    if acc.relations is not None:
        named = ((corrected_label(summary), acc.relations), (odometry_label(summary), acc.odom_relations))
        named += (("scan-matched odometry", acc.scan_odom_relations),) if acc.scan_odom_relations else ()
        source = esc(acc.relations_file or "")
        out += [
            f'<p class="muted">relation metric (Kümmerle et al. 2009) against {source}</p>',
            table(RELATION_HEADER, [[name, *_relation_cells(e)] for name, e in named]),
        ]
    return out


RELATION_HEADER = [
    "trajectory (relations)", "translation mean [m]", "std [m]", "rotation mean [°]", "std [°]", "used"
]  # fmt: skip


def _relation_cells(e: RelationError | None) -> list:
    """Translation and rotation mean, std; 'n of total': NaN for what was not measured."""
    if e is None:
        return [math.nan] * 4 + [""]
    values = (e.trans_mean, e.trans_std, e.rot_mean_deg, e.rot_std_deg)
    return [math.nan if v is None else v for v in values] + [f"{e.n} of {e.n_total}"]


def _consistency_section(c: MapConsistency | None, name: str, odometry: str = "odometry") -> list[str]:
    """The map-consistency figures (no ground truth needed): the estimate (called ``name``) vs the
    odometry (called ``odometry``)."""
    if c is None:
        return []
    rows = [
        [name, c.occupied_cells, c.cells_vs_odom, 100 * c.revisit_mean, 100 * c.revisit_share],
        [odometry, c.odom_occupied_cells, 1.0, 100 * c.odom_revisit_mean, 100 * c.odom_revisit_share],
    ]
    return [
        "<h3>Map consistency</h3>",
        f'<p class="muted">{c.scans} scans, {c.points} points placed with each trajectory: occupied '
        f"{100 * c.cell:g} cm cells (fewer is crisper) and the revisit misalignment (distance to the nearest "
        "point of scans far apart in the sequence; share: the points that have one within 30 cm). "
        "No ground truth needed.</p>",
        table(CONSISTENCY_HEADER, rows),
    ]


CONSISTENCY_HEADER = [
    "trajectory (map)", "occupied cells", "vs odometry", "revisit misalignment [cm]", "revisited points [%]"
]  # fmt: skip


def _loops_section(run_dir: Path, summary: RunSummary) -> list[str]:
    """With submaps: how many, the loop closures accepted and refused, the loop time, and loops.csv's
    candidates counted by outcome and reason."""
    c, t = summary.counts, summary.timing
    if c.submaps is None:
        return []
    pairs = [
        ("submaps", c.submaps),
        ("loop closures accepted", c.loops_accepted),
        ("loop closures refused", c.loops_rejected),
        ("loop closing and graph time [s]", float(t.t_loop or 0.0)),
    ]
    path = run_dir / "loops.csv"
    rows = loop_reason_rows(read_csv(path)) if path.is_file() else []
    if rows:
        candidates = table(LOOPS_HEADER, rows, name_cols=2)
    else:
        candidates = (
            f'<p class="muted">{"no loop-closure candidate" if path.is_file() else "no loops.csv"}</p>'
        )
    return ["<h3>Loop closures</h3>", _kv_table(pairs), candidates]


LOOPS_HEADER = ["outcome", "reason", "candidates"]
ACCEPTED_REASON = "verified, inside the gate"  # loops.csv's empty reason of an accepted closure


def loop_reason_rows(loops: dict) -> list[list]:
    """loops.csv's candidates counted by outcome (accepted first) and reason, most frequent first; a
    reason's figures (the χ² of a gated closure, how many closures agreed) left out so that like
    reasons count together."""
    counts: Counter[tuple[bool, str]] = Counter()
    for accepted, reason in zip(loops["accepted"], loops["reason"], strict=True):
        kind = _reason_kind(str(reason)) or (ACCEPTED_REASON if accepted else "")
        counts[(not accepted, kind)] += 1
    order = sorted(counts.items(), key=lambda kv: (kv[0][0], -kv[1], kv[0][1]))
    return [["refused" if refused else "accepted", reason, n] for (refused, reason), n in order]


def _reason_kind(reason: str) -> str:
    """A loops.csv reason without its figures: '(chi2 12.3)' and a leading count dropped."""
    return re.sub(r"^\d+ ", "", re.sub(r"\s*\([^)]*\d[^)]*\)", "", reason))


def _ate_cells(a: Ate | None) -> list:
    """ATE RMSE, mean, max, heading RMSE, poses: NaN (and no count) for what was not measured."""
    if a is None:
        return [math.nan] * 4 + [""]
    return [a.rmse, a.mean, a.max, math.nan if a.rot_rmse is None else a.rot_rmse, a.n]


def _figures(run_dir: Path, label: str) -> list[str]:
    return [figure(run_dir / name, f"{label}: {name}") for name in RUN_FIGURES if (run_dir / name).is_file()]


def _config_section(summary: RunSummary) -> list[str]:
    config = {"config": summary.config, "versions": summary.versions}
    text = json.dumps(config, indent=2, default=str)
    return [
        f"<details><summary>Resolved configuration and versions</summary><pre>{esc(text)}</pre></details>"
    ]


def _ensure_figures(out_dir: Path, names: Iterable[str], draw: Callable[[Path], list[Path]]) -> None:
    if not all((out_dir / n).is_file() for n in names):
        draw(out_dir)


def _run_report(out_dir: Path) -> str:
    summary = RunSummary.read(out_dir)
    title = f"cornerslam run — {Path(summary.input.log).name} ({summary.assoc})"
    body = [f"<h1>{esc(title)}</h1>"]
    body += _summary_section(summary, out_dir)
    body += ["<h2>Figures</h2>", *_figures(out_dir, summary.assoc)]
    body += ["<h2>Configuration</h2>", *_config_section(summary)]
    return _page(title, body)


MAIN_COLUMNS = [c for c in COMPARISON_COLUMNS if c not in COMPARISON_LOOP_COLUMNS]


def _comparison_table(columns: dict, n: int, names: list[str], wide: bool = False, timed: bool = True) -> str:
    """comparison.csv's ``names`` columns as a table of its ``n`` rows, the best values highlighted (the
    times only when ``timed``: the runs did not share the CPU)."""
    rows = [[columns[c][i] for c in names] for i in range(n)]
    return table(names, rows, best=best_cells(columns, n, names, timed), wide=wide)


def _loop_comparison(columns: dict, n: int, timed: bool = True) -> list[str]:
    """The associators on loop closing (comparison.csv's appended columns) as a table of their own —
    the main one is as wide as a page — when the runs had submaps; its times ranked only when ``timed``
    (the runs timed apart), as the main table's."""
    numeric = [c for c in COMPARISON_LOOP_COLUMNS if c in columns and columns[c].dtype != object]
    if any(c not in numeric for c in COMPARISON_LOOP_COLUMNS[:4]):  # no submaps (empty cells), or older
        return []
    # (refine_factors: empty without graph.refine, then left out)
    return ["<h3>Loop closing</h3>", _comparison_table(columns, n, ["assoc", *numeric], timed=timed)]


def _compare_report(out_dir: Path) -> str:
    columns = read_csv(out_dir / "comparison.csv")
    assocs = compare_assocs(out_dir)
    n = len(assocs)
    summaries = {a: RunSummary.read(out_dir / a) for a in assocs}
    log = summaries[assocs[0]].input.log if assocs else ""
    log_name = Path(log).name if assocs else out_dir.name
    title = f"cornerslam compare — {log_name} ({', '.join(assocs)})"
    at_once = max((s.timing.concurrent_filters or 1 for s in summaries.values()), default=1)
    span = span_text(summaries[assocs[0]].input) if assocs else ""
    part = f" ({esc(span)})" if span else ""
    shared = (
        f" The {n} filters ran {at_once} at a time (<code>--jobs</code>): each one's times include waiting "
        "for the CPU, and which waited depends on the order of <code>--assoc</code> — their times are not "
        "compared here; run with <code>--jobs 1</code> to compare them."
        if at_once > 1
        else ""
    )
    if assocs and summaries[assocs[0]].scan_odometry is not None:  # (input.odometry: scans)
        shared += " The odom_* columns score the scans' own odometry (<code>input.odometry=scans</code>)."
    body = [
        f"<h1>{esc(title)}</h1>",
        "<nav>" + "".join(f'<a href="#assoc-{esc(a)}">{esc(a)}</a>' for a in assocs) + "</nav>",
        "<h2>Comparison</h2>",
        f'<p class="muted">log {esc(log)}{part}; times in seconds, ATE and relation errors in metres '
        "(rpe_trans_per_m per metre), rotations in degrees; best value per column highlighted (not "
        f"matched_total's: more matches is better only when they are right, the ATE tells).{shared}</p>",
        _comparison_table(columns, n, MAIN_COLUMNS, wide=True, timed=at_once == 1),
        *_loop_comparison(columns, n, timed=at_once == 1),
        "<h2>Figures</h2>",
        *[figure(out_dir / name, name) for name in COMPARE_FIGURES if (out_dir / name).is_file()],
    ]
    for a in assocs:
        s = summaries[a]
        body.append(f'<h2 id="assoc-{esc(a)}">{esc(a)}</h2>')
        body += [
            h.replace("<h2>", "<h3>").replace("</h2>", "</h3>") for h in _summary_section(s, out_dir / a)
        ]
        body += _figures(out_dir / a, a)
        body += _config_section(s)
    return _page(title, body)


def write_report(out_dir: Path) -> Path:
    """Write ``out_dir/report.html`` for a run or compare directory (drawing missing figures first)."""
    out_dir = Path(out_dir)
    if (out_dir / "comparison.csv").is_file():
        names = list(COMPARE_FIGURES) + [f"{a}/{f}" for a in compare_assocs(out_dir) for f in RUN_FIGURES]
        _ensure_figures(out_dir, names, plot_compare)
        text = _compare_report(out_dir)
    else:
        _ensure_figures(out_dir, RUN_FIGURES, plot_run)
        text = _run_report(out_dir)
    path = out_dir / "report.html"
    path.write_text(text, encoding="utf-8")
    return path
