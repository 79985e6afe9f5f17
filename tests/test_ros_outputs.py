"""What a ROS user expects of a run's outputs (issue 17): an occupancy grid that map_server loads,
trajectories in the log's odometry frame next to odometry.tum and scan_matched.tum, a results MCAP
that places the robot and its scans by itself, the laser mount's source, default output names that
never replace another log's output.

The log: 100 scans ray cast in the simulated office (simworld.py) along 17 m of corridor with a 90°
turn, laser on the base (no tf in the log). Its odometry frame sits at ``ODOM_IN_WORLD`` in the world
(far from the origin and turned), and the odometry drifts in heading; the ground truth beside it is
the true pose in that odometry frame, as a ROS user's ground truth usually is. Every reference below is
the world (walls, true poses) or arithmetic written out here, never the code under test.
"""

from __future__ import annotations

import base64
import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from mcap.reader import make_reader
from test_report_mcap import validate

from cornerslam_cli.cli import cli
from cornerslam_cli.logs.writers import RawScan, write_mcap
from cornerslam_cli.report import occupancy
from cornerslam_cli.report.occupancy import (
    COUNT_MAX,
    FREE,
    OCCUPIED,
    UNKNOWN,
    ScanStore,
    cell_units,
    classify,
    line_cells,
    trace,
)
from cornerslam_cli.report.odom_frame import in_odom_frame, landmarks_in_odom_frame
from cornerslam_cli.report.ownership import MARKER
from cornerslam_cli.report.tables import read_csv, read_tum, write_tum
from cornerslam_cli.simulate import SimParams, drive
from cornerslam_cli.simworld import office_world, raycast
from cornerslam_cli.slam import StepRecord
from cornerslam_cli.types import OdomSample

ODOM_IN_WORLD = (30.0, -20.0, 1.0)  # the odometry frame's pose in the world: x, y (m), yaw (rad)
HEADING_DRIFT = 0.002  # rad added to every odometry increment's turn
RESOLUTION = 0.05  # the default grid resolution


def matrix(x: float, y: float, yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


def pose_of(M: np.ndarray) -> np.ndarray:
    return np.array([M[0, 2], M[1, 2], math.atan2(M[1, 0], M[0, 0])])


def apply(M: np.ndarray, xy: np.ndarray) -> np.ndarray:
    return np.asarray(xy) @ M[:2, :2].T + M[:2, 2]


WORLD_FROM_ODOM = matrix(*ODOM_IN_WORLD)
ODOM_FROM_WORLD = np.linalg.inv(WORLD_FROM_ODOM)


def distance_to_walls(points: np.ndarray, walls: np.ndarray) -> np.ndarray:
    """(k,) distance of each point (world frame) to the nearest wall segment."""
    a, e = walls[:, 0], walls[:, 1] - walls[:, 0]
    t = np.clip(((points[:, None] - a) * e).sum(-1) / (e * e).sum(-1), 0.0, 1.0)
    return np.linalg.norm(points[:, None] - a - t[..., None] * e, axis=-1).min(axis=1)


@pytest.fixture(scope="module")
def far_log(tmp_path_factory) -> dict:
    """The log (no tf at all, odometry on nav_msgs/Odometry) and LOG.gt.tum beside it."""
    truth = drive(np.array([(12.0, 5.0), (24.5, 5.0), (24.5, 12.0)]), 1, SimParams(), 0.2)[:200:2]
    world, rng = office_world(), np.random.default_rng(5)
    angles = np.linspace(-0.75 * math.pi, 0.75 * math.pi, 541)
    gt = np.array([pose_of(ODOM_FROM_WORLD @ matrix(*p)) for p in truth])  # true poses, odometry frame
    odom = [gt[0]]
    for a, b in zip(gt[:-1], gt[1:], strict=True):  # true increments, each turned a little too far
        step = np.linalg.inv(matrix(*a)) @ matrix(*b)
        odom.append(pose_of(matrix(*odom[-1]) @ matrix(*pose_of(step)[:2], pose_of(step)[2] + HEADING_DRIFT)))
    scans, odoms = [], []
    for i, base in enumerate(truth):
        r = raycast(world, base, angles, 20.0)
        r = np.where(np.isfinite(r), r + rng.normal(0.0, 0.005, len(r)), np.inf)
        stamp = 1_700_000_000.0 + 0.4 * i
        scans.append(
            RawScan(stamp, angles[0], angles[1] - angles[0], r.astype(np.float32), 0.05, 20.0, "laser")
        )
        odoms.append(OdomSample(stamp, *odom[i]))
    d = tmp_path_factory.mktemp("far")
    log = write_mcap(d / "far.mcap", scans, odoms)
    stamps = np.array([s.stamp for s in scans])
    write_tum(d / "far.mcap.gt.tum", stamps, gt)
    return {"log": log, "truth": truth, "gt": gt, "world": world, "dir": d}


@pytest.fixture(scope="module")
def far_run(far_log) -> dict:
    out = far_log["dir"] / "out"
    mcap = far_log["dir"] / "results.mcap"
    res = CliRunner().invoke(cli, ["run", str(far_log["log"]), "--out", str(out), "--mcap-out", str(mcap)])
    assert res.exit_code == 0, res.output
    return {"out": out, "mcap": mcap, "stdout": res.output}


# ----------------------------------------------------------------------------- 2: frames that line up
def test_trajectory_starts_at_the_first_odometry_pose_and_lines_up_unaligned(far_log, far_run):
    out = far_run["out"]
    stamps, est = read_tum(out / "trajectory.tum")
    _, odom = read_tum(out / "odometry.tum")
    _, scan_matched = read_tum(out / "scan_matched.tum")
    tr = read_csv(out / "trajectory.csv")
    np.testing.assert_allclose(est[0], odom[0], atol=1e-8)  # trajectory.tum vs odometry.tum: same start
    np.testing.assert_allclose(odom[0], far_log["gt"][0], atol=1e-8)
    np.testing.assert_allclose(
        odom, np.column_stack((tr["odom_x"], tr["odom_y"], tr["odom_theta"])), atol=1e-8
    )
    np.testing.assert_allclose(
        scan_matched,
        np.column_stack((tr["scan_odom_x"], tr["scan_odom_y"], tr["scan_odom_theta"])),
        atol=1e-8,
    )
    # evo_ape without alignment: the position error at each stamp against the ground truth, as given
    gt = far_log["gt"]
    ape = np.sqrt(np.mean(np.sum((est[:, :2] - gt[:, :2]) ** 2, axis=1)))
    odom_ape = np.sqrt(np.mean(np.sum((odom[:, :2] - gt[:, :2]) ** 2, axis=1)))
    assert ape < 0.05 < 0.3 < odom_ape  # the estimate is on the truth; the drifting odometry is not
    summary = json.loads((out / "summary.json").read_text())
    assert summary["accuracy"]["ate"]["rmse"] < 0.05  # (aligned) and the final pose in the same frame
    np.testing.assert_allclose(summary["final_pose"], est[-1], atol=1e-8)


def test_segments_and_landmarks_are_in_the_odometry_frame(far_log, far_run):
    walls = far_log["world"].walls
    ln = read_csv(far_run["out"] / "lines.csv")
    ends = np.column_stack((np.r_[ln["x1"], ln["x2"]], np.r_[ln["y1"], ln["y2"]]))
    d = distance_to_walls(apply(WORLD_FROM_ODOM, ends), walls)
    # 95 % within 6 cm: a frame error would put them metres off (5 cm before the fused front end of
    # issue 15, whose chain follows this fixture's bias-corrected odometry; see its closing note)
    assert len(d) > 500 and np.percentile(d, 95) < 0.06
    lm = read_csv(far_run["out"] / "map.csv")
    xy = apply(WORLD_FROM_ODOM, np.column_stack((lm["x"], lm["y"])))
    assert len(xy) > 20 and np.percentile(distance_to_walls(xy, walls), 90) < 0.1


def record(pose_var, cov_xy, segments) -> StepRecord:
    return StepRecord(0, 0.0, np.array([1.0, 2.0, 0.5]), np.array(pose_var), np.zeros(3), np.zeros(3),
                      0, 0, 0, 0, 0, 0, 0, 0.0, 0.0, 0.0, 0.0, np.array(segments), cov_xy=cov_xy)  # fmt: skip


def test_moving_a_step_into_the_odometry_frame_by_hand():
    """A quarter turn and a shift: x and y swap roles, the variances swap, the covariance turns sign."""
    r = in_odom_frame(
        record([0.04, 0.01, 0.002], 0.005, [[1.0, 0.0, 1.0, 2.0]]), np.array([10.0, 20.0, math.pi / 2])
    )
    np.testing.assert_allclose(r.pose, [10.0 - 2.0, 20.0 + 1.0, 0.5 + math.pi / 2], atol=1e-12)
    np.testing.assert_allclose(r.pose_var, [0.01, 0.04, 0.002], atol=1e-15)
    assert r.cov_xy == pytest.approx(-0.005, abs=1e-15)
    np.testing.assert_allclose(r.segments_map, [[10.0, 21.0, 8.0, 21.0]], atol=1e-12)
    same = record([0.04, 0.01, 0.002], 0.005, [[1.0, 0.0, 1.0, 2.0]])
    assert in_odom_frame(same, np.zeros(3)) is same  # odometry from zero: written exactly as filtered
    lm = {"id": np.array([0]), "x": np.array([1.0]), "y": np.array([0.0]), "phi": np.array([1.2]),
          "var_x": np.array([0.04]), "var_y": np.array([0.01]), "cov_xy": np.array([0.005])}  # fmt: skip
    moved = landmarks_in_odom_frame(lm, np.array([10.0, 20.0, math.pi / 2]))
    assert [moved[k][0] for k in ("x", "y", "phi", "var_x", "var_y", "cov_xy")] == pytest.approx(
        [10.0, 21.0, 1.2, 0.01, 0.04, -0.005], abs=1e-12
    )


# ----------------------------------------------------------------------------- 1: the occupancy grid
def read_pgm(path: Path) -> np.ndarray:
    """A binary PGM (P5, 8 bit) as rows top first; comment lines skipped."""
    data = path.read_bytes()
    tokens, pos = [], 0
    while len(tokens) < 4:
        line_end = data.index(b"\n", pos)
        line = data[pos:line_end].split(b"#")[0]
        tokens += line.split()
        pos = line_end + 1
    assert tokens[0] == b"P5" and int(tokens[3]) == 255
    cols, rows = int(tokens[1]), int(tokens[2])
    return np.frombuffer(data[pos : pos + rows * cols], dtype=np.uint8).reshape(rows, cols)


def load_map(out: Path) -> tuple[dict, np.ndarray, np.ndarray]:
    """(map.yaml as a dict, the image of its ``image`` file as map_server reads it: row 0 at the top)."""
    meta = yaml.safe_load((out / "map.yaml").read_text())
    image = read_pgm(out / meta["image"])
    return meta, image


def cell_centres(meta: dict, image: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Centres (odometry frame) of image pixels (row 0 at the top, as map_server reads it)."""
    res, (x0, y0, _) = meta["resolution"], meta["origin"]
    return np.column_stack((x0 + (cols + 0.5) * res, y0 + (image.shape[0] - 1 - rows + 0.5) * res))


def pixel_of(meta: dict, image: np.ndarray, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    res, (x0, y0, _) = meta["resolution"], meta["origin"]
    cols = np.floor((xy[:, 0] - x0) / res).astype(int)
    rows = image.shape[0] - 1 - np.floor((xy[:, 1] - y0) / res).astype(int)
    return rows, cols


def test_map_yaml_is_a_map_server_map(far_run):
    meta, image = load_map(far_run["out"])
    assert meta == {
        "image": "map.pgm",
        "mode": "trinary",
        "resolution": RESOLUTION,
        "origin": meta["origin"],
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
    }
    assert len(meta["origin"]) == 3 and meta["origin"][2] == 0.0
    assert set(np.unique(image)) == {OCCUPIED, FREE, UNKNOWN}  # map_saver's trinary values
    # map_server's reading: p = (255 - v) / 255, occupied above occupied_thresh, free below free_thresh
    p = (255 - np.array([OCCUPIED, FREE, UNKNOWN])) / 255
    assert p[0] > 0.65 and p[1] < 0.196 and 0.196 < p[2] < 0.65


def test_walls_land_within_one_cell_free_space_is_free_unknown_is_unknown(far_log, far_run):
    meta, image = load_map(far_run["out"])
    walls, res = far_log["world"].walls, meta["resolution"]
    rows, cols = np.nonzero(image == OCCUPIED)
    occupied = apply(WORLD_FROM_ODOM, cell_centres(meta, image, rows, cols))
    d = distance_to_walls(occupied, walls)
    assert len(d) > 500
    # a wall crosses (or touches) the cell: 99 % before the fused front end of issue 15 (its chain follows
    # this fixture's bias-corrected odometry, whose per-keyframe drift leaves ~1 cm), 88 % with it
    assert np.mean(d <= res) > 0.85 and np.mean(d <= 2 * res) > 0.99 and d.max() < 4 * res
    # the walls the robot saw are occupied: wall points near the true path, 1 cm off their cell's edge
    gt = far_log["gt"]
    r, c = pixel_of(meta, image, gt[:, :2])
    assert np.all(image[r, c] == FREE)  # where the robot drove
    mid = (gt[:-1, :2] + gt[1:, :2]) / 2
    r, c = pixel_of(meta, image, mid)
    assert np.all(image[r, c] == FREE)
    # outside the building's shell (0..30 × 0..20 m) no beam ever went: unknown
    rows, cols = np.indices(image.shape).reshape(2, -1)
    world = apply(WORLD_FROM_ODOM, cell_centres(meta, image, rows, cols))
    x0, y0, x1, y1 = far_log["world"].bounds
    outside = (world[:, 0] < x0 - 2 * res) | (world[:, 0] > x1 + 2 * res)
    outside |= (world[:, 1] < y0 - 2 * res) | (world[:, 1] > y1 + 2 * res)
    assert outside.sum() > 1000 and np.all(image[rows[outside], cols[outside]] == UNKNOWN)


def test_grid_files_are_part_of_the_marked_output(far_run):
    marker = json.loads((far_run["out"] / MARKER).read_text())
    assert {"map.pgm", "map.yaml", "map_grid.png", "odometry.tum", "scan_matched.tum"} <= set(marker["files"])
    assert (far_run["out"] / "map_grid.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_grid_over_its_cell_cap_is_written_coarser_with_a_warning(far_log, tmp_path):
    out = tmp_path / "out"
    res = CliRunner().invoke(
        cli, ["run", str(far_log["log"]), "--out", str(out), "-q", "--set", "grid.max_cells=20000"]
    )
    assert res.exit_code == 0, res.output
    meta, image = load_map(out)
    assert image.size <= 20000 and meta["resolution"] in (0.1, 0.2, 0.4, 0.8)
    warnings = json.loads((out / "summary.json").read_text())["warnings"]
    assert any("grid.max_cells=20000" in w and f"{meta['resolution']:g} m" in w for w in warnings)


def test_bad_grid_resolution_is_refused(far_log, tmp_path):
    res = CliRunner().invoke(
        cli, ["run", str(far_log["log"]), "--out", str(tmp_path / "o"), "--set", "grid.resolution=0"]
    )
    assert res.exit_code == 2 and "grid.resolution" in res.output and not (tmp_path / "o").exists()


def test_ray_cells_against_dense_sampling():
    """Every traced cell lies on the segment (a dense sampling of it touches the cell), the end's own
    cell is apart, and there is one cell per step along the major axis."""
    rng = np.random.default_rng(1)
    start = rng.uniform(0.0, 3.0, (50, 2))
    end = rng.uniform(0.0, 3.0, (50, 2))
    lo, res, cols = np.zeros(2), 0.05, 61
    beam, cells, ends = line_cells(start, end, lo, res, cols)
    for k in range(50):
        t = np.linspace(0.0, 1.0, 20001)[:, None]
        dense = np.floor((start[k] + t * (end[k] - start[k])) / res).astype(int)
        touched = set((dense[:, 1] * cols + dense[:, 0]).tolist())
        mine = cells[beam == k]
        assert set(mine.tolist()) <= touched
        assert len(mine) == max(1, math.ceil(np.abs(end[k] - start[k]).max() / res - 1e-9))
        assert ends[k] == int(np.floor(end[k, 1] / res)) * cols + int(np.floor(end[k, 0] / res))


def test_grid_traced_in_parts_equals_the_grid_traced_at_once(monkeypatch):
    """A store's scans ray traced a few at a time (CHUNK points per part) give the grid of one pass
    (CHUNK beyond every beam): the same cells, origin and resolution, with a cell whose counts
    saturate (uint16) across parts and scans without points among them."""
    rng = np.random.default_rng(4)
    store = ScanStore()
    for i in range(300):
        pose = np.array([*rng.normal(0.0, 0.3, 2), rng.uniform(-math.pi, math.pi)])
        store.add(pose, rng.normal(0.0, 3.0, (rng.integers(0, 40) * (i % 7 != 3), 2)))
    for _ in range(700):  # 70,000 beams ending in one cell: more than a uint16 counts
        store.add(np.zeros(3), np.tile([[1.0, 0.0]], (100, 1)))
    grids = []
    for chunk in (10**9, 333):
        monkeypatch.setattr(occupancy, "CHUNK", chunk)
        assert (len(store.parts(chunk)) == 1) == (chunk > store.n_points)
        grids.append(occupancy.build_grid(store, 0.05, 10**7, print))
    whole, parts = grids
    assert np.array_equal(whole.cells, parts.cells) and (OCCUPIED == whole.cells).any()
    assert whole.origin == parts.origin and whole.resolution == parts.resolution


def test_a_store_far_from_the_odometry_origin_keeps_millimetres():
    """The same scans with every pose moved by 10⁷ m (UTM-scale odometry): the same grid cells, its
    origin moved by 10⁷ m, the same map consistency and rays to a micrometre, and moving a scan
    (the smoothed poses) moves it alike. Before the store kept odometry-frame float32 (1 m apart at
    10⁷ m): map.pgm a star of rays, the consistency 0."""
    from cornerslam_cli.report.consistency import store_consistency

    rng = np.random.default_rng(7)
    wall = np.column_stack((np.full(60, 3.0), np.linspace(-2.0, 2.0, 60)))
    poses = np.column_stack((np.arange(150) * 0.05, np.zeros(150), rng.normal(0.0, 0.05, 150)))
    far = np.array([1e7, -2e7, 0.0])
    near, moved = ScanStore(), ScanStore()
    for p in poses:
        scan = wall - (p[0], 0.0)  # (the heading's noise ignored: any scan will do)
        near.add(p, scan)
        moved.add(p + far, scan)
    # the first scan moved (applied on the left): by d, θ near the origin, by what is the same there
    d, th = np.array([0.01, -0.02]), 0.003
    R = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    near.move(np.array([0]), np.array([[*d, th]]))
    moved.move(np.array([0]), np.array([[*(d + far[:2] - R @ far[:2]), th]]))
    (s0, e0), (s1, e1) = near.rays(), moved.rays()
    np.testing.assert_allclose(s1 - far[:2], s0, atol=1e-6)
    np.testing.assert_allclose(e1 - far[:2], e0, atol=1e-6)
    g0, g1 = (occupancy.build_grid(s, 0.05, 10**7, print) for s in (near, moved))
    assert np.array_equal(g0.cells, g1.cells) and (OCCUPIED == g0.cells).any()
    np.testing.assert_allclose(np.subtract(g1.origin, g0.origin), far[:2], atol=1e-6)
    odoms = poses[:, :3]
    c0, c1 = store_consistency(near, odoms), store_consistency(moved, odoms + far)
    assert dataclasses.asdict(c0) == pytest.approx(dataclasses.asdict(c1), rel=1e-6, abs=1e-9)
    assert c0.revisit_share > 0 and c0.occupied_cells > 0


def test_scan_store_thins_beyond_its_cap():
    store = ScanStore(max_points=1000)
    for i in range(10):
        store.add(np.array([float(i), 0.0, math.pi / 2]), np.column_stack((np.ones(300), np.arange(300.0))))
    assert store.n_seen == 3000 and store.n_points <= 1000 and store.stride == 4
    start, end = store.rays()
    # a quarter turn: the laser frame's x is the world's y
    np.testing.assert_allclose(end[0], [0.0, 1.0], atol=1e-6)
    np.testing.assert_allclose(start[-1], [9.0, 0.0])
    # a thinned scan is a copy: a view would keep every beam of the scan in memory
    assert all(q.base is None for q in store.points)
    assert sum(q.nbytes for q in store.points) == 8 * store.n_points


# ----------------------------------------------------------------------------- 3: the results MCAP
def read_mcap(path: Path) -> dict[str, list[dict]]:
    """{topic: [payload]} of a results MCAP, each payload checked against the schema embedded with it."""
    out: dict[str, list[dict]] = {}
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            payload = json.loads(message.data)
            validate(payload, json.loads(schema.data), channel.topic)
            out.setdefault(channel.topic, []).append(payload)
    return out


def yaw_of(q: dict) -> float:
    return 2 * math.atan2(q["z"], q["w"])


def test_results_mcap_places_the_robot_and_its_scans_alone(far_log, far_run):
    msgs = read_mcap(far_run["mcap"])
    tr = read_csv(far_run["out"] / "trajectory.csv")
    n = len(tr["step"])
    # odom → base_link from the log's odometry (the log has no tf for it)
    odom_tf = msgs["/cornerslam/odom_tf"]
    assert len(odom_tf) == n
    assert {(m["parent_frame_id"], m["child_frame_id"]) for m in odom_tf} == {("odom", "base_link")}
    # the chain map → odom → base_link puts the base at the corrected pose
    for i in (0, n // 2, n - 1):
        a, b = msgs["/cornerslam/tf"][i], odom_tf[i]
        chain = matrix(a["translation"]["x"], a["translation"]["y"], yaw_of(a["rotation"])) @ matrix(
            b["translation"]["x"], b["translation"]["y"], yaw_of(b["rotation"])
        )
        np.testing.assert_allclose(pose_of(chain)[:2], [tr["x"][i], tr["y"][i]], atol=1e-6)
    # the scans, in map, on the world's walls
    scans = msgs["/cornerslam/scan"]
    assert len(scans) == n and {m["frame_id"] for m in scans} == {"map"}
    assert scans[0]["point_stride"] == 8 and [f["name"] for f in scans[0]["fields"]] == ["x", "y"]
    assert {m["pose"]["orientation"]["w"] for m in scans} == {1.0}  # each cloud at its pose: a position

    def placed(m: dict) -> np.ndarray:
        at = m["pose"]["position"]
        return np.frombuffer(base64.b64decode(m["data"]), "<f4").reshape(-1, 2) + (at["x"], at["y"])

    pts = np.concatenate([placed(m) for m in scans])
    assert len(pts) > 10_000
    d = distance_to_walls(apply(WORLD_FROM_ODOM, pts[::20].astype(float)), far_log["world"].walls)
    assert np.percentile(d, 95) < 0.05


def test_results_mcap_leaves_odom_to_base_to_a_log_that_has_it(tmp_path):
    """A log whose odometry is tf odom → base_link: the results MCAP must not publish it again."""
    scans = [
        RawScan(float(i), -1.5, 0.01, np.full(301, 3.0, np.float32), 0.05, 20.0, "laser") for i in range(5)
    ]
    odoms = [OdomSample(float(i), 0.1 * i, 0.0, 0.0) for i in range(5)]
    log = write_mcap(tmp_path / "tf.mcap", scans, odoms, odom_as_tf=True)
    res = CliRunner().invoke(
        cli, ["run", str(log), "--out", str(tmp_path / "o"), "-q", "--mcap-out", str(tmp_path / "r.mcap")]
    )
    assert res.exit_code == 0, res.output
    assert json.loads((tmp_path / "o" / "summary.json").read_text())["input"]["odom_on_tf"] is True
    msgs = read_mcap(tmp_path / "r.mcap")
    assert "/cornerslam/odom_tf" not in msgs and len(msgs["/cornerslam/tf"]) == 5


# ----------------------------------------------------------------------------- 6: the laser mount
def test_a_log_without_tf_says_the_mount_is_the_default_and_warns(far_log, far_run):
    summary = json.loads((far_run["out"] / "summary.json").read_text())
    assert summary["input"]["laser_to_base_source"] == "default"
    assert any("no tf base_link→laser" in w and "input.laser" in w for w in summary["warnings"])
    assert "laser mount: x=0.000 m y=0.000 m yaw=0.000 rad (the built-in default" in far_run["stdout"]
    res = CliRunner().invoke(cli, ["info", str(far_log["log"])])
    assert res.exit_code == 0 and "laser     not on tf: from the config's input.laser" in res.output


@pytest.mark.parametrize(
    ("args", "source"),
    [
        (["--set", "input.laser.x=0.1"], "config"),
        (["--set", "input.laser.from_tf=false"], "config"),
        # zeros set are the config's too: they were "the built-in default: … not in the config", warned
        (["--set", "input.laser.x=0", "--set", "input.laser.y=0", "--set", "input.laser.yaw=0"], "config"),
        (["--set", "input.laser={yaw: 0.0}"], "config"),
    ],
)
def test_a_mount_given_in_the_config_is_not_warned(far_log, tmp_path, args, source):
    out = tmp_path / "o"
    res = CliRunner().invoke(cli, ["run", str(far_log["log"]), "--out", str(out), *args])
    assert res.exit_code == 0, res.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["input"]["laser_to_base_source"] == source
    assert not any("→laser" in w for w in summary["warnings"])
    assert "(from the config's input.laser)" in res.stdout and "not in the config" not in res.stdout


def test_mount_from_tf_and_from_a_preset(tmp_path, monkeypatch):
    from cornerslam_cli import lasers
    from cornerslam_cli.config import Config, from_dict

    preset = lasers.PRESETS["hokuyo_270deg"]
    with_mount = lasers.LaserPreset(preset.description, preset.beams, preset.increment_deg,
                                    {**preset.config, "input": {"laser": {"x": 0.2}}})  # fmt: skip
    monkeypatch.setitem(lasers.PRESETS, "hokuyo_270deg", with_mount)
    cfg = from_dict(Config, {"input": {"laser_preset": "hokuyo_270deg", "laser": {"x": 0.2}}})
    assert lasers.mount_source(cfg) == "preset"
    cfg = from_dict(Config, {"input": {"laser_preset": "hokuyo_270deg", "laser": {"x": 0.3}}})
    assert lasers.mount_source(cfg) == "config"
    scans = [
        RawScan(float(i), -1.5, 0.01, np.full(301, 3.0, np.float32), 0.05, 20.0, "laser") for i in range(5)
    ]
    odoms = [OdomSample(float(i), 0.1 * i, 0.0, 0.0) for i in range(5)]
    log = write_mcap(tmp_path / "tf.mcap", scans, odoms, tf_static=(0.1, 0.0, 0.0))
    res = CliRunner().invoke(cli, ["run", str(log), "--out", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    assert "laser mount: x=0.100 m y=0.000 m yaw=0.000 rad (from the log's tf)" in res.output
    assert json.loads((tmp_path / "o" / "summary.json").read_text())["input"]["laser_to_base_source"] == "tf"


# ----------------------------------------------------------------------------- 7: same stem, default out
def test_two_logs_with_one_stem_never_share_the_default_output(far_log, tmp_path, monkeypatch):
    for d in ("a", "b"):
        (tmp_path / d).mkdir()
        (tmp_path / d / "far.mcap").write_bytes(far_log["log"].read_bytes())
    monkeypatch.chdir(tmp_path)
    runner = CliRunner()
    assert runner.invoke(cli, ["run", "a/far.mcap", "-q"]).exit_code == 0
    out = tmp_path / "cornerslam_out" / "far_pca"
    before = (out / "trajectory.csv").read_bytes()
    assert runner.invoke(cli, ["run", "a/far.mcap", "-q"]).exit_code == 0  # the same log again: replaced
    res = runner.invoke(cli, ["run", "b/far.mcap", "-q"])
    assert res.exit_code == 2
    line = res.output.strip()
    assert line.count("\n") == 0 and line.startswith("error: 'cornerslam_out/far_pca' holds the output of")
    assert str(tmp_path / "a" / "far.mcap") in line and "b/far.mcap" in line and "--out" in line
    assert (out / "trajectory.csv").read_bytes() == before
    assert json.loads((out / MARKER).read_text())["log"] == str(tmp_path / "a" / "far.mcap")
    assert runner.invoke(cli, ["run", "b/far.mcap", "-q", "--out", "cornerslam_out/far_pca"]).exit_code == 0
    res = runner.invoke(cli, ["compare", "a/far.mcap", "-q", "--assoc", "icnn"])
    assert res.exit_code == 0, res.output
    res = runner.invoke(cli, ["compare", "b/far.mcap", "-q", "--assoc", "icnn"])
    assert res.exit_code == 2 and "far_compare" in res.output


def test_an_output_without_the_log_in_its_marker_is_judged_by_its_summary(far_log, tmp_path, monkeypatch):
    """An output of a version before the marker held the log: summary.json's input.log decides."""
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "far.mcap").write_bytes(far_log["log"].read_bytes())
    monkeypatch.chdir(tmp_path)
    runner = CliRunner()
    assert runner.invoke(cli, ["run", str(far_log["log"]), "-q"]).exit_code == 0
    marker_path = tmp_path / "cornerslam_out" / "far_pca" / MARKER
    marker = json.loads(marker_path.read_text())
    del marker["log"]
    marker_path.write_text(json.dumps(marker))
    res = runner.invoke(cli, ["run", "b/far.mcap", "-q"])
    assert res.exit_code == 2 and str(far_log["log"]) in res.output
    assert runner.invoke(cli, ["run", str(far_log["log"]), "-q"]).exit_code == 0


def test_compiled_ray_tracing_counts_the_cells_of_line_cells_and_saturates():
    """trace() counts, per cell, the ends (hits) and the other sampled cells (passes) of line_cells'
    numpy sampling exactly — rays in every direction, short and long, some ending in their own start
    cell — and a count stops at COUNT_MAX instead of wrapping round."""
    rng = np.random.default_rng(2)
    start = rng.uniform(0.0, 4.0, (3_000, 2))
    end = start + rng.normal(0.0, 1.0, (3_000, 2)) * rng.choice([0.01, 1.0], (3_000, 1))
    end = np.clip(end, 0.0, 4.0)
    lo, res, cols = np.zeros(2), 0.05, 82
    beam, cells, ends = line_cells(start, end, lo, res, cols)
    want_hits, want_passes = np.zeros(82 * 82, np.int64), np.zeros(82 * 82, np.int64)
    np.add.at(want_hits, ends, 1)
    np.add.at(want_passes, cells[cells != ends[beam]], 1)
    hits, passes = np.zeros(82 * 82, np.uint16), np.zeros(82 * 82, np.uint16)
    trace(cell_units(start, lo, res), cell_units(end, lo, res), cols, hits, passes)
    assert np.array_equal(hits, want_hits) and np.array_equal(passes, want_passes)
    assert want_passes.sum() > 5 * len(start) and (want_hits > 1).any()
    hits[ends[0]] = COUNT_MAX - 3
    trace(
        cell_units(start[:1], lo, res).repeat(10, 0),
        cell_units(end[:1], lo, res).repeat(10, 0),
        cols,
        hits,
        passes,
    )
    assert hits[ends[0]] == COUNT_MAX  # not wrapped round


def test_grid_extent_is_the_box_of_every_ray_start_and_end():
    """The extent, read from the stored float32 points a part at a time, is the box of the rays'
    starts and ends in float64 — a scan without points adds no start (its laser is far away here)."""
    rng = np.random.default_rng(6)
    store = ScanStore()
    for i in range(40):
        pose = np.array([*rng.normal(0.0, 2.0, 2), rng.uniform(-math.pi, math.pi)])
        store.add(
            pose if i % 9 else np.array([50.0, -50.0, 0.0]), rng.normal(0.0, 3.0, ((i % 9 > 0) * 30, 2))
        )
    start, end = store.rays()
    lo, hi = occupancy.extent(store, store.parts(100))
    assert np.array_equal(lo, np.minimum(start.min(0), end.min(0))) and lo.dtype == np.float64
    assert np.array_equal(hi, np.maximum(start.max(0), end.max(0))) and hi.max() < 20.0


def test_classify_by_hand():
    hits = np.array([0, 0, 1, 1, 2, 7_000], dtype=np.uint16)
    passes = np.array([0, 5, 3, 4, 6, 21_000], dtype=np.uint16)
    # unknown, free, 1 of 4 beams end here: occupied, 1 of 5: free, 2 of 8: occupied, 1 of 4: occupied
    assert classify(hits, passes).tolist() == [UNKNOWN, FREE, OCCUPIED, FREE, OCCUPIED, OCCUPIED]


def test_without_scan_matching_there_is_no_scan_matched_trajectory(far_log, tmp_path):
    out = tmp_path / "o"
    res = CliRunner().invoke(
        cli, ["run", str(far_log["log"]), "--out", str(out), "-q", "--set", "scan_match.enabled=false"]
    )
    assert res.exit_code == 0, res.output
    assert not (out / "scan_matched.tum").exists()
    _, est = read_tum(out / "trajectory.tum")
    _, odom = read_tum(out / "odometry.tum")
    np.testing.assert_allclose(est[0], odom[0], atol=1e-8)
    np.testing.assert_allclose(odom[0], far_log["gt"][0], atol=1e-8)  # the log's first odometry pose
    assert "scan_matched.tum" not in json.loads((out / MARKER).read_text())["files"]


TFS = ("tf", "odom_tf")


@pytest.mark.parametrize("encoding", ["cdr", "ros1", "json"])
def test_the_odometrys_own_frame_is_the_one_map_hangs_from(tmp_path, encoding):
    """Odometry given in frame wheel_odom (its header frame_id): the results MCAP hung map from 'odom', a
    frame the log never had, and gave base_link a second parent (a ROS-user probe). The frame_id is
    taken, as the child_frame_id is for the robot's frame, unless input.odom_frame is set (to another
    frame than the default's: as input.base_frame, a key left at its default cannot be told from unset)."""
    scans = [
        RawScan(float(i), -1.5, 0.01, np.full(301, 3.0, np.float32), 0.05, 20.0, "laser") for i in range(5)
    ]
    odoms = [OdomSample(float(i), 0.1 * i, 0.0, 0.0) for i in range(5)]
    log = write_mcap(tmp_path / "w.mcap", scans, odoms, encoding=encoding, odom_frame="wheel_odom")
    for sets, frame in (([], "wheel_odom"), (["--set", "input.odom_frame=odom_combined"], "odom_combined")):
        out, mcap = tmp_path / f"o{len(sets)}", tmp_path / f"r{len(sets)}.mcap"
        args = ["run", str(log), "--out", str(out), "-q", "--mcap-out", str(mcap), *sets]
        res = CliRunner().invoke(cli, args)
        assert res.exit_code == 0, res.output
        assert json.loads((out / "summary.json").read_text())["input"]["odom_frame"] == frame
        msgs = read_mcap(mcap)
        links = [{(m["parent_frame_id"], m["child_frame_id"]) for m in msgs[f"/cornerslam/{t}"]} for t in TFS]
        assert links == [{("map", frame)}, {(frame, "base_link")}]


@pytest.mark.parametrize(
    ("frame_id", "child", "tf_odom", "taken", "on_tf"),
    [
        ("base_link", "", None, "odom", False),  # the robot's own frame: its mount edge must stay one
        ("map", "base_link", None, "odom", False),  # the results MCAP's own frame: map → map
        ("wheel_odom", "base_link", ("odom", "base_link"), "odom", True),  # the log's tf says otherwise
        ("wheel_odom", "base_link", ("wheel_odom", "base_link"), "wheel_odom", True),  # the tf agrees
    ],
)
def test_an_odometry_frame_the_tf_does_not_bear_out_is_not_taken(
    tmp_path, frame_id, child, tf_odom, taken, on_tf
):
    """The Odometry's frame_id is taken only where the log's tf agrees with it (a review: frame_id
    base_link dropped the laser mount's edge, map gave the results MCAP map → map, and wheel_odom beside
    tf odom → base_link gave base_link two parents); the mount stays the tf's."""
    from _log_fixtures import make_odoms, make_scans, write_messages_mcap

    from cornerslam_cli.logs import open_log
    from cornerslam_cli.logs.writers import serializer
    from cornerslam_cli.logs.writers.ros import LASERSCAN, ODOMETRY, TFMESSAGE

    ros, ns = serializer("cdr"), (lambda t: int(round(t * 1e9)))
    scans, odoms = make_scans(10), make_odoms(11)
    msgs = [("/tf_static", TFMESSAGE, ns(0.0), ros.tf(0.0, "base_link", scans[0].frame_id, 0.3, 0.1, 0.5))]
    msgs += [("/scan", LASERSCAN, ns(s.stamp), ros.laserscan(s)) for s in scans]
    for o in odoms:
        msgs.append(("/odom", ODOMETRY, ns(o.stamp), ros.odometry(o, frame_id, child)))
        if tf_odom:
            msgs.append(("/tf", TFMESSAGE, ns(o.stamp), ros.tf(o.stamp, *tf_odom, o.x, o.y, o.theta)))
    log = write_messages_mcap(tmp_path / "f.mcap", sorted(msgs, key=lambda m: m[2]))
    with open_log(log) as reader:
        assert reader.laser_to_base() == pytest.approx((0.3, 0.1, 0.5))
        assert (reader.odom_frame, reader.odom_on_tf) == (taken, on_tf)
