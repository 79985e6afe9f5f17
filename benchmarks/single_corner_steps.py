"""Steps where one matched corner turns the filter's heading away from the scan-matched chain.

    python benchmarks/single_corner_steps.py LOG [--config FILE] [--set K=V]... [--steps 127,454]
                                             [--json OUT.json] [--variant none|handed|verify|skip]

A diagnostic (nothing here changes the library or a default): the run of ``cornerslam run`` with its
stages observed by patching them in this process —
the extractor's corner kinds, the fusion's inputs (odometry increment and its model covariance, the
scan match and its fit covariance, the learnt scales) and the final motion covariance of each frame,
and every EKF update's pre-update state. Prints, per log:

* the motion input's heading σ per step (Frame.motion_cov) against the step-to-step heading
  disagreement of the chain with the odometry, and the learnt odometry model;
* every step with exactly one matched corner whose filter heading increment departs > 1° from the
  chain's: the corner (kind, position, covariance), its landmark (sightings before, from where), the
  innovation, D², the gain's heading row, and which increment the later scans agree with (scans
  k..k+``AFTER`` placed after the step against scans k−``BEFORE``..k−1, with the filter's increment
  or the chain's at step k); with a reference (LOG.gt.tum) also the reference's increment;
* ``--steps``: the full record of those steps.

``--variant`` (experiments, not defaults): ``handed`` refuses a pair whose corner lies on the other side
of its walls than the landmark did when it was created (``corner_sides``: a mirror image that φ cannot
tell); ``skip`` never updates the filter with a single matched pair;
``verify`` keeps a single pair's update only when the scan's points fit the open submap's earlier
points no worse (``VERIFY_MARGIN``) at the updated pose than at the predicted one, else restores the
filter and drops the pair. Findings: docs/results/single_corner_steps.md.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parent))

import cornerslam_cli.frontend as fe  # noqa: E402
import cornerslam_cli.slam as slam_module  # noqa: E402
from cornerslam_cli.filter.ekf import Ekf  # noqa: E402
from cornerslam_cli.filter.models import observe_one  # noqa: E402
from cornerslam_cli.geometry import compose, relative, wrap_angle  # noqa: E402
from cornerslam_cli.hierarchy import HierarchicalSlam  # noqa: E402
from cornerslam_cli.lasers import resolve_config  # noqa: E402
from cornerslam_cli.motion.fusion import OdometryFusion  # noqa: E402
from cornerslam_cli.motion.icp import ScanMatcher  # noqa: E402
from cornerslam_cli.pipeline import run_filter  # noqa: E402
from cornerslam_cli.report.run_writer import load_reference  # noqa: E402
from cornerslam_cli.report.tables import read_tum  # noqa: E402

THRESHOLD = np.radians(1.0)  # a single-corner step "turns" the heading when it departs this much
BEFORE, AFTER = 60, 30  # scans: the past the later scans are held against; the later scans
CAP = 0.3  # m: nearest-point distances capped here (the revisit metric's cap)
VERIFY_MARGIN = 0.005  # m: the variant "verify" keeps a one-pair update that fits the scan this much worse


class Observer:
    """What the patched stages saw, by step."""

    def __init__(self, variant: str = "none"):
        self.variant = variant  # "none", "handed", "verify" or "skip" (the module docstring)
        self.n_reverted = 0  # pairs the variant refused or whose update it dropped
        self.cur_points: np.ndarray | None = None
        self.cur_sub = None
        self.laser2base = np.zeros(3)
        self.step = -1
        self.submap = 0
        self.kinds: dict[float, np.ndarray] = {}
        self.sides: dict[float, np.ndarray] = {}  # per scan: each corner's side (corner_sides), sensor frame
        self.cur_sides: np.ndarray | None = None  # the current frame's, base frame
        self.cur_slam = None
        self.new_sides: np.ndarray | None = None  # the sides of the corners the step will augment
        self.landmark_side: dict[tuple[int, int], float] = {}  # (submap, id): its side, submap frame
        self.frames: list[dict] = []
        self.updates: dict[int, dict] = {}
        self.sightings: dict[tuple[int, int], list[tuple[int, np.ndarray, np.ndarray]]] = {}
        self._fuse = None

    def install(self):
        obs = self
        extract0, scan_matched0 = fe.extract, fe._scan_matched
        fuse0, fallback0 = OdometryFusion.fuse, ScanMatcher._fallback
        update0, augment0, hstep0 = Ekf.update, Ekf.augment, HierarchicalSlam.step
        make0 = slam_module.make_associator

        def extract(scan, *a, **k):
            segments, corners = extract0(scan, *a, **k)
            obs.kinds[scan.stamp] = corners.kind.copy()
            obs.sides[scan.stamp] = corner_sides(segments, corners)
            return segments, corners

        def scan_matched(frame, scan, matcher, laser2base):
            obs._fuse = None
            out = scan_matched0(frame, scan, matcher, laser2base)
            rec = {"stamp": frame.stamp, "odom": frame.odom.copy(), "motion_cov": out.motion_cov,
                   "matched": out.scan_matched, "fit": out.scan_fit, "points": frame.points,
                   "kinds": obs.kinds.pop(frame.stamp, None), "z": frame.z.copy(), "fuse": obs._fuse,
                   "k": matcher.fusion.k, "s": matcher.fusion.s, "c": matcher.fusion.c.copy()}  # fmt: skip
            obs.frames.append(rec)
            return out

        def fuse(self, o, cov_o, m, cov_m, prefer=None):
            r = fuse0(self, o, cov_o, m, cov_m, prefer)
            obs._fuse = {"o": o.copy(), "cov_o": cov_o.copy(), "m": m.copy(), "cov_m": cov_m.copy(),
                         "inc": r.inc.copy(), "cov": r.cov.copy(), "accepted": r.accepted}  # fmt: skip
            return r

        def fallback(self, o, cov_o, fit, searched=False):
            obs._fuse = {"o": o.copy(), "cov_o": cov_o.copy(), "fallback": True}
            return fallback0(self, o, cov_o, fit, searched)

        def update(self, ids, z, C):
            ids = np.asarray(ids, dtype=np.int64)
            mu, P = self.mu.copy(), self.P.copy()
            pairs = []
            for i, zi, Ci in zip(ids.tolist(), np.asarray(z), np.asarray(C), strict=True):
                cols = [0, 1, 2, 3 + 3 * i, 4 + 3 * i, 5 + 3 * i]
                h, H6 = observe_one(mu[:3], mu[3 + 3 * i : 6 + 3 * i])
                H = np.zeros((3, len(mu)))
                H[:, cols] = H6
                S = H @ P @ H.T + Ci
                nu = zi - h
                nu[2] = wrap_angle(nu[2])
                K = P @ H.T @ np.linalg.inv(S)
                pairs.append({"id": i, "z": zi.copy(), "C": Ci.copy(), "h": h, "nu": nu,
                              "S": S, "d2": float(nu @ np.linalg.solve(S, nu)), "K_theta": K[2].copy(),
                              "landmark": mu[3 + 3 * i : 6 + 3 * i].copy(),
                              "P_ll": P[3 + 3 * i : 6 + 3 * i, 3 + 3 * i : 6 + 3 * i].copy(),
                              "P_rl": P[:3, 3 + 3 * i : 6 + 3 * i].copy(),
                              "seen": list(obs.sightings.get((obs.submap, i), []))})  # fmt: skip
            if len(ids) == 1 and obs.variant == "skip":
                obs.n_reverted += 1
                return 0.0
            d = self._dim
            mu_buf, P_buf, n_obs = self._mu_buf.copy(), self._P_buf[:d, :d].copy(), self._n_obs.copy()
            out = update0(self, ids, z, C)
            if len(ids) == 1 and obs.variant == "verify" and not obs.scans_agree(mu[:3], self.mu[:3]):
                self._mu_buf[:] = mu_buf
                self._P_buf[:d, :d] = P_buf
                self._n_obs[:] = n_obs
                obs.n_reverted += 1
                return 0.0
            obs.updates[obs.step] = {"pose_before": mu[:3], "P_rr": P[:3, :3], "pairs": pairs,
                                     "pose_after": self.mu[:3].copy()}  # fmt: skip
            for i, zi in zip(ids.tolist(), np.asarray(z), strict=True):
                obs.sightings.setdefault((obs.submap, i), []).append(
                    (obs.step, self.mu[:3].copy(), zi.copy())
                )
            return out

        def augment(self, z, C):
            new = augment0(self, z, C)
            sides = obs.new_sides if obs.new_sides is not None and len(obs.new_sides) == len(new) else None
            for j, (i, zi) in enumerate(zip(np.asarray(new).tolist(), np.asarray(z), strict=True)):
                obs.sightings[(obs.submap, i)] = [(obs.step, self.mu[:3].copy(), zi.copy())]
                if sides is not None:
                    obs.landmark_side[(obs.submap, i)] = float(sides[j] + self.mu[2])
            return new

        def hstep(self, frame):
            obs.step, obs.submap = self.slam.n_steps, self._open.index
            obs.cur_points, obs.cur_sub = frame.points, self._open
            obs.laser2base = np.asarray(self.laser2base)
            side = obs.sides.pop(frame.stamp, None)
            obs.cur_sides = None if side is None else side + self.laser2base[2]
            obs.cur_slam = self.slam
            return hstep0(self, frame)

        def make(cfg):
            assoc = make0(cfg)

            def associate(z, C, pred):
                r = assoc(z, C, pred)
                return obs.handed(r) if obs.variant == "handed" else obs.keep_sides(r)

            return associate

        fe.extract, fe._scan_matched, slam_module.make_associator = extract, scan_matched, make
        OdometryFusion.fuse, ScanMatcher._fallback = fuse, fallback
        Ekf.update, Ekf.augment, HierarchicalSlam.step = update, augment, hstep

    def keep_sides(self, r):
        """Note the sides of the corners the step will augment (those ``r`` left unmatched)."""
        self.new_sides = None if self.cur_sides is None else self.cur_sides[r.pairs < 0]
        return r

    def handed(self, r):
        """``r`` without the pairs whose corner and landmark lie on opposite sides: the corner's side
        in the submap (robot heading + its side in the base frame) more than 90° from the side the
        landmark was created with (a mirror image: the other jamb of a door, the same angle opening the
        other way). Those corners become new landmarks."""
        if self.cur_sides is not None:
            heading = float(self.cur_slam.ekf.pose[2])
            pairs = r.pairs.copy()
            for m, i in enumerate(pairs.tolist()):
                side = self.landmark_side.get((self.submap, i))
                if i >= 0 and side is not None:
                    if abs(wrap_angle(self.cur_sides[m] + heading - side)) > 0.5 * np.pi:
                        pairs[m] = -1
                        self.n_reverted += 1
            r = dataclasses.replace(r, pairs=pairs, d2=np.where(pairs >= 0, r.d2, np.nan))
        return self.keep_sides(r)

    def scans_agree(self, before: np.ndarray, after: np.ndarray) -> bool:
        """The scan's points fit the open submap's earlier points (its frame) no worse at pose
        ``after`` than at ``before``: mean nearest-point distance, capped at CAP, within
        ``VERIFY_MARGIN``; no points to judge by: True."""
        sub = self.cur_sub
        if self.cur_points is None or sub is None or not sub.points:
            return True
        tree = cKDTree(np.concatenate(sub.points))
        pts = self.cur_points.astype(float)

        def score(pose):
            lp = compose(pose, self.laser2base)
            c, s = np.cos(lp[2]), np.sin(lp[2])
            d, _ = tree.query(pts @ np.array([[c, s], [-s, c]]) + lp[:2], distance_upper_bound=CAP)
            return float(np.minimum(d, CAP).mean())

        return score(after) <= score(before) + VERIFY_MARGIN


def run(log: Path, config: str | None, sets: list[str], variant: str = "none") -> tuple[Observer, dict]:
    obs = Observer(variant)
    obs.install()
    cfg = resolve_config(log, config, sets)
    src = fe.open_input(log, cfg)
    with tempfile.TemporaryDirectory() as tmp:
        dest = Path(tmp)
        run_filter(fe.frames(src, cfg), src, cfg, dest, load_reference(log), time.perf_counter())
        stamps, out = read_tum(dest / "trajectory.tum")
        files = {"stamps": stamps, "output": out, "chain": read_tum(dest / "scan_matched.tum")[1],
                 "odometry": read_tum(dest / "odometry.tum")[1]}  # fmt: skip
        with open(dest / "trajectory.csv") as f:
            rows = list(csv.DictReader(f))
        files["online"] = np.array([[float(r[f"online_{k}"]) for k in ("x", "y", "theta")] for r in rows])
        files["submap"] = np.array([int(r["submap"]) for r in rows])
        files["summary"] = json.loads((dest / "summary.json").read_text())
    files["laser2base"] = np.asarray(src.laser2base, dtype=float)
    gt = log.with_name(log.name.split(".")[0] + ".gt.tum")
    if gt.exists():
        from frontend_panel import reference

        files["reference"] = reference(log, log.parent, stamps)
    return obs, files


def agreement(obs: Observer, poses: np.ndarray, laser2base: np.ndarray, k: int) -> float:
    """Mean capped nearest-point distance of scans k..k+AFTER to scans k−BEFORE..k−1 (laser poses
    = base ``poses`` ∘ mount)."""
    lp = compose(poses, laser2base)

    def placed(i):
        p = obs.frames[i]["points"].astype(float)
        c, s = np.cos(lp[i, 2]), np.sin(lp[i, 2])
        return p @ np.array([[c, s], [-s, c]]) + lp[i, :2]

    past = np.vstack([placed(i) for i in range(max(0, k - BEFORE), k)])
    later = np.vstack([placed(i) for i in range(k, min(len(poses), k + AFTER))])
    d, _ = cKDTree(past).query(later, distance_upper_bound=CAP)
    return float(np.minimum(d, CAP).mean())


def corner_sides(segments, corners) -> np.ndarray:
    """(m,) each corner's side, sensor frame (rad): the direction from the corner into the wall(s) that
    make it — towards its segment's middle (end point), the bisector of its two segments' directions
    (intersection). φ, the angle between the lines, is the same for a corner and its mirror image; the
    side is not."""
    out = np.zeros(len(corners))
    for m in range(len(corners)):
        v = np.zeros(2)
        for j in corners.segs[m]:
            if j >= 0:
                d = 0.5 * (segments.p1[j] + segments.p2[j]) - corners.z[m, :2]
                v += d / max(np.hypot(*d), 1e-9)
        out[m] = np.arctan2(v[1], v[0])
    return out


def nearest(zs: np.ndarray, z: np.ndarray) -> int:
    """Index of the corner of ``zs`` (m, 3) that is ``z``."""
    return int(np.argmin(np.abs(zs - z).sum(axis=1)))


def with_increment(poses: np.ndarray, k: int, inc: np.ndarray) -> np.ndarray:
    """``poses`` with the increment into step k replaced by ``inc`` (the later increments kept)."""
    incs = relative(poses[:-1], poses[1:])
    incs[k - 1] = inc
    out = [poses[0]]
    for d in incs:
        out.append(compose(out[-1], d))
    return np.array(out)


def analyse(obs: Observer, files: dict, detail: list[int]) -> dict:
    chain, online, output = files["chain"], files["online"], files["output"]
    n = len(chain)
    inc = {k: relative(v[:-1], v[1:]) for k, v in (("chain", chain), ("online", online), ("output", output),
                                                    ("odometry", files["odometry"]))}  # fmt: skip
    if "reference" in files:
        inc["reference"] = relative(files["reference"][:-1], files["reference"][1:])
    sig = np.array([np.sqrt(f["motion_cov"][2, 2]) if f["motion_cov"] is not None else np.nan
                    for f in obs.frames])  # fmt: skip
    d_co = wrap_angle(inc["chain"][:, 2] - inc["odometry"][:, 2])
    res = {"steps": n, "odometry_model": files["summary"].get("odometry_model"),
           "revisit": files["summary"]["consistency"]["revisit_mean"],
           "motion_sigma_theta_deg": {"median": float(np.degrees(np.nanmedian(sig[1:]))),
                                      "rms": float(np.degrees(np.sqrt(np.nanmean(sig[1:] ** 2))))},
           "chain_minus_odometry_deg": {"median_abs": float(np.degrees(np.median(np.abs(d_co)))),
                                        "rms": float(np.degrees(np.sqrt(np.mean(d_co**2))))}}  # fmt: skip
    fused = [(f["fuse"], f["k"], f["s"]) for f in obs.frames if f["fuse"] is not None and "m" in f["fuse"]]
    if fused:  # the two sources' heading σ as the fusion weighed them (learnt scales at that step)
        med = lambda v: float(np.degrees(np.median(np.sqrt(v))))  # noqa: E731
        res["fusion_sigma_theta_deg"] = {
            "odometry_k": med([k * u["cov_o"][2, 2] for u, k, _ in fused]),
            "match_s": med([s * u["cov_m"][2, 2] for u, _, s in fused]),
            "match_fit_raw": med([u["cov_m"][2, 2] for u, _, _ in fused]),
            "fused": med([u["cov"][2, 2] for u, _, _ in fused]),
            "accepted": int(sum(u["accepted"] for u, _, _ in fused)),
            "n": len(fused),
        }
    if "reference" in inc:
        e = wrap_angle(inc["chain"][:, 2] - inc["reference"][:, 2])
        res["chain_heading_error_deg"] = {
            "median_abs": float(np.degrees(np.median(np.abs(e)))),
            "rms": float(np.degrees(np.sqrt(np.mean(e**2)))),
        }
        res["chain_heading_nees"] = float(np.mean(e**2 / sig[1:] ** 2))
    k_sub = files["submap"]
    first_of_submap = np.r_[True, k_sub[1:] != k_sub[:-1]]
    rows = []
    for k in range(1, n):
        u = obs.updates.get(k)
        if u is None or len(u["pairs"]) != 1 or first_of_submap[k]:
            continue
        dth = {w: float(wrap_angle(inc[w][k - 1, 2] - inc["chain"][k - 1, 2])) for w in ("online", "output")}
        if abs(dth["online"]) <= THRESHOLD and k not in detail:
            continue
        p = u["pairs"][0]
        kinds = obs.frames[k]["kinds"]
        row = {"step": k, "submap": int(k_sub[k]), "dtheta_online_deg": np.degrees(dth["online"]),
               "dtheta_output_deg": np.degrees(dth["output"]),
               "filter_dtheta_deg": float(np.degrees(wrap_angle(u["pose_after"][2] - u["pose_before"][2]))),
               "sigma_theta_before_deg": float(np.degrees(np.sqrt(u["P_rr"][2, 2]))),
               "z": p["z"].tolist(), "range": float(np.hypot(*p["z"][:2])),
               "sd_z_cm": (100 * np.sqrt(np.diag(p["C"])[:2])).tolist(),
               "sd_phi_deg": float(np.degrees(np.sqrt(p["C"][2, 2]))),
               "kinds": None if kinds is None else kinds.tolist(),
               "kind": None if kinds is None else int(kinds[nearest(obs.frames[k]["z"], p["z"])]),
               "landmark": p["landmark"].tolist(),
               "landmark_sd_cm": (100 * np.sqrt(np.diag(p["P_ll"])[:2])).tolist(),
               "seen_before": len(p["seen"]),
               "seen_at": [(s, float(np.hypot(*z[:2])), float(np.degrees(np.arctan2(z[1], z[0]))))
                           for s, _, z in p["seen"]][-6:],
               "first_seen": p["seen"][0][0] if p["seen"] else None,
               "nu": [100 * p["nu"][0], 100 * p["nu"][1], float(np.degrees(p["nu"][2]))],
               "d2": p["d2"]}  # fmt: skip
        S, nu = p["S"], p["nu"]
        # the gain's heading row (rad per m, m, rad of innovation): Δθ = K[θ]·ν
        row["K_theta_row"] = [float(v) for v in p["K_theta"]]
        row["dtheta_from_gain_deg"] = float(np.degrees(p["K_theta"] @ nu))
        row["S_sd_cm"] = (100 * np.sqrt(np.diag(S)[:2])).tolist()
        a_chain = agreement(obs, with_increment(online, k, inc["chain"][k - 1]), files["laser2base"], k)
        a_filter = agreement(obs, online, files["laser2base"], k)
        row["later_scans_cm"] = {"filter": 100 * a_filter, "chain": 100 * a_chain}
        if "reference" in inc:
            row["reference_minus_chain_deg"] = float(
                np.degrees(wrap_angle(inc["reference"][k - 1, 2] - inc["chain"][k - 1, 2]))
            )
        row["motion_sigma_theta_deg"] = float(np.degrees(sig[k]))
        rows.append(row)
    res["single_corner_turns"] = rows
    res["n_single_steps"] = int(sum(1 for k, u in obs.updates.items() if len(u["pairs"]) == 1))
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("log", type=Path)
    ap.add_argument("--config")
    ap.add_argument("--set", dest="sets", action="append", default=[])
    ap.add_argument("--steps", default="")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--variant", choices=("none", "handed", "verify", "skip"), default="none")
    args = ap.parse_args()
    detail = [int(s) for s in args.steps.split(",") if s]
    obs, files = run(args.log, args.config, args.sets, args.variant)
    res = analyse(obs, files, detail)
    res["log"], res["variant"], res["n_reverted"] = args.log.name, args.variant, obs.n_reverted
    res["ate"] = files["summary"].get("accuracy")
    text = json.dumps(res, indent=1, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o))
    if args.json:
        args.json.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
