"""The regression references of the sample logs (sample_logs/expected.json): show what moved, accept it.

    python sample_logs/update_expected.py                    # run every reference, print what moved
    python sample_logs/update_expected.py --accept "why"     # ... and write the new figures, the reason
                                                             # recorded in the file's "history"

Accept only after a change that is *meant* to move the results, and say why. The file holds figures
only: tests/test_regression.py reads each run's summary.json with its own code and keeps its own
tolerances (exact counts, ATE within 1.25 × the reference + 5 mm), so accepting new figures never
loosens the test. Without ``--accept`` nothing is written and the exit status is 1 when anything moved.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import json
import math
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

HERE = Path(__file__).resolve().parent
EXPECTED = HERE / "expected.json"

# reference name -> (log, extra command-line arguments: what a user of that robot would pass)
ROOT = HERE.parent  # the runs start here: arguments name files relative to the repository
MINES = ["--config", "configs/mines.yaml"]  # the rover's body (70 beams at each end), its laser mount
SINGLE_MAP = ["--set", "submaps.enabled=false"]  # the paper's single EKF map (no submaps, no pose graph)
NO_SCAN_MATCH = ["--set", "scan_match.enabled=false"] + SINGLE_MAP  # the paper's filter: wheel odometry only
RUNS = {
    "sim_office.mcap": ("sim_office.mcap", []),
    "sim_office.mcap single map": ("sim_office.mcap", SINGLE_MAP),
    "intel_cut.clf": ("intel_cut.clf", []),
    "intel_cut.clf single map": ("intel_cut.clf", SINGLE_MAP),
    "intel_cut.clf scan_match off": ("intel_cut.clf", NO_SCAN_MATCH),
    "mines_exp3_cut.bag": ("mines_exp3_cut.bag", MINES),
    "mines_exp3_cut.bag single map": ("mines_exp3_cut.bag", MINES + SINGLE_MAP),
    "mines_exp3_cut.bag scan_match off": ("mines_exp3_cut.bag", MINES + NO_SCAN_MATCH),
}


def run_summary(log: str, args: list[str], out: Path) -> dict:
    """summary.json of ``cornerslam run`` on a sample log (in-process, through the CLI)."""
    from click.testing import CliRunner

    from cornerslam_cli.cli import cli

    with contextlib.chdir(ROOT):
        res = CliRunner().invoke(cli, ["run", str(HERE / log), "--out", str(out), "-q", *args])
    if res.exit_code != 0:
        raise RuntimeError(f"cornerslam run {log} {' '.join(args)} failed: {res.output}")
    return json.loads((out / "summary.json").read_text())


def reference_of(summary: dict) -> dict:
    """The figures kept for one run: deterministic counts, the final pose and the ATEs when known."""
    counts, acc = summary["counts"], summary.get("accuracy") or {}
    figures = {key: counts.get(key) for key in ("steps", "landmarks", "matched_total", "scans_matched")}
    figures["final_pose"] = summary["final_pose"]
    for key in ("ate", "odom_ate", "scan_odom_ate"):
        figures[f"{key}_rmse"] = acc[key]["rmse"] if key in acc else None
    return figures


def compute(run: Callable[[str, list[str], Path], dict] = run_summary) -> dict:
    """Every reference run's entry: log, arguments and figures."""
    runs = {}
    with tempfile.TemporaryDirectory() as tmp:
        for i, (name, (log, args)) in enumerate(RUNS.items()):
            runs[name] = {"log": log, "args": args, **reference_of(run(log, args, Path(tmp) / str(i)))}
    return runs


def differences(old: dict, new: dict) -> list[str]:
    """One line per figure that moved, per run added and per run removed."""
    lines = [f"{name}: removed" for name in old if name not in new]
    for name, entry in new.items():
        if name not in old:
            lines.append(f"{name}: new")
            continue
        for key, value in entry.items():
            if _moved(old[name].get(key), value):
                lines.append(f"{name}: {key} {_show(old[name].get(key))} -> {_show(value)}")
    return lines


def _moved(old, new) -> bool:
    """Whether a figure moved: counts by any change, floats by more than a millionth of their size
    (what :func:`_show` prints; below that another machine's rounding moves them, and the regression
    test's tolerances are far wider), lists element by element."""
    if isinstance(old, list) and isinstance(new, list):
        return len(old) != len(new) or any(_moved(a, b) for a, b in zip(old, new, strict=True))
    if isinstance(old, float) and isinstance(new, float):
        return not math.isclose(old, new, rel_tol=1e-6, abs_tol=1e-9)
    return old != new


def _show(value) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, list):
        return "[" + ", ".join(_show(v) for v in value) + "]"
    return str(value)


def code_version() -> str:
    """The commit the figures were computed on (``-dirty``: with uncommitted changes), or "unknown"."""
    try:
        out = subprocess.run(
            ["git", "describe", "--always", "--dirty", "--abbrev=12"],
            cwd=HERE, capture_output=True, text=True, check=True,
        )  # fmt: skip
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return out.stdout.strip()


def accept(old: dict, runs: dict, reason: str, changes: list[str]) -> dict:
    """The new file content: the new figures, the old history plus one entry saying what and why."""
    entry = {
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "reason": reason,
        "commit": code_version(),
        "changes": changes,
    }
    return {"runs": runs, "history": [*old.get("history", []), entry]}


def main(argv: list[str] | None = None, run: Callable[[str, list[str], Path], dict] = run_summary) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--accept", metavar="REASON", help="write the new figures, recording REASON")
    opts = parser.parse_args(argv)
    if opts.accept is not None and not opts.accept.strip():
        parser.error("--accept needs a reason: what changed in the code and why the figures move")
    old = json.loads(EXPECTED.read_text()) if EXPECTED.exists() else {}
    runs = compute(run)
    changes = differences(old.get("runs", {}), runs)
    print("\n".join(changes) if changes else "no figure moved")
    if opts.accept is None:
        if changes:
            print('not written: run with --accept "REASON" to record these figures', file=sys.stderr)
        return 1 if changes else 0
    if changes:
        EXPECTED.write_text(json.dumps(accept(old, runs, opts.accept.strip(), changes), indent=2) + "\n")
        print(f"wrote {EXPECTED}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
