"""MCAP logs (ROS 2 or ROS 1 profile, or JSON as foxglove_bridge / rosbridge record them)."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from ...types import OdomSample
from ..ros import is_static
from .base import RawScan
from .ros import RosTopics, ros_messages, serializer, shuffled

LIBRARY = "cornerslam"  # the Header record's library of a log written here (simulate.py checks it)


def qos_profile(latched: bool) -> str:
    """``offered_qos_profiles`` in rosbag2's numeric (version 8) YAML: reliable, keep last (1 when
    ``latched``, with transient local durability, else 10, volatile), the rest default."""
    zero = "\n    sec: 0\n    nsec: 0"
    return (
        f"- history: 1\n  depth: {1 if latched else 10}\n  reliability: 1\n"
        f"  durability: {1 if latched else 2}\n"
        f"  deadline:{zero}\n  lifespan:{zero}\n  liveliness: 1\n  liveliness_lease_duration:{zero}\n"
        "  avoid_ros_namespace_conventions: false"
    )


def write_mcap(
    path: str | Path,
    scans: Iterable[RawScan],
    odoms: Iterable[OdomSample],
    *,
    encoding: str = "cdr",
    compression: str = "zstd",
    chunk_size: int = 1024 * 1024,
    shuffle_blocks: int = 0,
    summary: bool = True,
    repeat_channels: bool = True,
    metadata: dict[str, dict[str, str]] | None = None,
    **topics,
) -> Path:
    """Write an MCAP log. ``encoding``: ``cdr`` (ROS 2 profile), ``ros1`` (ROS 1 profile), ``json``
    (foxglove_bridge / rosbridge recordings; ``json-ros1`` with ROS 1 field names); ``topics``: the
    fields of :class:`RosTopics`.

    ``shuffle_blocks`` > 0 writes the messages in blocks of that many, the blocks in a seeded random
    order, one message per chunk: a valid file whose chunks are not in log-time order (the whole log
    is held in memory to do so). ``summary=False`` writes no summary section (no chunk index, no
    statistics), as some recorders do; ``repeat_channels=False`` a summary without the channel and
    schema records (they are only in the data section: the mcap writer's option). ``metadata``: MCAP
    Metadata records, name → string map (simulate's record of its companion files).
    """
    from mcap.writer import CompressionType, IndexType, Writer

    ros = serializer(encoding)
    path = Path(path)
    comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}[
        compression
    ]
    messages = ros_messages(ros, scans, odoms, RosTopics(**topics))
    if shuffle_blocks > 0:
        messages, chunk_size = shuffled(messages, shuffle_blocks), 1
    with open(path, "wb") as f:
        no_summary = dict.fromkeys(
            ("repeat_channels", "repeat_schemas", "use_statistics", "use_summary_offsets"), False
        )
        kw = {} if summary else dict(no_summary, index_types=IndexType.NONE)
        if not repeat_channels:
            kw.update(repeat_channels=False, repeat_schemas=False)
        w = Writer(f, chunk_size=chunk_size, compression=comp, **kw)
        w.start(profile=ros.profile, library=LIBRARY)
        channels: dict[str, int] = {}
        for topic, typename, t, data in messages:
            cid = channels.get(topic)
            if cid is None:
                sid = w.register_schema(
                    name=ros.schema_name(typename),
                    encoding=ros.schema_encoding,
                    data=ros.msgdef(typename).encode(),
                )
                # ROS 2: /tf_static offered latched, as tf2's static broadcaster does (ros2 bag play
                # offers what the bag recorded; without it a listener started later never gets the mount)
                latched = ros.profile == "ros2" and is_static(topic)
                meta = {"offered_qos_profiles": qos_profile(True)} if latched else {}
                cid = channels[topic] = w.register_channel(
                    topic=topic, message_encoding=ros.message_encoding, schema_id=sid, metadata=meta
                )
            w.add_message(channel_id=cid, log_time=t, data=data, publish_time=t)
        for name, record in (metadata or {}).items():
            w.add_metadata(name, record)
        w.finish()
    return path


def copy_mcap_without(src: str | Path, dst: str | Path, topics: set[str]) -> Path:
    """``src`` copied to ``dst`` record by record, the messages of ``topics`` left out (a log without its
    odometry, for a run on the scans alone: tests, benchmarks/scan_odometry_panel.py)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(src, "rb") as f, open(dst, "wb") as g:
        w = Writer(g)
        w.start(profile="ros2", library=LIBRARY)
        ids: dict[int, int] = {}
        for schema, channel, m in make_reader(f).iter_messages():
            if channel.topic in topics:
                continue
            if channel.id not in ids:
                sid = w.register_schema(schema.name, schema.encoding, schema.data)
                ids[channel.id] = w.register_channel(channel.topic, channel.message_encoding, sid)
            w.add_message(ids[channel.id], m.log_time, m.data, m.publish_time)
        w.finish()
    return Path(dst)
