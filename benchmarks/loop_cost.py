"""Loop closing's cost, this build against another (default main), side by side in one run.

    .venv/bin/python benchmarks/loop_cost.py [--baseline main] [--runs 3] [--profile] [LOG]
    # default LOG: radish/infinite-corridor.log (1,941 keyframes) under --data (real_logs.default_data)

Each build runs ``cornerslam run LOG`` ``--runs`` times, the builds alternating so that the load of a
shared machine falls on both alike. Per run: Σ t_loop of timing.csv (what loop closing — candidate
verification and the pose graph's optimisation, on the steps that close a submap — adds to the steps),
summary.json's t_loop (that plus the final keyframe graph's solve), the run's CPU seconds (its process's
rusage), and t_loop per step by tenth of the log. The outputs are compared byte for byte
(trajectory.tum, trajectory.csv, map.csv, loops.csv): a faster build that changes them is refused.
With ``--profile``, one more run of each build under cProfile, enabled only inside loop closing
(HierarchicalSlam._close): the share of its time each stage takes. Medians and ratios (base / this)
are printed as Markdown; docs/results/loop_cost.md holds a run. Wall-clock figures of one run on a
loaded machine mean little; CPU seconds and the medians of several runs, and the profile's shares, say
more.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import pstats
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from _baseline import ROOT, build_env, revision, source_tree
from real_logs import default_data

COMPARED = ["trajectory.tum", "trajectory.csv", "map.csv", "loops.csv"]
TENTHS = 10

# cProfile inside HierarchicalSlam._close only (the time timing.csv's t_loop measures), then the CLI
PROFILED_RUN = """
import cProfile, sys
from cornerslam_cli import hierarchy
from cornerslam_cli.cli import main
profile, close = cProfile.Profile(), hierarchy.HierarchicalSlam._close
def _close(self, *args, **kwargs):
    profile.enable()
    try:
        return close(self, *args, **kwargs)
    finally:
        profile.disable()
hierarchy.HierarchicalSlam._close = _close
try:
    main(sys.argv[2:], standalone_mode=False)
finally:
    profile.dump_stats(sys.argv[1])
"""

# the stages of loop closing, (label, file, function); cumulative times (a stage holds the ones below it)
STAGES = [
    ("close a submap: keyframe chain (graph/submap.py keyframe_factors)", "submap.py", "keyframe_factors"),
    ("pose graph: optimize (GTSAM iSAM2)", "posegraph.py", "optimize"),
    ("pose graph: relative / marginal queries", "posegraph.py", ("relative", "marginal")),
    ("candidates (paths near the new submap)", "hierarchy.py", "candidates"),
    ("corners: hypotheses (pair_hypotheses)", "loops.py", "pair_hypotheses"),
    ("corners: corner sets (corner_sets)", "loops.py", "corner_sets"),
    ("  of which the associator (PCA)", "pca.py", "__call__"),
    ("points: correlative search (prepare + best)", "correlative.py", ("prepare", "best")),
    ("ICP refinement (register)", "icp.py", "register"),
    ("ICP maps of candidates (LocalMap.build)", "icp.py", "build"),
    ("fitness (overlap_fitness, distinct)", "loops.py", "overlap_fitness"),
]


def run(env: dict, log: Path, out: Path, profile: Path | None = None) -> dict:
    """One ``cornerslam run`` with the build of ``env``; its loop-closing figures."""
    args = ["run", str(log), "--out", str(out), "-q"]
    if profile is None:
        cmd = [sys.executable, "-m", "cornerslam_cli", *args]
    else:
        cmd = [sys.executable, "-c", PROFILED_RUN, str(profile), *args]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    err = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"{' '.join(cmd[:4])} … failed:\n{err}")
    with open(out / "timing.csv", newline="") as f:
        t_loop = [float(r["t_loop"]) for r in csv.DictReader(f)]
    summary = json.loads((out / "summary.json").read_text())
    n = len(t_loop)
    bounds = [round(k * n / TENTHS) for k in range(TENTHS + 1)]
    tenths = [1e3 * sum(t_loop[a:b]) / max(b - a, 1) for a, b in zip(bounds, bounds[1:], strict=False)]
    return {
        "sum_t_loop": sum(t_loop),
        "summary_t_loop": float(summary["timing"]["t_loop"]),
        "cpu": usage.ru_utime + usage.ru_stime,
        "tenths_ms": tenths,
        "outputs": {f: (out / f).read_bytes() for f in COMPARED},
    }


def stage_times(profile: Path) -> tuple[float, list[tuple[str, float]]]:
    """(profiled seconds inside _close, [(stage, seconds)]) of a profile written by PROFILED_RUN."""
    stats = pstats.Stats(str(profile)).stats

    def cumulative(file: str, names) -> float:
        names = (names,) if isinstance(names, str) else names
        return sum(v[3] for k, v in stats.items() if k[0].endswith(file) and k[2] in names)

    total = cumulative("hierarchy.py", "_close")
    return total, [(label, cumulative(file, names)) for label, file, names in STAGES]


def median(xs: list[float]) -> float:
    return statistics.median(xs)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("log", nargs="?", type=Path)
    ap.add_argument("--data", type=Path, default=None, help="directory of the Radish logs")
    ap.add_argument("--baseline", default="main")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--profile", action="store_true")
    args = ap.parse_args()
    log = args.log or (args.data or default_data()) / "radish" / "infinite-corridor.log"
    names = {"base": f"{args.baseline} ({revision(args.baseline)})", "this": f"this build ({revision()})"}
    results: dict[str, list[dict]] = {"base": [], "this": []}
    profiles: dict[str, tuple] = {}
    with tempfile.TemporaryDirectory() as tmp, source_tree(args.baseline) as base_src:
        envs = {"base": build_env(base_src), "this": build_env(ROOT)}
        warm = Path(tmp) / "warm"  # compile a fresh checkout's kernels before anything is timed
        for key, env in envs.items():
            sample = ROOT / "sample_logs" / "intel_cut.clf"
            run(env, sample, warm / key)
        for i in range(args.runs):
            for key, env in envs.items():
                results[key].append(run(env, log, Path(tmp) / f"{key}-{i}"))
                print(
                    f"run {i + 1}/{args.runs} {key}: Σ t_loop {results[key][-1]['sum_t_loop']:.3f} s",
                    file=sys.stderr,
                )
        if args.profile:
            for key, env in envs.items():
                prof = Path(tmp) / f"{key}.prof"
                run(env, log, Path(tmp) / f"{key}-profiled", prof)
                profiles[key] = stage_times(prof)
    same = all(r["outputs"] == results["base"][0]["outputs"] for rs in results.values() for r in rs)
    print(f"# Loop closing's cost: {names['this']} against {names['base']}\n")
    print(f"{log.name}, {args.runs} runs of each build, alternating; medians.\n")
    print(f"| figure | {names['base']} | {names['this']} | ratio base / this |")
    print("|---|---:|---:|---:|")
    for label, key, unit in (
        ("Σ t_loop of timing.csv (per-step loop closing)", "sum_t_loop", "s"),
        ("summary t_loop (with the final keyframe graph)", "summary_t_loop", "s"),
        ("CPU of the whole run", "cpu", "s"),
    ):
        b, t = median([r[key] for r in results["base"]]), median([r[key] for r in results["this"]])
        print(f"| {label} | {b:.3f} {unit} | {t:.3f} {unit} | {b / t:.2f} |")
    for key in ("base", "this"):
        runs = ", ".join(f"{r['sum_t_loop']:.3f}" for r in results[key])
        print(f"\n{names[key]}: Σ t_loop of each run {runs} s", end="")
    print("\n\nt_loop per step by tenth of the log (ms, medians):\n")
    print("| build | " + " | ".join(str(k + 1) for k in range(TENTHS)) + " |")
    print("|---|" + "---:|" * TENTHS)
    for key in ("base", "this"):
        cells = [median([r["tenths_ms"][k] for r in results[key]]) for k in range(TENTHS)]
        print(f"| {names[key]} | " + " | ".join(f"{c:.2f}" for c in cells) + " |")
    print(f"\nOutputs ({', '.join(COMPARED)}) of every run byte-identical: {'yes' if same else 'NO'}")
    if profiles:
        print("\nWhere loop closing's time goes (cProfile inside HierarchicalSlam._close; cumulative, so a")
        print("stage includes those it calls; the profiler's own overhead inflates Python-heavy stages):\n")
        print(f"| stage | {names['base']} s | share | {names['this']} s | share |")
        print("|---|---:|---:|---:|---:|")
        (tb, sb), (tt, st) = profiles["base"], profiles["this"]
        for (label, b), (_, t) in zip(sb, st, strict=True):
            print(f"| {label} | {b:.3f} | {100 * b / tb:.0f} % | {t:.3f} | {100 * t / tt:.0f} % |")
        print(f"| all of loop closing (profiled) | {tb:.3f} | 100 % | {tt:.3f} | 100 % |")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
