"""ROS 1 bags (v2.0) and ROS 2 bag directories (sqlite3 or MCAP storage), written with rosbags."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from ...types import OdomSample
from .base import RawScan
from .ros import RosSerializer, RosTopics, ros_messages


def write_rosbag1(
    path: str | Path,
    scans: Iterable[RawScan],
    odoms: Iterable[OdomSample],
    **topics,
) -> Path:
    """Write a ROS 1 bag (v2.0, uncompressed chunks); ``topics``: the fields of :class:`RosTopics`."""
    from rosbags.rosbag1 import Writer

    ros = RosSerializer("ros1")
    path = Path(path)
    with Writer(path) as w:
        conns = {}
        for topic, typename, t, data in ros_messages(ros, scans, odoms, RosTopics(**topics)):
            if topic not in conns:
                conns[topic] = w.add_connection(
                    topic, typename, typestore=ros.store, latching=1 if topic == "/tf_static" else None
                )
            w.write(conns[topic], t, data)
    return path


def write_rosbag2(
    path: str | Path,
    scans: Iterable[RawScan],
    odoms: Iterable[OdomSample],
    *,
    storage: str = "sqlite3",
    **topics,
) -> Path:
    """Write a ROS 2 bag directory (``storage`` ``sqlite3`` or ``mcap``); ``path`` must not exist;
    ``topics``: the fields of :class:`RosTopics`."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    plugin = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}[storage]
    ros = RosSerializer("cdr")
    path = Path(path)
    with Writer(path, version=9, storage_plugin=plugin) as w:
        conns = {}
        for topic, typename, t, data in ros_messages(ros, scans, odoms, RosTopics(**topics)):
            if topic not in conns:
                conns[topic] = w.add_connection(topic, typename, typestore=ros.store)
            w.write(conns[topic], t, data)
    return path
