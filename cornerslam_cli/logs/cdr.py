"""Decoding of the three message types cornerslam reads, from ROS 2 CDR or ROS 1 serialization.

sensor_msgs/LaserScan is decoded by hand (struct + ``np.frombuffer``): it is the bulk of every log.
nav_msgs/Odometry is decoded by hand too (header, child_frame_id, pose: the 56 bytes we need);
rosbags' generic deserializer spends ~40 µs on its covariance arrays, which halved the read rate
(one odometry message per scan). Both are checked against rosbags in the tests. tf messages go
through rosbags' typestores (``Stores.ROS2_HUMBLE`` for CDR, ``Stores.ROS1_NOETIC`` for ROS 1),
with types the store lacks registered from the schema text stored in the log.

LaserScan layout (both encodings): Header (ROS 1: uint32 seq first; stamp int32 sec, uint32 nsec;
string frame_id), float32 angle_min, angle_max, angle_increment, time_increment, scan_time,
range_min, range_max, float32[] ranges, float32[] intensities.
CDR: 4-byte encapsulation header (``00 01`` little endian, ``00 00`` big endian), strings are a
uint32 length including the NUL, fields aligned to their size relative to the end of the
encapsulation header. ROS 1: little endian, strings without NUL, no alignment.
"""

from __future__ import annotations

import re
import struct
from functools import lru_cache
from typing import NamedTuple

import numpy as np
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

from .base import Channel, normalize_msgtype, ros2_typename, strip_frame

Stamp = tuple[int, int]


class LaserScanTuple(NamedTuple):
    """The fields of a sensor_msgs/LaserScan that a run uses (ranges as float32, as in the message)."""

    stamp: Stamp
    frame_id: str
    angle_min: float
    angle_max: float
    angle_increment: float
    range_min: float
    range_max: float
    ranges: np.ndarray
    time_increment: float  # s between beams; 0 = not given


_HDR_LE = struct.Struct("<iII")
_HDR_BE = struct.Struct(">iII")
_SCAN_LE = struct.Struct("<7fI")
_SCAN_BE = struct.Struct(">7fI")
_ROS1_HDR = struct.Struct("<IiII")
_F32_LE = np.dtype("<f4")
_F32_BE = np.dtype(">f4")


_U32_LE = struct.Struct("<I")
_U32_BE = struct.Struct(">I")


class DecodeError(ValueError):
    """A message's bytes do not hold what its type says."""


def _check_intensities(data: bytes | memoryview, off: int, u32: struct.Struct) -> None:
    """The intensities sequence after the ranges must fit the message too (catches truncation)."""
    if off + 4 > len(data):
        raise DecodeError("LaserScan intensities missing (message truncated)")
    (m,) = u32.unpack_from(data, off)
    if off + 4 + 4 * m > len(data):
        raise DecodeError(f"LaserScan intensities ({m}) overrun the message ({len(data)} bytes)")


def decode_laserscan_cdr(data: bytes | memoryview) -> LaserScanTuple:
    """(stamp, frame_id, angle_min, angle_max, angle_increment, range_min, range_max, ranges float32,
    time_increment)."""
    size = len(data)
    if size < 24:
        raise DecodeError(f"LaserScan of {size} bytes is too short")
    kind = data[1]
    if data[0] != 0 or kind not in (0, 1):
        raise DecodeError(f"unsupported CDR encapsulation {bytes(data[:2]).hex()}")
    le = kind == 1
    sec, nsec, slen = (_HDR_LE if le else _HDR_BE).unpack_from(data, 4)
    off = 16 + slen
    if slen == 0 or off + 32 > size:
        raise DecodeError("LaserScan frame_id overruns the message")
    frame = bytes(data[16 : off - 1]).decode("utf-8", "replace")
    off = 4 + ((off - 4 + 3) & ~3)  # align 4 (relative to the encapsulation header)
    a_min, a_max, a_inc, t_inc, _, r_min, r_max, n = (_SCAN_LE if le else _SCAN_BE).unpack_from(data, off)
    off += 32
    if off + 4 * n > size:
        raise DecodeError(f"LaserScan ranges ({n}) overrun the message ({size} bytes)")
    _check_intensities(data, off + 4 * n, (_U32_LE if le else _U32_BE))
    ranges = np.frombuffer(data, dtype=_F32_LE if le else _F32_BE, count=n, offset=off)
    return LaserScanTuple((sec, nsec), frame, a_min, a_max, a_inc, r_min, r_max, ranges, t_inc)


def decode_laserscan_ros1(data: bytes | memoryview) -> LaserScanTuple:
    """As :func:`decode_laserscan_cdr`, for ROS 1 serialization."""
    size = len(data)
    if size < 48:
        raise DecodeError(f"LaserScan of {size} bytes is too short")
    _, sec, nsec, slen = _ROS1_HDR.unpack_from(data, 0)
    off = 16 + slen
    if off + 32 > size:
        raise DecodeError("LaserScan frame_id overruns the message")
    frame = bytes(data[16:off]).decode("utf-8", "replace")
    a_min, a_max, a_inc, t_inc, _, r_min, r_max, n = _SCAN_LE.unpack_from(data, off)
    off += 32
    if off + 4 * n > size:
        raise DecodeError(f"LaserScan ranges ({n}) overrun the message ({size} bytes)")
    _check_intensities(data, off + 4 * n, _U32_LE)
    ranges = np.frombuffer(data, dtype=_F32_LE, count=n, offset=off)
    return LaserScanTuple((sec, nsec), frame, a_min, a_max, a_inc, r_min, r_max, ranges, t_inc)


def _odometry_head_cdr(data: bytes | memoryview) -> tuple[str, Stamp, int, int]:
    """(byte order, stamp, offset of child_frame_id's length, that length) of a CDR nav_msgs/Odometry."""
    size = len(data)
    if size < 20 or data[0] != 0 or data[1] not in (0, 1):
        raise DecodeError("Odometry too short or unsupported CDR encapsulation")
    e = "<" if data[1] == 1 else ">"
    sec, nsec, slen = struct.unpack_from(e + "iII", data, 4)
    off = 4 + ((16 + slen - 4 + 3) & ~3)  # after frame_id, aligned 4
    if off + 4 > size:
        raise DecodeError("Odometry frame_id overruns the message")
    (clen,) = struct.unpack_from(e + "I", data, off)
    return e, (sec, nsec), off, clen


def _odometry_head_ros1(data: bytes | memoryview) -> tuple[Stamp, int, int]:
    """As :func:`_odometry_head_cdr` (without the byte order), for ROS 1 serialization."""
    size = len(data)
    if size < 20:
        raise DecodeError("Odometry too short")
    _, sec, nsec, slen = _ROS1_HDR.unpack_from(data, 0)
    off = 16 + slen
    if off + 4 > size:
        raise DecodeError("Odometry frame_id overruns the message")
    (clen,) = _U32_LE.unpack_from(data, off)
    return (sec, nsec), off, clen


def _text(data: bytes | memoryview, start: int, length: int, what: str) -> str:
    """The string of ``length`` bytes at ``start`` (a CDR string's NUL dropped)."""
    if start + length > len(data):
        raise DecodeError(f"{what} overruns the message")
    return bytes(data[start : start + length]).rstrip(b"\0").decode("utf-8", "replace")


def odometry_frame_cdr(data: bytes | memoryview) -> str:
    """The child_frame_id of a CDR nav_msgs/Odometry: the frame whose pose it gives (the robot's)."""
    _, _, off, clen = _odometry_head_cdr(data)
    return _text(data, off + 4, clen, "Odometry child_frame_id")


def odometry_frame_ros1(data: bytes | memoryview) -> str:
    """As :func:`odometry_frame_cdr`, for ROS 1 serialization."""
    _, off, clen = _odometry_head_ros1(data)
    return _text(data, off + 4, clen, "Odometry child_frame_id")


def odometry_parent_cdr(data: bytes | memoryview) -> str:
    """The header frame_id of a CDR nav_msgs/Odometry: the frame its pose is given in (the odometry's)."""
    e, _, _, _ = _odometry_head_cdr(data)
    (slen,) = struct.unpack_from(e + "I", data, 12)
    return _text(data, 16, slen, "Odometry frame_id")


def odometry_parent_ros1(data: bytes | memoryview) -> str:
    """As :func:`odometry_parent_cdr`, for ROS 1 serialization."""
    _odometry_head_ros1(data)
    return _text(data, 16, _ROS1_HDR.unpack_from(data, 0)[3], "Odometry frame_id")


def decode_odometry_cdr(
    data: bytes | memoryview,
) -> tuple[Stamp, float, float, tuple[float, float, float, float]]:
    """(stamp, x, y, quaternion xyzw) of a CDR nav_msgs/Odometry (header, child_frame_id, pose)."""
    size = len(data)
    e, (sec, nsec), off, clen = _odometry_head_cdr(data)
    off = 4 + ((off + 4 + clen - 4 + 7) & ~7)  # after child_frame_id, aligned 8
    if off + 56 > size:
        raise DecodeError("Odometry pose overruns the message")
    x, y, _, qx, qy, qz, qw = struct.unpack_from(e + "7d", data, off)
    return (sec, nsec), x, y, (qx, qy, qz, qw)


def decode_odometry_ros1(
    data: bytes | memoryview,
) -> tuple[Stamp, float, float, tuple[float, float, float, float]]:
    """As :func:`decode_odometry_cdr`, for ROS 1 serialization."""
    size = len(data)
    (sec, nsec), off, clen = _odometry_head_ros1(data)
    off += 4 + clen
    if off + 56 > size:
        raise DecodeError("Odometry pose overruns the message")
    x, y, _, qx, qy, qz, qw = struct.unpack_from("<7d", data, off)
    return (sec, nsec), x, y, (qx, qy, qz, qw)


@lru_cache(maxsize=2)
def typestore(encoding: str):
    """The shared rosbags typestore for ``cdr`` (ROS 2 Humble) or ``ros1`` (ROS 1 Noetic)."""
    return get_typestore(Stores.ROS1_NOETIC if encoding == "ros1" else Stores.ROS2_HUMBLE)


def ensure_type(channel: Channel) -> str:
    """Typestore name of the channel's type, registering it from the log's schema if missing."""
    store = typestore(channel.encoding)
    name = ros2_typename(channel.msgtype)
    if name in store.fielddefs:
        return name
    if not channel.msgdef:
        raise DecodeError(f"type {channel.msgtype} unknown and the log holds no definition of it")
    if channel.msgdef_format == "ros2idl":
        types = get_types_from_idl(channel.msgdef)
    else:
        types = get_types_from_msg(channel.msgdef, name)
    store.register({k: v for k, v in types.items() if k not in store.fielddefs})
    return name


# the standard messages' fields, in order, as the hand decoders above read them (ROS 1 and ROS 2 alike)
STANDARD_FIELDS = {
    "sensor_msgs/LaserScan": (
        "header", "angle_min", "angle_max", "angle_increment", "time_increment", "scan_time",
        "range_min", "range_max", "ranges", "intensities",
    ),
    "nav_msgs/Odometry": ("header", "child_frame_id", "pose", "twist"),
}  # fmt: skip
# the types of LaserScan's numeric fields (the decoders read them as 4-byte floats)
FLOAT_TYPES = {n: "float32" for n in STANDARD_FIELDS["sensor_msgs/LaserScan"][1:8]} | {
    "ranges": "float32[]",
    "intensities": "float32[]",
}


def definition_note(channel: Channel) -> str:
    """Why a message of ``channel`` may not decode: " (its recorded sensor_msgs/LaserScan is not the
    standard message: fields added: 'quality')" when the definition the log recorded (``ros1msg`` /
    ``ros2msg`` text) has other fields, or LaserScan's numbers in other types, than the standard message
    the decoders read — a vendor's modified copy under the standard name — else "" (the same fields, no
    definition recorded, or one in IDL)."""
    msgtype = normalize_msgtype(channel.msgtype)
    want = STANDARD_FIELDS.get(msgtype)
    if want is None or not channel.msgdef or channel.msgdef_format == "ros2idl":
        return ""
    fields = {}  # name: type, in order
    for line in channel.msgdef.split("\n"):
        if line.startswith("==="):  # the definitions of the types it uses follow
            break
        words = line.split("#", 1)[0].split()
        if len(words) >= 2 and "=" not in "".join(words[1:]):  # (a constant: 'uint8 FRONT=1', 'A = 1')
            fields[words[1]] = re.sub(r"\[<=\d+\]$", "[]", words[0])  # (a bounded sequence reads as one)
    names = tuple(fields)
    retyped = [f"{n!r} is {t}" for n, t in fields.items() if FLOAT_TYPES.get(n, t) != t]
    if names == want and not retyped:
        return ""
    added = [repr(n) for n in names if n not in want]
    lost = [repr(n) for n in want if n not in names]
    parts = (("fields added:", added), ("missing:", lost))
    said = [f"{label} {', '.join(them)}" for label, them in parts if them]
    what = "; ".join(said + retyped) or "its fields in another order"
    return f" (its recorded {msgtype} is not the standard message: {what})"


class Decoder:
    """Decodes the messages of one channel (topic) into plain tuples."""

    def __init__(self, channel: Channel):
        self.channel = channel
        self.ros1 = channel.encoding == "ros1"
        if channel.encoding not in ("cdr", "ros1"):
            raise DecodeError(f"message encoding {channel.encoding!r} not supported (cdr or ros1)")
        self.laserscan = decode_laserscan_ros1 if self.ros1 else decode_laserscan_cdr
        self.odometry = decode_odometry_ros1 if self.ros1 else decode_odometry_cdr
        self.odometry_frame = odometry_frame_ros1 if self.ros1 else odometry_frame_cdr
        self.odometry_parent = odometry_parent_ros1 if self.ros1 else odometry_parent_cdr
        self._name: str | None = None

    def _deserialize(self, data: bytes | memoryview):
        if self._name is None:
            self._name = ensure_type(self.channel)
        store = typestore(self.channel.encoding)
        if self.ros1:
            return store.deserialize_ros1(data, self._name)
        return store.deserialize_cdr(data, self._name)

    def transforms(self, data: bytes | memoryview) -> list:
        """[(parent, child, stamp, translation xyz, quaternion xyzw)] of a tf message."""
        msg = self._deserialize(data)
        out = []
        for tf in msg.transforms:
            t, q = tf.transform.translation, tf.transform.rotation
            out.append(
                (
                    strip_frame(tf.header.frame_id),
                    strip_frame(tf.child_frame_id),
                    (tf.header.stamp.sec, tf.header.stamp.nanosec),
                    (t.x, t.y, t.z),
                    (q.x, q.y, q.z, q.w),
                )
            )
        return out


def is_laserscan(channel: Channel) -> bool:
    return normalize_msgtype(channel.msgtype) == "sensor_msgs/LaserScan"
