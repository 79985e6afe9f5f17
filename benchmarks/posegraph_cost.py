"""Benchmark: cost of the global pose graph (graph/posegraph.py) as submaps accumulate, iSAM2 vs LM.

    .venv/bin/python benchmarks/posegraph_cost.py                          # 100 and 1,000 submaps
    .venv/bin/python benchmarks/posegraph_cost.py --sizes 100 --kernel-scale 1.0 --out /tmp/pg.md

Results: docs/results/posegraph_cost.md.

The use the hierarchy makes of it, one closed submap at a time: add the submap's sequential factor, its
loop closures (here: to the submap one lap back and its neighbour, as a robot circling a building
finds them), optimize(), then the candidate search's questions (marginal of the new node, relative
pose and covariance to ``--candidates`` earlier nodes). Submaps are 8 m apart with noise of a closed
submap's EKF covariance; a lap is 20 submaps. Times are wall seconds per submap on this machine; the
two solvers see the same factors and should end at the same poses (the largest difference is printed).
"steps" are iSAM2 updates or LM iterations per optimize(); "not converged": optimize() calls that
stopped at the step limit.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cornerslam_cli.geometry import wrap_angle  # noqa: E402
from cornerslam_cli.graph.params import GraphConfig  # noqa: E402
from cornerslam_cli.graph.posegraph import PoseGraph  # noqa: E402

PER_LAP = 20  # submaps round the circuit
SEQ_COV = np.diag([0.05**2, 0.03**2, 0.01**2])  # a closed submap's end pose, 8 m travelled
LOOP_COV = np.diag([0.03**2, 0.03**2, 0.005**2])  # a verified closure


def measurements(n: int, seed: int):
    """Sequential factors of n submaps and, per submap j, its loops [(i, rel)] to earlier submaps."""
    rng = np.random.default_rng(seed)
    step = np.array([8.0, 0.0, 2.0 * np.pi / PER_LAP])
    noise = lambda cov: np.linalg.cholesky(cov) @ rng.standard_normal(3)
    seq = [step + noise(SEQ_COV) for _ in range(n)]
    loops = {}
    for j in range(PER_LAP + 1, n + 1):
        loops[j] = [(j - PER_LAP, noise(LOOP_COV)), (j - PER_LAP - 1, step + noise(LOOP_COV))]
    return seq, loops


def run(cfg: GraphConfig, seq, loops, candidates: int) -> dict:
    """Per-submap seconds of optimize() and of the candidate queries, and the final poses."""
    g = PoseGraph(cfg)
    t_opt, t_query, steps = [], [], []
    for rel in seq:
        j = g.add_sequential(rel, SEQ_COV)
        for i, z in loops.get(j, []):
            g.add_loop(i, j, z, LOOP_COV)
        t0 = time.perf_counter()
        g.optimize()
        t1 = time.perf_counter()
        g.marginal(j)
        for i in range(max(0, j - PER_LAP - candidates // 2), max(0, j - PER_LAP + candidates // 2)):
            g.relative(i, j)
        t_query.append(time.perf_counter() - t1)
        t_opt.append(t1 - t0)
        steps.append((g.iterations, g.converged))
    return {"optimize": np.array(t_opt), "query": np.array(t_query), "steps": steps, "poses": g.poses()}


def row(n: int, solver: str, r: dict, diff: float) -> str:
    ms = lambda a: f"{1e3 * a:.2f}"
    t, q = r["optimize"], r["query"]
    tail = t[-max(1, len(t) // 10) :]
    return (
        f"| {n} | {solver} | {ms(np.median(t))} | {ms(t.mean())} | {ms(tail.mean())} | {ms(t.max())} "
        f"| {t.sum():.2f} | {ms(q.mean())} | {np.mean([k for k, _ in r['steps']]):.1f} "
        f"| {sum(not c for _, c in r['steps'])} | {diff:.1e} |"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[100, 1000])
    ap.add_argument("--kernel", default="cauchy", choices=["cauchy", "dcs", "none"])
    ap.add_argument("--kernel-scale", type=float, default=GraphConfig().kernel_scale)
    ap.add_argument("--candidates", type=int, default=8, help="relative() queries per submap")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    lines = [
        f"Pose graph cost per submap, kernel {args.kernel} (scale {args.kernel_scale}), "
        f"{args.candidates} relative() queries per submap; {platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()}",
        "",
        "| submaps | solver | optimize median ms | mean ms | last 10 % mean ms | max ms | total s "
        "| queries mean ms | mean steps | not converged | max pose diff isam2 vs lm |",
        "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for n in args.sizes:
        seq, loops = measurements(n, args.seed)
        res = {
            s: run(
                GraphConfig(solver=s, kernel=args.kernel, kernel_scale=args.kernel_scale),
                seq,
                loops,
                args.candidates,
            )
            for s in ("isam2", "lm")
        }
        d = res["isam2"]["poses"] - res["lm"]["poses"]
        d[:, 2] = wrap_angle(d[:, 2])
        diff = float(np.abs(d).max())
        lines += [row(n, s, res[s], diff) for s in ("isam2", "lm")]
        print(f"{n} submaps done", file=sys.stderr)
    text = "\n".join(lines)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
