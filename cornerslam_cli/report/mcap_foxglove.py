"""The Foxglove encoding of the results MCAP (report/mcap_out.py's default, ``--mcap-profile foxglove``).

Why JSON: Foxglove reads its well-known schemas (``foxglove.PoseInFrame``, ``foxglove.SceneUpdate``,
...) in any of its encodings, and the JSON one needs nothing beyond the ``mcap`` package we already
depend on: each channel has ``message_encoding="json"`` and a ``jsonschema`` schema named after the
Foxglove type, and each message is a UTF-8 JSON object. Protobuf would add ``protobuf`` plus compiled
descriptors, ``foxglove-sdk`` a native wheel. JSON costs file size (about 3–5× protobuf), which is small
next to the laser log itself. The schemas below are the Foxglove JSON schemas (foxglove-sdk
``schemas/jsonschema``) trimmed to the fields we write — every field Foxglove marks required is kept and
filled.
"""

from __future__ import annotations

import base64
import json

import numpy as np

from .mcap_items import (
    CORNER_ARROW,
    GREEN,
    GREY,
    LANDMARK_DIAMETER,
    MAP_FRAME,
    ORANGE,
    TOPICS,
    Channel,
    LandmarkItem,
)
from .occupancy import Grid
from .run_dir import ELLIPSE_SIGMA
from .tables import json_text


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


# --- message builders (JSON payloads) ---------------------------------------------------------------
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


def _grid(ns: int, grid: Grid) -> dict:
    """A foxglove.Grid of the occupancy grid in ``map``: cell (0, 0) at its origin, rows along +y, one
    int8 ``occupancy`` per cell (Grid.nav_values)."""
    values = grid.nav_values()
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


class FoxgloveEncoding:
    """Foxglove's schemas in JSON (the module docstring): the topics of ``TOPICS``, one schema each."""

    profile = ""  # (MCAP's profile: none)
    metadata: dict[str, dict[str, str]] = {}  # (no metadata records of its own)

    def channel(self, key: str) -> Channel | None:
        if key not in TOPIC_SCHEMAS:  # (a ROS-only item: the scans' origin, which a cloud's pose holds here)
            return None
        name = TOPIC_SCHEMAS[key]
        return Channel(TOPICS[key], name, "jsonschema", json.dumps(SCHEMAS[name]).encode(), "json", {})

    def encode(self, ns: int, key: str, item) -> bytes:
        return json_text(_BUILDERS[key](ns, item), separators=(",", ":")).encode()


def _pose_in_frame(ns: int, pose: np.ndarray) -> dict:
    return {"timestamp": _time(ns), "frame_id": MAP_FRAME, "pose": _pose(*pose)}


def _landmark(ns: int, lm: LandmarkItem) -> dict:
    green, orange = _color(*GREEN), _color(*ORANGE)
    size = {"x": LANDMARK_DIAMETER, "y": LANDMARK_DIAMETER, "z": LANDMARK_DIAMETER}
    sphere = {"pose": _pose(lm.x, lm.y), "size": size, "color": green}
    ellipse = _line(1, [_point(px, py) for px, py in lm.ellipse], green, 2.0)
    direction = _line(0, [_point(lm.x, lm.y), _point(*lm.tip(CORNER_ARROW))], orange, 2.0)
    meta = {
        "id": lm.ident,
        "phi": f"{lm.phi:.4f}",
        "n_obs": lm.n_obs,
        "first_step": lm.first_step,
        "last_step": lm.last_step,
        "ellipse": f"{ELLIPSE_SIGMA:g} sigma",
    }
    entity = _entity(ns, f"landmark/{lm.ident}", [sphere], [ellipse, direction], meta)
    return {"deletions": [], "entities": [entity]}


def _segments(ns: int, item: tuple[int, np.ndarray]) -> dict:
    step, segs = item
    entities = []
    if len(segs):
        pts = [_point(*p) for s in segs for p in (s[:2], s[2:])]
        grey = _color(*GREY)
        entities.append(_entity(ns, f"segments/{step}", [], [_line(2, pts, grey, 1.0)]))
    return {"deletions": [], "entities": entities}


_BUILDERS = {
    "pose": _pose_in_frame,
    "odom_pose": _pose_in_frame,
    "path": lambda ns, item: _poses_in_frame(ns, item[0]),
    "odom_path": lambda ns, item: _poses_in_frame(ns, item[0]),
    "ground_truth_path": lambda ns, item: _poses_in_frame(ns, item[0]),
    "tf": lambda ns, item: _transform(ns, *item),
    "odom_tf": lambda ns, item: _transform(ns, *item),
    "scan": lambda ns, item: _point_cloud(ns, *item),
    "landmarks": _landmark,
    "segments": _segments,
    "grid": _grid,
}
