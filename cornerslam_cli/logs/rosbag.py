"""ROS 1 ``.bag`` files and ROS 2 bags (sqlite3 or mcap storage), through rosbags.

rosbags reads the bag indices at open (counts, time span: ``info()`` is cheap) and streams the
raw message bytes, which go through the same decoders as MCAP (hand-written LaserScan decoder for
ROS 1 and CDR, rosbags' typestore for Odometry and tf). A bag rosbags cannot open (unindexed,
corrupt) raises LogError; data that turns out corrupt while reading ends the read with a warning.

A ROS 2 bag whose storage is one MCAP file is read by cornerslam's own MCAP reader, as that file
given alone is (a file cut by a killed recorder is read up to the cut; a topic's message definition
recorded as "unknown" does not matter). A bag directory without metadata.yaml but with one storage
file (``.mcap`` or ``.db3``) is read from that file, warned; a ``.db3`` may be given alone. rosbags
(0.11) refuses a sqlite3 bag in which a type's definition is recorded in an encoding it does not
know (rosbag2 Iron+ records "unknown", or nothing, for a type whose .msg it could not find): those
definitions are left out (:class:`_Sqlite3`); cornerslam needs none but LaserScan's, Odometry's
and tf's, which it has. metadata.yaml message counts of 0 over a storage that holds messages (a
killed recorder's, an edited bag's) are taken as unknown, warned, not as an empty bag.
"""

from __future__ import annotations

import os
import urllib.parse
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import apsw  # rosbags' SQLite binding (a dependency of rosbags)
import yaml
from rosbags.interfaces import MessageDefinitionFormat
from rosbags.rosbag1 import Reader as Reader1
from rosbags.rosbag2 import Reader as Reader2
from rosbags.rosbag2.reader import DirectoryReader
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader

from ..errors import LogError
from ..ranges import short_text
from .base import Channel, ReadStats
from .mcap import mcap_source
from .ros import RosLogReader, merged

STORAGE_SUFFIXES = (".mcap", ".db3")  # a ROS 2 bag's storage files
DEFINITION_COLUMNS = ("topic_type", "encoding", "encoded_message_definition", "type_description_hash")
KNOWN_DEFINITIONS = ("ros2msg", "ros2idl")  # the encodings of message definitions rosbags reads


def _known_definitions_only(cursor: apsw.Cursor, row: tuple):
    """apsw row tracer: drops a ``message_definitions`` row whose encoding rosbags does not know."""
    if len(row) == 4 and row[1] not in KNOWN_DEFINITIONS:
        if tuple(d[0] for d in cursor.getdescription()) == DEFINITION_COLUMNS:
            return None  # (apsw skips the row)
    return row


def _trace_definitions(conn: apsw.Connection) -> None:
    conn.row_trace = _known_definitions_only


class _Sqlite3(Sqlite3Reader):
    """rosbags' sqlite3 storage, reading past message definitions in an encoding it does not know:
    their rows are left out while it opens the file (a connection hook of apsw, the SQLite binding
    rosbags uses, installed while ``_open`` runs: a connection another thread opens meanwhile gets the
    row tracer too, which drops no message row, those having 3 columns), so those types read as having
    no definition. rosbags ≥ 0.11.6 (its ``_open``; pyproject.toml)."""

    def _open(self) -> None:
        apsw.connection_hooks.append(_trace_definitions)
        try:
            super()._open()
        finally:
            apsw.connection_hooks.remove(_trace_definitions)


class _Directory(DirectoryReader):
    STORAGE_PLUGINS = {**DirectoryReader.STORAGE_PLUGINS, "sqlite3": _Sqlite3}


class _Reader2(Reader2):
    STORAGE_PLUGINS = {**Reader2.STORAGE_PLUGINS, "dir": _Directory, ".db3": _Sqlite3}


META = "metadata.yaml"  # a ROS 2 bag directory's index


class RosbagSource:
    """A :class:`~cornerslam_cli.logs.ros.RawSource` over a rosbags reader (ROS 1 or ROS 2)."""

    def __init__(self, path: Path, stats: ReadStats, ros2: bool):
        self.path = Path(path)
        self.stats = stats
        self.format = "rosbag2" if ros2 else "rosbag1"
        self.encoding = "cdr" if ros2 else "ros1"
        kind = "ROS 2 bag" if ros2 else "ROS 1 bag"
        try:
            self._reader = (_Reader2 if ros2 else Reader1)(self.path)
            self._reader.open()
        except Exception as exc:  # noqa: BLE001 - rosbags raises many types for bad bags
            problem, hint = str(exc), "check the bag"
            if "index" in problem.lower():
                hint = "the bag is not indexed (recording interrupted?): run `rosbag reindex` on it"
            if isinstance(exc, KeyError):  # rosbags' lookup of a message definition's encoding
                problem = f"a message definition is in an encoding rosbags does not read ({exc})"
                hint = "give its storage files (.mcap, .db3) one at a time"
            elif (isinstance(exc, TypeError) or "NoneType" in problem) and (self.path / META).is_file():
                problem = f"a field of its metadata.yaml or storage is missing or mistyped ({problem})"
                hint = "restore its metadata.yaml (`ros2 bag reindex` writes one), or give its storage file"
            elif ros2 and (bad := _unreadable_storage(self.path)):  # (a split bag's last file, cut)
                problem = f"its storage file '{bad}' cannot be read ({problem})"
                hint = (
                    "give the bag's storage files one at a time: the others read alone, and a .mcap cut "
                    "short is read up to its cut; `mcap recover` repairs it"
                    if bad.endswith(".mcap")
                    else "give the bag's other storage files one at a time, each reads alone; sqlite3's "
                    "`.recover` may save the damaged one"
                )
            raise LogError(f"cannot read {kind} '{self.path.name}': {problem}", hint) from exc
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
        if bad := [c.topic for c in self._channels if (c.count or 0) < 0]:  # an edited metadata.yaml's
            self.stats.warn("%s: its metadata.yaml counts a negative number of messages on %s: message "
                            "counts unknown", self.path.name, ", ".join(map(short_text, bad)))  # fmt: skip
            self._channels = [replace(c, count=None) for c in self._channels]
        elif ros2 and self._channels and not self._reader.message_count and self._holds_messages():
            self.stats.warn(
                "%s: its metadata.yaml counts no messages but its storage holds some (metadata.yaml is "
                "stale; `ros2 bag reindex` writes it again): message counts unknown",
                self.path.name,
            )
            self._channels = [replace(c, count=None) for c in self._channels]

    def _holds_messages(self) -> bool:
        """Whether the storage holds a message (asked when the metadata counts none)."""
        try:
            return next(iter(self._reader.messages()), None) is not None
        except Exception:  # noqa: BLE001 - a damaged storage: the read will say so
            return False

    def channels(self) -> list[Channel]:
        return self._channels

    def topic_spans(self) -> dict[str, tuple[int, int]]:
        """Each topic's first and last log time [ns]: a ROS 1 bag's from its index (read at open), a ROS 2
        bag's in sqlite3 storage from its files' message rows (:func:`sqlite_spans`); none else."""
        if self.format == "rosbag2":
            return sqlite_spans(_sqlite_files(self.path))
        out: dict[str, tuple[int, int]] = {}
        for c in self._reader.connections:
            if index := self._reader.indexes.get(c.id):
                out[c.topic] = merged(out.get(c.topic), (index[0].time, index[-1].time))
        return out

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
    """A ROS 2 bag directory, or a ``.db3`` storage file alone (see the module docstring)."""
    stats = ReadStats()
    path = Path(path)
    storage = _sole_storage(path, stats)
    if storage.suffix != ".mcap":
        return RosLogReader(RosbagSource(storage, stats, ros2=True), path, stats=stats, **kw)
    source = mcap_source(storage, stats, f"ROS 2 bag '{path.name}': {storage.name}", "check the bag")
    source.format = "rosbag2"
    return RosLogReader(source, path, stats=stats, **kw)


def _unreadable_storage(directory: Path) -> str | None:
    """Of a split ROS 2 bag (a directory whose metadata.yaml names several storage files), the first
    file rosbags cannot open alone (a recorder killed mid-file leaves the last one cut), else None:
    rosbags refuses the whole bag naming none (a ROS-user probe)."""
    info = _bag_info(directory) if directory.is_dir() else None
    if info is None or info[1] or len(info[2]) < 2:  # (file-compressed: none opens alone; a review)
        return None
    for name in info[2]:
        if not (directory / name).is_file():  # (a missing one: rosbags names it)
            continue
        try:
            reader = _Reader2(directory / name)
            reader.open()
            reader.close()
        except Exception:  # noqa: BLE001 - rosbags raises many types for a bad file
            return name
    return None


def _bag_info(directory: Path) -> tuple[str, bool, list[str], str] | None:
    """(storage identifier, compressed, storage file names, the compression format when each message is
    compressed on its own — ``compression_mode: message`` — else "") from the metadata.yaml in
    ``directory``; None when there is none or it cannot be read so (rosbags, which reads the bag, says
    what is wrong)."""
    try:
        info = yaml.safe_load((directory / META).read_text())["rosbag2_bagfile_information"]
        files = info["relative_file_paths"]
        storage, packed = str(info["storage_identifier"]), str(info.get("compression_format") or "")
        per_message = str(info.get("compression_mode") or "").lower() == "message"
    except Exception:  # noqa: BLE001 - any unreadable metadata: no answer here
        return None
    if not isinstance(files, list):
        return None
    return storage, bool(packed), [str(f) for f in files], (packed or "compressed") if per_message else ""


def _sqlite_files(path: Path) -> list[Path]:
    """The sqlite3 storage files of a ROS 2 bag (a directory, or a ``.db3`` alone): none when its storage
    is compressed or not sqlite3, or its metadata.yaml cannot be read."""
    if path.suffix == ".db3":
        return [path]
    info = _bag_info(path)
    if info is None or info[0] != "sqlite3" or info[1]:
        return []
    return [path / f for f in info[2]]


def sqlite_spans(files: list[Path]) -> dict[str, tuple[int, int]]:
    """Each topic's first and last timestamp [ns] in sqlite3 storage ``files`` (one pass over the messages'
    rows, not their data: 0.35 s for a 620 MB file of 30 topics, where walking the timestamp index per
    topic took 13 s); {} if a file cannot be read so."""
    out: dict[str, tuple[int, int]] = {}
    query = (
        "SELECT topics.name, MIN(messages.timestamp), MAX(messages.timestamp) FROM messages "
        "JOIN topics ON messages.topic_id = topics.id GROUP BY messages.topic_id"
    )
    try:
        for f in files:
            uri = f"file:{urllib.parse.quote(str(f))}?immutable=1"
            conn = apsw.Connection(uri, flags=apsw.SQLITE_OPEN_READONLY | apsw.SQLITE_OPEN_URI)
            try:
                for name, lo, hi in conn.execute(query):
                    out[name] = merged(out.get(name), (lo, hi))
            finally:
                conn.close()
    except apsw.Error:
        return {}
    return out


def split_bag_of(path: Path) -> int | None:
    """The number of storage files of the ROS 2 bag whose metadata.yaml lists the storage file ``path``
    (a bag ``ros2 bag record --max-bag-size`` split) when it is more than one, else None."""
    info = _bag_info(path.parent) if path.suffix in STORAGE_SUFFIXES else None
    files = [Path(f).name for f in info[2]] if info else []
    return len(files) if len(files) > 1 and path.name in files else None


def message_compression_of(path: Path) -> str | None:
    """The compression format (zstd) of the ROS 2 bag whose metadata.yaml lists the storage file ``path``
    when it compresses each message on its own (``compression_mode: message``), else None: such a file
    read alone gives compressed bytes for messages (the bag's directory is read through rosbags)."""
    info = _bag_info(path.parent) if path.suffix in STORAGE_SUFFIXES and not path.is_dir() else None
    if info is None or not info[3] or path.name not in [Path(f).name for f in info[2]]:
        return None
    return info[3]


def _sole_storage(path: Path, stats: ReadStats) -> Path:
    """What to read of a ROS 2 bag: its one MCAP file when metadata.yaml says so (mcap storage, one
    file, no file compression); the one storage file of a directory without metadata.yaml (warned);
    else ``path`` itself (a directory for rosbags, or a ``.db3``)."""
    if not path.is_dir():
        return path
    metadata = path / "metadata.yaml"
    if not metadata.is_file():
        files = sorted(f for f in path.iterdir() if f.suffix in STORAGE_SUFFIXES and f.is_file())
        name = path.name or os.path.basename(os.path.abspath(path))  # `.`: the directory's own name
        if len(files) != 1:
            listed = ", ".join(f.name for f in files[:3]) + (", …" if len(files) > 3 else "")
            raise LogError(
                f"directory '{name}' has no metadata.yaml and {len(files)} storage files"
                + (f" ({listed})" if files else ""),
                f"give one log file; if it is a ROS 2 bag, `ros2 bag reindex {path}` writes its "
                "metadata.yaml again",
            )
        stats.warn("%s has no metadata.yaml: its one storage file %s is read alone", name, files[0].name)
        return files[0]
    info = _bag_info(path)
    if info is not None and info[0] == "mcap" and not info[1] and len(info[2]) == 1:
        sole = path / info[2][0]
        if sole.suffix == ".mcap" and sole.is_file():
            return sole
    return path
