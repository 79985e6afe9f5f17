"""Whole-run throughput: `cornerslam run` on a 1,081-beam, 10 Hz simulated log (issue 15 target:
>= 300 scans/s with scan matching on), this build side by side with another (default: main).

    python benchmarks/bench_run.py [--laps 1] [--baseline main] [--repeat 2]   # writes docs/results/run.md
    python benchmarks/bench_run.py --set scan_match.near_history=100   # this build so: run_<set>.md

Both builds run the same log in one benchmark run, interleaved (baseline, this, baseline, this, ...) so
that the shared machine's load falls on both alike, after one untimed short run of each (a fresh
source tree compiles its Numba kernels: tens of seconds of wall time); of the ``--repeat`` runs of a
build and case the one with the least processing time is reported. "scans/s" counts the scans read
from the log per second of processing (extract + scan match + predict + match + update, as timing.csv
records them); "wall scans/s" divides by the whole command's wall time (start-up, reading,
synchronisation, writing the tables included). Per-stage figures are medians per step from timing.csv.
"same output" compares trajectory.csv, map.csv and lines.csv of the two builds byte for byte.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _baseline import ROOT, build_env, revision, source_tree

KEYFRAMES = ["--set", "keyframes.linear_update=0.1", "--set", "keyframes.angular_update=0.1"]
CASES = [
    ("every scan", []),
    ("every scan, no scan matching", ["--set", "scan_match.enabled=false"]),
    ("keyframes 0.1 m / 0.1 rad", KEYFRAMES),
]
STAGES = ["t_extract", "t_scan_match", "t_predict", "t_match", "t_update", "t_total"]
OUTPUTS = ["trajectory.csv", "map.csv", "lines.csv"]


def run_once(env: dict, log: Path, out: Path, assoc: str, extra: list[str]) -> dict:
    """One `cornerslam run`; its counts, medians per stage (ms) and throughput."""
    t0 = time.perf_counter()
    cmd = [sys.executable, "-m", "cornerslam_cli", "run", str(log), "--assoc", assoc, "--out", str(out), "-q"]
    subprocess.run([*cmd, *extra], check=True, env=env)
    wall = time.perf_counter() - t0
    s = json.loads((out / "summary.json").read_text())
    with open(out / "timing.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    med = {k: 1e3 * sorted(float(r[k]) for r in rows)[len(rows) // 2] for k in STAGES}
    c, t = s["counts"], s["timing"]
    return {"scans": c["scans_in"], "steps": c["steps"], "landmarks": c["landmarks"],
            "sps": c["scans_in"] / t["t_total"], "wall_sps": c["scans_in"] / wall, "median_ms": med,
            "ate": s["accuracy"]["ate"]["rmse"], "versions": s["versions"], "out": out}  # fmt: skip


PROFILED = [  # (file under cornerslam_cli/, function, what it is)
    ("motion/icp.py", "register", "scan matching: ICP registration (iterations compiled)"),
    ("motion/icp.py", "_grow_map", "scan matching: local map rebuild"),
    ("motion/fusion.py", "fuse", "scan matching: fusion with the odometry"),
    ("motion/fusion.py", "_learn", "  re-estimate of its noise model"),
    ("features/lines.py", "extract_segments", "extraction: line segments"),
    ("features/lines.py", "partition", "  partition (steps 1-6, compiled)"),
    ("features/lines.py", "fit_ranges", "  two-pass line fit (compiled)"),
    ("features/corners.py", "extract_corners", "extraction: corners (compiled)"),
    ("association/gating.py", "gate", "association: gating (compiled)"),
    ("association/pca.py", "group_searches", "association: JCBB per group (compiled)"),
    ("association/pca.py", "combine_groups", "association: PCBB/NUBB combination (compiled)"),
    ("filter/ekf.py", "update", "update: EKF correction"),
    ("filter/ekf.py", "_apply_low_rank", "  Σ − U Uᵀ"),
    ("filter/ekf.py", "check_health", "update: health check of Σ"),
    ("filter/ekf.py", "predict", "prediction"),
    ("logs/sync.py", "synchronise", "outside the stages: reading + synchronising"),
    ("report/run_writer.py", "step", "outside the stages: writing the tables"),
]


def profile(env: dict, log: Path, out: Path, extra: list[str]) -> list[tuple[str, float, float]]:
    """(what, ms per scan, calls per scan) of the functions in PROFILED, from cProfile of one run
    (cumulative time: a function's callees included)."""
    import pstats

    prof = out.with_suffix(".prof")
    cmd = [sys.executable, "-m", "cProfile", "-o", str(prof), "-m", "cornerslam_cli", "run", str(log),
           "--out", str(out), "-q", *extra]  # fmt: skip
    subprocess.run(cmd, check=True, env=env)
    n = json.loads((out / "summary.json").read_text())["counts"]["scans_in"]
    found = {}
    for (file, _, name), (_, calls, _, cum, _) in pstats.Stats(str(prof)).stats.items():
        key = (file.split("cornerslam_cli/")[-1], name)
        if "cornerslam_cli/" in file and (key not in found or cum > found[key][0]):
            found[key] = (cum, calls)
    return [
        (what, 1e3 * found[f, fn][0] / n, found[f, fn][1] / n) for f, fn, what in PROFILED if (f, fn) in found
    ]


def same_outputs(a: Path, b: Path) -> bool:
    return all((a / f).read_bytes() == (b / f).read_bytes() for f in OUTPUTS)


def side_by_side(builds: dict[str, dict], log: Path, tmp: Path, repeat: int, sets: list[str]) -> list[tuple]:
    """(case, build label, best run) for every case and build, interleaved; ``sets`` (``--set`` options)
    for the last build (this one)."""
    rows, this = [], list(builds)[-1]
    for label, extra in CASES:
        best: dict[str, dict] = {}
        for rep in range(repeat):
            for name, env in builds.items():
                own = sets if name == this else []
                r = run_once(env, log, tmp / f"{name}-{len(rows)}-{rep}", "pca", [*extra, *own])
                print(name, label, f"{r['sps']:.0f} scans/s", flush=True)
                if name not in best or r["sps"] > best[name]["sps"]:
                    best[name] = r
        rows += [(label, name, r) for name, r in best.items()]
    return rows


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--laps", type=int, default=1)
    ap.add_argument("--baseline", default="main", help="git revision to compare with ('' for none)")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                    help="config override of this build's runs (report: run_<KEY-VALUE>.md)")  # fmt: skip
    args = ap.parse_args()
    sets = [x for kv in args.sets for x in ("--set", kv)]
    this = f"this build ({revision()})" + "".join(f" `{kv}`" for kv in args.sets)
    with tempfile.TemporaryDirectory() as t, source_tree(args.baseline or "HEAD") as base_src:
        tmp = Path(t)
        log = tmp / "bench.mcap"
        cur_env = build_env(ROOT)
        subprocess.run([sys.executable, "-m", "cornerslam_cli", "simulate", str(log), "--seed", "5",
                        "--laps", str(args.laps), "-q"], check=True, env=cur_env)  # fmt: skip
        builds = (
            {f"{args.baseline} ({revision(args.baseline)})": build_env(base_src)} if args.baseline else {}
        )
        builds[this] = cur_env
        for i, env in enumerate(builds.values()):  # untimed: a fresh source tree compiles its kernels
            run_once(env, log, tmp / f"warm-{i}", "pca", ["--max-scans", "20"])
        rows = side_by_side(builds, log, tmp, args.repeat, sets)
        assoc_rows = []
        for assoc in ("icnn", "jcbb"):
            r = run_once(cur_env, log, tmp / f"assoc-{assoc}", assoc, sets)
            assoc_rows.append((assoc, r))
        profiles = [
            (label, profile(cur_env, log, tmp / f"prof-{i}", [*extra, *sets]))
            for i, (label, extra) in enumerate(CASES[:2])
        ]
        identical = {
            label: same_outputs(*(r["out"] for case, _, r in rows if case == label))
            for label, _ in CASES
            if args.baseline
        }
        versions = rows[-1][2]["versions"]
        text = report(args, rows, assoc_rows, identical, versions, this, profiles)
    name = "run" + "".join("_" + re.sub(r"[^A-Za-z0-9._-]+", "-", kv) for kv in args.sets)
    (ROOT / "docs" / "results" / f"{name}.md").write_text(text)
    print(text)
    return 0


def report(args, rows, assoc_rows, identical, versions, this, profiles) -> str:
    lines = [
        "# Whole-run throughput (benchmarks/bench_run.py)",
        "",
        f"`cornerslam simulate --seed 5 --laps {args.laps}` (1,081 beams over 270°, 10 Hz), then "
        f"`cornerslam run --assoc pca` with each build; {platform.machine()}, {os.cpu_count()} cores shared "
        f"with other work (1-min load average {os.getloadavg()[0]:.2f} at the end), Python "
        f"{platform.python_version()}, BLAS single-threaded (the CLI's default): "
        f"{versions.get('blas', '?')}, numpy SIMD {versions.get('numpy_simd', '?')}. Best of "
        f"{args.repeat} interleaved runs per build and case; stage columns are medians per step (ms).",
        "",
        "| case | build | scans/s (processing) | scans/s (wall) | extract | scan match | predict | match "
        "| update | total | landmarks | ATE m |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for label, name, r in rows:
        m = r["median_ms"]
        lines.append(
            f"| {label} | {name} | {r['sps']:.0f} | {r['wall_sps']:.0f} | "
            + " | ".join(f"{m[k]:.2f}" for k in STAGES)
            + f" | {r['landmarks']} | {r['ate']:.3f} |"
        )
    if args.baseline:
        lines += ["", f"Ratio, this build ÷ {args.baseline} (throughput: > 1 is faster; stage times: < 1 is "
                  "faster), and whether trajectory.csv, map.csv and lines.csv are byte-identical:", "",
                  "| case | scans/s | wall scans/s | extract | scan match | predict | match | update | total "
                  "| same output |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|---|"]  # fmt: skip
        for label, _ in CASES:
            base, cur = (r for case, _, r in rows if case == label)
            ratio = [
                f"{cur['median_ms'][k] / base['median_ms'][k]:.2f}" if base["median_ms"][k] > 0 else "–"
                for k in STAGES
            ]
            lines.append(
                f"| {label} | {cur['sps'] / base['sps']:.2f} | {cur['wall_sps'] / base['wall_sps']:.2f} | "
                + " | ".join(ratio)
                + f" | {'yes' if identical[label] else 'NO'} |"
            )
    lines += ["", f"Other associators, {this}, every scan:", "",
              "| assoc | scans/s (processing) | scans/s (wall) | match ms (median) | total ms (median) "
              "| ATE m |",
              "|---|---:|---:|---:|---:|---:|"]  # fmt: skip
    for assoc, r in assoc_rows:
        m = r["median_ms"]
        lines.append(
            f"| {assoc} | {r['sps']:.0f} | {r['wall_sps']:.0f} | {m['t_match']:.2f} | {m['t_total']:.2f} "
            f"| {r['ate']:.3f} |"
        )
    lines += ["", f"Where the time goes, {this} (cProfile of one run, PCA: cumulative ms per scan, callees "
              "included; the profiler's overhead inflates Python-heavy code, so read the shares, not the "
              "absolute times):", "",
              "| function | " + " | ".join(f"{label}: ms/scan | calls/scan" for label, _ in profiles) + " |",
              "|---|" + "---:|---:|" * len(profiles)]  # fmt: skip
    whats = [w for w, _, _ in profiles[0][1]]
    table = [{w: (ms, calls) for w, ms, calls in prof} for _, prof in profiles]
    for w in whats:
        cells = [f"{t[w][0]:.3f} | {t[w][1]:.1f}" if w in t else "– | –" for t in table]
        lines.append(f"| {w} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
