"""How was the radish panel's noisy odometry made? Its increments against its exact twin's.

    python benchmarks/radish_odometry.py [--data DIR] [--out FILE]

Each radish building comes as NAME.log (odometry re-made from the reference's increments with seeded
errors) and NAME-exact.log (the reference itself as odometry), with the same ODOM lines. Their
increments' difference is the noisy odometry's error, increment by increment (frame of the previous
pose). Two least-squares fits over each log and pooled over all seven:

- the *heading drift* per metre of the odometry's own path, c_θ (fit of the heading error on L);
- the *sideways step* of that drift: the lateral error fitted as a·c_θ·L·x/2 (plus a scale of y), so
  that a = 1 for an odometry integrated along the path (the heading drifts *during* the increment,
  turning its direction of travel by c_θ·L/2: what motion/fusion.py's model leaves out, and what a
  simulated odometry integrated at 50 Hz has, benchmarks/odometry_regimes.py) and a = 0 for one whose
  drift is added to the heading at the end of each increment. The random heading noise's share in the
  direction of travel is given beside it (≈ 0.5 when split evenly before and after the translation).

A description of the data, used by nothing: it tells which drift model a benchmark on these logs
rewards. Writes docs/results/radish_odometry.md; deterministic.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from radish_panel import BUILDINGS  # noqa: E402
from real_logs import ROOT, default_data  # noqa: E402

from cornerslam_cli.geometry import relative  # noqa: E402


def odom_poses(path: Path) -> np.ndarray:
    """(n, 3) the x, y, θ of the log's ODOM lines, in order."""
    rows = [line.split()[1:4] for line in path.read_text().splitlines() if line.startswith("ODOM ")]
    return np.array(rows, dtype=float)


def increments(poses: np.ndarray) -> np.ndarray:
    return relative(poses[:-1], poses[1:])


def fit(noisy: np.ndarray, exact: np.ndarray) -> dict:
    """The fits of the module docstring on one log's (or the pooled) increments."""
    e = noisy - exact
    e[:, 2] = np.arctan2(np.sin(e[:, 2]), np.cos(e[:, 2]))
    L = np.hypot(exact[:, 0], exact[:, 1])
    c_theta = float(e[:, 2] @ L / (L @ L))
    X = np.column_stack((c_theta * L * exact[:, 0] / 2, exact[:, 1]))
    (a, _), res, *_ = np.linalg.lstsq(X, e[:, 1], rcond=None)
    sigma2 = float(res[0]) / (len(e) - 2) if len(res) else float("nan")
    se_a = float(np.sqrt(sigma2 * np.linalg.inv(X.T @ X)[0, 0]))
    share = float((e[:, 2] * exact[:, 0]) @ e[:, 1] / ((e[:, 2] * exact[:, 0]) @ (e[:, 2] * exact[:, 0])))
    return {"n": len(e), "c_theta": c_theta, "a": float(a), "se_a": se_a, "share": share}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=None)
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "radish_odometry.md")
    args = ap.parse_args()
    radish = (args.data or default_data()) / "radish"
    rows, pooled = [], ([], [])
    for name in BUILDINGS:
        noisy, exact = odom_poses(radish / f"{name}.log"), odom_poses(radish / f"{name}-exact.log")
        if len(noisy) != len(exact):
            raise SystemExit(f"{name}: {len(noisy)} ODOM lines against {len(exact)} in its exact twin")
        n, x = increments(noisy), increments(exact)
        rows.append((name, fit(n, x)))
        pooled[0].append(n)
        pooled[1].append(x)
    rows.append(("pooled", fit(np.vstack(pooled[0]), np.vstack(pooled[1]))))
    lines = [
        "# The radish panel's noisy odometry, increment by increment",
        "",
        "`python benchmarks/radish_odometry.py` (see its docstring): each noisy log's ODOM increments "
        "against its exact twin's. *Sideways step*: the lateral error as a multiple of c_θ·L·x/2 "
        "(1: the drift acts along the increment, as in an odometry integrated along the path; 0: it is "
        "added at the end of each increment), ± its standard error. *Noise share*: the random heading "
        "error's share in the direction of travel. Deterministic.",
        "",
        "| log | increments | heading drift c_θ (rad/m) | sideways step (× c_θ·L·x/2) | noise share |",
        "|---|---:|---:|---|---:|",
    ]
    for name, r in rows:
        lines.append(
            f"| {name} | {r['n']} | {r['c_theta']:.5f} | {r['a']:.2f} ± {r['se_a']:.2f} | {r['share']:.2f} |"
        )
    args.out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
