"""Loop closures of the radish panel against the reference: how many were right, how many wrong.

    python benchmarks/radish_panel.py            # first: the runs (cornerslam_out/radish_panel/NAME)
    python benchmarks/loop_closures.py [--work cornerslam_out/radish_panel]

For every run of the panel with submaps (noisy and exact odometry), each row of its loops.csv is
compared with the reference: the true relative pose of the two submap origins (submap s's origin is
the robot's pose at the last step of submap s − 1; submap 0's, at step 0), the reference interpolated at
those steps' stamps. A closure is *right* when it is within ``RIGHT_XY`` / ``RIGHT_THETA`` of it.
Diagnostics only: nothing here feeds back into a default. Writes docs/results/loop_closures.md.
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from radish_panel import BUILDINGS  # noqa: E402
from real_logs import ROOT, default_data  # noqa: E402

from cornerslam_cli.evaluate import interpolate_inside  # noqa: E402
from cornerslam_cli.geometry import relative, wrap_angle  # noqa: E402
from cornerslam_cli.report.tables import read_tum  # noqa: E402

RIGHT_XY, RIGHT_THETA = 0.5, 0.1  # m, rad
NEAR = 3.0  # m: two submap origins this close (truly) should be a candidate pair


def origins_truth(run: Path, gt: Path) -> tuple[dict[int, np.ndarray], int]:
    """The true pose of each submap's origin (NaN outside the reference) and the number of submaps."""
    with open(run / "trajectory.csv") as f:
        rows = list(csv.DictReader(f))
    stamps = np.array([float(r["stamp"]) for r in rows])
    sub = np.array([int(r["submap"]) for r in rows])
    inside, g = interpolate_inside(*read_tum(gt), stamps)
    truth = np.full((len(stamps), 3), np.nan)
    truth[inside] = g
    first = {int(s): int(np.argmax(sub == s)) for s in np.unique(sub)}
    return {s: truth[max(k - 1, 0)] for s, k in first.items()}, len(first)


def is_right(origin: dict[int, np.ndarray], row: dict) -> bool:
    """Whether a loops.csv ``row``'s pose is within RIGHT_XY / RIGHT_THETA of the true relative pose of
    its two submap origins (``origin``: :func:`origins_truth`)."""
    true = relative(origin[int(row["other_submap"])], origin[int(row["submap"])])
    got = np.array([float(row[k]) for k in ("dx", "dy", "dtheta")])
    return bool(
        np.hypot(*(true[:2] - got[:2])) < RIGHT_XY and abs(wrap_angle(true[2] - got[2])) < RIGHT_THETA
    )


def score(run: Path, gt: Path) -> dict:
    origin, n_sub = origins_truth(run, gt)
    with open(run / "loops.csv") as f:
        loops = list(csv.DictReader(f))
    out = {"submaps": n_sub, "verified": len(loops), "accepted": 0, "wrong": 0, "refused_right": 0}
    tried = set()
    for r in loops:
        a, b = int(r["other_submap"]), int(r["submap"])
        tried.add((a, b))
        right = is_right(origin, r)
        if r["accepted"] == "1":
            out["accepted"] += 1
            out["wrong"] += not right
        else:
            out["refused_right"] += right
    near = [
        (a, b)
        for b in range(n_sub)
        for a in range(b - 1)
        if np.hypot(*(origin[a][:2] - origin[b][:2])) < NEAR
    ]
    out["near"] = len(near)
    out["near_tried"] = sum(p in tried for p in near)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=default_data())
    ap.add_argument("--work", type=Path, default=ROOT / "cornerslam_out" / "radish_panel")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "loop_closures.md")
    args = ap.parse_args()
    lines = [
        "# Loop closures on the radish panel, against the reference",
        "",
        "From `python benchmarks/loop_closures.py` over the runs of `benchmarks/radish_panel.py` (default "
        f"config). A closure is right within {RIGHT_XY} m / {RIGHT_THETA} rad of the reference's relative "
        "pose of the two submap origins. *verified*: candidate pairs matched (loops.csv rows); *refused "
        f"but right*: a refused candidate whose pose was right; *near pairs*: submaps whose true origins are "
        f"within {NEAR} m (at least one submap apart), and how many of them were candidates.",
        "",
        "| log | submaps | verified | accepted | accepted and wrong | refused but right | near pairs "
        "| of them candidates |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    total = {"accepted": 0, "wrong": 0}
    for name in [f"{b}{v}" for v in ("", "-exact") for b in BUILDINGS]:
        run = args.work / name
        if not (run / "loops.csv").is_file():
            raise SystemExit(f"{run / 'loops.csv'} not found: run benchmarks/radish_panel.py first")
        s = score(run, args.data / "radish" / f"{name}.gt.tum")
        total["accepted"] += s["accepted"]
        total["wrong"] += s["wrong"]
        lines.append(
            f"| {name} | {s['submaps']} | {s['verified']} | {s['accepted']} | {s['wrong']} | "
            f"{s['refused_right']} | {s['near']} | {s['near_tried']} |"
        )
        print(name, s, flush=True)
    lines += ["", f"In all: {total['accepted']} closures accepted, {total['wrong']} of them wrong.", ""]
    args.out.write_text("\n".join(lines))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
