"""Where the radish panel's error is, and why candidate closures were refused.

    python benchmarks/radish_panel.py            # first: the runs (cornerslam_out/radish_panel/NAME)
    python benchmarks/panel_diagnostics.py [--work cornerslam_out/radish_panel] [--data DIR]

Per run of the panel: the ATE of the smoothed and of the online (causal) trajectory; the ATE left when
every submap is aligned to the reference on its own (the error *inside* submaps: the rest is between
them); the RMS error of the relative pose of consecutive submap origins (the drift a submap adds). For
the exact-odometry logs also the ATE over the keyframes before the last one whose reference its own
scans refute by more than ``REFUTE_TURN`` (benchmarks/reference_check.py): a front end that follows its
scans cannot follow the reference past it. Over the noisy runs: when the front end first took the
odometer scale error and the heading drift out of an increment, and the heading error its chain had
gathered by then. Over every run: how much its heading error (against the reference) changes over 1,
8 and 64 keyframes, the chain's and the output's (medians) — a random walk's grows with the square
root of the lag, a jitter's does not. Also over the noisy runs: refused candidates by reason and how
many were right (benchmarks/loop_closures.py's rule), and for those refused for low fitness, how many
right and wrong ones a lower ``loops.min_fitness`` would have let through. Diagnostics only: nothing here
feeds back into a default. Writes docs/results/panel_diagnostics.md; deterministic.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from loop_closures import RIGHT_THETA, RIGHT_XY, is_right, origins_truth  # noqa: E402
from radish_panel import BUILDINGS  # noqa: E402
from real_logs import ROOT, default_data  # noqa: E402
from reference_check import check  # noqa: E402

from cornerslam_cli.evaluate import align_se2, align_sim2, apply_se2, interpolate_inside  # noqa: E402
from cornerslam_cli.geometry import relative, wrap_angle  # noqa: E402
from cornerslam_cli.report.tables import read_tum  # noqa: E402

REFUTE_TURN = 5.0  # degrees
REFUTED_WINDOW = 10  # keyframes either side of a refuted one left out of "outside refuted"
FITNESS_STEPS = (0.3, 0.4, 0.45)
LAGS = (1, 8, 64)  # keyframes: how the heading error changes over these many


def aligned_rmse(est: np.ndarray, ref: np.ndarray) -> float:
    """ATE RMSE of ``est`` (n, 3) against ``ref`` after the best SE(2) alignment of the positions."""
    if len(est) < 3:
        return 0.0
    moved = apply_se2(*align_se2(est[:, :2], ref[:, :2]), est)[:, :2]
    return float(np.sqrt(np.mean(np.sum((moved - ref[:, :2]) ** 2, axis=1))))


def trajectory(run: Path, gt: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The run's smoothed poses, submap per step and the reference (NaN rows outside it), per step."""
    stamps, est = read_tum(run / "trajectory.tum")
    with open(run / "trajectory.csv") as f:
        sub = np.array([int(r["submap"]) for r in csv.DictReader(f)])
    inside, g = interpolate_inside(*read_tum(gt), stamps)
    ref = np.full((len(stamps), 3), np.nan)
    ref[inside] = g
    return est, sub, ref


def against_reference(run: Path, name: str, gt: Path) -> tuple[np.ndarray, np.ndarray]:
    """``run``'s poses in ``name`` (a TUM file) where the reference covers them, and the reference there."""
    stamps, est = read_tum(run / name)
    inside, ref = interpolate_inside(*read_tum(gt), stamps)
    return est[inside], ref


def scaled_rmse(est: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    """Scale of the best similarity of ``est`` (n, 3) onto ``ref`` (> 1: est is smaller) and the ATE
    RMSE after it (evaluate.align_sim2)."""
    scale, ang, t = align_sim2(est[:, :2], ref[:, :2])
    moved = apply_se2(ang, t, np.column_stack((scale * est[:, :2], est[:, 2])))[:, :2]
    return scale, float(np.sqrt(np.mean(np.sum((moved - ref[:, :2]) ** 2, axis=1))))


def refuted_stamps(exact_run: Path, refuted: list[int]) -> np.ndarray:
    """Stamps of the exact-odometry run's keyframes ``refuted`` (indices: its steps, reference_check's k)."""
    with open(exact_run / "trajectory.csv") as f:
        stamps = np.array([float(r["stamp"]) for r in csv.DictReader(f)])
    return stamps[refuted]


def errors(run: Path, gt: Path, last_good: int | None = None, refuted: np.ndarray | None = None) -> dict:
    est, sub, ref = trajectory(run, gt)
    ok = ~np.isnan(ref[:, 0])
    within = np.zeros(len(est))
    for s in np.unique(sub):
        m = ok & (sub == s)
        within[m] = 0.0 if m.sum() < 3 else aligned_rmse(est[m], ref[m])
    first = [int(np.argmax(sub == s)) for s in np.unique(sub)]
    pairs = [(i, j) for i, j in zip(first[:-1], first[1:], strict=True) if ok[i] and ok[j]]
    d = np.array([relative(est[i], est[j]) - relative(ref[i], ref[j]) for i, j in pairs]).reshape(-1, 3)
    d[:, 2] = wrap_angle(d[:, 2])
    summary = json.loads((run / "summary.json").read_text())["accuracy"]
    row = {
        "ate": aligned_rmse(est[ok], ref[ok]),
        "online": summary["online_ate"]["rmse"],
        "within": float(np.sqrt(np.mean(within[ok] ** 2))),
        "origin_xy": float(np.sqrt(np.mean(np.sum(d[:, :2] ** 2, axis=1)))) if len(d) else float("nan"),
        "origin_deg": float(np.degrees(np.sqrt(np.mean(d[:, 2] ** 2)))) if len(d) else float("nan"),
    }
    row["scale"], row["ate_scaled"] = scaled_rmse(est[ok], ref[ok])
    if last_good is not None:
        keep = ok & (np.arange(len(est)) < last_good)
        row["before_refuted"] = aligned_rmse(est[keep], ref[keep])
    if refuted is not None and len(refuted):
        stamps, _ = read_tum(run / "trajectory.tum")
        near = np.zeros(len(est), dtype=bool)
        for k in np.searchsorted(stamps, refuted):
            near[max(k - REFUTED_WINDOW, 0) : k + REFUTED_WINDOW + 1] = True
        row["outside_refuted"] = aligned_rmse(est[ok & ~near], ref[ok & ~near])
    return row


def bias_taken(run: Path, gt: Path) -> dict:
    """When ``run``'s front end first took the odometer scale error and the heading drift out of an
    increment (summary.json odometry_model: the steps; None: never), the terms at the
    end, and its chain's (scan_matched.tum) heading error against the reference — the turn since the
    first keyframe less the reference's — just before the drift was taken and its rate after (° per 100
    keyframes)."""
    model = json.loads((run / "summary.json").read_text())["odometry_model"]
    if "scale_error_from_keyframe" not in model and model["odom_scale_error"] != 0.0:
        sys.exit(f"{run}: summary.json predates odometry_model.*_from_keyframe: re-run radish_panel.py")
    chain, ref = against_reference(run, "scan_matched.tum", gt)
    turn = wrap_angle((chain[:, 2] - chain[0, 2]) - (ref[:, 2] - ref[0, 2]))
    heading = np.degrees(np.unwrap(turn))
    k = model.get("heading_drift_from_keyframe")
    row = {
        "scale_from": model.get("scale_error_from_keyframe"),
        "drift_from": k,
        "scale": model["odom_scale_error"],
        "drift": model["heading_drift_per_m"],
        "n": len(heading),
    }
    if k is not None and 1 <= k < len(heading) - 1:
        row["before"] = float(heading[k - 1])
        row["rate_before"] = 100.0 * float(heading[k - 1]) / max(k - 1, 1)
        row["rate_after"] = 100.0 * float(heading[-1] - heading[k - 1]) / (len(heading) - k)
    return row


def heading_lags(run: Path, gt: Path, name: str) -> list[float]:
    """Median size (°) of the change of ``run``'s ``name`` (a TUM file) heading error against the
    reference over each of LAGS keyframes: the error's turn from keyframe i to i + L less the
    reference's. The median, not the RMS: the few keyframes whose reference its scans refute by 10–20°
    (csail, fhw: reference_check.md) would set an RMS."""
    est, ref = against_reference(run, name, gt)
    error = np.unwrap(wrap_angle(est[:, 2] - ref[:, 2]))
    return [float(np.degrees(np.median(np.abs(error[lag:] - error[:-lag])))) for lag in LAGS]


def refusals(run: Path, gt: Path, out: Counter, right: Counter, low: list) -> None:
    """Count ``run``'s refused candidates by reason and the right ones; low fitness: (fitness, right)."""
    origin, _ = origins_truth(run, gt)
    with open(run / "loops.csv") as f:
        for r in csv.DictReader(f):
            if r["accepted"] == "1":
                continue
            ok = is_right(origin, r)
            reason = r["reason"].split("(")[0].strip()
            out[reason] += 1
            right[reason] += ok
            if reason == "low fitness":
                low.append((float(r["fitness"]), ok))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=default_data())
    ap.add_argument("--work", type=Path, default=ROOT / "cornerslam_out" / "radish_panel")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "panel_diagnostics.md")
    args = ap.parse_args()
    radish = args.data / "radish"
    lines = [
        "# Where the panel's error is, and why closures were refused",
        "",
        "`python benchmarks/panel_diagnostics.py` over the runs of `benchmarks/radish_panel.py` (see its "
        "docstring). *Inside submaps*: ATE RMSE with every submap aligned to the reference on its own. "
        "*Origins*: RMS error of consecutive submap origins' relative pose. *Scale*: of the best "
        "similarity (Umeyama with scale, evo's `--correct_scale`) of the trajectory onto the reference, "
        "> 1 where ours is the smaller, and the ATE after it: a 2-D laser's trajectory takes its scale "
        "from the ranges, so a scale off 1 is a disagreement between the scans and the reference, not "
        "something to correct. *Before refuted*: exact "
        f"odometry, ATE over the keyframes before the last one whose reference its scans refute by more "
        f"than {REFUTE_TURN:.0f}° (reference_check.py). *Outside refuted*: the ATE (aligned again) "
        f"without the keyframes within {REFUTED_WINDOW} of one whose reference its scans refute "
        "(reference_check.py on the exact twin: same scans and stamps; the keyframes listed).",
        "",
        "| log | ATE (m) | online ATE (m) | inside submaps (m) | origins (cm, °) | scale "
        "| ATE with scale (m) | before refuted (m) | outside refuted (m) |",
        "|---|---:|---:|---:|---|---:|---:|---:|---|",
    ]
    # (k, fit gain, m, °) per keyframe of the exact twin whose reference its scans refute
    refutes = {b: check((radish / f"{b}-exact.log", []))["refuted"] for b in BUILDINGS}
    refuted = {b: [k for k, _, _, _ in refutes[b]] for b in BUILDINGS}
    for variant in ("", "-exact"):
        for b in BUILDINGS:
            name = f"{b}{variant}"
            last_good = None
            if variant:
                turns = [k for k, _, _, deg in refutes[b] if abs(deg) > REFUTE_TURN]
                last_good = max(turns) if turns else None
            stamps = refuted_stamps(args.work / f"{b}-exact", refuted[b])
            r = errors(args.work / name, radish / f"{name}.gt.tum", last_good, stamps)
            before = f"{r['before_refuted']:.3f} (< {last_good})" if "before_refuted" in r else ""
            outside = (
                f"{r['outside_refuted']:.3f} (without {', '.join(map(str, refuted[b]))})"
                if "outside_refuted" in r
                else ""
            )
            lines.append(
                f"| {name} | {r['ate']:.3f} | {r['online']:.3f} | {r['within']:.3f} "
                f"| {100 * r['origin_xy']:.1f}, {r['origin_deg']:.2f} | {r['scale']:.4f} "
                f"| {r['ate_scaled']:.3f} | {before} | {outside} |"
            )
    lines += [
        "",
        "When the front end took the odometry's bias out (noisy runs; summary.json `odometry_model`): "
        "the step (trajectory.csv's) whose increment first had the odometer scale error, the heading "
        "drift taken out (a term is taken once it is 3 standard errors from zero, a scale error once it "
        "is also ≥ 1 %; each log's odometry "
        "was made with +2 % scale and 0.005 rad/m drift), the terms at the end, and the scan-matched chain's "
        "heading error against the reference (its turn since the first keyframe less the reference's) "
        "just before the drift was taken, and its rate before and after (° per 100 keyframes). Until "
        "then the odometry's share of each increment (about a tenth in heading, where the matches are "
        "the sharper) carries the drift into the chain.",
        "",
        "| log | steps | scale taken from step | drift taken from step | scale, drift at the end "
        "| chain heading error before the drift (°) | rate before → after (°/100) |",
        "|---|---:|---:|---:|---|---:|---|",
    ]
    for b in BUILDINGS:
        t = bias_taken(args.work / b, radish / f"{b}.gt.tum")
        before = f"{t['before']:+.2f}" if "before" in t else ""
        rates = f"{t['rate_before']:+.2f} → {t['rate_after']:+.2f}" if "before" in t else ""
        lines.append(
            f"| {b} | {t['n']} | {t['scale_from'] or 'never'} | {t['drift_from'] or 'never'} "
            f"| {100 * t['scale']:+.2f} %, {t['drift']:+.4f} rad/m | {before} | {rates} |"
        )
    lags = " / ".join(map(str, LAGS))
    lines += [
        "",
        "How the heading error builds up: the median size of its change (°) over "
        f"{lags} keyframes, of the scan-matched chain (scan_matched.tum) and of the output "
        "(trajectory.tum), and what a random walk with the chain's 1-keyframe steps would reach over "
        f"{LAGS[-1]} (√{LAGS[-1]} times them). Below that, part of the per-keyframe error does not add "
        "up; what does add up over many keyframes is what closures must take out, and the output's "
        "figure is the smaller where they did.",
        "",
        f"| log | chain over {lags} (°) | output over {lags} (°) | random walk over {LAGS[-1]} (°) |",
        "|---|---|---|---:|",
    ]
    for variant in ("", "-exact"):
        for b in BUILDINGS:
            name = f"{b}{variant}"
            gt = radish / f"{name}.gt.tum"
            chain = heading_lags(args.work / name, gt, "scan_matched.tum")
            output = heading_lags(args.work / name, gt, "trajectory.tum")
            lines.append(
                f"| {name} | {' / '.join(f'{x:.2f}' for x in chain)} "
                f"| {' / '.join(f'{x:.2f}' for x in output)} | {np.sqrt(LAGS[-1]) * chain[0]:.2f} |"
            )
    out, right, low = Counter(), Counter(), []
    for b in BUILDINGS:
        refusals(args.work / b, radish / f"{b}.gt.tum", out, right, low)
    lines += [
        "",
        f"Refused candidates over the noisy runs, and how many were right (within {RIGHT_XY} m / "
        f"{RIGHT_THETA} rad of the reference):",
        "",
        "| reason | refused | right |",
        "|---|---:|---:|",
        *(f"| {k} | {out[k]} | {right[k]} |" for k in sorted(out, key=lambda k: -out[k])),
        "",
        "Refused for low fitness, that a lower `loops.min_fitness` would take:",
        "",
        "| min_fitness | right | wrong |",
        "|---:|---:|---:|",
        *(
            f"| {f} | {sum(x >= f and ok for x, ok in low)} | {sum(x >= f and not ok for x, ok in low)} |"
            for f in FITNESS_STEPS
        ),
    ]
    text = "\n".join(lines) + "\n"
    args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
