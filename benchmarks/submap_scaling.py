"""Cost against log length, two-level SLAM (submaps + pose graph) beside the paper's single map.

    python benchmarks/submap_scaling.py [--data DIR] [--scans 20000] [--short 2000] [--repeat 3]
                                        [--set KEY=VALUE ...]

For each log and mode (``submaps.enabled`` true / false), one ``cornerslam run`` (a subprocess; its
peak RSS is the kernel's ``ru_maxrss`` of that process, from ``wait4``): the per-step time (timing.csv
``t_total``, which holds loop closing and the graph's optimisation on the steps that close a submap)
over the last 10 % of steps against the first 10 %, the throughput of the filter (steps / Σ t_total)
and of the whole run (steps / wall time: reading, the front end, the filter, every output), the peak
memory. Logs: the real infinite-corridor (1,941 keyframes) and the first ``--short`` and ``--scans``
scans (``--max-scans``) of one simulated multi-lap office log (10 Hz, 1,081 beams, every scan a
keyframe), so memory is compared between a short and a 10× longer run of the same world. Writes
``docs/results/submap_scaling.md``. Every figure in it is from one run of this script on one machine:
the ratios are the claim; absolute times vary with the machine and its load (say so when quoting).
A short run before them compiles the kernels of a fresh checkout. The real log's two-level run is
repeated ``--repeat`` times (its outputs are the same each time, its
times are not): the table shows the run of median last/first, a line below the range of all, and
that run's per-step time, loop closing's share and loop candidates verified by tenth of the log
(on infinite-corridor the robot revisits little in its first tenth). With ``--set`` (repeatable), a
third mode runs submaps with those settings too (e.g. ``graph.refine=true``: is an option's cost flat?),
written to ``docs/results/submap_scaling_<settings>.md`` unless ``--out`` says where.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from real_logs import CLI, ROOT, default_data  # noqa: E402

from cornerslam_cli.config import config_from  # noqa: E402
from cornerslam_cli.errors import CornerslamError  # noqa: E402
from cornerslam_cli.simulate import SimParams  # noqa: E402
from cornerslam_cli.simworld import OFFICE_LOOP  # noqa: E402

MODES = {"submaps": ["--set", "submaps.enabled=true"], "single map": ["--set", "submaps.enabled=false"]}


def run(log: Path, out: Path, extra: list[str]) -> dict:
    """One run and its figures: per-step time first / last 10 %, throughput, peak memory."""
    cmd = [*CLI, "run", str(log), "--out", str(out), "-q", *extra]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    err = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)  # this process's own rusage (Linux ru_maxrss: KB)
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed: {err.strip()[-400:]}")
    s = json.loads((out / "summary.json").read_text())
    with open(out / "timing.csv") as f:
        rows = list(csv.DictReader(f))
    t = np.array([float(r["t_total"]) for r in rows])
    loop = np.array([float(r["t_loop"] or 0.0) for r in rows])
    tenth = max(1, len(t) // 10)
    first, last = t[:tenth].mean(), t[-tenth:].mean()
    ate = (s.get("accuracy") or {}).get("ate") or {}
    timing = s["timing"]
    return {
        "steps": len(t),
        "first_ms": 1e3 * first,
        "last_ms": 1e3 * last,
        "ratio": last / first,
        "last_loop_ms": 1e3 * loop[-tenth:].mean(),
        "tenths_ms": [1e3 * c.mean() for c in np.array_split(t, 10)],  # per-step time by tenth of the log
        "tenths_loop_ms": [1e3 * c.mean() for c in np.array_split(loop, 10)],
        "tenths_candidates": candidates_by_tenth(out / "loops.csv", len(t)),
        "t": t,  # per-step t_total, s (not printed: repeat_line's fastest of the runs)
        "scans_per_s": timing["scans_per_second"],
        "run_scans_per_s": len(t) / timing["wall_time"],
        "wall": timing["wall_time"],
        "rss_mb": usage.ru_maxrss / 1024.0,
        "ate": ate.get("rmse"),
        "submaps": s["counts"].get("submaps"),
        "loops": s["counts"].get("loops_accepted"),
    }


def candidates_by_tenth(loops_csv: Path, steps: int) -> list[int]:
    """Loop candidates verified (loops.csv rows) in each tenth of the steps (none without submaps)."""
    if not loops_csv.is_file():
        return [0] * 10
    with open(loops_csv) as f:
        at = np.array([int(r["step"]) for r in csv.DictReader(f)], dtype=np.int64)
    bounds = [len(c) for c in np.array_split(np.arange(steps), 10)]
    edges = np.concatenate(([0], np.cumsum(bounds)))
    return np.histogram(at, bins=edges)[0].tolist()


def simulated(tmp: Path, scans: int) -> Path:
    """A simulated multi-lap office log of at least ``scans`` scans (whole laps)."""
    p = SimParams()
    loop = np.vstack((OFFICE_LOOP, OFFICE_LOOP[:1]))
    per_lap = float(np.hypot(*np.diff(loop, axis=0).T).sum()) / p.speed * p.rate  # turns add a few
    laps = max(1, math.ceil(scans / per_lap))
    out = tmp / f"sim_{laps}laps.mcap"
    cmd = [*CLI, "simulate", str(out), "--laps", str(laps), "--seed", "1", "-q"]
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed: {res.stderr.strip()}")
    return out


def table(rows: list[tuple[str, str, dict]]) -> list[str]:
    lines = [
        "| log | mode | steps | submaps | loops | ATE m | per-step first 10 % ms | last 10 % ms "
        "| of which loops ms | last/first | filter scans/s | whole run scans/s | peak RSS MB |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for log, mode, r in rows:
        ate = "" if r["ate"] is None else f"{r['ate']:.3f}"
        loops = "" if r["loops"] is None else r["loops"]
        lines.append(
            f"| {log} | {mode} | {r['steps']:,} | {r['submaps'] or ''} | {loops} "
            f"| {ate} | {r['first_ms']:.1f} | {r['last_ms']:.1f} | {r['last_loop_ms']:.1f} "
            f"| {r['ratio']:.2f} | {r['scans_per_s']:.0f} | {r['run_scans_per_s']:.0f} "
            f"| {r['rss_mb']:.0f} |"
        )
    return lines


def repeat_line(name: str, mode: str, runs: list[dict]) -> str:
    """The spread of one log's repeated runs (sorted by last/first)."""
    ratios = ", ".join(f"{r['ratio']:.2f}" for r in runs)
    firsts = ", ".join(f"{r['first_ms']:.1f}" for r in runs)
    lasts = ", ".join(f"{r['last_ms']:.1f}" for r in runs)
    # each step's fastest of the runs: the same work each time (the outputs are the same), so what the
    # runs differ by is the machine's load, which the minimum is least moved by (as timeit takes it)
    fastest = np.min([r["t"] for r in runs], axis=0)
    tenth = max(1, len(fastest) // 10)
    first, last = 1e3 * fastest[:tenth].mean(), 1e3 * fastest[-tenth:].mean()
    return (
        f"{name}, {mode}, {len(runs)} runs (same outputs): last/first {ratios} (the table: the median); "
        f"first 10 % {firsts} ms; last 10 % {lasts} ms. Each step's fastest of the {len(runs)} runs (the "
        f"same work each time; the load of the machine is what differs, and moves a minimum least): "
        f"last/first {last / first:.2f} ({first:.1f} and {last:.1f} ms)."
    )


def tenths_line(name: str, mode: str, r: dict) -> str:
    """Per-step time by tenth of the log (the run in the table): is the cost growing, or a tenth's?"""
    tenths = ", ".join(f"{t:.1f}" for t in r["tenths_ms"])
    loops = ", ".join(f"{t:.1f}" for t in r["tenths_loop_ms"])
    candidates = ", ".join(str(c) for c in r["tenths_candidates"])
    return (
        f"{name}, {mode}, by tenth of the log: per-step time {tenths} ms; of which loop closing {loops} ms; "
        f"loop candidates verified {candidates}."
    )


def memory_lines(rows: list[tuple[str, str, dict]], modes: dict[str, list[str]]) -> list[str]:
    """Peak memory of the long simulated run against the short one, per mode."""
    sim = [(mode, r) for log, mode, r in rows if log.startswith("simulated")]
    lines = []
    for mode in modes:
        short, long = [r for m, r in sim if m == mode]
        lines.append(
            f"Peak memory, {mode}, {long['steps']:,} vs {short['steps']:,} simulated scans: "
            f"{long['rss_mb'] / short['rss_mb']:.2f}× ({long['rss_mb']:.0f} vs {short['rss_mb']:.0f} MB)."
        )
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=default_data())
    ap.add_argument("--scans", type=int, default=20_000)
    ap.add_argument("--short", type=int, default=2_000)
    ap.add_argument("--repeat", type=int, default=3, help="runs of the real log with submaps (timing spread)")
    ap.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", help="a third mode: submaps with these"
    )
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    if min(args.scans, args.short, args.repeat) < 1:
        ap.error("--scans, --short and --repeat must be at least 1")
    try:  # a mistyped setting fails now, not after minutes of the other modes' runs
        config_from({}, args.set)
    except CornerslamError as e:
        ap.error(str(e))
    modes = dict(MODES)
    if args.set:
        variant = " ".join(args.set)
        modes = {
            "submaps": MODES["submaps"],
            f"submaps, {variant}": [*MODES["submaps"], *(a for s in args.set for a in ("--set", s))],
            "single map": MODES["single map"],
        }
    slug = (
        re.sub(r"[^A-Za-z0-9._-]+", "-", "_" + "_".join(s.replace("=", "-") for s in args.set))
        if args.set
        else ""
    )
    out = args.out or ROOT / "docs" / "results" / f"submap_scaling{slug}.md"
    if not out.parent.is_dir() or out.is_dir():
        ap.error(f"--out: {out} is a folder" if out.is_dir() else f"--out: no folder {out.parent}")
    rows = []
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        corridor = args.data / "radish" / "infinite-corridor.log"
        if not corridor.is_file():
            raise SystemExit(f"no {corridor} (give --data, the folder of the real logs)")
        logs = [("infinite-corridor", corridor, [])]
        sim = simulated(tmp, max(args.short, args.scans))
        logs += [(f"simulated, {n:,} scans", sim, ["--max-scans", str(n)]) for n in (args.short, args.scans)]
        # a short run first: a fresh checkout compiles its Numba kernels in its first run (a minute), which
        # would land in the first timed run's wall time and memory
        run(corridor, tmp / "warm-up", ["--max-scans", "50"])
        repeats = []
        for name, log, limit in logs:
            for mode, extra in modes.items():
                n = args.repeat if name == "infinite-corridor" and mode.startswith("submaps") else 1
                runs = [run(log, tmp / f"{len(rows)}_{k}", [*limit, *extra]) for k in range(n)]
                for r in runs:
                    print(name, mode, json.dumps({k: v for k, v in r.items() if k != "t"}), flush=True)
                runs.sort(key=lambda r: r["ratio"])
                rows.append((name, mode, runs[(len(runs) - 1) // 2]))
                if n > 1:
                    repeats += [repeat_line(name, mode, runs), tenths_line(name, mode, rows[-1][2])]
    text = [
        "# Cost against log length: submaps + pose graph vs the single map",
        "",
        f"From `python benchmarks/submap_scaling.py{' ' if args.set else ''}"
        f"{' '.join('--set ' + s for s in args.set)}` (one run, this 2-core machine). Per-step time is",
        "timing.csv's `t_total` (loop closing and the graph's optimisation included on the steps that",
        "close a submap), averaged over the first and the last 10 % of the steps; 'of which loops': the",
        "last 10 %'s `t_loop` (loop closing and optimisation) per step. Filter scans/s: steps /",
        "Σ t_total; whole run: steps / wall time (reading, front end, filter and every output file).",
        "Peak RSS: the run process's maximum resident set (its own rusage).",
        "",
        *table(rows),
        "",
        *repeats,
        *memory_lines(rows, modes),
    ]
    out.write_text("\n".join(text) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
