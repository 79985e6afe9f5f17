"""A run's results as an MCAP file for Foxglove, to open beside the input log.

Why JSON: Foxglove reads its well-known schemas (``foxglove.PoseInFrame``, ``foxglove.SceneUpdate``,
...) in any of its encodings, and the JSON one needs nothing beyond the ``mcap`` package we already
depend on: each channel has ``message_encoding="json"`` and a ``jsonschema`` schema named after the
Foxglove type, and each message is a UTF-8 JSON object. Protobuf would add ``protobuf`` plus compiled
descriptors, ``foxglove-sdk`` a native wheel; ROS 2 CDR would need the ``foxglove_msgs`` definitions.
JSON costs file size (about 3–5× protobuf), which is small next to the laser log itself. The schemas
below are the Foxglove JSON schemas (foxglove-sdk ``schemas/jsonschema``) trimmed to the fields we
write — every field Foxglove marks required is kept and filled.

Topics (frame ``map`` is the SLAM map frame, the first corrected pose; log times are the scan stamps
from trajectory.csv, so everything lines up with the input log):

=====================================  =========================  ========================================
topic                                  schema                     messages
=====================================  =========================  ========================================
``/cornerslam/pose``                   foxglove.PoseInFrame       one per step: corrected robot pose
``/cornerslam/odom_pose``              foxglove.PoseInFrame       one per step: odometry, anchored on the
                                                                  first corrected pose
``/cornerslam/path``                   foxglove.PosesInFrame      one, at the first stamp: whole corrected
                                                                  trajectory
``/cornerslam/odom_path``              foxglove.PosesInFrame      one: whole odometry trajectory
``/cornerslam/ground_truth_path``      foxglove.PosesInFrame      one, only with ground truth (SE(2)-
                                                                  aligned like the ATE)
``/cornerslam/tf``                     foxglove.FrameTransform    one per step: ``map`` → odom frame
                                                                  (corrected ∘ the odometry as logged⁻¹;
                                                                  the log's tf odom → base when it has
                                                                  one beside the Odometry topic read)
``/cornerslam/odom_tf``                foxglove.FrameTransform    one per step, only when the log has no
                                                                  tf odom → base: odom → base frame
                                                                  from the log's odometry
``/cornerslam/scan``                   foxglove.PointCloud        one per step (when the run passes its
                                                                  scans): the scan's end points in
                                                                  ``map`` at the corrected pose
``/cornerslam/landmarks``              foxglove.SceneUpdate       one per landmark, at the stamp of the
                                                                  step that created it: sphere, 3σ
                                                                  ellipse (line loop), corner direction
``/cornerslam/segments``               foxglove.SceneUpdate       one per step: that step's segments
                                                                  (line list, kept, so the map builds up)
``/cornerslam/grid``                   foxglove.Grid              one, at the last stamp, when the run wrote
                                                                  map.pgm: the occupancy grid, int8 cells
                                                                  ``occupancy`` 100 / 0 / −1 (occupied /
                                                                  free / unknown, nav_msgs' values)
=====================================  =========================  ========================================

The transform is ``map`` → odom (REP 105: corrected pose ∘ odometry⁻¹), not ``map`` → base: the input
log usually already carries odom → base_link, and a second parent for base_link would make Foxglove's
transform tree flip between the two. With both files open, base_link sits at the corrected pose. A log
without odom → base_link on tf (``input.odom_on_tf`` false in summary.json: odometry from
nav_msgs/Odometry only, CARMEN) gets it here, from the odometry the run used, so the results MCAP
alone places the robot; with the scans in ``map`` it shows the robot moving through its map. The
poses are in the log's odometry frame, so ``map`` and odom coincide at the first scan.
Landmarks are the final estimates (map.csv holds only the final map), shown from their creation on.

Over 400 lines because the Foxglove schemas (trimmed JSON schemas, one per message type written) are
declared here beside the builders that fill them, so a field is added to both in one place.
"""

from __future__ import annotations

import base64
import csv
import json
import logging
from collections.abc import Callable, Sequence
from decimal import Decimal
from pathlib import Path

import numpy as np

from ..errors import display_path
from ..geometry import compose, compose_inverse, interpolate, inverse
from .occupancy import FREE, OCCUPIED, UNKNOWN, Grid, ScanStore, read_grid
from .ownership import RESULTS_MCAP_LIBRARY
from .run_dir import ELLIPSE_SIGMA, ellipse_polygons, load_run
from .tables import json_text

log = logging.getLogger("cornerslam.run")

MAP_FRAME = "map"
TOPICS = {
    "pose": "/cornerslam/pose",
    "odom_pose": "/cornerslam/odom_pose",
    "path": "/cornerslam/path",
    "odom_path": "/cornerslam/odom_path",
    "ground_truth_path": "/cornerslam/ground_truth_path",
    "tf": "/cornerslam/tf",
    "odom_tf": "/cornerslam/odom_tf",
    "scan": "/cornerslam/scan",
    "landmarks": "/cornerslam/landmarks",
    "segments": "/cornerslam/segments",
    "grid": "/cornerslam/grid",
}
LANDMARK_RADIUS = 0.15  # m, sphere diameter in Foxglove
CORNER_ARROW = 0.4  # m, length of the line showing a corner's direction φ


# --- Foxglove JSON schemas (trimmed to the fields written; names as in foxglove-sdk) -------------------
def _obj(title: str, props: dict, required: list[str] | None = None) -> dict:
    return {"title": title, "type": "object", "properties": props, "required": required or list(props)}


def _num() -> dict:
    return {"type": "number"}


def _arr(items: dict) -> dict:
    return {"type": "array", "items": items}


_TIME = {
    "type": "object",
    "title": "time",
    "properties": {"sec": {"type": "integer", "minimum": 0}, "nsec": {"type": "integer", "minimum": 0}},
    "required": ["sec", "nsec"],
}
_DURATION = dict(_TIME, title="duration")
_VECTOR3 = _obj("foxglove.Vector3", {"x": _num(), "y": _num(), "z": _num()})
_POINT3 = _obj("foxglove.Point3", {"x": _num(), "y": _num(), "z": _num()})
_QUATERNION = _obj("foxglove.Quaternion", {"x": _num(), "y": _num(), "z": _num(), "w": _num()})
_COLOR = _obj("foxglove.Color", {"r": _num(), "g": _num(), "b": _num(), "a": _num()})
_POSE = _obj("foxglove.Pose", {"position": _VECTOR3, "orientation": _QUATERNION})
_STRING = {"type": "string"}
_KEY_VALUE = _obj("foxglove.KeyValuePair", {"key": _STRING, "value": _STRING})
_SPHERE = _obj("foxglove.SpherePrimitive", {"pose": _POSE, "size": _VECTOR3, "color": _COLOR})
_LINE = _obj(
    "foxglove.LinePrimitive",
    {
        "type": {"type": "integer", "description": "0 LINE_STRIP, 1 LINE_LOOP, 2 LINE_LIST"},
        "pose": _POSE,
        "thickness": _num(),
        "scale_invariant": {"type": "boolean"},
        "points": _arr(_POINT3),
        "color": _COLOR,
        "colors": _arr(_COLOR),
        "indices": _arr({"type": "integer", "minimum": 0}),
    },
)
_UNUSED_PRIMITIVES = ("arrows", "cubes", "cylinders", "triangles", "texts", "models")  # always empty
_SCENE_ENTITY = _obj(
    "foxglove.SceneEntity",
    {
        "timestamp": _TIME,
        "frame_id": _STRING,
        "id": _STRING,
        "lifetime": _DURATION,
        "frame_locked": {"type": "boolean"},
        "metadata": _arr(_KEY_VALUE),
        "spheres": _arr(_SPHERE),
        "lines": _arr(_LINE),
        **{k: _arr({"type": "object"}) for k in _UNUSED_PRIMITIVES},
    },
)
_FIELD = _obj(
    "foxglove.PackedElementField",
    {"name": _STRING, "offset": {"type": "integer", "minimum": 0}, "type": {"type": "integer"}},
)
SCHEMAS: dict[str, dict] = {
    "foxglove.PoseInFrame": _obj(
        "foxglove.PoseInFrame", {"timestamp": _TIME, "frame_id": _STRING, "pose": _POSE}
    ),
    "foxglove.PosesInFrame": _obj(
        "foxglove.PosesInFrame", {"timestamp": _TIME, "frame_id": _STRING, "poses": _arr(_POSE)}
    ),
    "foxglove.FrameTransform": _obj(
        "foxglove.FrameTransform",
        {
            "timestamp": _TIME,
            "parent_frame_id": _STRING,
            "child_frame_id": _STRING,
            "translation": _VECTOR3,
            "rotation": _QUATERNION,
        },
    ),
    "foxglove.PointCloud": _obj(
        "foxglove.PointCloud",
        {
            "timestamp": _TIME,
            "frame_id": _STRING,
            "pose": _POSE,
            "point_stride": {"type": "integer", "minimum": 0},
            "fields": _arr(_FIELD),
            "data": {"type": "string", "contentEncoding": "base64"},
        },
    ),
    "foxglove.Grid": _obj(
        "foxglove.Grid",
        {
            "timestamp": _TIME,
            "frame_id": _STRING,
            "pose": _POSE,
            "column_count": {"type": "integer", "minimum": 0},
            "cell_size": _obj("foxglove.Vector2", {"x": _num(), "y": _num()}),
            "row_stride": {"type": "integer", "minimum": 0},
            "cell_stride": {"type": "integer", "minimum": 0},
            "fields": _arr(_FIELD),
            "data": {"type": "string", "contentEncoding": "base64"},
        },
    ),
    "foxglove.SceneUpdate": _obj(
        "foxglove.SceneUpdate",
        {"deletions": _arr({"type": "object"}), "entities": _arr(_SCENE_ENTITY)},
    ),
}
TOPIC_SCHEMAS = {
    "pose": "foxglove.PoseInFrame",
    "odom_pose": "foxglove.PoseInFrame",
    "path": "foxglove.PosesInFrame",
    "odom_path": "foxglove.PosesInFrame",
    "ground_truth_path": "foxglove.PosesInFrame",
    "tf": "foxglove.FrameTransform",
    "odom_tf": "foxglove.FrameTransform",
    "scan": "foxglove.PointCloud",
    "landmarks": "foxglove.SceneUpdate",
    "segments": "foxglove.SceneUpdate",
    "grid": "foxglove.Grid",
}


# --- message builders ---------------------------------------------------------------------------------
def stamp_to_ns(text: str) -> int:
    """Decimal seconds as written in trajectory.csv → integer nanoseconds, without float rounding."""
    return int((Decimal(text) * 1_000_000_000).to_integral_value())


def _time(ns: int) -> dict:
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _point(x: float, y: float) -> dict:
    return {"x": float(x), "y": float(y), "z": 0.0}


def _quat(yaw: float) -> dict:
    return {"x": 0.0, "y": 0.0, "z": float(np.sin(yaw / 2)), "w": float(np.cos(yaw / 2))}


def _pose(x: float, y: float, yaw: float = 0.0) -> dict:
    return {"position": _point(x, y), "orientation": _quat(yaw)}


def _color(r: float, g: float, b: float, a: float = 1.0) -> dict:
    return {"r": r, "g": g, "b": b, "a": a}


def _line(kind: int, points: list[dict], color: dict, thickness: float) -> dict:
    return {
        "type": kind,
        "pose": _pose(0.0, 0.0),
        "thickness": thickness,
        "scale_invariant": True,  # thickness in screen pixels
        "points": points,
        "color": color,
        "colors": [],
        "indices": [],
    }


def _entity(ns: int, ident: str, spheres: list, lines: list, metadata: dict | None = None) -> dict:
    return {
        "timestamp": _time(ns),
        "frame_id": MAP_FRAME,
        "id": ident,
        "lifetime": {"sec": 0, "nsec": 0},  # zero: stays until replaced
        "frame_locked": False,
        "metadata": [{"key": k, "value": str(v)} for k, v in (metadata or {}).items()],
        "spheres": spheres,
        "lines": lines,
        **{k: [] for k in _UNUSED_PRIMITIVES},
    }


def _transform(ns: int, parent: str, child: str, pose) -> dict:
    return {"timestamp": _time(ns), "parent_frame_id": parent, "child_frame_id": child,
            "translation": _point(pose[0], pose[1]), "rotation": _quat(pose[2])}  # fmt: skip


INT8, FLOAT32 = 2, 7  # foxglove.NumericType
GRID_VALUES = {OCCUPIED: 100, FREE: 0, UNKNOWN: -1}  # map.pgm's pixels → nav_msgs/OccupancyGrid's values


def _grid(ns: int, grid: Grid) -> dict:
    """A foxglove.Grid of the occupancy grid in ``map``: cell (0, 0) at its origin, rows along +y, one
    int8 ``occupancy`` per cell (GRID_VALUES)."""
    values = np.full(grid.cells.shape, -1, dtype=np.int8)
    for pixel, value in GRID_VALUES.items():
        values[grid.cells == pixel] = value
    cols, size = grid.cells.shape[1], {"x": grid.resolution, "y": grid.resolution}
    return {"timestamp": _time(ns), "frame_id": MAP_FRAME, "pose": _pose(*grid.origin), "column_count": cols,
            "cell_size": size, "row_stride": cols, "cell_stride": 1,
            "fields": [{"name": "occupancy", "offset": 0, "type": INT8}],
            "data": base64.b64encode(values.tobytes()).decode()}  # fmt: skip


def _point_cloud(ns: int, xy: np.ndarray, origin: np.ndarray) -> dict:
    """A foxglove.PointCloud of the points ``xy`` (k, 2) relative to ``origin`` (the cloud's pose) in
    ``map``: float32 x, y per point."""
    fields = [{"name": "x", "offset": 0, "type": FLOAT32}, {"name": "y", "offset": 4, "type": FLOAT32}]
    data = np.ascontiguousarray(xy, dtype="<f4").tobytes()
    return {"timestamp": _time(ns), "frame_id": MAP_FRAME, "pose": _pose(*origin), "point_stride": 8,
            "fields": fields, "data": base64.b64encode(data).decode()}  # fmt: skip


def _poses_in_frame(ns: int, poses: np.ndarray) -> dict:
    return {"timestamp": _time(ns), "frame_id": MAP_FRAME, "poses": [_pose(*p) for p in poses]}


def _stamp_texts(path: Path) -> list[str]:
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        return [row["stamp"] for row in reader]


def write_results_mcap(
    out_dir: Path,
    path: Path,
    results: Path | None = None,
    ground_truth: str | Path | None = None,
    scans: ScanStore | None = None,
    anchors: Sequence[tuple[float, tuple[float, float, float]]] = (),
    clock_offset: int = 0,
    tf_odometry: tuple[np.ndarray, np.ndarray] | None = None,
    warn: Callable[..., None] | None = None,
) -> Path:
    """Write a run directory's trajectory, landmarks and segment map to ``path`` (MCAP, JSON + Foxglove
    schemas); returns ``path``. See the module docstring for the topics. ``results`` is the name of
    the run directory recorded in the metadata (default ``out_dir``; a staging directory's target);
    ``ground_truth`` the TUM file the run was scored against (default: the one its summary names);
    ``scans`` the run's scans, one per step (occupancy.ScanStore), published on ``/cornerslam/scan``;
    ``anchors`` the run's re-anchorings of its odometry (logs/sync.py SyncStats), taken back out of it;
    ``clock_offset`` [ns] added to every log and publish time (the log's recorder clock, ahead of the
    stamps: pipeline.recorder_clock), not to the messages' own timestamps. ``tf_odometry``: the log's tf
    odom → base (stamps, poses) where the run read another odometry: map → odom is built on it at the
    steps inside its span, so that the log's own tf places the robot at its corrected pose."""
    from mcap.writer import Writer

    out_dir, path = Path(out_dir), Path(path)
    run = load_run(out_dir, ground_truth)
    stamp_texts = _stamp_texts(out_dir / "trajectory.csv")
    stamps_ns = [stamp_to_ns(t) for t in stamp_texts]
    ns_of_step = dict(zip(run.steps.astype(int).tolist(), stamps_ns, strict=True))
    # odom-frame poses as logged, for the map → odom transform
    stamps = np.array([float(t) for t in stamp_texts])
    odom_raw = as_logged(read_odom(out_dir), stamps, anchors)
    if tf_odometry is not None:
        odom_raw = on_logged_tf(odom_raw, stamps, *tf_odometry, warn)
    inp = run.summary.config.get("input", {})  # the run's config
    # the frame the odometry gave the poses in (a nav_msgs/Odometry's frame_id), else the config's
    odom_frame = run.summary.input.odom_frame or str(inp.get("odom_frame") or "odom")
    # the frame the odometry gave the pose of (a nav_msgs/Odometry's child_frame_id), else the config's
    base_frame = run.summary.input.base_frame or str(inp.get("base_frame") or "base_link")
    odom_tf = not run.summary.input.odom_on_tf  # the log lacks odom → base on tf (or did not say)

    msgs: list[tuple[int, str, dict]] = []  # (log time ns, topic key, payload)
    for ns, c, o, m in zip(stamps_ns, run.corrected, run.odometry, compose_inverse(run.corrected, odom_raw),
                           strict=True):  # fmt: skip
        msgs.append((ns, "pose", {"timestamp": _time(ns), "frame_id": MAP_FRAME, "pose": _pose(*c)}))
        msgs.append((ns, "odom_pose", {"timestamp": _time(ns), "frame_id": MAP_FRAME, "pose": _pose(*o)}))
        msgs.append((ns, "tf", _transform(ns, MAP_FRAME, odom_frame, m)))
    if odom_tf:
        msgs += [
            (ns, "odom_tf", _transform(ns, odom_frame, base_frame, o))
            for ns, o in zip(stamps_ns, odom_raw, strict=True)
        ]
    if scans is not None:
        msgs += [
            (ns, "scan", _point_cloud(ns, xy, scans.anchor))
            for ns, xy in zip(stamps_ns, scans.points, strict=True)
        ]
    if stamps_ns:
        t0 = stamps_ns[0]
        msgs.append((t0, "path", _poses_in_frame(t0, run.corrected)))
        msgs.append((t0, "odom_path", _poses_in_frame(t0, run.odometry)))
        if run.ground_truth is not None:
            msgs.append((t0, "ground_truth_path", _poses_in_frame(t0, run.ground_truth)))
    msgs += _landmark_messages(run.landmarks, ns_of_step, stamps_ns[0] if stamps_ns else 0)
    msgs += _segment_messages(run.lines, run.steps.astype(int), stamps_ns)
    if stamps_ns and (grid := read_grid(out_dir)) is not None:  # (written before the results MCAP)
        msgs.append((stamps_ns[-1], "grid", _grid(stamps_ns[-1], grid)))
    msgs.sort(key=lambda m: m[0])  # stable: per-stamp order as appended

    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="", library=RESULTS_MCAP_LIBRARY)
        used = {key for _, key, _ in msgs}  # a topic with nothing to say is not declared (an unscored run)
        needed = {TOPIC_SCHEMAS[key] for key in used}
        schema_ids = {
            name: w.register_schema(name, "jsonschema", json.dumps(schema).encode())
            for name, schema in SCHEMAS.items()
            if name in needed
        }
        channels = {
            key: w.register_channel(topic, "json", schema_ids[TOPIC_SCHEMAS[key]])
            for key, topic in TOPICS.items()
            if key in used
        }
        seq: dict[str, int] = dict.fromkeys(TOPICS, 0)
        for ns, key, payload in msgs:
            data = json_text(payload, separators=(",", ":")).encode()
            w.add_message(channels[key], ns + clock_offset, data, ns + clock_offset, seq[key])
            seq[key] += 1
        w.add_metadata(
            "cornerslam",
            {
                "log": run.summary.input.log,
                "assoc": run.assoc,
                "version": run.summary.cornerslam_version,
                "results": display_path(out_dir if results is None else results),  # MCAP strings are UTF-8
            },
        )
        w.finish()
    return path


def as_logged(odom: np.ndarray, stamps: Sequence[float], anchors: Sequence) -> np.ndarray:
    """The odometry poses ``odom`` (n, 3) at ``stamps`` as the log gave them: each re-anchoring's F (from
    its stamp on, corrected = F ∘ raw; ``anchors`` in stamp order) taken back out, raw = F⁻¹ ∘ corrected —
    so that map → odom ∘ the log's own odom → base_link is the corrected pose after an odometry jump too."""
    if not len(anchors) or not len(odom):
        return odom
    at = np.array([a[0] for a in anchors])
    k = np.searchsorted(at, np.asarray(stamps, dtype=float), side="right") - 1  # the anchor in effect
    fix = np.vstack((np.zeros(3), np.array([a[1] for a in anchors])))[k + 1]
    return compose(inverse(fix), odom)


TF_DIFFERS = 0.05  # m: the log's tf odometry this far from the run's is another estimate, warned of


def on_logged_tf(
    odom: np.ndarray,
    stamps: np.ndarray,
    tf_stamps: np.ndarray,
    tf_poses: np.ndarray,
    warn: Callable[..., None] | None = None,
) -> np.ndarray:
    """The odometry poses ``odom`` at ``stamps`` replaced, inside the tf's span, by the log's tf odom → base
    (``tf_stamps``, ``tf_poses``) interpolated there; warned when the two differ by over TF_DIFFERS (the
    tf another estimate of the robot's motion: an EKF's beside the wheels' /odom)."""
    inside = (stamps >= tf_stamps[0]) & (stamps <= tf_stamps[-1])
    if not inside.any():
        return odom
    out = odom.copy()
    out[inside] = interpolate(tf_stamps, tf_poses, stamps[inside])
    off = float(np.max(np.hypot(*(out[inside, :2] - odom[inside, :2]).T)))
    if off > TF_DIFFERS:
        (warn or log.warning)(
            "the log's tf odom → base differs from the odometry the run used by up to %.2f m: the results "
            "MCAP's map → odom is built on the tf's, so the log's own tf places the robot at its corrected "
            "pose", off,
        )  # fmt: skip
    return out


def read_odom(out_dir: Path) -> np.ndarray:
    """Odometry poses (n, 3) in the odom frame (trajectory.csv odom_* columns: re-anchored across any
    odometry jump, :func:`as_logged` gives them as logged)."""
    from .tables import read_csv

    t = read_csv(Path(out_dir) / "trajectory.csv")
    return np.column_stack((t["odom_x"], t["odom_y"], t["odom_theta"]))


def _landmark_messages(lm: dict[str, np.ndarray], ns_of_step: dict[int, int], t0: int) -> list:
    n = len(lm.get("id", ()))
    if n == 0:
        return []
    xy = np.column_stack((lm["x"], lm["y"]))
    cov = np.empty((n, 2, 2))
    cov[:, 0, 0], cov[:, 1, 1] = lm["var_x"], lm["var_y"]
    cov[:, 0, 1] = cov[:, 1, 0] = lm["cov_xy"]
    ellipses = ellipse_polygons(xy, np.nan_to_num(cov), k=24)
    green, orange = _color(0.17, 0.63, 0.17), _color(1.0, 0.5, 0.05)
    out = []
    for i in range(n):
        ident = int(lm["id"][i])
        ns = ns_of_step.get(int(lm["first_step"][i]), t0)
        x, y, phi = float(lm["x"][i]), float(lm["y"][i]), float(lm["phi"][i])
        size = {"x": LANDMARK_RADIUS, "y": LANDMARK_RADIUS, "z": LANDMARK_RADIUS}
        sphere = {"pose": _pose(x, y), "size": size,
                  "color": green}  # fmt: skip
        ellipse = _line(1, [_point(px, py) for px, py in ellipses[i]], green, 2.0)
        tip = _point(x + CORNER_ARROW * np.cos(phi), y + CORNER_ARROW * np.sin(phi))
        direction = _line(0, [_point(x, y), tip], orange, 2.0)
        meta = {
            "id": ident,
            "phi": f"{phi:.4f}",
            "n_obs": int(lm["n_obs"][i]),
            "first_step": int(lm["first_step"][i]),
            "last_step": int(lm["last_step"][i]),
            "ellipse": f"{ELLIPSE_SIGMA:g} sigma",
        }
        update = {
            "deletions": [],
            "entities": [_entity(ns, f"landmark/{ident}", [sphere], [ellipse, direction], meta)],
        }
        out.append((ns, "landmarks", update))
    return out


def _segment_messages(lines: dict[str, np.ndarray], steps: np.ndarray, stamps_ns: list[int]) -> list:
    seg_steps = lines.get("step", np.empty(0)).astype(int)
    order = np.argsort(seg_steps, kind="stable")
    seg_steps = seg_steps[order]
    grey = _color(0.3, 0.3, 0.3, 0.8)
    out = []
    for step, ns in zip(steps.tolist(), stamps_ns, strict=True):
        lo, hi = np.searchsorted(seg_steps, [step, step + 1])
        idx = order[lo:hi]
        entities = []
        if len(idx):
            pts = []
            for j in idx:
                pts += [_point(lines["x1"][j], lines["y1"][j]), _point(lines["x2"][j], lines["y2"][j])]
            entities.append(_entity(ns, f"segments/{step}", [], [_line(2, pts, grey, 1.0)]))
        out.append((ns, "segments", {"deletions": [], "entities": entities}))
    return out
