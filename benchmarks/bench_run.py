"""Whole-run throughput: `cornerslam run` on a 1,081-beam, 10 Hz simulated log (issue 5 target:
>= 100 scans/s with PCA on this machine), every scan and with keyframes, for each associator.

    python benchmarks/bench_run.py [--laps 1]     # writes docs/results/run.md

"scans/s" counts the scans read from the log per second of processing (extract + scan match + predict +
match + update, as timing.csv records them); "wall scans/s" divides by the whole command's wall time
(reading, synchronisation, writing the tables included).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
KEYFRAMES = ["--set", "keyframes.linear_update=0.1", "--set", "keyframes.angular_update=0.1"]
CASES = [
    ("every scan", []),
    ("keyframes 0.1 m / 0.1 rad", KEYFRAMES),
    ("every scan, no scan matching", ["--set", "scan_match.enabled=false"]),
]


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--laps", type=int, default=1)
    args = ap.parse_args()
    exe = (
        [sys.executable, "-m", "cornerslam_cli"]
        if not os.environ.get("CORNERSLAM_EXE")
        else [os.environ["CORNERSLAM_EXE"]]
    )
    rows, versions = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "bench.mcap"
        subprocess.run(
            [*exe, "simulate", str(log), "--seed", "5", "--laps", str(args.laps), "-q"], check=True
        )
        for assoc in ("icnn", "jcbb", "pca"):
            for label, extra in CASES:
                out = Path(tmp) / f"{assoc}-{len(rows)}"
                t0 = time.perf_counter()
                subprocess.run(
                    [*exe, "run", str(log), "--assoc", assoc, "--out", str(out), "-q", *extra], check=True
                )
                wall = time.perf_counter() - t0
                s = json.loads((out / "summary.json").read_text())
                c, t, versions = s["counts"], s["timing"], s["versions"]
                rows.append(
                    (assoc, label, c["scans_in"], c["steps"], c["landmarks"], c["scans_in"] / t["t_total"],
                     c["scans_in"] / wall, 1000 * t["t_total"] / c["steps"], s["accuracy"]["ate"]["rmse"])
                )  # fmt: skip
                print(rows[-1], flush=True)
    lines = [
        "# Whole-run throughput (benchmarks/bench_run.py)",
        "",
        f"`cornerslam simulate --seed 5 --laps {args.laps}` (1,081 beams over 270°, 10 Hz), "
        f"then `cornerslam run` per associator; {platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, BLAS single-threaded (the CLI's default): "
        f"{versions.get('blas', '?')}, numpy SIMD {versions.get('numpy_simd', '?')}.",
        "",
        "| assoc | scans | steps | landmarks | scans/s (processing) | scans/s (wall) | ms/step | ATE m |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for a, label, n, steps, lm, sps, wsps, ms, ate in rows:
        lines.append(
            f"| {a} ({label}) | {n} | {steps} | {lm} | {sps:.0f} | {wsps:.0f} | {ms:.2f} | {ate:.3f} |"
        )
    (ROOT / "docs" / "results" / "run.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
