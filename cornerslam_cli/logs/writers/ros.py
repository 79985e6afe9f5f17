"""ROS messages for the ROS log writers (MCAP, ROS 1 bag, ROS 2 bag): LaserScan, Odometry and tf
built and serialized in one encoding (CDR or ROS 1 with rosbags' typestores, or JSON as
foxglove_bridge / rosbridge record it), and a whole log's messages in stamp order.

The three ROS writers take the options they share (topics, frames, how odometry is written) as
keyword arguments, the fields of :class:`RosTopics`.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass

import numpy as np

from ...types import OdomSample
from ..cdr import typestore
from .base import RawScan, merged, stamp_ns, stamp_parts

LASERSCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
TFMESSAGE = "tf2_msgs/msg/TFMessage"
_TF_MSGDEF = "geometry_msgs/TransformStamped[] transforms\n"

Quaternion = tuple[float, float, float, float]


def quaternion_of_yaw(yaw: float) -> Quaternion:
    return (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))


@dataclass(frozen=True)
class RosTopics:
    """What the ROS writers (MCAP, ROS 1 bag, ROS 2 bag) write where.

    scan_topic, odom_topic : topic names of the LaserScan and Odometry messages
    tf_static : (x, y, yaw) of the laser in base_frame, written once on /tf_static as
        base_frame→frame_id of the scans; None writes no /tf_static
    odom_as_tf : odometry as /tf odom_frame→base_frame instead of a nav_msgs/Odometry topic
    odom_quaternion : the orientation quaternion (x, y, z, w) written for an odometry sample (default:
        the unit quaternion of its theta; the fault tests write unnormalised ones)
    log_time_offset : seconds added to the stamps to make the log (receive) times (a recording of
        simulated time: header stamps from 0, log time from the wall clock)
    """

    scan_topic: str = "/scan"
    odom_topic: str = "/odom"
    tf_static: tuple[float, float, float] | None = None
    odom_as_tf: bool = False
    odom_frame: str = "odom"
    base_frame: str = "base_link"
    odom_quaternion: Callable[[OdomSample], Quaternion] | None = None
    log_time_offset: float = 0.0


class RosSerializer:
    """Builds and serializes LaserScan, Odometry and tf messages in one encoding (``cdr`` or ``ros1``)."""

    def __init__(self, encoding: str):
        if encoding not in ("cdr", "ros1"):
            raise ValueError(f"encoding must be 'cdr' or 'ros1', not {encoding!r}")
        self.ros1 = encoding == "ros1"
        self.store = store = typestore(encoding)
        if TFMESSAGE not in store.fielddefs:  # ROS 1 Noetic store lacks tf2_msgs
            from rosbags.typesys import get_types_from_msg

            store.register(get_types_from_msg(_TF_MSGDEF, TFMESSAGE))
        T = store.types
        self._Time, self._Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
        self._T = T
        # how an MCAP file declares these messages
        self.message_encoding = encoding
        self.schema_encoding = "ros1msg" if self.ros1 else "ros2msg"
        self.profile = "ros1" if self.ros1 else "ros2"

    def schema_name(self, typename: str) -> str:
        return typename.replace("/msg/", "/") if self.ros1 else typename

    def serialize(self, msg, typename: str) -> bytes:
        if self.ros1:
            return bytes(self.store.serialize_ros1(msg, typename))
        return bytes(self.store.serialize_cdr(msg, typename))

    def msgdef(self, typename: str) -> str:
        return self.store.generate_msgdef(typename, ros_version=1 if self.ros1 else 2)[0]

    def header(self, stamp: float, frame: str):
        sec, nsec = stamp_parts(stamp)
        t = self._Time(sec=sec, nanosec=nsec)
        if self.ros1:
            return self._Header(seq=0, stamp=t, frame_id=frame)
        return self._Header(stamp=t, frame_id=frame)

    def laserscan(self, s: RawScan) -> bytes:
        r = np.asarray(s.ranges, dtype=np.float32)
        msg = self._T[LASERSCAN](
            header=self.header(s.stamp, s.frame_id),
            angle_min=float(s.angle_min),
            angle_max=float(s.angle_max),
            angle_increment=float(s.angle_increment),
            time_increment=float(s.time_increment),
            scan_time=0.0,
            range_min=float(s.range_min),
            range_max=float(s.range_max),
            ranges=r,
            intensities=np.zeros(0, dtype=np.float32),
        )
        return self.serialize(msg, LASERSCAN)

    def _pose(self, x: float, y: float, yaw: float, q: Quaternion | None = None):
        T = self._T
        qx, qy, qz, qw = quaternion_of_yaw(yaw) if q is None else q
        return T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0), T["geometry_msgs/msg/Quaternion"](
            x=qx, y=qy, z=qz, w=qw
        )

    def odometry(self, o: OdomSample, odom_frame: str, base_frame: str, q: Quaternion | None = None) -> bytes:
        """A nav_msgs/Odometry of o; ``q`` replaces the orientation quaternion of o.theta."""
        T = self._T
        p, q = self._pose(o.x, o.y, o.theta, q)
        zero3 = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        msg = T[ODOMETRY](
            header=self.header(o.stamp, odom_frame),
            child_frame_id=base_frame,
            pose=T["geometry_msgs/msg/PoseWithCovariance"](
                pose=T["geometry_msgs/msg/Pose"](position=p, orientation=q), covariance=np.zeros(36)
            ),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=zero3, angular=zero3), covariance=np.zeros(36)
            ),
        )
        return self.serialize(msg, ODOMETRY)

    def tf(self, stamp: float, parent: str, child: str, x: float, y: float, yaw: float) -> bytes:
        T = self._T
        p, q = self._pose(x, y, yaw)
        ts = T["geometry_msgs/msg/TransformStamped"](
            header=self.header(stamp, parent),
            child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](
                translation=T["geometry_msgs/msg/Vector3"](x=p.x, y=p.y, z=0.0), rotation=q
            ),
        )
        return self.serialize(T[TFMESSAGE](transforms=[ts]), TFMESSAGE)


class JsonSerializer:
    """LaserScan, Odometry and tf messages as JSON, as foxglove_bridge / rosbridge clients record them
    (MCAP message encoding ``json``, the schema named by the ROS type): ROS 2 field names, or ROS 1
    ones (header seq, stamp secs/nsecs) with ``ros1_names``. NaN and infinite ranges are ``null``."""

    message_encoding = "json"
    schema_encoding = "jsonschema"
    profile = ""

    def __init__(self, ros1_names: bool = False):
        self.ros1 = ros1_names

    def schema_name(self, typename: str) -> str:
        return typename.replace("/msg/", "/") if self.ros1 else typename

    def msgdef(self, typename: str) -> str:
        return json.dumps({"title": self.schema_name(typename), "type": "object"})

    def header(self, stamp: float, frame: str) -> dict:
        sec, nsec = stamp_parts(stamp)
        if self.ros1:
            return {"seq": 0, "stamp": {"secs": sec, "nsecs": nsec}, "frame_id": frame}
        return {"stamp": {"sec": sec, "nanosec": nsec}, "frame_id": frame}

    def laserscan(self, s: RawScan) -> bytes:
        r = np.asarray(s.ranges, dtype=np.float32).tolist()  # the values a float32 message holds
        msg = {
            "header": self.header(s.stamp, s.frame_id),
            **{k: float(np.float32(getattr(s, k))) for k in ("angle_min", "angle_max", "angle_increment")},
            "time_increment": float(s.time_increment),
            "scan_time": 0.0,
            "range_min": float(np.float32(s.range_min)),
            "range_max": float(np.float32(s.range_max)),
            "ranges": [v if math.isfinite(v) else None for v in r],
            "intensities": [],
        }
        return json.dumps(msg, allow_nan=False).encode()

    def odometry(self, o: OdomSample, odom_frame: str, base_frame: str, q: Quaternion | None = None) -> bytes:
        q = quaternion_of_yaw(o.theta) if q is None else q
        zero = dict.fromkeys("xyz", 0.0)
        msg = {
            "header": self.header(o.stamp, odom_frame),
            "child_frame_id": base_frame,
            "pose": {
                "pose": {
                    "position": {"x": o.x, "y": o.y, "z": 0.0},
                    "orientation": dict(zip("xyzw", q, strict=True)),
                },
                "covariance": [0.0] * 36,
            },
            "twist": {"twist": {"linear": zero, "angular": zero}, "covariance": [0.0] * 36},
        }
        return json.dumps(msg).encode()

    def tf(self, stamp: float, parent: str, child: str, x: float, y: float, yaw: float) -> bytes:
        ts = {
            "header": self.header(stamp, parent),
            "child_frame_id": child,
            "transform": {
                "translation": {"x": x, "y": y, "z": 0.0},
                "rotation": dict(zip("xyzw", quaternion_of_yaw(yaw), strict=True)),
            },
        }
        return json.dumps({"transforms": [ts]}).encode()


def serializer(encoding: str) -> RosSerializer | JsonSerializer:
    """The message builder of an MCAP ``encoding``: ``cdr``, ``ros1``, ``json`` or ``json-ros1``."""
    if encoding in ("json", "json-ros1"):
        return JsonSerializer(ros1_names=encoding == "json-ros1")
    return RosSerializer(encoding)


def ros_messages(
    ros: RosSerializer | JsonSerializer, scans: Iterable[RawScan], odoms: Iterable[OdomSample], o: RosTopics
) -> Iterator[tuple[str, str, int, bytes]]:
    """(topic, typename, log_time_ns, data) of a whole log, in stamp order."""
    static_done = o.tf_static is None
    for m in merged(scans, odoms):
        t = stamp_ns(m.stamp + o.log_time_offset)
        if isinstance(m, RawScan):
            if not static_done:
                yield "/tf_static", TFMESSAGE, t, ros.tf(m.stamp, o.base_frame, m.frame_id, *o.tf_static)
                static_done = True
            yield o.scan_topic, LASERSCAN, t, ros.laserscan(m)
        elif o.odom_as_tf:
            yield "/tf", TFMESSAGE, t, ros.tf(m.stamp, o.odom_frame, o.base_frame, m.x, m.y, m.theta)
        else:
            q = o.odom_quaternion(m) if o.odom_quaternion is not None else None
            yield o.odom_topic, ODOMETRY, t, ros.odometry(m, o.odom_frame, o.base_frame, q)


def shuffled(messages: Iterable, block: int) -> Iterator:
    """The messages in blocks of ``block``, the blocks in a seeded random order."""
    items = list(messages)
    blocks = [items[i : i + block] for i in range(0, len(items), block)]
    for i in np.random.default_rng(0).permutation(len(blocks)):
        yield from blocks[i]
