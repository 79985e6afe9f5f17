"""Where a radish log's reference poses disagree with its own scans.

    python benchmarks/reference_check.py [--data DIR] [--jobs 2]

The exact-odometry logs (radish/NAME-exact.log) carry the reference poses as odometry, so a front end
that follows its scans cannot score 0 against them where the reference itself is wrong. For every
keyframe k (the run's own keyframe selection, default config): the scans of the ``scan_match.window``
keyframes before it placed at their reference poses make a local map (motion/icp.py's LocalMap, as the
front end builds it); scan k is scored at its reference pose (share of its points within
``inlier_distance`` of the map: the front end's fit) and at the best pose of a correlative search of ±
``SEARCH_XY`` m / ± ``SEARCH_THETA`` rad around it, refined by ICP (motion/). A keyframe *refutes* the
reference when the best pose fits at least ``REFUTE_FIT`` better and lies more than ``REFUTE_XY`` m or
``REFUTE_THETA`` rad from it. Nothing here is fed back into a default: it says how far the panel's
exact-odometry figures can be trusted.

A second table measures the **small-scale** disagreement, keyframe by keyframe: ICP of scan k on the same
map, started at its reference pose — how far it moves (the pose its scan fits best near the reference)
and the median point-to-line distance of the scan's points to the map (nearest map point within
``P2L_CAP``, along its normal) at the reference pose and at ICP's. ICP fits 3 numbers to ~100–300
points, so on exact poses it lowers that residual by a few per cent and moves by its own noise: the
**control** rows are the same check on simulated logs (simulate.simulate_log, 1° beams, ``SIM_RATE`` Hz,
so keyframes as sparse as the panel's; ``CONTROLS``: the simulator's 270° laser, and 180° ones like
the radish lasers with 1 and 3 cm of range noise, in the office and in a loop of corridors) against
their exact ground truth. Where a reference moves much more than the controls, and its scans fit
clearly better where ICP puts them, the reference itself is off — a floor under any relative-pose
error measured against it.

A third table signs ICP's move along the direction of travel (negative: ICP shortens the reference's
step), split by how many of the scan's points lie on map lines facing the travel (``FACING``): where
fewer than ``FEW_FACING`` do (a corridor), little holds the pose along it, and a reference made where its
own scans could not hold it either may have followed its odometry there. The corridor-loop control
(``RING_LAPS`` laps, so the comparison has the precision) says what ICP does there against the truth.
Writes ``docs/results/reference_check.md``; deterministic.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parent))
from frontend_panel import keyframes, reference  # noqa: E402
from radish_panel import BUILDINGS  # noqa: E402
from real_logs import ROOT, default_data  # noqa: E402

from cornerslam_cli.geometry import relative, transform_points, wrap_angle  # noqa: E402
from cornerslam_cli.motion.correlative import Window, search  # noqa: E402
from cornerslam_cli.motion.icp import LocalMap, register, voxel_thin  # noqa: E402
from cornerslam_cli.motion.params import ScanMatchConfig  # noqa: E402

WINDOW = ScanMatchConfig().window  # keyframes in the local map by default (the run's scan_match.window)
SEARCH_XY, SEARCH_THETA = 0.3, 0.3  # m, rad: the search around the reference pose
REFUTE_FIT = 0.2  # the best pose fits this much better (share of points) ...
REFUTE_XY, REFUTE_THETA = 0.1, np.radians(3.0)  # ... and lies this far away: the reference is refuted
P2L_CAP = 0.15  # m: a scan point counts for the point-to-line residual when a map point is this near
FACING = np.radians(45.0)  # a map line faces the direction of travel when its normal is this near it
FEW_FACING = 10  # keyframes with fewer scan points on such lines: little to hold the pose along the travel
SIM_SEED, SIM_RATE = 1, 1.0  # the controls: a scan a second (0.5 m at the simulator's speed)
# (name, field of view °, beams: 1° apart, σ of the range noise's constant part m, world: the office, or
# RING — a corridor loop like infinite-corridor's, where ICP knows little along the axis)
CONTROLS = (
    ("270°, 1 cm", 270, 271, 0.01, "office"),
    ("180°, 1 cm", 180, 181, 0.01, "office"),
    ("180°, 3 cm", 180, 181, 0.03, "office"),
    ("180°, 1 cm, corridor loop ×3", 180, 181, 0.01, "ring"),
)
# the corridor loop: 2.4 m wide around a 57.6 × 17.6 m block, the outer walls' doors (0.9 m) every 7.3 m;
# driven RING_LAPS times (~970 keyframes), so its move along the travel is known to ±0.26 %
RING_LAPS = 3
RING_DOORS = [(float(d), 0.9) for d in np.arange(3.0, 60.0, 7.3)]
RING_LOOP = np.array([(0.0, 0.0), (60.0, 0.0), (60.0, 20.0), (0.0, 20.0)])


def point_to_line(local: LocalMap, tree: cKDTree, placed: np.ndarray) -> float:
    """Median distance of the ``placed`` points to the map along the normal of their nearest map point
    (those with a map point within P2L_CAP that has a normal)."""
    d, i = tree.query(placed)
    ok = (d < P2L_CAP) & local.has_normal[np.minimum(i, len(local.points) - 1)]
    r = np.einsum("ij,ij->i", placed[ok] - local.points[i[ok]], local.normals[i[ok]])
    return float(np.median(np.abs(r))) if ok.any() else float("nan")


def facing(local: LocalMap, tree: cKDTree, placed: np.ndarray, u: np.ndarray) -> int:
    """How many of the ``placed`` points lie (within P2L_CAP) on map lines facing the direction of
    travel ``u`` (normal within FACING of it): what tells ICP where the robot is along its travel."""
    d, i = tree.query(placed)
    ok = (d < P2L_CAP) & local.has_normal[np.minimum(i, len(local.points) - 1)]
    return int(np.sum(np.abs(local.normals[i[ok]] @ u) > np.cos(FACING)))


def check(args: tuple[Path, list[str]], refute: bool = True) -> dict:
    log, sets = args
    run_cfg, src, pairs = keyframes(log, sets)
    if log.suffix == ".mcap":  # the simulated control: its ground truth at the keyframes' stamps
        ref = reference(log, log.parent, np.array([p.scan.stamp for p in pairs]))
    else:
        ref = np.array([p.odom for p in pairs])  # -exact logs: the reference poses are the odometry
    return scored(log.name.removesuffix(".log"), run_cfg.scan_match, src.laser2base, pairs, ref, refute)


def reference_maps(pts: list[np.ndarray], ref: np.ndarray, cfg: ScanMatchConfig):
    """(k, local map, scan) for every keyframe k from ``cfg.window`` on whose scan keeps at least 10 points:
    the scans ``pts`` (base frame) of the window keyframes before it placed at their reference poses ``ref``
    (as the front end builds its map), and scan k, each thinned as the front end thins them."""
    for k in range(cfg.window, len(pts)):
        m = np.concatenate([transform_points(pts[i], ref[i]) for i in range(k - cfg.window, k)])
        local = LocalMap.build(m[voxel_thin(m, cfg.voxel)])
        q = pts[k][voxel_thin(pts[k], cfg.scan_voxel)]
        if len(q) >= 10:
            yield k, local, q


def scored(name: str, cfg: ScanMatchConfig, laser2base, pairs, ref: np.ndarray, refute: bool = True) -> dict:
    """The keyframes' checks (module docstring); ``refute`` False: the small-scale ones only (ICP from
    the reference), without the correlative search of the refutation."""
    pts = [transform_points(p.scan.points(), laser2base) for p in pairs]  # base frame
    refuted, small = [], []
    for k, local, q in reference_maps(pts, ref, cfg):
        tree = cKDTree(local.points)
        near = register(q, local, ref[k], cfg).pose  # ICP from the reference pose
        d = relative(ref[k], near)
        travel = np.asarray(ref[k][:2]) - ref[k - 1][:2]
        u = travel / max(float(np.hypot(*travel)), 1e-9)  # the direction of travel
        small.append(
            (
                float(np.hypot(d[0], d[1])),
                abs(float(wrap_angle(d[2]))),
                point_to_line(local, tree, transform_points(q, ref[k])),
                point_to_line(local, tree, transform_points(q, near)),
                float((np.asarray(near[:2]) - ref[k][:2]) @ u),  # ICP's move along the travel
                float(np.hypot(*travel)),
                facing(local, tree, transform_points(q, ref[k]), u),
            )
        )
        if not refute:
            continue
        found = search(
            q, local.points, ref[k], Window(SEARCH_XY, SEARCH_THETA), cfg.search_resolution, cfg.search_sigma
        )
        best = register(q, local, found.pose, cfg).pose
        gain = local.fit(transform_points(q, best), cfg.inlier_distance) - local.fit(
            transform_points(q, ref[k]), cfg.inlier_distance
        )
        d = relative(ref[k], best)
        if gain >= REFUTE_FIT and (np.hypot(d[0], d[1]) > REFUTE_XY or abs(wrap_angle(d[2])) > REFUTE_THETA):
            refuted.append((k, gain, float(np.hypot(d[0], d[1])), float(np.degrees(wrap_angle(d[2])))))
    return {"log": name, "keyframes": len(pairs), "refuted": refuted, "small": np.array(small)}


def ring_world():
    """The corridor loop of the last control (``RING_*``): the robot drives its middle line."""
    from cornerslam_cli import simworld as sw

    x0, x1, y0, y1 = -1.2, 61.2, -1.2, 21.2
    outer = [
        sw.wall((x0, y0), (x1, y0), RING_DOORS),
        sw.wall((x1, y0), (x1, y1), RING_DOORS[:2]),
        sw.wall((x1, y1), (x0, y1), RING_DOORS),
        sw.wall((x0, y1), (x0, y0), RING_DOORS[:2]),
    ]
    return sw.make_world(np.concatenate([*outer, sw.rectangle(30.0, 10.0, 57.6, 17.6)]), "ring")


def controls(data_dir: Path) -> list[Path]:
    """The simulated control logs (``CONTROLS``), written into ``data_dir``."""
    from cornerslam_cli.simulate import simulate_log

    logs = []
    for i, (_, fov, beams, sigma, world) in enumerate(CONTROLS):
        log = data_dir / f"control{i}.mcap"
        ring = {"world": ring_world(), "waypoints": RING_LOOP, "laps": RING_LAPS} if world == "ring" else {}
        simulate_log(
            log, seed=SIM_SEED, rate=SIM_RATE, beams=beams, speed=0.5, fov=np.radians(fov), sigma_a=sigma,
            **ring,
        )  # fmt: skip
        logs.append(log)
    return logs


def small_row(r: dict) -> str:
    s = r["small"]
    moved, turned, at_ref, at_icp = s[:, 0], np.degrees(s[:, 1]), s[:, 2], s[:, 3]
    ok = np.isfinite(at_ref) & np.isfinite(at_icp)
    return (
        f"| {r['log']} | {len(s)} | {100 * np.mean(moved):.1f} / {100 * np.median(moved):.1f} "
        f"| {np.mean(turned):.2f} | {1000 * np.mean(at_ref[ok]):.1f} | {1000 * np.mean(at_icp[ok]):.1f} "
        f"| {100 * np.mean(at_icp[ok] < at_ref[ok]):.0f} % |"
    )


def along_row(r: dict) -> str:
    """ICP's signed move along the travel, per metre travelled (%), and its mean (cm) with its standard
    error, for keyframes with few and with many scan points on lines facing the travel."""
    s = r["small"]
    cells = []
    for sel in (s[:, 6] < FEW_FACING, s[:, 6] >= FEW_FACING):
        a = s[sel, 4]
        if len(a) < 2:
            cells.append(f"{len(a)} | – | –")
            continue
        cells.append(
            f"{len(a)} | {100 * a.sum() / s[sel, 5].sum():+.2f} % "
            f"| {100 * a.mean():+.2f} ± {100 * a.std(ddof=1) / np.sqrt(len(a)):.2f}"
        )
    return f"| {r['log']} | " + " | ".join(cells) + " |"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=default_data())
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    logs = [args.data / "radish" / f"{b}-exact.log" for b in BUILDINGS]
    with tempfile.TemporaryDirectory() as tmp:
        logs += controls(Path(tmp))
        with ProcessPoolExecutor(args.jobs) as ex:
            rows = list(ex.map(check, [(log, []) for log in logs]))
    rows, sims = rows[: -len(CONTROLS)], rows[-len(CONTROLS) :]
    lines = [
        "# Where the reference poses disagree with their own scans",
        "",
        "`python benchmarks/reference_check.py` (default config; see its docstring). For each keyframe of "
        f"the exact-odometry logs: its scan against the {WINDOW} keyframes before it placed at their "
        "reference poses, scored at its own reference pose and at the best pose within "
        f"± {SEARCH_XY} m / ± {SEARCH_THETA} rad. *Refuted*: the best pose fits ≥ {REFUTE_FIT} better "
        f"(share of points within the front end's inlier distance) and lies > {REFUTE_XY} m or "
        f"> {np.degrees(REFUTE_THETA):.0f}° away. A front end that follows the scans leaves the reference "
        "there, so these keyframes bound what exact-odometry ATE can show. Deterministic.",
        "",
        "| log | keyframes | refuted | where (keyframe: fit gain, m, °) |",
        "|---|---:|---:|---|",
    ]
    for r in rows:
        where = "; ".join(f"{k}: +{g:.2f}, {d:.2f} m, {a:+.1f}°" for k, g, d, a in r["refuted"][:12])
        more = f" … ({len(r['refuted']) - 12} more)" if len(r["refuted"]) > 12 else ""
        lines.append(f"| {r['log']} | {r['keyframes']} | {len(r['refuted'])} | {where}{more} |")
    lines += [
        "",
        "## Small-scale disagreement: ICP started at each reference pose",
        "",
        "The same map per keyframe; ICP (the front end's, default config) started at the keyframe's "
        "reference pose. *Moved*: how far the pose its scan fits best lies from the reference (mean / "
        "median). *Residual*: the median distance of the scan's points to the map along the normal of "
        f"their nearest map point (within {P2L_CAP} m), at the reference pose and at ICP's, averaged over "
        "the keyframes. *Controls*: the same check on simulated logs (the office, seed "
        f"{SIM_SEED}, a scan every 0.5 m, 1° beams; the simulator's 270° laser, and 180° ones like the "
        "radish lasers with 1 and 3 cm of range noise, plus 0.2 % of the range; and a 180° one in a "
        "loop of 2.4 m wide corridors with a door every 7.3 m, like infinite-corridor's) against their "
        "exact ground truth — what ICP's own noise and its fit of 3 numbers to the points give when the "
        "reference is right. Along a corridor ICP holds the pose only loosely along the axis: the "
        "corridor control moves about three times as far as the office (mean), so part of a real log's "
        "move in metres is ICP's own; its turn and its share of keyframes that fit better are not. "
        "The references (or the scans' mount or stamps they assume: the laser at "
        "the robot's origin, as the logs give it) are inconsistent with their scans where they move "
        "well beyond the controls and fit better at far more than half the keyframes; ICP's move is an "
        "estimate of by how much, per keyframe, not a measurement of it (the worlds differ).",
        "",
        "| log | keyframes | moved (cm, mean / median) | turned (°, mean) | residual at reference (mm) "
        "| residual at ICP (mm) | keyframes ICP fits better |",
        "|---|---:|---|---:|---:|---:|---:|",
        *(small_row(r) for r in rows),
        *(
            small_row({**r, "log": f"control: simulated, exact, {c[0]}"})
            for r, c in zip(sims, CONTROLS, strict=True)
        ),
        "",
        "## Along the direction of travel",
        "",
        "The same ICP runs, signed: how far ICP moves the pose *along the direction of travel* (from the "
        "previous keyframe's reference pose to this one's; negative: back, a shorter step), as a share "
        "of the distance travelled and as a mean per keyframe (cm, ± its standard error). Split by what "
        "can hold the pose along the travel: keyframes with fewer than "
        f"{FEW_FACING} scan points on map lines facing it (normal within {np.degrees(FACING):.0f}°: a "
        "corridor's end, door jambs, furniture) and those with more. The controls say what ICP does "
        "where the reference is the truth.",
        "",
        f"| log | keyframes, < {FEW_FACING} facing | ICP's move along the travel | mean (cm) "
        f"| keyframes, ≥ {FEW_FACING} facing | ICP's move along the travel | mean (cm) |",
        "|---|---:|---:|---|---:|---:|---|",
        *(along_row(r) for r in rows),
        *(
            along_row({**r, "log": f"control: simulated, exact, {c[0]}"})
            for r, c in zip(sims, CONTROLS, strict=True)
        ),
    ]
    text = "\n".join(lines) + "\n"
    (ROOT / "docs" / "results" / "reference_check.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
