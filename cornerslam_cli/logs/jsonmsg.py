"""Decoding of ROS messages recorded as JSON (MCAP channels with message encoding ``json``).

foxglove_bridge / rosbridge clients record what they receive as JSON: the channel's schema name is
the ROS type (``sensor_msgs/msg/LaserScan``, ``nav_msgs/msg/Odometry``, ``tf2_msgs/msg/TFMessage``)
and each message is the ROS message as a JSON object with the ROS field names. Both stamp spellings
occur: ROS 2 ``{"sec", "nanosec"}`` and ROS 1 ``{"secs", "nsecs"}``. JSON has no NaN or infinity:
such ranges arrive as ``null`` (or as Python's ``NaN``/``Infinity`` tokens), both read as NaN (an
invalid beam).

:class:`JsonDecoder` returns the same tuples as :class:`~cornerslam_cli.logs.cdr.Decoder`, so the
readers do not care which encoding a topic has.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from .base import Channel, strip_frame
from .cdr import DecodeError, LaserScanTuple, Stamp

Quaternion = tuple[float, float, float, float]


def _object(data: bytes | memoryview) -> dict:
    try:
        msg = json.loads(bytes(data))
    except (ValueError, UnicodeDecodeError) as exc:  # JSONDecodeError is a ValueError
        raise DecodeError(f"not JSON ({exc})") from exc
    if not isinstance(msg, dict):
        raise DecodeError(f"a JSON {type(msg).__name__}, not an object")
    return msg


def _field(msg: dict, *path: str) -> Any:
    """msg[path[0]][path[1]]...; DecodeError naming the dotted field if it is missing."""
    v: Any = msg
    for i, key in enumerate(path):
        if not isinstance(v, dict) or key not in v:
            raise DecodeError(f"JSON message has no field '{'.'.join(path[: i + 1])}'")
        v = v[key]
    return v


def _number(msg: dict, *path: str) -> float:
    v = _field(msg, *path)
    if v is None:  # how JSON writers spell NaN
        return math.nan
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise DecodeError(f"JSON field '{'.'.join(path)}' is {v!r}, not a number")
    return float(v)


def json_stamp(header: dict) -> Stamp:
    """(sec, nanosec) of a JSON std_msgs/Header: ROS 2 ``sec``/``nanosec`` or ROS 1 ``secs``/``nsecs``."""
    stamp = _field(header, "stamp")
    if not isinstance(stamp, dict):
        raise DecodeError(f"JSON field 'header.stamp' is {stamp!r}, not a time")
    sec_key = "sec" if "sec" in stamp else "secs"
    nsec_key = next((k for k in ("nanosec", "nsecs", "nsec") if k in stamp), "nanosec")
    sec, nsec = _number(stamp, sec_key), _number(stamp, nsec_key)
    if not (sec.is_integer() and nsec.is_integer()):
        raise DecodeError(f"JSON header stamp {stamp!r} is not whole seconds and nanoseconds")
    return int(sec), int(nsec)


def _vector(msg: dict, *path: str, keys: str = "xyz") -> tuple[float, ...]:
    return tuple(_number(msg, *path, k) for k in keys)


def _frame(msg: dict, *path: str) -> str:
    v = _field(msg, *path)
    if not isinstance(v, str):
        raise DecodeError(f"JSON field '{'.'.join(path)}' is {v!r}, not a string")
    return v


class JsonDecoder:
    """Decodes the JSON messages of one channel into the tuples of ``cdr.Decoder``."""

    def __init__(self, channel: Channel):
        self.channel = channel

    def laserscan(self, data: bytes | memoryview) -> LaserScanTuple:
        """(stamp, frame_id, angle_min, angle_max, angle_increment, range_min, range_max, ranges,
        time_increment: 0 when the message has none)."""
        msg = _object(data)
        ranges = _field(msg, "ranges")
        if not isinstance(ranges, list):
            raise DecodeError(f"JSON field 'ranges' is a {type(ranges).__name__}, not a list")
        try:
            r = np.array(ranges, dtype=np.float64)  # null -> NaN
        except (TypeError, ValueError) as exc:
            raise DecodeError(f"JSON field 'ranges' holds something other than numbers ({exc})") from exc
        if r.ndim != 1:
            raise DecodeError("JSON field 'ranges' is not a flat list of numbers")
        a_min, a_max, a_inc, r_min, r_max = (
            _number(msg, k) for k in ("angle_min", "angle_max", "angle_increment", "range_min", "range_max")
        )
        stamp, frame = json_stamp(_field(msg, "header")), _frame(msg, "header", "frame_id")
        t_inc = msg.get("time_increment")  # optional: absent or not a number = not given
        t_inc = float(t_inc) if isinstance(t_inc, (int, float)) and not isinstance(t_inc, bool) else 0.0
        return LaserScanTuple(stamp, frame, a_min, a_max, a_inc, r_min, r_max, r, t_inc)

    def odometry(self, data: bytes | memoryview) -> tuple[Stamp, float, float, Quaternion]:
        """(stamp, x, y, quaternion xyzw) of a nav_msgs/Odometry."""
        msg = _object(data)
        x, y = _vector(msg, "pose", "pose", "position", keys="xy")
        q = _vector(msg, "pose", "pose", "orientation", keys="xyzw")
        return json_stamp(_field(msg, "header")), x, y, q  # type: ignore[return-value]

    def odometry_frame(self, data: bytes | memoryview) -> str:
        """The child_frame_id of a nav_msgs/Odometry: the frame whose pose it gives (the robot's)."""
        return _frame(_object(data), "child_frame_id")

    def odometry_parent(self, data: bytes | memoryview) -> str:
        """The header frame_id of a nav_msgs/Odometry: the frame its pose is given in (the odometry's)."""
        return _frame(_object(data), "header", "frame_id")

    def transforms(self, data: bytes | memoryview) -> list:
        """[(parent, child, stamp, translation xyz, quaternion xyzw)] of a tf message."""
        msg = _object(data)
        tfs = _field(msg, "transforms")
        if not isinstance(tfs, list):
            raise DecodeError("JSON field 'transforms' is not a list")
        out = []
        for tf in tfs:
            if not isinstance(tf, dict):
                raise DecodeError("JSON field 'transforms' holds something other than transforms")
            out.append(
                (
                    strip_frame(_frame(tf, "header", "frame_id")),
                    strip_frame(_frame(tf, "child_frame_id")),
                    json_stamp(_field(tf, "header")),
                    _vector(tf, "transform", "translation"),
                    _vector(tf, "transform", "rotation", keys="xyzw"),
                )
            )
        return out
