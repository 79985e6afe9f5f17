"""Runs on the scans alone (``input.odometry: scans``) against runs with the log's odometry, over every
real log here and the simulated office loop.

    python benchmarks/scan_odometry_panel.py [--data DIR] [--jobs 2]

Each log runs twice through ``cornerslam run`` (a subprocess), on the default config (Mines: its config,
configs/mines.yaml): with the log's odometry, and with ``--set input.odometry=scans``, which reads none of
it. Nothing is tuned per log. Figures: the radish buildings' ATE against the corrected poses beside each
(the exact-odometry variants hold the same scans: a run on the scans alone is the same on both); Intel's
relation error; the Mines rover's revisit misalignment (no reference: the map's agreement with itself);
the simulated office loop (``sample_logs/sim_office.mcap``, its ground truth) with its odometry taken
out. The radish buildings also run on their scans alone with the motion noise model four times tighter
(``ekf.alpha1..4`` ÷ 4), the variant the mode's default was chosen against. Writes
``docs/results/scan_odometry_panel.md``. Deterministic: a re-run gives the same figures (timings aside).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from radish_panel import BUILDINGS, relation_line, run  # noqa: E402
from real_logs import INTEL, LOGS, ROOT, default_data, relation_args  # noqa: E402

from cornerslam_cli.logs.writers.mcap import copy_mcap_without  # noqa: E402

ALONE = ["--set", "input.odometry=scans"]
SIM = ROOT / "sample_logs" / "sim_office.mcap"


def without_odometry(src: Path, dst: Path) -> Path:
    """``src`` copied without its /odom messages, its ground truth beside it."""
    copy_mcap_without(src, dst, {"/odom"})
    dst.with_suffix(".gt.tum").write_bytes(src.with_suffix(".gt.tum").read_bytes())
    return dst


TIGHTER = [f"--set=ekf.alpha{i}={v / 4:g}" for i, v in ((1, 0.05), (2, 0.01), (3, 0.05), (4, 0.01))]


def spacing(run_dir: Path) -> str:
    """How far apart the log's scans are: the median and largest step between consecutive steps of a run
    with the log's odometry (its estimate), and the largest turn."""
    t = np.loadtxt(run_dir / "trajectory.csv", delimiter=",", skiprows=1, usecols=(2, 3, 4))
    d = np.hypot(*np.diff(t[:, :2], axis=0).T)
    turn = np.degrees(np.abs(np.angle(np.exp(1j * np.diff(t[:, 2])))))
    return f"{np.median(d):.2f} / {d.max():.2f} m, {turn.max():.0f}°"


def ate_line(name: str, log_run: dict, alone: dict, work: Path) -> str:
    a, b = log_run["accuracy"], alone["accuracy"]
    odo = alone["scan_odometry"]
    return (
        f"| {name} | {spacing(work / f'{name}-log')} | {alone['counts']['steps']} | {b['ate']['rmse']:.3f} "
        f"| {b['odom_ate']['rmse']:.3f} | {a['ate']['rmse']:.3f} | {odo['searched']} | {odo['coasted']} "
        f"| {odo['gaps']} "
        f"| {alone['timing']['scans_per_second']:.0f} | {log_run['timing']['scans_per_second']:.0f} |"
    )


def revisit(s: dict, of: str = "") -> str:
    """A run's revisit misalignment (``of="odom_"``: its odometry's), as the run prints it."""
    c = s["consistency"]
    return f"{100 * c[of + 'revisit_mean']:.1f} cm on {100 * c[of + 'revisit_share']:.0f} %"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=default_data(), help="folder of the real logs")
    ap.add_argument("--work", type=Path, default=ROOT / "cornerslam_out" / "scan_odometry_panel")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "scan_odometry_panel.md")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    radish = [(b, args.data / "radish" / f"{b}.log", []) for b in BUILDINGS]
    mines = [(n, args.data / p, ["--config", str(c)]) for n, (p, c) in LOGS.items() if n != "intel"]
    intel = [("intel", args.data / INTEL, relation_args(args.data))]
    logs = radish + intel + mines
    if missing := [str(p) for _, p, _ in logs if not p.exists()]:
        ap.error(f"{', '.join(missing)} not found (pass --data DIR)")
    modes = {"log": [], "alone": ALONE, "tighter": [*ALONE, *TIGHTER]}
    with tempfile.TemporaryDirectory() as tmp, ThreadPoolExecutor(args.jobs) as pool:
        sim = without_odometry(SIM, Path(tmp) / "sim_office_alone.mcap")
        logs.append(("sim_office", SIM, []))
        jobs = {
            (name, mode): pool.submit(
                run, sim if (name, mode) == ("sim_office", "alone") else log, args.work / f"{name}-{mode}",
                [*more, *modes[mode]],
            )
            for name, log, more in logs
            for mode in modes
            if mode != "tighter" or name in BUILDINGS
        }  # fmt: skip
        s = {k: j.result() for k, j in jobs.items()}
    head = (
        "| log | between scans: median / largest step, largest turn | steps | ATE on the scans alone (m) "
        "| its scan odometry ATE (m) | ATE with the log's odometry (m) | scans searched | scans coasted "
        "| gaps | steps/s alone | steps/s with odometry |"
    )
    rule = "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    ates = np.array([s[(b, "alone")]["accuracy"]["ate"]["rmse"] for b in BUILDINGS])
    tight = np.array([s[(b, "tighter")]["accuracy"]["ate"]["rmse"] for b in BUILDINGS])
    worst = BUILDINGS[int(np.argmax(ates))]
    alone_intel = relation_line(s[("intel", "alone")]).replace("(odometry ", "(its scan odometry ")
    text = [
        "# Runs on the scans alone (input.odometry: scans)",
        "",
        "`python benchmarks/scan_odometry_panel.py` (see its docstring): each log with its odometry and on "
        "its scans alone, default config (Mines: configs/mines.yaml), pca, nothing tuned per log. ATE: RMSE "
        "after SE(2) alignment (a run on the scans alone starts at the origin of its own frame). *Between "
        "scans*: from the run with the log's odometry. *Scans searched*: registered from a correlative "
        "search's pose; *coasted*: no registration fitted, placed by the constant-velocity guess; *gaps*: "
        "scans after a gap in time (5× the usual spacing of scans at a steady rate). "
        "Deterministic: a re-run gives the same figures (timings aside).",
        "",
        "## radish/ buildings (ATE against the corrected poses; odometry: the noisy one)",
        "",
        head,
        rule,
        *(ate_line(b, s[(b, "log")], s[(b, "alone")], args.work) for b in BUILDINGS),
        "",
        f"On the scans alone: median ATE **{np.median(ates):.3f} m**, worst **{ates.max():.3f} m** "
        f"({worst}).",
        "",
        "The motion noise model four times tighter (`ekf.alpha1..4` ÷ 4; the mode's default is the wheel "
        "odometry's): "
        + ", ".join(f"{b} {v:.3f}" for b, v in zip(BUILDINGS, tight, strict=True))
        + f" m; median {np.median(tight):.3f}, worst {tight.max():.3f} m.",
        "",
        "## Simulated office loop (sample_logs/sim_office.mcap, its /odom taken out for the run alone)",
        "",
        head,
        rule,
        ate_line("sim_office", s[("sim_office", "log")], s[("sim_office", "alone")], args.work),
        "",
        "## Intel (relation metric, Kümmerle et al. 2009)",
        "",
        f"Between scans: {spacing(args.work / 'intel-log')}.",
        "",
        "On the scans alone: " + alone_intel,
        "",
        "With its noisy odometry: " + relation_line(s[("intel", "log")]),
        "",
        "## Mines rover (revisit misalignment: no reference)",
        "",
        "| log | between scans | steps | on the scans alone | its scan odometry | with the wheel odometry "
        "| the wheel odometry |",
        "|---|---|---:|---|---|---|---|",
        *(
            f"| {n} | {spacing(args.work / f'{n}-log')} | {s[(n, 'alone')]['counts']['steps']} "
            f"| {revisit(s[(n, 'alone')])} | {revisit(s[(n, 'alone')], 'odom_')} | {revisit(s[(n, 'log')])} "
            f"| {revisit(s[(n, 'log')], 'odom_')} |"
            for n, _, _ in mines
        ),
        "",
    ]
    args.out.write_text("\n".join(text))
    print("\n".join(text))


if __name__ == "__main__":
    main()
