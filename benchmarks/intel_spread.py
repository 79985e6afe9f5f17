"""How far the Intel figures move with the floating-point kernels, and why.

    python benchmarks/intel_spread.py [--data DIR] [--out docs/results/intel_spread.md]

The same command — ``cornerslam compare intel-noisy-odom.log --assoc icnn,jcbb,pca`` with the Kümmerle
relations, default config — once per setting, one at a time:

* this CPU's defaults, twice (same bytes = the run is deterministic on one machine);
* each OpenBLAS kernel set this CPU can run (``OPENBLAS_CORETYPE``; settings that load the same kernels
  as an earlier one are left out), and two BLAS threads;
* numpy's SIMD dispatch capped below this CPU's widest level (``NPY_DISABLE_CPU_FEATURES``), and the
  Haswell kernels with numpy capped at AVX2 — what a CPU without AVX-512 computes;
* the default kernels on a log with one odometry reading moved by 1 µm (x of ODOM line k): the same
  sensitivity without any change of kernels;
* scan matching off (``scan_match.enabled=false``) under the defaults and the AVX2 setting.

Each row: the relation error (translation mean, m) of each associator and of the scan-matched odometry,
the kernels summary.json recorded, and the first step whose scan-matched pose differs from the first
default run by more than 1 mm. Also written: ``intel_spread.json`` (min/max per column over the
scan-matching rows), which ``benchmarks/real_logs.py`` quotes in real_logs.md.
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


def first_divergence(run_dir: Path, ref_dir: Path) -> str:
    a, b = scan_odom(run_dir), scan_odom(ref_dir)
    if a.shape != b.shape:
        return "different steps"
    far = np.flatnonzero(np.hypot(*(a - b).T) > DIVERGED)
    return str(far[0]) if len(far) else "never"


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


def plan(data: Path, tmp: Path) -> list[tuple[str, Path, dict[str, str], list[str]]]:
    """(label, log, environment, --set overrides) of every run, the reference first."""
    log = data / INTEL
    runs = [("this CPU's defaults", log, {}, []), ("this CPU's defaults, again", log, {}, [])]
    runs.append(("OPENBLAS_NUM_THREADS=2", log, {"OPENBLAS_NUM_THREADS": "2"}, []))
    seen = {kernels_of({})[0]}
    for core in CORETYPES:
        env = {"OPENBLAS_CORETYPE": core}
        if (k := kernels_of(env)[0]) not in seen:
            seen.add(k)
            runs.append((f"OPENBLAS_CORETYPE={core}", log, env, []))
    runs += [(label, log, env, []) for label, env in simd_caps()]
    avx2 = {"OPENBLAS_CORETYPE": "Haswell", **avx2_cap()}
    runs.append(("no AVX-512: Haswell kernels, numpy without AVX-512", log, avx2, []))
    for k in PERTURBED_ODOM_LINES:
        runs.append((f"ODOM line {k}: x + 1 µm", perturbed_log(log, k, tmp / f"intel-odom{k}.log"), {}, []))
    off = ["scan_match.enabled=false"]
    runs += [("scan matching off, defaults", log, {}, off), ("scan matching off, no AVX-512", log, avx2, off)]
    return runs


def table(results: list[dict]) -> list[str]:
    cols = [*ASSOCS, "scan-matched odometry"]
    lines = [
        f"| setting | BLAS kernels | numpy SIMD | {' | '.join(cols)} | first step > 1 mm from the first run |",
        "|---|---|---|" + "---:|" * len(cols) + "---:|",
    ]
    for r in results:
        fig = " | ".join("—" if r["off"] and c not in ASSOCS else f"{r['fig'][c]:.3f}" for c in cols)
        lines.append(f"| {r['label']} | {r['blas']} | {r['simd']} | {fig} | {r['diverge']} |")
    return lines


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=default_data(), help="folder of the real logs")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "intel_spread.md")
    args = ap.parse_args()
    if not (args.data / INTEL).exists():
        ap.error(f"{args.data / INTEL} not found (pass --data DIR or set CORNERSLAM_REAL_DATA)")
    results: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp:
        for i, (label, log, env, sets) in enumerate(plan(args.data, Path(tmp))):
            r = run_compare(log, args.data, Path(tmp) / f"run{i}", env, sets)
            blas = r["versions"].get("blas", "?").split("; ")
            off = bool(sets)
            ref = next((q for q in results if q["off"] == off), None)
            r.update(label=label, off=off, blas=" / ".join(sorted({b.split()[-1] for b in blas})))
            r.update(simd=r["versions"].get("numpy_simd", "?"))
            r["diverge"] = "—" if off or ref is None else first_divergence(r["dir"], ref["dir"])
            r["same_as_ref"] = ref is not None and same_bytes(r["dir"], ref["dir"])
            results.append(r)
            print(label, {k: round(v, 3) for k, v in r["fig"].items()}, r["blas"], r["simd"], flush=True)
    on = [r for r in results if not r["off"]]
    cols = [*ASSOCS, "scan-matched odometry"]
    rng = {c: (min(r["fig"][c] for r in on), max(r["fig"][c] for r in on)) for c in cols}
    off = [r for r in results if r["off"]]
    off_same = all(r["fig"][a] == off[0]["fig"][a] for r in off for a in ASSOCS)
    v = results[0]["versions"]
    lines = [
        "# Intel: how far the figures move with the floating-point kernels",
        "",
        "Generated by `benchmarks/intel_spread.py`: `cornerslam compare intel-noisy-odom.log --assoc "
        "icnn,jcbb,pca --relations intel.relations --time-offset 976052857.334`, default config, under each "
        "setting below, one run at a time. Figures: Kümmerle relation error, translation mean (m). "
        f"numpy {v['numpy']}, scipy {v['scipy']}, Python {v['python']}.",
        "",
        *table(results),
        "",
        "Range over the "
        + str(len(on))
        + " scan-matching rows: "
        + ", ".join(f"{c} {lo:.3f}–{hi:.3f} m" for c, (lo, hi) in rng.items())
        + ".",
        f"The second default run is byte-identical to the first: {results[1]['same_as_ref']}. "
        "Scan matching off: every associator's figure is "
        + ("the same under both settings." if off_same else "different between the two settings."),
        "",
        "## Why",
        "",
        "Each run is deterministic on one machine (no time budget is set by default, no randomness, the "
        "worker processes of `compare` only split the associators), but different floating-point kernels "
        "round the same sums differently in the last bit: OpenBLAS picks its kernels for the CPU "
        "(`OPENBLAS_CORETYPE` overrides), and numpy dispatches its loops to the widest SIMD level the CPU has. "
        "With scan matching off those bits stay bits. The scan matcher (point-to-line ICP against a "
        "local map) makes discrete decisions on continuous values — which map point is a point's 5th "
        "neighbour (and so whether it lies on a line and gets a normal), which points are inside the "
        "correspondence and inlier distances, which voxel keeps which point, whether the fit is low enough "
        "to retry other headings — so a last-bit difference that lands on one of those boundaries changes "
        "the match by a fraction of a millimetre, which changes the next local map, and the runs part; "
        "a 1 µm change of one odometry reading does the same without any change of kernels.",
        "",
        "Traced by hand between the SkylakeX kernels (this machine's default) and the Haswell ones: the "
        "scan-matched poses differ by 1e-16 m from the first match on and by 4e-14 m at step 205; at step 206 "
        "map point 50 of the local map has two neighbours at the same distance (0.098235558897640 m, "
        "differing in the 15th digit), the kd-tree returns a different one as the 5th neighbour, the "
        "neighbourhood is on a line with one (eigenvalue ratio 0.05) and not with the other (0.26 > 0.2), "
        "so one residual enters the Gauss–Newton sum or not, and the match moves by 0.45 mm. The poses are "
        "1 mm apart at step 210, 1 cm at 250, 10 cm at 366; the associators then see different corners in "
        "different places (ICNN first matches differently at step 465).",
        "",
        "So a figure published to three digits is one sample: on another machine expect the range above, "
        "and compare runs made on one machine. summary.json records the kernels (`versions.blas`, "
        "`versions.numpy_simd`) next to the numpy and scipy versions.",
        "",
    ]
    args.out.write_text("\n".join(lines))
    summary = {"settings": len(on), "range": {c: list(r) for c, r in rng.items()}, "numpy": v["numpy"]}
    args.out.with_suffix(".json").write_text(json.dumps(summary, indent=2) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
