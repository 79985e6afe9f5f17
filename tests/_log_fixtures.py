"""Helpers for the log tests: seeded synthetic scans/odometry and one writer per format."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from cornerslam_cli.logs.writers import RawScan, write_carmen, write_mcap, write_rosbag1, write_rosbag2
from cornerslam_cli.types import OdomSample, Scan

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"


def make_scans(
    n: int = 12, beams: int = 181, seed: int = 0, t0: float = 1_700_000_000.0, **kw
) -> list[RawScan]:
    """n scans at 10 Hz (stamps t0 + 0.05 + 0.1 i) with some invalid beams of every kind."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        r = rng.uniform(0.5, 20.0, beams)
        r[rng.integers(0, beams, 5)] = np.inf
        r[rng.integers(0, beams, 3)] = np.nan
        r[rng.integers(0, beams, 2)] = 0.05  # below range_min
        r[rng.integers(0, beams, 2)] = 30.0  # == range_max: no return
        args = dict(angle_min=-math.pi / 2, angle_increment=math.pi / 180, range_min=0.1, range_max=30.0)
        args.update(kw)
        out.append(RawScan(t0 + 0.05 + 0.1 * i, ranges=r, **args))
    return out


def make_odoms(n: int = 12, t0: float = 1_700_000_000.0) -> list[OdomSample]:
    return [OdomSample(t0 + 0.1 * i, 0.1 * i, 0.02 * i, 0.03 * i) for i in range(n)]


def _mcap_ros1(p, s, o, **kw):
    return write_mcap(p, s, o, encoding="ros1", **kw)


def _mcap_json(p, s, o, **kw):
    return write_mcap(p, s, o, encoding="json", **kw)


def _mcap_json_ros1(p, s, o, **kw):
    return write_mcap(p, s, o, encoding="json-ros1", **kw)


def _rosbag2_mcap(p, s, o, **kw):
    return write_rosbag2(p, s, o, storage="mcap", **kw)


# format name -> (file name, writer); all accept tf_static / odom_as_tf except CARMEN
ROS_WRITERS = {
    "mcap-cdr": ("log.mcap", write_mcap),
    "mcap-ros1": ("log.mcap", _mcap_ros1),
    "mcap-json": ("log.mcap", _mcap_json),  # foxglove_bridge / rosbridge recordings
    "mcap-json-ros1": ("log.mcap", _mcap_json_ros1),
    "rosbag1": ("log.bag", write_rosbag1),
    "rosbag2-sqlite3": ("bag2", write_rosbag2),
    "rosbag2-mcap": ("bag2", _rosbag2_mcap),
}
WRITERS = dict(ROS_WRITERS, carmen=("log.clf", write_carmen))


def write_log(fmt: str, tmp_path: Path, scans=None, odoms=None, **kw) -> Path:
    name, writer = WRITERS[fmt]
    scans = make_scans() if scans is None else scans
    odoms = make_odoms() if odoms is None else odoms
    return writer(tmp_path / name, scans, odoms, **kw)


def split(msgs) -> tuple[list[Scan], list[OdomSample]]:
    msgs = list(msgs)
    return [m for m in msgs if isinstance(m, Scan)], [m for m in msgs if isinstance(m, OdomSample)]


def write_messages_mcap(path: Path, messages, encoding: str = "cdr", declared=()) -> Path:
    """MCAP with arbitrary topics: messages = [(topic, typename, log_time_ns, data)]; ``encoding`` cdr,
    ros1 (schemas from rosbags) or json; ``declared``: (topic, typename) channels with no message."""
    from mcap.writer import CompressionType, Writer

    from cornerslam_cli.logs.writers import serializer

    ros = serializer(encoding)
    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.NONE)
        w.start(profile="ros2", library="test")
        chans = {}
        for topic, typename in declared:
            sid = w.register_schema(typename, ros.schema_encoding, ros.msgdef(typename).encode())
            chans[topic] = w.register_channel(topic, ros.message_encoding, sid)
        for topic, typename, t, data in messages:
            if topic not in chans:
                sid = w.register_schema(typename, ros.schema_encoding, ros.msgdef(typename).encode())
                chans[topic] = w.register_channel(topic, ros.message_encoding, sid)
            w.add_message(chans[topic], t, data, t)
        w.finish()
    return path


def scan_messages(topic: str = "/scan", n: int = 5, encoding: str = "cdr", **kw):
    from cornerslam_cli.logs.writers import RosSerializer

    ros = RosSerializer(encoding)
    return [
        (topic, "sensor_msgs/msg/LaserScan", int(s.stamp * 1e9), ros.laserscan(s))
        for s in make_scans(n, **kw)
    ]


def odom_messages(topic: str = "/odom", n: int = 5, encoding: str = "cdr"):
    from cornerslam_cli.logs.writers import RosSerializer

    ros = RosSerializer(encoding)
    return [
        (topic, "nav_msgs/msg/Odometry", int(o.stamp * 1e9), ros.odometry(o, "odom", "base_link"))
        for o in make_odoms(n)
    ]


def rewrite_mcap(src: Path, dst: Path, change) -> Path:
    """``src`` copied to ``dst`` message by message, each as ``change(schema, message)`` gives it:
    (log time ns, publish time ns, data)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(src, "rb") as f, open(dst, "wb") as g:
        w = Writer(g)
        w.start(profile="ros2", library="test")
        ids: dict[int, int] = {}
        for schema, channel, m in make_reader(f).iter_messages():
            if channel.id not in ids:
                sid = w.register_schema(schema.name, schema.encoding, schema.data)
                ids[channel.id] = w.register_channel(channel.topic, channel.message_encoding, sid)
            log_time, publish_time, data = change(schema, m)
            w.add_message(ids[channel.id], log_time, data, publish_time)
        w.finish()
    return dst
