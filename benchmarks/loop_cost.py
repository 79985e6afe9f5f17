"""Loop closing's cost, this build against another (default main), side by side in one run.

    .venv/bin/python benchmarks/loop_cost.py [--baseline main] [--runs 3] [--profile] [LOG]
    .venv/bin/python benchmarks/loop_cost.py --replay [--runs 5] [--profile] [LOG]
    # default LOG: radish/infinite-corridor.log (1,941 keyframes) under --data (real_logs.default_data)

Whole runs (the default): each build runs ``cornerslam run LOG`` ``--runs`` times, the builds alternating
so that the load of a shared machine falls on both alike. Per run: Σ t_loop of timing.csv (what loop
closing — candidate verification and the pose graph's optimisation, on the steps that close a submap —
adds to the steps; wall clock), summary.json's t_loop (that plus the final keyframe graph's solve), the
CPU seconds spent inside loop closing (HierarchicalSlam._close, the code t_loop times) and in the whole
run, and t_loop per step by tenth of the log. The outputs are compared byte for byte (trajectory.tum,
trajectory.csv, map.csv, loops.csv): a faster build that changes them is refused.

``--replay``: the front end runs once (this build; its frames pickled), then each build's two-level
SLAM replays those frames ``--runs`` times, alternating: the CPU seconds inside loop closing, ~5 s a run
instead of a whole run's ~90 s (the front end's), and a digest of the smoothed poses and loops.csv's rows
that must agree.

``--profile``: one more replay or run of each build under cProfile (CPU time), enabled only inside
loop closing: the share of it each stage takes. Medians and ratios (base / this) are printed as
Markdown; docs/results/loop_cost.md holds a run. On a loaded machine wall-clock figures of one run mean
little; the CPU seconds, the medians of several runs and the profile's shares say more.
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

# inside HierarchicalSlam._close (the code timing.csv's t_loop times): its CPU seconds, and with a profile
# path cProfile (CPU time) of it; then the CLI (whole runs) or a replay of pickled frames (--replay)
DRIVER = """
from cornerslam_cli.blas import single_threaded_blas
single_threaded_blas()  # before numpy is first imported, as the command does (cornerslam_cli/blas.py)
import cProfile, hashlib, json, pickle, sys, time
from cornerslam_cli import hierarchy
out, prof_path, mode, *rest = sys.argv[1:]
profile = cProfile.Profile(time.process_time) if prof_path != "-" else None
close, spent = hierarchy.HierarchicalSlam._close, [0.0]
def _close(self, *args, **kwargs):
    t0 = time.process_time()
    if profile:
        profile.enable()
    try:
        return close(self, *args, **kwargs)
    finally:
        if profile:
            profile.disable()
        spent[0] += time.process_time() - t0
hierarchy.HierarchicalSlam._close = _close
result = {}
if mode == "cli":
    from cornerslam_cli.cli import main
    if rc := main(rest, standalone_mode=False):
        sys.exit(rc)  # (click returns a failed run's exit code here)
elif mode == "dump":
    from cornerslam_cli.frontend import frames, open_input
    from cornerslam_cli.options import command_config
    cfg = command_config(None, [], log_path=rest[0])
    src = open_input(rest[0], cfg, None)
    with open(rest[1], "wb") as f:
        pickle.dump((rest[0], list(frames(src, cfg, None)), src.laser2base), f)
else:
    from cornerslam_cli.association import pca
    from cornerslam_cli.motion import icp
    from cornerslam_cli.options import command_config
    icp.load_kernels(); pca.load_kernels()  # (a run's front end and filter load them before any close)
    with open(rest[0], "rb") as f:
        log, frames, laser2base = pickle.load(f)
    slam = hierarchy.HierarchicalSlam(command_config(None, [], log_path=log), laser2base)
    for frame in frames:
        slam.step(frame)
    slam.finish()
    digest = hashlib.sha256(slam.final_poses().tobytes() + repr(slam.loop_rows()).encode()).hexdigest()
    result["digest"] = digest[:16]
result["cpu_loop"] = spent[0]
with open(out, "w") as f:
    json.dump(result, f)
if profile:
    profile.dump_stats(prof_path)
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


def driver(
    env: dict, tmp: Path, mode: str, args: list[str], profile: Path | None = None
) -> tuple[dict, float]:
    """DRIVER with the build of ``env``: (what it wrote, the process's CPU seconds)."""
    out = tmp / f"driver-{os.getpid()}-{len(list(tmp.iterdir()))}.json"
    cmd = [sys.executable, "-c", DRIVER, str(out), str(profile or "-"), mode, *args]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    err = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"{mode} {' '.join(args)} failed:\n{err}")
    return json.loads(out.read_text()), usage.ru_utime + usage.ru_stime


def run(env: dict, tmp: Path, log: Path, out: Path, profile: Path | None = None) -> dict:
    """One ``cornerslam run`` with the build of ``env``; its loop-closing figures."""
    inside, cpu = driver(env, tmp, "cli", ["run", str(log), "--out", str(out), "-q"], profile)
    with open(out / "timing.csv", newline="") as f:
        t_loop = [float(r["t_loop"]) for r in csv.DictReader(f)]
    summary = json.loads((out / "summary.json").read_text())
    n = len(t_loop)
    bounds = [round(k * n / TENTHS) for k in range(TENTHS + 1)]
    tenths = [1e3 * sum(t_loop[a:b]) / max(b - a, 1) for a, b in zip(bounds, bounds[1:], strict=False)]
    return {
        "sum_t_loop": sum(t_loop),
        "summary_t_loop": float(summary["timing"]["t_loop"]),
        "cpu_loop": inside["cpu_loop"],
        "cpu": cpu,
        "tenths_ms": tenths,
        "outputs": {f: (out / f).read_bytes() for f in COMPARED},
    }


def stage_times(profile: Path) -> tuple[float, list[tuple[str, float]]]:
    """(profiled seconds inside _close, [(stage, seconds)]) of a profile written by DRIVER."""
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
    ap.add_argument("--data", type=Path, default=None, help="directory of the real logs")
    ap.add_argument("--baseline", default="main")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument(
        "--replay", action="store_true", help="replay one front end's frames (CPU inside loop closing)"
    )
    ap.add_argument("--profile", action="store_true")
    args = ap.parse_args()
    log = (args.log or (args.data or default_data()) / "radish" / "infinite-corridor.log").resolve()
    names = {"base": f"{args.baseline} ({revision(args.baseline)})", "this": f"this build ({revision()})"}
    results: dict[str, list[dict]] = {"base": [], "this": []}
    profiles: dict[str, tuple] = {}
    with tempfile.TemporaryDirectory() as tmp_name, source_tree(args.baseline) as base_src:
        tmp = Path(tmp_name)
        envs = {"base": build_env(base_src), "this": build_env(ROOT)}
        for key, env in envs.items():  # compile a fresh checkout's kernels before anything is timed
            run(env, tmp, ROOT / "sample_logs" / "intel_cut.clf", tmp / f"warm-{key}")
        frames = tmp / "frames.pickle"
        if args.replay:
            driver(envs["this"], tmp, "dump", [str(log), str(frames)])
        for i in range(args.runs):
            for key, env in envs.items():
                if args.replay:
                    results[key].append(driver(env, tmp, "replay", [str(frames)])[0])
                else:
                    results[key].append(run(env, tmp, log, tmp / f"{key}-{i}"))
                print(
                    f"{i + 1}/{args.runs} {key}: CPU in loop closing {results[key][-1]['cpu_loop']:.3f} s",
                    file=sys.stderr,
                )
        if args.profile:
            for key, env in envs.items():
                prof = tmp / f"{key}.prof"
                if args.replay:
                    driver(env, tmp, "replay", [str(frames)], prof)
                else:
                    run(env, tmp, log, tmp / f"{key}-profiled", prof)
                profiles[key] = stage_times(prof)
    report(args, log, names, results, profiles)
    return 0 if same_outputs(results, args.replay) else 1


def same_outputs(results: dict[str, list[dict]], replay: bool) -> bool:
    key = "digest" if replay else "outputs"
    return all(r[key] == results["base"][0][key] for rs in results.values() for r in rs)


def report(args, log: Path, names: dict, results: dict[str, list[dict]], profiles: dict) -> None:
    how = "replays of one front end's frames" if args.replay else "whole runs"
    print(f"# Loop closing's cost: {names['this']} against {names['base']}\n")
    print(f"{log.name}, {args.runs} {how} of each build, alternating; medians.\n")
    print(f"| figure | {names['base']} | {names['this']} | ratio base / this |")
    print("|---|---:|---:|---:|")
    rows = [("CPU inside loop closing (HierarchicalSlam._close)", "cpu_loop")]
    if not args.replay:
        rows = [
            ("Σ t_loop of timing.csv (per-step loop closing, wall clock)", "sum_t_loop"),
            ("summary t_loop (with the final keyframe graph, wall clock)", "summary_t_loop"),
            *rows,
            ("CPU of the whole run (its process)", "cpu"),
        ]
    for label, key in rows:
        b, t = median([r[key] for r in results["base"]]), median([r[key] for r in results["this"]])
        print(f"| {label} | {b:.3f} s | {t:.3f} s | {b / t:.2f} |")
    for key in ("base", "this"):
        each = ", ".join(f"{r['cpu_loop']:.3f}" for r in results[key])
        print(f"\n{names[key]}: CPU inside loop closing, each run: {each} s", end="")
    print()
    if not args.replay:
        print("\nt_loop per step by tenth of the log (ms, medians):\n")
        print("| build | " + " | ".join(str(k + 1) for k in range(TENTHS)) + " |")
        print("|---|" + "---:|" * TENTHS)
        for key in ("base", "this"):
            cells = [median([r["tenths_ms"][k] for r in results[key]]) for k in range(TENTHS)]
            print(f"| {names[key]} | " + " | ".join(f"{c:.2f}" for c in cells) + " |")
    what = "smoothed poses and loops.csv rows" if args.replay else ", ".join(COMPARED)
    print(
        f"\nOutputs ({what}) of every run identical: {'yes' if same_outputs(results, args.replay) else 'NO'}"
    )
    if profiles:
        print("\nWhere loop closing's CPU time goes (cProfile inside HierarchicalSlam._close; cumulative: a")
        print("stage includes those it calls; the profiler's own overhead inflates Python-heavy stages):\n")
        print(f"| stage | {names['base']} s | share | {names['this']} s | share | ratio |")
        print("|---|---:|---:|---:|---:|---:|")
        (tb, sb), (tt, st) = profiles["base"], profiles["this"]
        for (label, b), (_, t) in zip(sb, st, strict=True):
            ratio = f"{b / t:.2f}" if t > 0 else "–"
            print(f"| {label} | {b:.3f} | {100 * b / tb:.0f} % | {t:.3f} | {100 * t / tt:.0f} % | {ratio} |")
        print(f"| all of loop closing (profiled) | {tb:.3f} | 100 % | {tt:.3f} | 100 % | {tb / tt:.2f} |")


if __name__ == "__main__":
    sys.exit(main())
