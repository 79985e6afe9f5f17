"""Do the Intel figures depend on the machine? The same run under every floating-point setting at hand.

    python benchmarks/intel_spread.py [--data DIR] [--out docs/results/intel_spread.md]

The same command — ``cornerslam compare intel-noisy-odom.log --assoc icnn,jcbb,pca`` with the Kümmerle
relations, default config — once per setting, one at a time:

* this CPU's defaults, twice (same bytes = the run is deterministic on one machine);
* each OpenBLAS kernel set this CPU can run (``OPENBLAS_CORETYPE``; settings that load the same kernels
  as an earlier one are left out), and two BLAS threads;
* numpy's SIMD dispatch capped below this CPU's widest level (``NPY_DISABLE_CPU_FEATURES``), and the
  Haswell kernels with numpy capped below AVX-512 — what a CPU without AVX-512 computes;
* the default kernels on a log with one odometry reading moved by 1 µm (x of ODOM line k): a change of
  the input far below the sensor's resolution;
* scan matching off (``scan_match.enabled=false``) under the defaults and the no-AVX-512 setting.

Each row: the relation error (translation mean, m) of each associator and of the scan-matched odometry,
the kernels summary.json recorded, and how far the scan-matched poses are from those of the first run.
Also written: ``intel_spread.json`` (min/max per column over the scan-matching rows), which
``benchmarks/real_logs.py`` quotes in real_logs.md.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from real_logs import ASSOCS, CLI, INTEL, ROOT, default_data, relation_args

from cornerslam_cli import fpenv

CORETYPES = ("Prescott", "Nehalem", "Sandybridge", "Haswell", "Zen", "SkylakeX", "Cooperlake")
PERTURBED_ODOM_LINES = (100, 300, 500, 700)  # 1-based index among the ODOM lines
MICRON = 1e-6
DIVERGED = 1e-3  # m: "differs from the reference run" in the last column


def run_compare(log: Path, data: Path, out: Path, env: dict[str, str], sets: list[str]) -> dict:
    """One ``cornerslam compare`` (one process at a time: the machine is shared); its figures."""
    cmd = [
        *CLI,
        "compare",
        str(log),
        "--assoc",
        ",".join(ASSOCS),
        "--out",
        str(out),
        "-q",
        *relation_args(data),
    ]
    for s in sets:
        cmd += ["--set", s]
    subprocess.run(cmd, check=True, env={**os.environ, **env}, stdout=subprocess.DEVNULL)
    with open(out / "comparison.csv") as f:
        rows = {r["assoc"]: r for r in csv.DictReader(f)}
    versions = json.loads((out / ASSOCS[0] / "summary.json").read_text())["versions"]
    fig = {a: float(rows[a]["rel_trans_mean"]) for a in ASSOCS}
    fig["scan-matched odometry"] = float(rows[ASSOCS[0]]["scan_odom_rel_trans_mean"])
    return {"fig": fig, "versions": versions, "dir": out}


def scan_odom(run_dir: Path) -> np.ndarray:
    """The scan-matched poses (x, y) of every step (the same for every associator)."""
    with open(run_dir / ASSOCS[0] / "trajectory.csv") as f:
        return np.array([[float(r["scan_odom_x"]), float(r["scan_odom_y"])] for r in csv.DictReader(f)])


def divergence(run_dir: Path, ref_dir: Path) -> tuple[str, str]:
    """(largest distance between the scan-matched positions of two runs, first step beyond 1 mm)."""
    a, b = scan_odom(run_dir), scan_odom(ref_dir)
    if a.shape != b.shape:
        return "inf (different steps)", "—"
    d = np.hypot(*(a - b).T)
    far = np.flatnonzero(d > DIVERGED)
    return f"{d.max():.1e}", str(far[0]) if len(far) else "never"  # (formatted for the table)


def same_bytes(a: Path, b: Path) -> bool:
    return all(
        (a / x / "trajectory.csv").read_bytes() == (b / x / "trajectory.csv").read_bytes() for x in ASSOCS
    )


def kernels_of(env: dict[str, str]) -> tuple[str, str]:
    """(BLAS kernels, numpy SIMD) a process started with ``env`` uses."""
    code = "from cornerslam_cli import fpenv; d = fpenv.describe(); print(d['blas']); print(d['numpy_simd'])"
    env = {**os.environ, **env}
    out = subprocess.run([sys.executable, "-c", code], env=env, check=True, capture_output=True, text=True)
    return tuple(out.stdout.splitlines()[:2])


def simd_caps() -> list[tuple[str, dict[str, str]]]:
    """numpy dispatch capped below each level this CPU uses: (label, env), from the widest down."""
    used = fpenv.simd_targets()
    labels = [f"baseline {fpenv.simd_baseline()}", *used[:-1]]
    return [
        (f"numpy SIMD capped at {labels[i]}", {"NPY_DISABLE_CPU_FEATURES": " ".join(used[i:])})
        for i in range(len(used) - 1, -1, -1)
    ]


def avx2_cap() -> dict[str, str]:
    """NPY_DISABLE_CPU_FEATURES that leaves numpy no AVX-512 loops (names differ across numpy versions)."""
    wide = [t for t in fpenv.simd_targets() if "AVX512" in t or t == "X86_V4"]
    return {"NPY_DISABLE_CPU_FEATURES": " ".join(wide)} if wide else {}


def perturbed_log(src: Path, line_no: int, dst: Path) -> Path:
    """``src`` with the x of its ``line_no``-th ODOM line moved by 1 µm (everything else byte-identical)."""
    lines, seen = src.read_text().splitlines(keepends=True), 0
    for i, line in enumerate(lines):
        if line.startswith("ODOM "):
            seen += 1
            if seen == line_no:
                f = line.split(" ")
                f[1] = f"{float(f[1]) + MICRON:.6f}"
                lines[i] = " ".join(f)
                break
    dst.write_text("".join(lines))
    return dst


def plan(data: Path, tmp: Path) -> list[tuple[str, str, Path, dict[str, str], list[str]]]:
    """(kind, label, log, environment, --set overrides) of every run; the first of each kind is its
    reference. Kinds: "kernels" (same input, other floating-point kernels), "input" (1 µm changes),
    "off" (scan matching off)."""
    log = data / INTEL
    runs = [
        ("kernels", "this CPU's defaults", log, {}, []),
        ("kernels", "this CPU's defaults, again", log, {}, []),
    ]
    runs.append(("kernels", "OPENBLAS_NUM_THREADS=2", log, {"OPENBLAS_NUM_THREADS": "2"}, []))
    seen = {kernels_of({})[0]}
    for core in CORETYPES:
        env = {"OPENBLAS_CORETYPE": core}
        if (k := kernels_of(env)[0]) not in seen:
            seen.add(k)
            runs.append(("kernels", f"OPENBLAS_CORETYPE={core}", log, env, []))
    runs += [("kernels", label, log, env, []) for label, env in simd_caps()]
    avx2 = {"OPENBLAS_CORETYPE": "Haswell", **avx2_cap()}
    runs.append(("kernels", "no AVX-512: Haswell kernels, numpy without AVX-512", log, avx2, []))
    for k in PERTURBED_ODOM_LINES:
        moved = perturbed_log(log, k, tmp / f"intel-odom{k}.log")
        runs.append(("input", f"ODOM line {k}: x + 1 µm", moved, {}, []))
    off = ["scan_match.enabled=false"]
    runs += [("off", "scan matching off, defaults", log, {}, off)]
    runs += [("off", "scan matching off, no AVX-512", log, avx2, off)]
    return runs


def table(results: list[dict]) -> list[str]:
    cols = [*ASSOCS, "scan-matched odometry"]
    lines = [
        f"| setting | BLAS kernels | numpy SIMD | {' | '.join(cols)} | max distance from the reference's "
        "scan-matched poses (m) | first step > 1 mm | trajectory.csv identical |",
        "|---|---|---|" + "---:|" * len(cols) + "---:|---:|---|",
    ]
    for r in results:
        fig = " | ".join(
            "—" if r["kind"] == "off" and c not in ASSOCS else f"{r['fig'][c]:.3f}" for c in cols
        )
        same = "reference" if r["same"] is None else "yes" if r["same"] else "no"
        head = f"| {r['label']} | {r['blas']} | {r['simd']} | {fig}"
        lines.append(f"{head} | {r['max_dist']} | {r['diverge']} | {same} |")
    return lines


def measure(data: Path) -> list[dict]:
    """Every run of the plan, each compared with the reference run (the first scan-matching run; for
    scan matching off, the first run with it off)."""
    results: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp:
        for i, (kind, label, log, env, sets) in enumerate(plan(data, Path(tmp))):
            r = run_compare(log, data, Path(tmp) / f"run{i}", env, sets)
            off = kind == "off"
            ref = next((q for q in results if (q["kind"] == "off") == off), None)
            blas = {b.split()[-1] for b in r["versions"].get("blas", "?").split("; ")}
            simd = r["versions"].get("numpy_simd", "?")
            r.update(kind=kind, label=label, blas=" / ".join(sorted(blas)), simd=simd)
            r["max_dist"], r["diverge"] = (
                ("—", "—") if off or ref is None else divergence(r["dir"], ref["dir"])
            )
            r["same"] = None if ref is None else same_bytes(r["dir"], ref["dir"])
            results.append(r)
            print(label, {k: round(v, 3) for k, v in r["fig"].items()}, r["blas"], simd, flush=True)
    return results


# What this table showed before the scan matcher's neighbourhoods included tied neighbours (measured
# with this script on the code before that change); kept because it explains figures published before.
HISTORY = """## Before: the figures depended on the machine (fixed)

Until the scan matcher's neighbourhoods included tied neighbours, the same 15 runs gave ICNN 0.182–0.364 m,
JCBB 0.165–0.268 m, PCA 0.165–0.268 m and scan-matched odometry 0.316–0.388 m, and a 1 µm change of one
odometry reading moved the scan-matched odometry by up to 2.4 cm of relation error (0.316–0.352 m). The
README's 0.190 / 0.165 / 0.165 / 0.328 m were the SkylakeX kernels' (the default on an AVX-512 CPU);
OPENBLAS_CORETYPE=Haswell gave 0.301 / 0.167 / 0.167 / 0.388 m, the figures reported in issue 13 (item 14);
a CPU without AVX-512 gave 0.183 / 0.165 / 0.165 / 0.336 m. Each run was deterministic on its machine; the
kernels round some sums differently in the last bit, and with scan matching off those bits stayed bits (the
table's last two rows, then as now).

Traced between the SkylakeX and the Haswell kernels: the scan-matched poses differed by 1e-16 m from the
first match on and by 4e-14 m at step 205. At step 206 map point 50 of the local map had two neighbours at
the same distance, 0.0982355588976401 m and ...4111 m (with SkylakeX; the order was the other way round with
Haswell): the beams either side of a point whose ranges are equal — CARMEN ranges are quantised to 1 cm —
are exactly equidistant from it, so which one the kd-tree called the 5th neighbour was decided by the last
bit. With one the five points lay on a line (eigenvalue ratio 0.05 < 0.2) and the point got a normal, with
the other not (0.26): one residual entered the Gauss–Newton sum or not, the match moved by 0.45 mm, the next
local map with it; 1 mm apart at step 210, 1 cm at 250, 10 cm at 366, and the associators then matched
differently (ICNN from step 465). The Nehalem run, 1 mm apart already at step 46, parted through the same
kind of tie at step 27 (map point 909, neighbours 908 and 910), where both choices gave a normal but in
directions 3° apart. The Mines logs parted the same way (exp1, SkylakeX vs Haswell kernels: scan-matched
odometry 0.33 m apart at the end; identical since the fix).

The fix: a map point's neighbourhood is its 5 nearest neighbours plus any tied with the 5th (within a
relative 1e-9), so its normal no longer depends on the order the kd-tree returns equidistant points in. Not
a parameter change; it moves the figures (Intel PCA 0.165 → 0.160 m, scan-matched odometry 0.328 → 0.372 m,
inside the range the machines used to give)."""

LIMITS = (
    "Not covered here: other CPUs' own kernels (only the kernel sets this CPU can run, selected by "
    "OPENBLAS_CORETYPE), other BLAS libraries (MKL, Apple Accelerate), other numpy/scipy versions (their "
    "sin/cos and kd-tree may round differently) and ARM. The scan matcher still makes discrete decisions on "
    "continuous values (correspondence and inlier distances, voxel cells, the retry threshold); a last-bit "
    "difference can still flip one, but only when a value falls within a rounding error of a threshold by "
    "chance, not systematically as the exact ties did. Re-run this script to check a new machine; "
    "summary.json records the kernels of every run (`versions.blas`, `versions.numpy_simd`)."
)


def figure_range(lo: float, hi: float) -> str:
    return f"{lo:.3f} m in every row" if f"{lo:.3f}" == f"{hi:.3f}" else f"{lo:.3f}–{hi:.3f} m"


def report(results: list[dict]) -> tuple[list[str], dict]:
    """The markdown table and notes, and the JSON summary real_logs.py quotes."""
    on = [r for r in results if r["kind"] != "off"]
    cols = [*ASSOCS, "scan-matched odometry"]
    rng = {c: (min(r["fig"][c] for r in on), max(r["fig"][c] for r in on)) for c in cols}
    identical = all(r["same"] for r in results if r["kind"] == "kernels" and r["same"] is not None)
    off = [r for r in results if r["kind"] == "off"]
    off_same = all(r["fig"][a] == off[0]["fig"][a] for r in off for a in ASSOCS)
    moved = max((r["max_dist"] for r in results if r["kind"] == "input"), key=lambda d: float(d.split()[0]))
    v = results[0]["versions"]
    lines = [
        "# Intel: do the figures depend on the machine?",
        "",
        "Generated by `benchmarks/intel_spread.py`: `cornerslam compare intel-noisy-odom.log --assoc "
        "icnn,jcbb,pca --relations intel.relations --time-offset 976052857.334`, default config, under each "
        "setting below, one run at a time (OPENBLAS_CORETYPE selects a BLAS kernel set, "
        "NPY_DISABLE_CPU_FEATURES caps numpy's SIMD dispatch). Figures: Kümmerle relation error, translation "
        f"mean (m). numpy {v['numpy']}, scipy {v['scipy']}, Python {v['python']}.",
        "",
        *table(results),
        "",
        f"Over the {len(on)} scan-matching rows: "
        + ", ".join(f"{c} {figure_range(*r)}" for c, r in rng.items())
        + ". Every associator's trajectory.csv is byte-identical to the reference's "
        + ("under every kernel setting" if identical else "NOT under every kernel setting (see the table)")
        + f"; the 1 µm input changes move the scan-matched poses by at most {moved} m. Scan matching off: "
        + (
            "the same figures under both settings."
            if off_same
            else "different figures under the two settings."
        ),
        "",
        LIMITS,
        "",
        HISTORY,
        "",
    ]
    summary = {"runs": len(on), "identical": identical, "range": {c: list(r) for c, r in rng.items()}}
    return lines, summary


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=default_data(), help="folder of the real logs")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "intel_spread.md")
    args = ap.parse_args()
    if not (args.data / INTEL).exists():
        ap.error(f"{args.data / INTEL} not found (pass --data DIR or set CORNERSLAM_REAL_DATA)")
    lines, summary = report(measure(args.data))
    args.out.write_text("\n".join(lines))
    args.out.with_suffix(".json").write_text(json.dumps(summary, indent=2) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
