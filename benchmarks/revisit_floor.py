"""The floor of the revisit misalignment: what a right trajectory scores on the same scans.

    python benchmarks/revisit_floor.py [--data DIR] [--out docs/results/revisit_floor.md] [--jobs 2]

The revisit misalignment (report/consistency.py, summary.json's ``consistency``) is a nearest-*point*
distance, so even exact poses score above zero: along-wall point spacing, range noise, and structure
seen differently from two places all count. Three sets of rows, each run with the default config
(``cornerslam run``'s pipeline, the run's own keyframes and kept scans; the library functions that
summary.json's figure comes from, ``revisit_misalignment``, called with other trajectories):

1. **radish/** (real SICK scans, 180°): the scans placed with the log's *reference* poses (NAME.gt.tum,
   a published SLAM solution, interpolated at the keyframes' stamps), with our output, with the
   scan-matched chain and with the (noisy, re-made) wheel odometry.
2. **simulated controls** (simulate.simulate_log, the office loop, 10 Hz like the Mines rover): a
   URG-04LX-like laser (240°, 682 beams, range noise σ = ``sigma_a`` + 0.2 % of the range) placed with
   the exact ground truth and with our output; with the simulator's 30 m range and with the URG's 5.6 m
   (``input.max_range``: beams beyond it dropped by the run, as the real laser does not return them).
3. **Mines** (``configs/mines.yaml``): output, online (causal) estimate, scan-matched chain, odometry;
   each log also with ``submaps.enabled=false``, exp4 with ``loops.enabled=false`` (diagnostics, not
   tuning); per 100-scan section of exp4 the figure of each trajectory and how far the output lies from
   the chain; the steps where exp4's output turns away from the chain, and the output scored again with
   the worst of them given the chain's increments (a counterfactual that attributes the gap).

Every trajectory is scored on the same kept scans (the run's ScanStore, laser frame); each pose is the
laser's (base pose ∘ mount). The output's figure is checked against the run's summary.json. Writes
``docs/results/revisit_floor.md``; deterministic (timings aside).
"""

from __future__ import annotations

import argparse
import csv
import os
import platform
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from frontend_panel import reference  # noqa: E402
from radish_panel import BUILDINGS  # noqa: E402
from real_logs import MINES, ROOT, default_data  # noqa: E402

from cornerslam_cli.frontend import frames, open_input  # noqa: E402
from cornerslam_cli.geometry import compose, relative, wrap_angle  # noqa: E402
from cornerslam_cli.lasers import resolve_config  # noqa: E402
from cornerslam_cli.pipeline import run_filter  # noqa: E402
from cornerslam_cli.report.consistency import (  # noqa: E402
    MARGIN,
    REVISIT_BLOCK,
    REVISIT_CAP,
    REVISIT_GAP,
    revisit_misalignment,
    tile_points,
    tiles,
)
from cornerslam_cli.report.occupancy import ScanStore  # noqa: E402
from cornerslam_cli.report.revisit_grid import nearest_far  # noqa: E402
from cornerslam_cli.report.run_writer import load_reference  # noqa: E402
from cornerslam_cli.report.tables import read_tum  # noqa: E402

SIM_SEED, SIM_RATE, SIM_SPEED = 1, 10.0, 0.5  # the office loop once, a scan every 5 cm
SIM_FOV, SIM_BEAMS = 240.0, 682  # the URG-04LX's scan (the Mines logs' first/last 70 beams: the rover's body)
URG_RANGE = 5.6  # m: the URG-04LX's maximum range (data sheet)
# (name, σ of the range noise's constant part m, maximum range m or None: the simulator's 30 m)
SIM_CONTROLS = (("1 cm, 30 m", 0.01, None), ("3 cm, 30 m", 0.03, None), ("1 cm, 5.6 m", 0.01, URG_RANGE))
SIM_CONTROLS += (("3 cm, 5.6 m", 0.03, URG_RANGE),)
MINES_LOGS = {"exp1": "exp1.mcap", "exp2": "exp2.mcap", "exp3": "exp3.bag", "exp4": "exp4.mcap"}
# (label, override, logs): every Mines log without the two levels, exp4 also without loop closing
DIAGNOSTICS = (
    ("submaps off", "submaps.enabled=false", tuple(MINES_LOGS)),
    ("loops off", "loops.enabled=false", ("exp4",)),
)
SECTION = 100  # scans: the sections of exp4's breakdown (= REVISIT_GAP)
DEPARTURES = 6  # exp4's steps listed whose heading increment departs most from the chain's
REPAIRED = (1, 2, 3, 5, 10)  # ... and the output with that many of them replaced by the chain's increments


def per_point(pts, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The revisit distance of every point that has a neighbour within the cap and its scan's block,
    tile by tile as consistency.figures computes them (their mean is revisit_misalignment's)."""
    ds, bs = [], []
    for lo, hi in tiles(pts, poses):
        xy, blocks, own, _ = tile_points(pts, poses, lo, hi, MARGIN)
        d = nearest_far(xy, blocks, own, REVISIT_GAP // REVISIT_BLOCK, REVISIT_CAP)
        ok = np.isfinite(d)
        ds.append(d[ok])
        bs.append(blocks[own][ok])
    return np.concatenate(ds), np.concatenate(bs)


def laser_poses(path: Path, laser2base) -> tuple[np.ndarray, np.ndarray]:
    """Stamps and the laser's poses of a run's TUM file (base poses ∘ mount)."""
    stamps, poses = read_tum(path)
    return stamps, compose(poses, np.asarray(laser2base, dtype=float))


def online_poses(dest: Path, laser2base) -> np.ndarray:
    """The causal (online) estimate of trajectory.csv, the laser's poses."""
    with open(dest / "trajectory.csv") as f:
        rows = list(csv.DictReader(f))
    base = np.array([[float(r[f"online_{k}"]) for k in ("x", "y", "theta")] for r in rows])
    return compose(base, np.asarray(laser2base, dtype=float))


def scored(case: dict) -> dict:
    """Run ``case`` (log, config, overrides) as ``cornerslam run`` does, keeping its scans, and score
    the revisit misalignment of its trajectories on them."""
    log, sets = Path(case["log"]), case.get("sets", [])
    cfg = resolve_config(log, case.get("config"), sets)
    src = open_input(log, cfg)
    store = ScanStore()
    with tempfile.TemporaryDirectory() as tmp:
        dest = Path(tmp)
        t0 = time.perf_counter()
        summary = run_filter(frames(src, cfg), src, cfg, dest, load_reference(log), t0, store)
        wall = time.perf_counter() - t0
        stamps, _ = read_tum(dest / "trajectory.tum")
        traj = {"output": laser_poses(dest / "trajectory.tum", src.laser2base)[1]}
        if case.get("online"):
            traj["online"] = online_poses(dest, src.laser2base)
        if (dest / "scan_matched.tum").exists():
            traj["chain"] = laser_poses(dest / "scan_matched.tum", src.laser2base)[1]
        traj["odometry"] = laser_poses(dest / "odometry.tum", src.laser2base)[1]
        steps = step_table(dest) if case.get("sections") else None
    if case.get("reference"):
        ref = compose(reference(log, log.parent, stamps), np.asarray(src.laser2base, dtype=float))
        traj = {"reference": ref, **traj}
    pts = store.laser_frame()
    scores = {k: revisit_misalignment(pts, p) for k, p in traj.items()}
    c, counts = summary.consistency, summary.counts
    # summary.json's figure (its scans at float32 poses, trajectory.tum's at 9 decimals)
    assert abs(scores["output"][0] - c.revisit_mean) < 1e-4, (scores["output"], c.revisit_mean)
    row = {
        "name": case["name"],
        "steps": counts.steps,
        "points": c.points,
        "scores": scores,
        "submaps": counts.submaps,
        "loops": (counts.loops_accepted, counts.loops_rejected),
        "preset": cfg.input.laser_preset,
        "wall": wall,
    }
    if case.get("sections"):
        row["sections"] = sections(pts, traj)
        row["departures"], row["repaired"] = departures(pts, traj["output"], traj["chain"], steps)
    return row


def sections(pts, traj: dict[str, np.ndarray]) -> list[dict]:
    """Per ``SECTION`` scans: each trajectory's revisited points and mean distance, and the output's
    mean distance (m) and heading difference (°) from the chain."""
    n = len(traj["output"])
    per = {k: per_point(pts, p) for k, p in traj.items()}
    d = traj["output"] - traj["chain"]
    dth = np.degrees(np.abs((d[:, 2] + np.pi) % (2 * np.pi) - np.pi))
    out = []
    for s in range(0, n, SECTION):
        row = {"scans": (s, min(s + SECTION, n) - 1)}
        for k, (dist, block) in per.items():
            sel = (block * REVISIT_BLOCK >= s) & (block * REVISIT_BLOCK < s + SECTION)
            row[k] = (int(sel.sum()), float(dist[sel].mean()) if sel.any() else float("nan"))
        row["apart"] = float(np.hypot(d[s : s + SECTION, 0], d[s : s + SECTION, 1]).mean())
        row["turned"] = float(dth[s : s + SECTION].mean())
        out.append(row)
    return out


def step_table(dest: Path) -> dict[str, np.ndarray]:
    """Per step of a run: its submap and heading σ (rad; trajectory.csv: with submaps, the local
    filter's variance plus the submap origin's), corners and matched corners (timing.csv)."""
    with open(dest / "trajectory.csv") as f:
        rows = list(csv.DictReader(f))
    submap = np.array([int(r["submap"]) for r in rows])
    sigma_theta = np.sqrt([float(r["var_theta"]) for r in rows])
    with open(dest / "timing.csv") as f:
        rows = list(csv.DictReader(f))
    return {
        "submap": submap,
        "sigma_theta": sigma_theta,
        "corners": np.array([int(r["n_corners"]) for r in rows]),
        "matched": np.array([int(r["n_matched"]) for r in rows]),
    }


def departures(pts, out: np.ndarray, chain: np.ndarray, steps: dict) -> tuple[list, dict]:
    """The steps whose increment of the output departs most in heading from the chain's increment:
    (step, submap, Δθ °, Δxy m, corners, matched, the heading σ ° at the step before) of the
    ``DEPARTURES`` largest; and the revisit
    figure of the output with its n largest replaced by the chain's increments (n in ``REPAIRED``)."""
    inc_out, inc_chain = relative(out[:-1], out[1:]), relative(chain[:-1], chain[1:])
    dth = wrap_angle(inc_out[:, 2] - inc_chain[:, 2])
    dxy = np.hypot(*(inc_out[:, :2] - inc_chain[:, :2]).T)
    order = np.argsort(-np.abs(dth), kind="stable")
    listed = [
        (k + 1, steps["submap"][k + 1], np.degrees(dth[k]), dxy[k], steps["corners"][k + 1])
        + (steps["matched"][k + 1], np.degrees(steps["sigma_theta"][k]))
        for k in order[:DEPARTURES].tolist()
    ]
    repaired = {}
    for n in REPAIRED:
        inc = inc_out.copy()
        inc[order[:n]] = inc_chain[order[:n]]
        poses = [out[0]]
        for d in inc:
            poses.append(compose(poses[-1], d))
        repaired[n] = revisit_misalignment(pts, np.array(poses))
    return listed, repaired


def sim_logs(tmp: Path) -> list[dict]:
    """The simulated control cases, their logs written into ``tmp``."""
    from cornerslam_cli.simulate import simulate_log

    cases = []
    for i, (name, sigma, max_range) in enumerate(SIM_CONTROLS):
        log = tmp / f"urg{i}.mcap"
        simulate_log(
            log,
            seed=SIM_SEED,
            rate=SIM_RATE,
            beams=SIM_BEAMS,
            speed=SIM_SPEED,
            fov=np.radians(SIM_FOV),
            sigma_a=sigma,
        )
        sets = [f"input.max_range={max_range}"] if max_range else []
        cases.append({"name": f"simulated URG, {name}", "log": log, "sets": sets, "reference": True})
    return cases


def cm(score: tuple[float, float]) -> str:
    mean, share = score
    return f"{100 * mean:.1f} ({100 * share:.0f} %)"


def commit(written: Path) -> str:
    """HEAD's short hash, marked when the clone has changes other than the file ``written``."""
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True)
    status = ["git", "status", "--porcelain", "--", "."]
    if written.resolve().is_relative_to(ROOT):
        status.append(f":(exclude){written.resolve().relative_to(ROOT)}")
    dirty = subprocess.run(status, cwd=ROOT, capture_output=True, text=True)
    return head.stdout.strip() + (" (uncommitted changes)" if dirty.stdout.strip() else "")


def loops(r: dict) -> str:
    if r["submaps"] is None:
        return "single map"
    return f"{r['submaps']}, {r['loops'][0]} / {r['loops'][1]}"


def score_table(rows: list[dict], cols: tuple[str, ...], head: str) -> list[str]:
    """One row per run: steps, points, the revisit score of each trajectory in ``cols`` (``head``
    their column titles, after the first column's), submaps and loops."""
    out = [
        f"| {head} | submaps, loops accepted / refused |",
        "|---|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        cells = " | ".join(cm(r["scores"][k]) if k in r["scores"] else "–" for k in cols)
        out.append(f"| {r['name']} | {r['steps']} | {r['points']:,} | {cells} | {loops(r)} |")
    return out


def floor_table(rows: list[dict], what: str, ref: str) -> list[str]:
    head = f"{what} | steps | points | {ref} | our output | scan-matched chain | odometry"
    return score_table(rows, ("reference", "output", "chain", "odometry"), head)


def mines_table(rows: list[dict]) -> list[str]:
    head = "log | steps | points | output (smoothed) | online (causal) | scan-matched chain | odometry"
    return score_table(rows, ("output", "online", "chain", "odometry"), head)


def section_table(rows: list[dict]) -> list[str]:
    cols = ("output", "online", "chain", "odometry")
    out = [
        "| scans | output | online | chain | odometry | output − chain: mean distance (cm), heading (°) |",
        "|---|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        cells = " | ".join(f"{100 * r[k][1]:.1f} ({r[k][0]:,})" for k in cols)
        out.append(
            f"| {r['scans'][0]}–{r['scans'][1]} | {cells} | {100 * r['apart']:.1f}, {r['turned']:.2f} |"
        )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=default_data())
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "revisit_floor.md")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    radish = [{"name": b, "log": args.data / "radish" / f"{b}.log", "reference": True} for b in BUILDINGS]
    mines = [
        {"name": n, "log": args.data / "mines" / f, "config": MINES, "online": True, "sections": n == "exp4"}
        for n, f in MINES_LOGS.items()
    ]
    mines += [
        {
            "name": f"{n}, {label}",
            "log": args.data / "mines" / MINES_LOGS[n],
            "config": MINES,
            "sets": [s],
            "online": True,
        }
        for label, s, logs in DIAGNOSTICS
        for n in logs
    ]
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        sims = sim_logs(Path(tmp))
        cases = radish + sims + mines
        with ProcessPoolExecutor(args.jobs) as ex:
            rows = list(ex.map(scored, cases))
    wall = time.perf_counter() - t0
    by = dict(zip([c["name"] for c in cases], rows, strict=True))
    lines = [
        "# The floor of the revisit misalignment",
        "",
        f"`python benchmarks/revisit_floor.py` (see its docstring), commit {commit(args.out)}, "
        f"{platform.machine()} ({os.cpu_count()} cores, {platform.node()}), Python "
        f"{platform.python_version()}; {wall:.0f} s wall with {args.jobs} processes. Default config "
        "(Mines: `configs/mines.yaml`). Revisit misalignment (report/consistency.py, the figure of "
        "summary.json's `consistency`): for each kept scan point placed with the trajectory, the "
        f"distance to the nearest point of scans ≥ {REVISIT_GAP} scans away (blocks of {REVISIT_BLOCK}), "
        f"capped at {REVISIT_CAP} m; the mean over the points that have such a neighbour, in cm, with "
        "their share in brackets. Every column of a row is scored on the same scans (the run's kept "
        "keyframes, laser frame); each trajectory places the laser at its base pose ∘ the mount.",
        "",
        "## Real SICK scans (radish), placed with their reference poses",
        "",
        "*Reference*: NAME.gt.tum (a published SLAM solution, reference_check.md shows it disagrees "
        "with its own scans by 2–3 cm a keyframe) interpolated at the keyframes' stamps. The lasers "
        "are 180° with 1° beams (csail, freiburg-101: 0.5°), sparser than the URG's 0.35°, and "
        "keyframes lie 0.3–1 m apart: this is what a published-quality trajectory scores on real "
        "data, not the URG's floor.",
        "",
        *floor_table([by[c["name"]] for c in radish], "log", "reference poses"),
        "",
        "## Simulated URG-like laser, placed with the exact ground truth",
        "",
        f"simulate.simulate_log: the office loop once (seed {SIM_SEED}), {SIM_RATE:.0f} Hz, "
        f"{SIM_SPEED} m/s, {SIM_FOV:.0f}° with {SIM_BEAMS} beams, range noise σ = the given constant + "
        "0.2 % of the range, 2 % dropouts; *5.6 m*: the run drops beams beyond the URG-04LX's range "
        "(`input.max_range`). *Reference* here is the exact ground truth: the floor of the metric "
        "with perfect poses in an idealised world (straight walls, no clutter, no glass).",
        "",
        *floor_table([by[c["name"]] for c in sims], "control", "exact ground truth"),
        "",
        f"Laser preset the runs chose: {', '.join(sorted({by[c['name']]['preset'] for c in sims}))}.",
        "",
        "## Mines (URG-04LX), our trajectories",
        "",
        "*Output*: trajectory.tum (the smoothed keyframe graph); *online*: the causal estimate "
        "(trajectory.csv `online_*`); *chain*: scan_matched.tum. Each log also with the two levels "
        "turned off (the paper's single map), exp4 also with loop closing off: diagnostics only, the "
        "defaults are unchanged.",
        "",
        *mines_table([by[c["name"]] for c in mines]),
        "",
        f"### exp4 per {SECTION}-scan section",
        "",
        "For the points of each section's scans: the revisit misalignment of each trajectory (cm; "
        "revisited points in brackets); and how far the output's laser poses lie from the chain's "
        "(both start at the first odometry pose).",
        "",
        *section_table(by["exp4"]["sections"]),
        "",
        "### exp4: the steps where the output turns away from the chain",
        "",
        "Per step, the output's increment (laser pose k−1 → k) against the chain's: the "
        f"{DEPARTURES} largest heading differences, with the step's corners and matched corners "
        "(timing.csv), submap, and the heading σ at the step before (trajectory.csv `var_theta`: the "
        "local filter's variance plus its submap origin's, so the local filter's own in submap 0 only). "
        "Then the "
        "output with its n largest such steps given the chain's increment instead (everything else "
        "the output's), scored again: how much of the gap to the chain those steps make.",
        "",
        "| step | submap | Δθ (°) | Δxy (cm) | corners | matched | σθ before (°) |",
        "|---:|---:|---:|---:|---:|---:|---:|",
        *(
            f"| {k} | {sm} | {dth:+.2f} | {100 * dxy:.1f} | {c} | {m} | {sd:.2f} |"
            for k, sm, dth, dxy, c, m, sd in by["exp4"]["departures"]
        ),
        "",
        "| output with n steps repaired | " + " | ".join(f"n = {n}" for n in REPAIRED) + " |",
        "|---|" + "---:|" * len(REPAIRED),
        "| revisit (cm) | " + " | ".join(cm(by["exp4"]["repaired"][n]) for n in REPAIRED) + " |",
    ]
    text = "\n".join(lines) + "\n"
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
