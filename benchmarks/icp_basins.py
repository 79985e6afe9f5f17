"""Where ICP ends when started a few centimetres apart: the roughness of its cost along the travel.

    python benchmarks/icp_basins.py [--data DIR] [--log edmonton] [--keyframes 12] [--out FILE]

The front end registers each keyframe's scan on a local map of the keyframes before it (motion/icp.py).
For the first ``--keyframes`` keyframes of a radish log (default config) this records each registration
the run made from the odometry's guess (its scan, its map, the guess, the pose ICP ended on) and runs
ICP again on the same scan and map from ``STARTS`` poses spread ±``SPREAD`` m along the heading around
the pose it ended on: on a smooth cost every start ends on the same pose; on a rough one, on several.
Per keyframe: the range (max − min) of the end poses along the heading, with the map as the front end
builds it (*plain*: a residual is the distance to the line through the nearest map point along that
point's normal) and with each map point moved onto the total-least-squares line of its 5 nearest
neighbours (*line-fitted*: the residual is then the distance to the neighbours' line, and does not jump by
the range noise when the nearest point changes from one neighbour to the next; branch ``surfel`` did
this in the front end — not adopted, README). Deterministic; writes ``docs/results/icp_basins.md``.
"""

from __future__ import annotations

import argparse
import dataclasses
import pickle
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _baseline import child_json, revision  # noqa: E402
from real_logs import ROOT, default_data  # noqa: E402

from cornerslam_cli.motion.icp import NORMAL_NEIGHBOURS, LocalMap, register  # noqa: E402
from cornerslam_cli.motion.params import ScanMatchConfig  # noqa: E402

STARTS = 9
SPREAD = 0.1  # m either way along the heading

# One run in a child process: the first registration of each of the first keyframes, pickled.
CHILD = r"""
import json, pickle, sys
from cornerslam_cli.cli import main
from cornerslam_cli.motion import icp

log, out, last = sys.argv[1], sys.argv[2], int(sys.argv[3])
calls, at = {}, {"step": 0}
register, step = icp.register, icp.ScanMatcher.step

def recorded(points, local, start, cfg, prior=None):
    reg = register(points, local, start, cfg, prior)
    if prior is None and 0 < at["step"] <= last and at["step"] not in calls:  # from the odometry's guess
        calls[at["step"]] = (points.copy(), local.points.copy(), start.copy(), reg.pose.copy())
    return reg

def stepped(self, points, odom):
    at["step"] = self.fusion.n_steps + 1 if self.pose is not None else 0
    return step(self, points, odom)

icp.register, icp.ScanMatcher.step = recorded, stepped
if rc := main(["run", log, "--out", out, "-q"], standalone_mode=False):
    sys.exit(rc)  # (click returns a failed run's exit code here: not a record of a whole run)
pickle.dump(calls, open(out + "/calls.pkl", "wb"))
print(json.dumps(out + "/calls.pkl"))
"""


def line_fitted(local: LocalMap) -> LocalMap:
    """``local`` with each map point that has a normal moved onto the line through its 5 nearest
    neighbours' mean along that normal (the residuals' points; the grid and normals unchanged)."""
    _, idx = local.grid.neighbours(NORMAL_NEIGHBOURS)
    mean = local.points[idx].mean(axis=1)
    off = np.einsum("ij,ij->i", local.normals, local.points - mean)
    moved = np.where(local.has_normal[:, None], local.points - off[:, None] * local.normals, local.points)
    return dataclasses.replace(local, padded_points=np.vstack((moved, np.zeros((1, 2)))))


def ends(points, local: LocalMap, guess, pose, cfg: ScanMatchConfig) -> np.ndarray:
    """Where ICP ends, along the heading of ``pose`` and relative to it, from STARTS starts ±SPREAD m
    along that heading (the prior stays the odometry's ``guess``, as in the run)."""
    u = np.array([np.cos(pose[2]), np.sin(pose[2])])
    out = []
    for d in np.linspace(-SPREAD, SPREAD, STARTS):
        start = pose + np.array([d * u[0], d * u[1], 0.0])
        end = register(points, local, start, cfg, prior=guess).pose
        out.append(float((end[:2] - pose[:2]) @ u))
    return np.array(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=default_data())
    ap.add_argument("--log", default="edmonton")
    ap.add_argument("--keyframes", type=int, default=12)
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "icp_basins.md")
    args = ap.parse_args()
    log = args.data / "radish" / f"{args.log}.log"
    with tempfile.TemporaryDirectory() as tmp:
        record = child_json(CHILD, str(log), tmp, str(args.keyframes), what=log.name)
        calls = pickle.loads(Path(record).read_bytes())
    cfg = ScanMatchConfig()
    lines = [
        "# Where ICP ends from starts a few centimetres apart",
        "",
        f"`python benchmarks/icp_basins.py --log {args.log} --keyframes {args.keyframes}` at {revision()} "
        f"(see its docstring): keyframes 1–{args.keyframes} of {args.log} (default config), each keyframe's "
        f"registration from the odometry's guess run again from {STARTS} starts ±{SPREAD:g} m along the "
        "heading around the pose it ended on. *Range*: max − min of where they end along the heading (cm); "
        "*σ*: ICP's own standard deviation there (cm, its covariance at the pose, before the fusion scales "
        "it by its learnt s); *ends*: each start's end relative to the run's pose (cm, starts from −, "
        "behind, to +). Deterministic.",
        "",
        "| keyframe | ICP's σ along the heading | plain: range | plain: ends | line-fitted: range "
        "| line-fitted: ends |",
        "|---:|---:|---:|---|---:|---|",
    ]
    within = {"plain": 0, "line": 0}
    for k in sorted(calls):
        points, map_points, guess, pose = calls[k]
        local = LocalMap.build(map_points)
        a = ends(points, local, guess, pose, cfg)
        u = np.array([np.cos(pose[2]), np.sin(pose[2])])
        sigma = float(np.sqrt(u @ register(points, local, pose, cfg, prior=guess).cov[:2, :2] @ u))
        b = ends(points, line_fitted(local), guess, pose, cfg)
        within["plain"] += np.ptp(a) <= 0.03
        within["line"] += np.ptp(b) <= 0.03
        lines.append(
            f"| {k} | {100 * sigma:.1f} | {100 * np.ptp(a):.1f} | {' '.join(f'{100 * v:+.1f}' for v in a)} "
            f"| {100 * np.ptp(b):.1f} | {' '.join(f'{100 * v:+.1f}' for v in b)} |"
        )
    lines += [
        "",
        f"Keyframes whose starts all end within 3 cm of each other: plain {within['plain']} of {len(calls)}, "
        f"line-fitted {within['line']} of {len(calls)}.",
    ]
    args.out.write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
