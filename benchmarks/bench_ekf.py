"""Benchmark: EKF-SLAM block-matrix update vs the dense textbook update (paper Table 1, NOTES §5).

    /work/venv/bin/python benchmarks/bench_ekf.py                     # prints markdown tables
    OPENBLAS_NUM_THREADS=1 /work/venv/bin/python benchmarks/bench_ekf.py --out /tmp/ekf_1thread.md

For each N (landmarks) a random SLAM state (correlated SPD Σ) is built, then per operation the median
wall time of several repetitions is taken, block and dense in the same process, so the ratios compare
like with like. The dense reference is tests/_ekf_dense.py (full (3N+3)² products, Σ ← (I − KH)Σ).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from _ekf_dense import DenseEkf  # noqa: E402

from cornerslam_cli.filter import Ekf, EkfConfig, observe  # noqa: E402

K_STEP = 10  # matched corners in one step (the paper's Fig 18 shows ~5–12)


def random_state(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    d = 3 + 3 * n
    mu = np.concatenate(([0.0, 0.0, 0.3], rng.uniform(-20, 20, 3 * n)))
    mu[5::3] = rng.uniform(0.3, 2.8, n)
    A = rng.standard_normal((d, d)) * 0.05
    return mu, A @ A.T / d + np.diag(rng.uniform(0.001, 0.05, d))


def pairs(rng, mu, k):
    n = (len(mu) - 3) // 3
    ids = rng.choice(n, size=k, replace=False)
    h, _, _ = observe(mu[:3], mu[3:].reshape(-1, 3)[ids])
    C = np.broadcast_to(np.diag([1e-3, 1e-3, 1e-4]), (k, 3, 3)).copy()
    return ids, h + rng.normal(0, 0.01, h.shape), C


def timed(fn, reps: int) -> float:
    """Median seconds of ``reps`` calls after one warm-up call."""
    fn()
    out = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return float(np.median(out))


def time_update(make, cfg, mu, P, ids, z, C, reps) -> float:
    """Median seconds of update() on a filter built by ``make`` (Ekf.from_state or DenseEkf)."""
    f = make(cfg, mu, P)
    return timed(lambda: f.update(ids, z, C), reps)


def time_growth(n: int) -> float:
    """Seconds per landmark to grow a map to n landmarks one augment() at a time (doubling buffer)."""

    def grow():
        e = Ekf(EkfConfig(initial_capacity=8))
        zc = np.diag([1e-3, 1e-3, 1e-4])[None]
        for i in range(n):
            e.augment([[1.0 + 0.01 * i, 0.5, 1.0]], zc)

    return timed(grow, 3) / n


def bench(ns: list[int], seed: int) -> list[dict]:
    rows = []
    seq, bat = EkfConfig(update="sequential"), EkfConfig(update="batched")
    for n in ns:
        rng = np.random.default_rng(seed + n)
        mu, P = random_state(rng, n)
        reps = 15 if n <= 200 else 7
        dreps = 5 if n <= 500 else 3
        one, step = pairs(rng, mu, 1), pairs(rng, mu, K_STEP)
        row = {"n": n}
        row["block_1"] = time_update(Ekf.from_state, seq, mu, P, *one, reps)
        row["dense_1"] = time_update(DenseEkf, seq, mu, P, *one, dreps)
        row["block_k_fused"] = time_update(Ekf.from_state, seq, mu, P, *step, reps)
        perpair = EkfConfig(update="sequential", fuse=False)
        row["block_k_perpair"] = time_update(Ekf.from_state, perpair, mu, P, *step, reps)
        row["block_k_batched"] = time_update(Ekf.from_state, bat, mu, P, *step, reps)
        joseph = EkfConfig(update="sequential", joseph=True)
        row["block_k_joseph"] = time_update(Ekf.from_state, joseph, mu, P, *step, reps)
        row["dense_k_batched"] = time_update(DenseEkf, bat, mu, P, *step, dreps)

        ekf = Ekf.from_state(EkfConfig(), mu, P)
        ref = DenseEkf(EkfConfig(), mu, P)
        o0, o1 = np.zeros(3), np.array([0.2, 0.05, 0.1])
        row["predict_block"] = timed(partial(ekf.predict, o0, o1), reps * 10)
        row["predict_dense"] = timed(partial(ref.predict, o0, o1), dreps)
        row["observe_all"] = timed(ekf.predict_observations, reps * 10)
        row["health"] = timed(partial(ekf.check_health, 0), reps)
        row["augment_per_lm"] = time_growth(n)
        rows.append(row)
        print(f"N={n} done", file=sys.stderr)
    return rows


def table(rows: list[dict]) -> str:
    ms = lambda s: f"{1e3 * s:.3g}"
    out = [
        "| N | Table 1 mults block | Table 1 mults dense | count ratio | block 1 pair ms | dense 1 pair ms "
        "| measured ratio |",
        "|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        n = r["n"]
        cb, cd = (3 * n + 3) * (9 * n + 18), (3 * n + 3) ** 3
        out.append(
            f"| {n} | {cb:.3g} | {cd:.3g} | {cd / cb:.0f} | {ms(r['block_1'])} | {ms(r['dense_1'])} "
            f"| {r['dense_1'] / r['block_1']:.0f}× |"
        )
    out += [
        "",
        f"One step with k = {K_STEP} matched corners (dense sequential = {K_STEP} × dense 1 pair):",
        "",
        "| N | fused sequential ms | per-pair sequential ms | batched ms | Joseph (fused) ms "
        "| dense batched ms | dense sequential ms (est.) | ratio dense seq / fused "
        "| ratio dense batched / batched |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        dseq = K_STEP * r["dense_1"]
        out.append(
            f"| {r['n']} | {ms(r['block_k_fused'])} | {ms(r['block_k_perpair'])} "
            f"| {ms(r['block_k_batched'])} "
            f"| {ms(r['block_k_joseph'])} | {ms(r['dense_k_batched'])} | {ms(dseq)} "
            f"| {dseq / r['block_k_fused']:.0f}× | {r['dense_k_batched'] / r['block_k_batched']:.0f}× |"
        )
    out += [
        "",
        "| N | predict block ms | predict dense ms | ratio | predict_observations ms | check_health ms "
        "| augment per landmark ms (amortised) |",
        "|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        out.append(
            f"| {r['n']} | {ms(r['predict_block'])} | {ms(r['predict_dense'])} "
            f"| {r['predict_dense'] / r['predict_block']:.0f}× | {ms(r['observe_all'])} | {ms(r['health'])} "
            f"| {ms(r['augment_per_lm'])} |"
        )
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[50, 100, 200, 500, 1000])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, help="also write the markdown here")
    args = ap.parse_args()
    env = (
        f"numpy {np.__version__}, python {platform.python_version()}, {os.cpu_count()} CPUs, "
        f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', 'unset')}"
    )
    text = f"Environment: {env}\n\n{table(bench(args.n, args.seed))}\n"
    print(text)
    if args.out:
        args.out.write_text(text)


if __name__ == "__main__":
    main()
