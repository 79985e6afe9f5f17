"""Benchmark of the associators (NOTES §4): the paper's hard step, scaling in m and n, precision/recall.

    /work/venv/bin/python benchmarks/bench_association.py [--quick] [--out docs/results]

Writes ``association.md`` (tables) and ``association_scaling.png`` into ``--out``. Problems are synthetic
(tests/_association_helpers.py): a valid Prediction built directly, no filter code involved.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

from _association_helpers import PAPER_HARD_COUNTS, hard_step, simulate_step  # noqa: E402

from cornerslam_cli.association import make_associator  # noqa: E402
from cornerslam_cli.association.params import AssociationConfig, JcbbConfig, PcaConfig  # noqa: E402

BUDGET_S = 2.0  # per call, scaling runs only

VARIANTS = {
    "icnn": AssociationConfig(method="icnn", euclidean_gate=0.0),
    "jcbb": AssociationConfig(method="jcbb", euclidean_gate=0.0),
    "jcbb-exact": AssociationConfig(method="jcbb", euclidean_gate=0.0, jcbb=JcbbConfig(joint_gate="exact")),
    "pca p=3": AssociationConfig(method="pca", euclidean_gate=0.0),
    "pca p=1": AssociationConfig(method="pca", euclidean_gate=0.0, pca=PcaConfig(group_size=1)),
    "pca p=5": AssociationConfig(method="pca", euclidean_gate=0.0, pca=PcaConfig(group_size=5)),
}


def timed(cfg, p, repeat=1):
    a = make_associator(cfg)
    best, r = np.inf, None
    for _ in range(repeat):
        t = time.perf_counter()
        r = a(p.z, p.C, p.pred)
        best = min(best, time.perf_counter() - t)
    return best, r


def bench_hard(seeds):
    rows = []
    for seed in seeds:
        p = hard_step(np.random.default_rng(seed))
        for name in ("icnn", "jcbb", "jcbb-exact", "pca p=3"):
            t, r = timed(VARIANTS[name], p, repeat=3)
            assert r.n_candidates.tolist() == list(PAPER_HARD_COUNTS)
            rows.append((seed, name, t, r.nodes, r.n_matched, r.joint_d2, r.budget_hit))
    return rows


def scaling_problem(rng, m, n):
    """m corners (m − 2 true, 2 spurious) among n landmarks in a 24 m × 24 m area, 20 % close twins,
    all corner angles within 90° ± 6° (indoor right-angle corners: φ barely discriminates)."""
    return simulate_step(
        rng,
        n=n,
        m_true=m - 2,
        n_spurious=2,
        n_twins=n // 5,
        extent=12.0,
        pose_sigma=(0.3, 0.3, 0.04),
        phi_range=(np.pi / 2 - 0.1, np.pi / 2 + 0.1),
    )


def bench_scaling(ms, ns, seeds):
    fast = JcbbConfig(explore_ties=False)
    budgeted = {
        "icnn": VARIANTS["icnn"],
        "jcbb": AssociationConfig(method="jcbb", euclidean_gate=0.0, jcbb=JcbbConfig(max_seconds=BUDGET_S)),
        "pca p=3": AssociationConfig(method="pca", euclidean_gate=0.0, pca=PcaConfig(max_seconds=BUDGET_S)),
        "jcbb no-ties": AssociationConfig(
            method="jcbb", jcbb=JcbbConfig(max_seconds=BUDGET_S, explore_ties=False)
        ),
        "pca p=3 no-ties": AssociationConfig(
            method="pca", euclidean_gate=0.0, jcbb=fast, pca=PcaConfig(max_seconds=BUDGET_S)
        ),
    }
    rows = []
    for axis, values in (("m", ms), ("n", ns)):
        for v in values:
            m, n = (v, 1000) if axis == "m" else (20, v)
            for seed in seeds:
                p = scaling_problem(np.random.default_rng(1000 * seed + v), m, n)
                cands = int(
                    np.sum([c for c in make_associator(budgeted["icnn"])(p.z, p.C, p.pred).n_candidates])
                )
                for name, cfg in budgeted.items():
                    t, r = timed(cfg, p)
                    rows.append((axis, m, n, seed, name, t, r.nodes, r.budget_hit, cands))
            print(f"scaling {axis}={v} done", flush=True)
    return rows


def bench_precision(trials):
    kw = {"n": 30, "m_true": 8, "n_spurious": 2, "n_twins": 8, "pose_sigma": (0.3, 0.3, 0.05)}
    names = list(VARIANTS)
    stats = {
        k: np.zeros(6) for k in names
    }  # matched, correct, true-landmark corners, spurious matched, t, jc
    for trial in range(trials):
        p = simulate_step(np.random.default_rng(10_000 + trial), **kw)
        real = p.truth >= 0
        for name in names:
            t, r = timed(VARIANTS[name], p)
            ok = r.pairs >= 0
            stats[name] += [
                ok.sum(),
                (r.pairs[ok] == p.truth[ok]).sum(),
                real.sum(),
                (ok & ~real).sum(),
                t,
                r.extra.get("jointly_compatible", True),
            ]
    return stats, kw


def plot(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, axis in zip(axes, ("m", "n"), strict=True):
        for name, style in (
            ("icnn", "o-"),
            ("jcbb", "s-"),
            ("pca p=3", "^-"),
            ("jcbb no-ties", "s--"),
            ("pca p=3 no-ties", "^--"),
        ):
            sel = [r for r in rows if r[0] == axis and r[4] == name]
            xs = sorted({r[1] if axis == "m" else r[2] for r in sel})
            med = [np.median([r[5] for r in sel if (r[1] if axis == "m" else r[2]) == x]) for x in xs]
            hit = [any(r[7] for r in sel if (r[1] if axis == "m" else r[2]) == x) for x in xs]
            (line,) = ax.semilogy(xs, med, style, label=name)
            hx = [x for x, h in zip(xs, hit, strict=True) if h]
            hy = [y for y, h in zip(med, hit, strict=True) if h]
            if hx:
                ax.semilogy(hx, hy, "x", color=line.get_color(), ms=12, mew=2)
        ax.axhline(BUDGET_S, color="grey", ls=":", lw=1)
        ax.set_xlabel("corners m (n = 1000)" if axis == "m" else "landmarks n (m = 20)")
        ax.set_ylabel("association time per step [s]")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(title="× = budget hit (2 s)")
    fig.suptitle("Association time, median of seeds (paper Fig 10 analogue)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def write_markdown(out, hard, scaling, prec, prec_kw, trials, elapsed):
    L = []
    L.append("# Data association: measured figures\n")
    L.append(
        f"Generated by `benchmarks/bench_association.py` on {platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()}, numpy {np.__version__}, one process (the machine is shared: "
        f"timings are indicative). Whole run: {elapsed:.0f} s.\n"
    )
    L.append("## The paper's hard step (eq 35: candidate counts [0 0 0 9 8 3 6 7 1 0 1 0])\n")
    L.append(
        "Synthetic: 12 corners 5–7 m away, pose σ = 0.3 m / 0.05 rad (strongly correlated innovations); "
        "corner i gets exactly counts[i] landmarks inside its individual gate, each with an innovation drawn "
        "independently, plus 20 far background landmarks (n = 54). Individually every candidate is "
        "plausible; jointly few combinations are. Time = best of 3 calls; paper: JCBB 3091 s, PCA 72 s.\n"
    )
    L.append("| seed | method | time [ms] | nodes | matched | joint D² |")
    L.append("|---|---|---|---|---|---|")
    for seed, name, t, nodes, nm, jd2, hit in hard:
        L.append(
            f"| {seed} | {name} | {t * 1e3:.1f} | {nodes} | {nm} | {jd2:.1f}{' (budget)' if hit else ''} |"
        )
    L.append("")
    for name in ("icnn", "jcbb", "jcbb-exact", "pca p=3"):
        ts = [r[2] for r in hard if r[1] == name]
        ns = [r[3] for r in hard if r[1] == name]
        L.append(f"- **{name}**: max {max(ts) * 1e3:.1f} ms, max {max(ns)} nodes over {len(ts)} seeds")
    L.append("")
    L.append("## Scaling (paper Fig 10 analogue)\n")
    L.append(
        f"`simulate_step` problems: n landmarks in a 24 m × 24 m area (20 % of them a close twin 0.25–0.5 m "
        f"from another, all corner angles 90° ± 6°), m corners (m − 2 observed landmarks, 2 spurious), "
        f"pose σ = 0.3 m / 0.04 rad. "
        f"JCBB and PCA run with a {BUDGET_S:.0f} s budget (`max_seconds`); a * marks runs where it hit. "
        f"Median over seeds; ‘cand’ = total individually compatible pairs. "
        f"Plot: `association_scaling.png`.\n"
    )
    names = ("icnn", "jcbb", "pca p=3", "jcbb no-ties", "pca p=3 no-ties")
    for axis in ("m", "n"):
        L.append(f"| {axis} | cand | " + " | ".join(f"{k} [ms] | nodes" for k in names) + " |")
        L.append("|---|---|" + "---|---|" * len(names))
        xs = sorted({r[1] if axis == "m" else r[2] for r in scaling if r[0] == axis})
        for x in xs:
            sel = [r for r in scaling if r[0] == axis and (r[1] if axis == "m" else r[2]) == x]
            cells = []
            for name in names:
                s = [r for r in sel if r[4] == name]
                t = np.median([r[5] for r in s]) * 1e3
                star = "*" * sum(r[7] for r in s)
                cells.append(f"{t:.1f}{star} | {int(np.median([r[6] for r in s]))}")
            cand = int(np.median([r[8] for r in sel if r[4] == "icnn"]))
            L.append(f"| {x} | {cand} | " + " | ".join(cells) + " |")
        L.append("")
    L.append(f"## Precision / recall over {trials} simulated steps with known truth\n")
    L.append(
        f"`simulate_step(**{prec_kw})`: 8 observed landmarks + 2 spurious corners per step among 30 "
        "landmarks of which 8 are close twins (0.25–0.5 m from another landmark, same corner angle ± 0.02 "
        "rad); the state estimate error is drawn from N(0, P) with a pose σ large enough to shift all "
        "innovations coherently by more than the twin spacing. precision = correct pairs / matched pairs; "
        "recall = correct pairs / corners that observe a landmark; spurious = spurious corners matched.\n"
    )
    L.append(
        "| method | precision | recall | spurious matched | mean time [ms] | answers jointly compatible |"
    )
    L.append("|---|---|---|---|---|---|")
    for name, (matched, correct, real, spur, t, jc) in prec.items():
        L.append(
            f"| {name} | {correct / matched:.3f} | {correct / real:.3f} | {int(spur)} | "
            f"{t / trials * 1e3:.2f} | {jc / trials:.1%} |"
        )
    L.append("")
    (out / "association.md").write_text("\n".join(L) + "\n")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    hard = bench_hard(range(2 if args.quick else 5))
    print("hard step done", flush=True)
    ms = [5, 10, 20, 30, 40, 60] if not args.quick else [5, 20]
    ns = [100, 250, 500, 1000, 2000] if not args.quick else [100, 500]
    scaling = bench_scaling(ms, ns, range(1 if args.quick else 3))
    trials = 100 if args.quick else 1000
    prec, kw = bench_precision(trials)
    plot(scaling, args.out / "association_scaling.png")
    write_markdown(args.out, hard, scaling, prec, kw, trials, time.perf_counter() - t0)
    print((args.out / "association.md").read_text())


if __name__ == "__main__":
    main()
