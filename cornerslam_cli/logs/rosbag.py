"""ROS 1 ``.bag`` files and ROS 2 bag directories (sqlite3 or mcap storage), through rosbags.

rosbags reads the bag indices at open (counts, time span: ``info()`` is cheap) and streams the
raw message bytes, which go through the same decoders as MCAP (hand-written LaserScan decoder for
ROS 1 and CDR, rosbags' typestore for Odometry and tf). A bag rosbags cannot open (unindexed,
corrupt) raises LogError; data that turns out corrupt while reading ends the read with a warning.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from rosbags.interfaces import MessageDefinitionFormat
from rosbags.rosbag1 import Reader as Reader1
from rosbags.rosbag2 import Reader as Reader2

from ..errors import LogError
from .base import Channel, ReadStats
from .ros import RosLogReader


class RosbagSource:
    """A :class:`~cornerslam_cli.logs.ros.RawSource` over a rosbags reader (ROS 1 or ROS 2)."""

    def __init__(self, path: Path, stats: ReadStats, ros2: bool):
        self.path = Path(path)
        self.stats = stats
        self.format = "rosbag2" if ros2 else "rosbag1"
        self.encoding = "cdr" if ros2 else "ros1"
        kind = "ROS 2 bag" if ros2 else "ROS 1 bag"
        try:
            self._reader = (Reader2 if ros2 else Reader1)(self.path)
            self._reader.open()
        except Exception as exc:  # noqa: BLE001 - rosbags raises many types for bad bags
            hint = "check the bag"
            if "index" in str(exc).lower():
                hint = "the bag is not indexed (recording interrupted?): run `rosbag reindex` on it"
            raise LogError(f"cannot read {kind} '{self.path.name}': {exc}", hint) from exc
        merged: dict[str, Channel] = {}
        for c in self._reader.connections:
            fmt = ""
            if c.msgdef.format == MessageDefinitionFormat.IDL:
                fmt = "ros2idl"
            elif c.msgdef.format == MessageDefinitionFormat.MSG:
                fmt = "ros2msg" if ros2 else "ros1msg"
            enc = getattr(c.ext, "serialization_format", self.encoding) or self.encoding
            prev = merged.get(c.topic)
            count = c.msgcount + (prev.count or 0 if prev else 0)
            merged[c.topic] = Channel(c.topic, c.msgtype, enc, count, c.msgdef.data, fmt)
        self._channels = list(merged.values())

    def channels(self) -> list[Channel]:
        return self._channels

    def time_range(self) -> tuple[int, int] | None:
        r = self._reader
        if not r.message_count:
            return None
        return r.start_time, max(r.start_time, r.end_time - 1)  # rosbags' end_time is last + 1

    def raw_messages(self, topics: set[str]) -> Iterator[tuple[str, int, bytes]]:
        conns = [c for c in self._reader.connections if c.topic in topics]
        if not conns:
            return
        try:
            for conn, t, raw in self._reader.messages(connections=conns):
                yield conn.topic, t, raw
        except Exception as exc:  # noqa: BLE001 - rosbags/sqlite3/mcap errors of a damaged bag
            self.stats.warn("%s: read stopped, the bag is damaged: %s", self.path.name, exc)

    def close(self) -> None:
        try:
            self._reader.close()
        except Exception:  # noqa: BLE001 - closing a half-open reader
            pass


def open_rosbag1(path: Path, **kw) -> RosLogReader:
    stats = ReadStats()
    return RosLogReader(RosbagSource(path, stats, ros2=False), path, stats=stats, **kw)


def open_rosbag2(path: Path, **kw) -> RosLogReader:
    stats = ReadStats()
    return RosLogReader(RosbagSource(path, stats, ros2=True), path, stats=stats, **kw)
