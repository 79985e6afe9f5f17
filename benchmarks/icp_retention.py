"""How much of its start's heading error ICP keeps: the odometry's drift leaking into the matches.

    python benchmarks/icp_retention.py [--data DIR] [--jobs 2] [--delta 0.01] [--out FILE]

The front end starts ICP at the odometry's guess (motion/icp.py) and fuses the match with that same
odometry as if the two were independent (motion/fusion.py). On sparse 1° scans ICP's cost is rough
(icp_basins.py): it ends in the local minimum nearest its start, so a match keeps part of the guess's
error — and so of the odometry's heading drift, before the fusion has learnt it.

For every keyframe k of each radish exact-odometry log (its reference poses; the run's keyframe selection,
default config) the scans of the ``scan_match.window`` keyframes before it, placed at their reference
poses, make the local map (as reference_check.py builds it), and scan k is registered from its reference
pose turned by +δ and by −δ. Its *retention* is (θ_end(+δ) − θ_end(−δ)) / 2δ: 0 when ICP ends on the same
pose from either start, 1 when it stays where it was started. Columns: ICP from the start alone (the front
end's) and from the start and from it turned by ±0.5° and ±1°, the best-fitting end kept (the patch's
``heading_starts=2``, its bound by the odometry's learnt heading noise left out: here every end counts).
Beside it, the heading error of the end from the reference pose itself (δ = 0; a retaining ICP started at
the truth looks better than it is). Deterministic.

The several starts are not in the package: they were tried in the front end (docs/results/patches/
headstarts.patch, its ``register_starts``; experiments.md, "ICP from several headings") and not adopted. This
script does the same with motion/icp.py's ``register`` (:func:`best_of_starts`), so it runs on main.
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from frontend_panel import keyframes  # noqa: E402
from radish_panel import BUILDINGS  # noqa: E402
from real_logs import ROOT, default_data  # noqa: E402
from reference_check import reference_maps  # noqa: E402

from cornerslam_cli.geometry import relative, transform_points, wrap_angle  # noqa: E402
from cornerslam_cli.motion.icp import LocalMap, Registration, register  # noqa: E402
from cornerslam_cli.motion.params import ScanMatchConfig  # noqa: E402

STARTS = (0, 2)  # starts each way of the two rows (the patch's scan_match.heading_starts)
STEP = 0.0087  # rad between two starts (the patch's heading_start_step, 0.5°)


def score(
    reg: Registration, points: np.ndarray, local: LocalMap, cfg: ScanMatchConfig
) -> tuple[float, float]:
    """(fit, −spread) of an end: the share of points within inlier_distance of the map, then the mean
    squared distance of the points to it, each capped there (larger is better)."""
    placed = transform_points(points, reg.pose)
    dist, _ = local.grid.query(placed, cfg.inlier_distance)
    return reg.fit, -float(np.mean(np.minimum(dist, cfg.inlier_distance) ** 2))


def best_of_starts(
    points: np.ndarray, local: LocalMap, start: np.ndarray, cfg: ScanMatchConfig, each_way: int
) -> Registration:
    """ICP from ``start`` and from it turned by ±j·STEP (j ≤ ``each_way``), each with its prior at
    ``start``: the end with the best :func:`score` (the first of equals: ``start``'s own)."""
    best = register(points, local, start, cfg)
    best_score = score(best, points, local, cfg)
    for j in range(1, each_way + 1):
        for sign in (1.0, -1.0):
            reg = register(points, local, start + (0.0, 0.0, sign * j * STEP), cfg, prior=start)
            if (s := score(reg, points, local, cfg)) > best_score:
                best, best_score = reg, s
    return best


def retention(args: tuple[Path, float]) -> dict:
    """Per keyframe and per ``STARTS``: the retention and the error from the reference (module docstring)."""
    log, delta = args
    run_cfg, src, pairs = keyframes(log, [])
    pts = [transform_points(p.scan.points(), src.laser2base) for p in pairs]
    ref = np.array([p.odom for p in pairs])  # -exact logs: the reference poses are the odometry
    cfg = run_cfg.scan_match
    kept, err = {n: [] for n in STARTS}, {n: [] for n in STARTS}
    for k, local, q in reference_maps(pts, ref, cfg):
        for starts in STARTS:
            starts_at = [ref[k] + (0.0, 0.0, turn) for turn in (0.0, delta, -delta)]
            ends = [best_of_starts(q, local, start, cfg, starts).pose for start in starts_at]
            end = [wrap_angle(relative(ref[k], e)[2]) for e in ends]
            kept[starts].append((end[1] - end[2]) / (2 * delta))
            err[starts].append(abs(end[0]))
    out = {n: (np.array(kept[n]), np.degrees(np.array(err[n]))) for n in STARTS}
    return {"log": log.name.removesuffix(".log"), "rows": out}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=default_data())
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--delta", type=float, default=0.01, help="rad: the start's heading error either way")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "icp_retention.md")
    args = ap.parse_args()
    logs = [args.data / "radish" / f"{b}-exact.log" for b in BUILDINGS]
    with ProcessPoolExecutor(args.jobs) as ex:
        results = list(ex.map(retention, [(log, args.delta) for log in logs]))
    lines = [
        "# How much of its start's heading error ICP keeps",
        "",
        f"`python benchmarks/icp_retention.py --delta {args.delta:g}` (see its docstring): every keyframe of "
        "each exact-odometry radish log registered on the keyframes before it at their reference poses, "
        f"from its reference pose turned by ±{np.degrees(args.delta):.2f}°. *Retention*: the share of that "
        "turn the end keeps (0: the same end from both starts; 1: ICP stays where it was started); "
        "*error*: the end's heading error from the reference pose itself. Deterministic.",
        "",
        "| log | keyframes | retention, one start: mean / median / 90th pct | retention, 5 starts "
        "| error, one start: mean (°) | error, 5 starts (°) |",
        "|---|---:|---|---|---:|---:|",
    ]
    for r in results:
        (k0, e0), (k2, e2) = r["rows"][STARTS[0]], r["rows"][STARTS[1]]
        cells = [f"{k.mean():.2f} / {np.median(k):.2f} / {np.percentile(k, 90):.2f}" for k in (k0, k2)]
        errors = f"{e0.mean():.3f} | {e2.mean():.3f}"
        lines.append(f"| {r['log']} | {len(k0)} | {cells[0]} | {cells[1]} | {errors} |")
    text = "\n".join(lines) + "\n"
    args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
