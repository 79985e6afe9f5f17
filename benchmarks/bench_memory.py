"""Peak memory of ``cornerslam run`` on a 100,000-scan log vs a 1,000-scan log of the same kind.

    python benchmarks/bench_memory.py [--scans 1000,100000] [--dir /tmp/cornerslam-bench] [--assoc pca]

The logs are tests/fault_corpus.py's long logs (a robot circling a box in a room, 64-beam scans at
10 Hz, odometry at 10 Hz), generated once into --dir (streamed: the writer holds one scan at a time).
Each run is a fresh subprocess; peak RSS comes from ``/usr/bin/time -v`` when present, else from
``resource.getrusage(RUSAGE_CHILDREN).ru_maxrss``. Target: the 100,000-scan peak within 1.5× the
1,000-scan peak (memory must not grow with the log's length). Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import json
import re
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from fault_corpus import build_long_log  # noqa: E402

CMD = [sys.executable, "-c", "from cornerslam_cli.cli import main; main()"]
GNU_TIME = Path("/usr/bin/time")


def peak_rss_run(log: Path, out: Path, assoc: str) -> tuple[float, float, dict]:
    """(peak RSS MiB, wall s, summary) of one ``cornerslam run`` in a fresh process."""
    cmd = [*CMD, "run", str(log), "--out", str(out), "-q", "--assoc", assoc]
    t0 = time.perf_counter()
    if GNU_TIME.exists():
        res = subprocess.run([str(GNU_TIME), "-v", *cmd], capture_output=True, text=True)
        m = re.search(r"Maximum resident set size \(kbytes\): (\d+)", res.stderr)
        kib = int(m.group(1)) if m else -1
    else:
        before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        res = subprocess.run(cmd, capture_output=True, text=True)
        kib = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss  # max over children so far
        if kib <= before:
            kib = before  # (an earlier, larger child; run each size in its own process to be exact)
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        raise SystemExit(f"run failed ({res.returncode}): {res.stderr[-2000:]}")
    return kib / 1024, wall, json.loads((out / "summary.json").read_text())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scans", default="1000,100000")
    ap.add_argument("--dir", default="/tmp/cornerslam-bench")
    ap.add_argument("--assoc", default="pca")
    args = ap.parse_args()
    d = Path(args.dir)
    rows = []
    for n in (int(v) for v in args.scans.split(",")):
        t0 = time.perf_counter()
        log = build_long_log(d, n)
        gen = time.perf_counter() - t0
        out = d / f"out_{n}"
        shutil.rmtree(out, ignore_errors=True)
        rss, wall, s = peak_rss_run(log, out, args.assoc)
        c = s["counts"]
        rows.append((n, log.stat().st_size / 2**20, gen, rss, wall, c["steps"], c["landmarks"]))
        print(f"{n} scans: peak RSS {rss:.1f} MiB, {wall:.1f} s, {c['steps']} steps", file=sys.stderr)
    print("| scans | log MiB | peak RSS MiB | wall s | steps | landmarks |")
    print("|---:|---:|---:|---:|---:|---:|")
    for n, mib, _gen, rss, wall, steps, lms in rows:
        print(f"| {n:,} | {mib:.1f} | {rss:.1f} | {wall:.1f} | {steps:,} | {lms} |")
    if len(rows) >= 2:
        ratio = rows[-1][3] / rows[0][3]
        print(f"\npeak RSS ratio {rows[-1][0]:,} / {rows[0][0]:,} scans: {ratio:.2f}× (target ≤ 1.5×)")


if __name__ == "__main__":
    main()
