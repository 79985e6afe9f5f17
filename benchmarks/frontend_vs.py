"""The front end's matching time per keyframe on the real-log panel, this build against another, in one
benchmark run: `frontend_panel.py` of each build, interleaved (baseline, this, baseline, this, ...).

    python benchmarks/frontend_vs.py [--baseline main] [--repeat 2] [--data DIR] [--out FILE]

For a change meant to make the front end faster and leave its results alone: per log, each run's median
CPU time per keyframe (frontend_panel.py's "match ms"), the ratio of this build's sum over the runs to
the baseline's, and whether every other figure of the row (the chain's errors, what it learnt) is the
same in every run of both builds. Writes docs/results/frontend_vs_<REV>.md by default.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _baseline import build_env, revision, source_tree  # noqa: E402
from real_logs import ROOT, default_data  # noqa: E402

MS_COLUMN = 7  # "match ms (CPU)" in frontend_panel.py's rows (after the log's name)


def rows(stdout: str) -> dict[str, tuple[float, str]]:
    """frontend_panel.py's table rows: log -> (match ms, the rest of the row without it)."""
    out = {}
    for line in stdout.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if not line.startswith("| ") or cells[0] == "log" or len(cells) <= MS_COLUMN:
            continue
        out[cells[0]] = (float(cells[MS_COLUMN]), "|".join(cells[:MS_COLUMN] + cells[MS_COLUMN + 1 :]))
    return out


def panel(tree: Path, data: Path) -> dict[str, tuple[float, str]]:
    """One frontend_panel.py run of the build under ``tree``."""
    script = tree / "benchmarks" / "frontend_panel.py"
    res = subprocess.run(
        [sys.executable, str(script), "--data", str(data)],
        env=build_env(tree), capture_output=True, text=True, check=True,
    )  # fmt: skip
    return rows(res.stdout)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--baseline", default="main")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--data", type=Path, default=default_data())
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    base_rev, this_rev = revision(args.baseline), revision()
    out = args.out or ROOT / "docs" / "results" / f"frontend_vs_{base_rev}.md"
    runs: dict[str, list[dict[str, tuple[float, str]]]] = {"baseline": [], "this": []}
    with source_tree(args.baseline) as base:
        for r in range(args.repeat):
            for name, tree in (("baseline", base), ("this", ROOT)):
                print(f"run {r + 1}/{args.repeat}: {name}", file=sys.stderr, flush=True)
                runs[name].append(panel(tree, args.data))
    logs = list(runs["baseline"][0])
    lines = [
        f"# Front end: matching time per keyframe, {this_rev} against {base_rev}",
        "",
        f"`python benchmarks/frontend_vs.py --baseline {args.baseline} --repeat {args.repeat}`: "
        "frontend_panel.py of both builds, interleaved, on this machine (median CPU ms per keyframe of "
        "each run; ratio: this build's sum over the runs ÷ the baseline's). *Same figures*: every other "
        "figure of the log's row is the same in every run of both builds.",
        "",
        "| log | baseline ms | this ms | ratio | same figures |",
        "|---|---|---|---:|---|",
    ]
    ratios = []
    for log in logs:
        b = [run[log][0] for run in runs["baseline"]]
        t = [run[log][0] for run in runs["this"]]
        same = len({run[log][1] for run in runs["baseline"] + runs["this"]}) == 1
        ratios.append(sum(t) / sum(b))
        lines.append(
            f"| {log} | {', '.join(f'{v:.1f}' for v in b)} | {', '.join(f'{v:.1f}' for v in t)} "
            f"| {ratios[-1]:.2f} | {'yes' if same else '**no**'} |"
        )
    lines += [
        "",
        f"Ratio over the {len(logs)} logs: median **{statistics.median(ratios):.2f}**, "
        f"{min(ratios):.2f}–{max(ratios):.2f}; below 1 on {sum(r < 1 for r in ratios)} of {len(logs)}.",
    ]
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
