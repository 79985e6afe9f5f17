"""Accuracy over the whole real-log panel: the seven radish/ buildings (noisy odometry and the
exact-odometry variants, ATE against the corrected poses beside each log) and Intel (relation metric).

    python benchmarks/radish_panel.py [--data DIR] [--jobs 2] [--set KEY=VALUE ...]

Default config, the laser preset chosen automatically, associator pca; nothing is tuned per log. Each
log runs once through ``cornerslam run`` (a subprocess); the figures come from its summary.json. Writes
``docs/results/radish_panel.md``: one row per log, then the median and the worst log.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from real_logs import CLI, INTEL, ROOT, default_data, relation_args  # noqa: E402

INTEL_GFS = INTEL.with_name("intel.gfs.log")
GFS_ODOM_LINES = ["--set", "input.odom_topic=ODOM"]  # its ODOM lines, 1,498 of which go back in time

BUILDINGS = ("aces", "csail", "edmonton", "fhw", "freiburg-101", "infinite-corridor", "orebro")


def run(log: Path, out: Path, extra: list[str]) -> dict:
    """``cornerslam run LOG`` into ``out``; its summary.json."""
    cmd = [*CLI, "run", str(log), "--out", str(out), "-q", *extra]
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed: {res.stderr.strip()}")
    return json.loads((out / "summary.json").read_text())


def ate_row(name: str, s: dict) -> dict:
    a = s["accuracy"]
    return {
        "log": name,
        "steps": s["counts"]["steps"],
        "ate": a["ate"]["rmse"],
        "odom_ate": a["odom_ate"]["rmse"],
        "scan_odom_ate": a["scan_odom_ate"]["rmse"] if "scan_odom_ate" in a else float("nan"),
        "rpe_step": a["rpe_step_rmse"],
        "scans_per_s": s["timing"]["scans_per_second"],
    }


def table(rows: list[dict]) -> list[str]:
    out = [
        "| log | steps | ATE RMSE (m) | odometry ATE (m) | scan-matched odometry ATE (m) "
        "| consecutive-scan error (m) | steps/s |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        out.append(
            f"| {r['log']} | {r['steps']} | {r['ate']:.3f} | {r['odom_ate']:.3f} "
            f"| {r['scan_odom_ate']:.3f} | {r['rpe_step']:.3f} | {r['scans_per_s']:.0f} |"
        )
    ates = np.array([r["ate"] for r in rows])
    worst = rows[int(np.argmax(ates))]
    out.append(f"\nMedian ATE **{np.median(ates):.3f} m**; worst **{worst['ate']:.3f} m** ({worst['log']}).")
    return out


def relation_line(s: dict) -> str:
    """The relation errors of a run's summary: SLAM, its odometry, its scan-matched odometry."""
    a = s["accuracy"]
    rel, odom, scan = a["relations"], a["odom_relations"], a.get("scan_odom_relations")
    return (
        f"{s['counts']['steps']} steps: translation {rel['trans_mean']:.3f} ± {rel['trans_std']:.3f} m, "
        f"rotation {rel['rot_mean_deg']:.2f} ± {rel['rot_std_deg']:.2f}° (odometry {odom['trans_mean']:.3f} m"
        + (f", scan-matched odometry {scan['trans_mean']:.3f} m" if scan else "")
        + ")."
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=default_data(), help="folder of the real logs")
    ap.add_argument("--work", type=Path, default=ROOT / "cornerslam_out" / "radish_panel")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "radish_panel.md")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--set", action="append", default=[], help="config override for every run")
    args = ap.parse_args()
    extra = [x for kv in args.set for x in ("--set", kv)]
    logs = [(f"{b}{v}", args.data / "radish" / f"{b}{v}.log") for v in ("", "-exact") for b in BUILDINGS]
    if missing := [str(p) for _, p in logs if not p.exists()]:
        ap.error(f"{', '.join(missing)} not found (pass --data DIR)")
    with ThreadPoolExecutor(args.jobs) as pool:
        jobs = [pool.submit(run, p, args.work / n, extra) for n, p in logs]
        intel_jobs = [
            pool.submit(run, args.data / log, args.work / name, [*relation_args(args.data), *more, *extra])
            for name, log, more in (
                ("intel", INTEL, []),
                ("intel-gfs", INTEL_GFS, []),
                ("intel-gfs-odom", INTEL_GFS, GFS_ODOM_LINES),
            )
        ]
        summaries = [j.result() for j in jobs]
        intel, gfs, gfs_odom = (j.result() for j in intel_jobs)
    rows = [ate_row(n, s) for (n, _), s in zip(logs, summaries, strict=True)]
    noisy, exact = rows[: len(BUILDINGS)], rows[len(BUILDINGS) :]
    text = [
        "# Accuracy over the real-log panel",
        "",
        "`python benchmarks/radish_panel.py` (default config, pca, laser preset chosen automatically, "
        f"nothing tuned per log{'; overrides: ' + ' '.join(args.set) if args.set else ''}). ATE: RMSE "
        "after SE(2) alignment against the corrected poses beside each log; consecutive-scan error: RMSE "
        "of the translational error of consecutive relative poses. Deterministic: a re-run gives the same "
        "figures (timings aside).",
        "",
        "## Noisy odometry (radish/NAME.log)",
        "",
        *table(noisy),
        "",
        "## Exact odometry (radish/NAME-exact.log: the reference poses themselves as odometry)",
        "",
        *table(exact),
        "",
        "## Intel (relation metric, Kümmerle et al. 2009)",
        "",
        "Noisy odometry (intel-noisy-odom.log): " + relation_line(intel),
        "",
        "gmapping's (RBPF) corrected poses as odometry (intel.gfs.log: the input scores as below under "
        "'odometry'), read by default from the pose stored with each scan (its ODOM lines go back in "
        "time): " + relation_line(gfs),
        "",
        "The same, read from its ODOM lines (`--set input.odom_topic=ODOM`; 1,498 of 14,541 go back in "
        "time, by up to 2,684 s: those not put back in order are dropped, the lines after a jump back too "
        "until their stamps pass it again, and the odometry is interpolated between the rest): "
        + relation_line(gfs_odom),
        "",
    ]
    args.out.write_text("\n".join(text))
    print("\n".join(text))


if __name__ == "__main__":
    main()
