"""Are this build's outputs those of another build (default main), byte for byte?

    python benchmarks/same_outputs.py [--baseline main] [LOG ...]   # default: every sample log

Runs `cornerslam run` with each build on each log, with scan matching on and off, and compares
trajectory.csv, trajectory.tum, map.csv, lines.csv, the non-timing columns of timing.csv and
summary.json without its timings. Prints one line per run and exits 1 if any output differs.
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from _baseline import ROOT, build_env, revision, source_tree

FILES = ["trajectory.csv", "trajectory.tum", "map.csv", "lines.csv"]
CASES = [("scan matching", []), ("no scan matching", ["--set", "scan_match.enabled=false"])]


def comparable(out: Path) -> dict[str, object]:
    """The outputs of a run that do not depend on the machine's speed."""
    got: dict[str, object] = {f: (out / f).read_bytes() for f in FILES}
    with open(out / "timing.csv", newline="") as f:
        got["timing.csv"] = [
            {k: v for k, v in r.items() if not k.startswith("t_")} for r in csv.DictReader(f)
        ]
    summary = json.loads((out / "summary.json").read_text())
    summary.pop("timing")
    got["summary.json"] = summary
    return got


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--baseline", default="main")
    ap.add_argument("logs", nargs="*", type=Path)
    args = ap.parse_args()
    logs = args.logs or sorted(
        p for p in (ROOT / "sample_logs").iterdir() if p.suffix in (".mcap", ".clf", ".bag")
    )
    differ = 0
    with tempfile.TemporaryDirectory() as t, source_tree(args.baseline) as base_src:
        for log in logs:
            for label, extra in CASES:
                outs = []
                for name, env in (("base", build_env(base_src)), ("this", build_env(ROOT))):
                    out = Path(t) / f"{log.stem}-{name}-{len(extra)}"
                    cmd = [
                        sys.executable,
                        "-m",
                        "cornerslam_cli",
                        "run",
                        str(log.resolve()),
                        "--out",
                        str(out),
                        "-q",
                    ]
                    subprocess.run([*cmd, *extra], check=True, env=env)
                    outs.append(comparable(out))
                bad = [k for k in outs[0] if outs[0][k] != outs[1][k]]
                differ += bool(bad)
                print(f"{log.name} ({label}): {'identical' if not bad else 'DIFFERENT: ' + ', '.join(bad)}")
    print(f"this build ({revision()}) vs {args.baseline} ({revision(args.baseline)}): {differ} runs differ")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
