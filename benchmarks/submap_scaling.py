"""Cost against log length, two-level SLAM (submaps + pose graph) beside the paper's single map.

    python benchmarks/submap_scaling.py [--data DIR] [--scans 20000] [--short 2000]

For each log and mode (``submaps.enabled`` true / false), one ``cornerslam run`` (a subprocess, its
peak RSS from the kernel): the per-step time (timing.csv ``t_total``, which holds loop closing and the
graph's optimisation on the steps that close a submap) over the last 10 % of steps against the first
10 %, the whole-run throughput, the peak memory. Logs: the real infinite-corridor (1,941 keyframes)
and simulated multi-lap office logs of ``--short`` and ``--scans`` scans (10 Hz, 1,081 beams), so
memory is compared between a short and a 10× longer run of the same world. Writes
``docs/results/submap_scaling.md``. Every figure in it is from one run of this script on one machine:
the ratios are the claim; absolute times vary with the machine and its load (say so when quoting).
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from real_logs import CLI, ROOT, default_data  # noqa: E402

SIM_SCANS_PER_LAP = 501  # the simulated office lap at 10 Hz, 0.5 m/s (cornerslam simulate)
MODES = {"submaps": ["--set", "submaps.enabled=true"], "single map": ["--set", "submaps.enabled=false"]}


def run(log: Path, out: Path, extra: list[str]) -> dict:
    """One run and its figures: per-step time first / last 10 %, throughput, peak memory."""
    cmd = [*CLI, "run", str(log), "--out", str(out), "-q", *extra]
    # a fresh interpreter per measured run so RUSAGE_CHILDREN's maximum is this run's own
    wrapper = [sys.executable, "-c", RSS_CHILD, *cmd]
    res = subprocess.run(wrapper, capture_output=True, text=True)
    if res.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed: {res.stderr.strip()[-400:]}")
    rss = float(res.stdout.strip().splitlines()[-1])
    s = json.loads((out / "summary.json").read_text())
    with open(out / "timing.csv") as f:
        t = np.array([float(r["t_total"]) for r in csv.DictReader(f)])
    tenth = max(1, len(t) // 10)
    first, last = t[:tenth].mean(), t[-tenth:].mean()
    ate = (s.get("accuracy") or {}).get("ate") or {}
    return {
        "steps": len(t),
        "first_ms": 1e3 * first,
        "last_ms": 1e3 * last,
        "ratio": last / first,
        "scans_per_s": s["timing"]["scans_per_second"],
        "wall": s["timing"]["wall_time"],
        "rss_mb": rss,
        "ate": ate.get("rmse"),
        "submaps": s["counts"].get("submaps"),
        "loops": s["counts"].get("loops_accepted"),
    }


# runs argv[1:] as a child and prints its peak RSS in MB (Linux ru_maxrss is in KB)
RSS_CHILD = (
    "import resource, subprocess, sys\n"
    "r = subprocess.run(sys.argv[1:])\n"
    "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0)\n"
    "sys.exit(r.returncode)\n"
)


def simulated(tmp: Path, scans: int) -> Path:
    """A simulated multi-lap office log of about ``scans`` scans (whole laps)."""
    laps = max(1, round(scans / SIM_SCANS_PER_LAP))
    out = tmp / f"sim_{laps}laps.mcap"
    cmd = [*CLI, "simulate", str(out), "--laps", str(laps), "--seed", "1", "-q"]
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed: {res.stderr.strip()}")
    return out


def table(rows: list[tuple[str, str, dict]]) -> list[str]:
    lines = [
        "| log | mode | steps | submaps | loops | ATE m | per-step first 10 % ms | last 10 % ms | last/first "
        "| scans/s | peak RSS MB |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for log, mode, r in rows:
        ate = "" if r["ate"] is None else f"{r['ate']:.3f}"
        loops = "" if r["loops"] is None else r["loops"]
        lines.append(
            f"| {log} | {mode} | {r['steps']:,} | {r['submaps'] or ''} | {loops} "
            f"| {ate} | {r['first_ms']:.1f} | {r['last_ms']:.1f} | {r['ratio']:.2f} | {r['scans_per_s']:.0f} "
            f"| {r['rss_mb']:.0f} |"
        )
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=default_data())
    ap.add_argument("--scans", type=int, default=20_000)
    ap.add_argument("--short", type=int, default=2_000)
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "submap_scaling.md")
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        corridor = args.data / "radish" / "infinite-corridor.log"
        logs = [("infinite-corridor", corridor)] if corridor.is_file() else []
        logs += [(f"simulated, {n:,} scans", simulated(tmp, n)) for n in (args.short, args.scans)]
        for name, log in logs:
            for mode, extra in MODES.items():
                r = run(log, tmp / f"{len(rows)}", extra)
                rows.append((name, mode, r))
                print(name, mode, json.dumps({k: v for k, v in r.items()}), flush=True)
    by = {(log, mode): r for log, mode, r in rows}
    sub = [r for (log, mode), r in by.items() if mode == "submaps" and log.startswith("simulated")]
    text = [
        "# Cost against log length: submaps + pose graph vs the single map",
        "",
        "From `python benchmarks/submap_scaling.py` (one run, this 2-core machine). Per-step time is",
        "timing.csv's `t_total` (loop closing and the graph's optimisation included on the steps that",
        "close a submap), averaged over the first and the last 10 % of the steps.",
        "",
        *table(rows),
        "",
    ]
    if len(sub) == 2:
        text.append(
            f"Peak memory, submaps, {sub[1]['steps']:,} vs {sub[0]['steps']:,} simulated scans: "
            f"{sub[1]['rss_mb'] / sub[0]['rss_mb']:.2f}×."
        )
    args.out.write_text("\n".join(text) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
