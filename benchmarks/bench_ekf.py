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

from cornerslam_cli.filter import Ekf, EkfConfig, motion_model, motion_noise, observe  # noqa: E402
from cornerslam_cli.geometry import wrap_angle  # noqa: E402

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


def clutter_run(cfg: EkfConfig, seed: int, n_steps: int = 200, clutter: int = 3) -> dict:
    """Simulated loop among 60 corners with known association plus ``clutter`` one-off spurious corners
    per keyframe (seen once, never again). Returns map size, time per step and mean robot NEES."""
    rng = np.random.default_rng(seed)
    lm_true = np.column_stack((rng.uniform(-7, 7, (60, 2)), rng.uniform(0.3, 2.8, 60)))
    C = np.diag([0.03**2, 0.03**2, 0.02**2])
    ekf = Ekf(cfg, pose0=(3.0, 0.0, np.pi / 2))
    true, odom = np.array([3.0, 0.0, np.pi / 2]), np.zeros(3)
    lm_id = -np.ones(len(lm_true), dtype=np.int64)
    nees, t_total = [], 0.0
    for _ in range(n_steps):
        u = (0.05, 0.25, 0.05)
        odom_next = motion_model(odom, u)[0]
        R = motion_noise(u, true[2], cfg.alphas, cfg.min_sigma_xy, cfg.min_sigma_theta)
        true = motion_model(true, u)[0] + np.linalg.cholesky(R) @ rng.standard_normal(3)
        h, _, _ = observe(true, lm_true)
        seen = np.flatnonzero(np.hypot(h[:, 0], h[:, 1]) < 5.0)
        z = h[seen] + rng.multivariate_normal(np.zeros(3), C, len(seen))
        z_clutter = np.column_stack((rng.uniform(-4, 4, (clutter, 2)), rng.uniform(0.3, 2.8, clutter)))
        known = lm_id[seen] >= 0
        t0 = time.perf_counter()
        ekf.predict(odom, odom_next)
        if known.any():
            ekf.update(lm_id[seen[known]], z[known], np.broadcast_to(C, (known.sum(), 3, 3)))
        new = np.vstack((z[~known], z_clutter))
        ids = ekf.augment(new, np.broadcast_to(C, (len(new), 3, 3)))
        lm_id[seen[~known]] = ids[: (~known).sum()]
        remap = ekf.prune_tentative()
        t_total += time.perf_counter() - t0
        lm_id = np.where(lm_id >= 0, remap[np.maximum(lm_id, 0)], -1)
        odom = odom_next
        e = true - ekf.pose
        e[2] = wrap_angle(e[2])
        nees.append(e @ np.linalg.solve(ekf.P[:3, :3], e))
    return {
        "n_landmarks": ekf.n_landmarks,
        "n_true_mapped": int((lm_id >= 0).sum()),
        "ms_per_step": 1e3 * t_total / n_steps,
        "nees": float(np.mean(nees)),
    }


def tentative_table(seeds: int = 5) -> str:
    out = [
        "| tentative_sightings | tentative_max_age | landmarks in state | true corners mapped | ms per step "
        "| mean robot NEES |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    for k, age in ((1, 5), (2, 3), (3, 5)):
        cfg = EkfConfig(
            alpha1=0.02, alpha2=0.002, alpha3=0.02, alpha4=0.002, tentative_sightings=k, tentative_max_age=age
        )
        runs = [clutter_run(cfg, s) for s in range(seeds)]
        mean = {key: np.mean([r[key] for r in runs]) for key in runs[0]}
        out.append(
            f"| {k} | {age} | {mean['n_landmarks']:.0f} | {mean['n_true_mapped']:.0f} / 60 "
            f"| {mean['ms_per_step']:.2f} | {mean['nees']:.2f} |"
        )
    return "\n".join(out)


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
    ap.add_argument("--tentative", action="store_true", help="only the tentative-landmark table")
    args = ap.parse_args()
    env = (
        f"numpy {np.__version__}, python {platform.python_version()}, {os.cpu_count()} CPUs, "
        f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', 'unset')}"
    )
    if args.tentative:
        text = f"Environment: {env}\n\n{tentative_table()}\n"
    else:
        text = f"Environment: {env}\n\n{table(bench(args.n, args.seed))}\n"
    print(text)
    if args.out:
        args.out.write_text(text)


if __name__ == "__main__":
    main()
