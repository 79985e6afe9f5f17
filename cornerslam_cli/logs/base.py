"""What every log reader provides, and the machinery shared by the ROS-message formats.

A reader yields :class:`~cornerslam_cli.types.Scan` and :class:`~cornerslam_cli.types.OdomSample`
objects in log-time order, streaming (memory does not grow with the log). Format modules
(``mcap.py``, ``rosbag.py``) only provide a :class:`RawSource`: topics and raw serialized messages.
:class:`RosLogReader` does the rest once: topic selection by message type, decoding, tf handling,
counters. ``carmen.py`` implements :class:`LogReader` directly (text lines, no topics).

Conventions (all formats)
-------------------------
* Stamps are the *header* stamp of each message (sensor time), in seconds. Zero is a valid stamp
  (simulated time starts at 0). Messages are yielded in log-time order.
* Message encodings: ``cdr`` (ROS 2), ``ros1`` and ``json`` (foxglove_bridge / rosbridge
  recordings, :mod:`.jsonmsg`); a chosen topic in another encoding (protobuf, flatbuffer, ...) is a
  LogError naming it, a tf topic in one is skipped with a warning.
* Odometry orientation quaternions are normalised before the yaw is taken; a degenerate one (norm
  ~0, or a non-finite component) skips its sample (counted in ``stats.decode_failed``, warned).
* A beam is valid when finite, > 0, >= range_min and < range_max (a reading equal to range_max
  is the driver's "no return"). Invalid beams are dropped and counted.
* A scan whose ranges count differs from ``(angle_max - angle_min) / angle_increment + 1`` is kept:
  ``len(ranges)`` beams from angle_min with angle_increment (counted in ``stats.size_mismatch``).
  A scan with angle_increment <= 0 or non-finite is skipped (``stats.scans_skipped``).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np

from ..errors import LogError, printable
from ..types import OdomSample, Scan

logger = logging.getLogger("cornerslam.logs")

LASERSCAN = "sensor_msgs/LaserScan"
ENCODINGS = ("cdr", "ros1", "json")  # message encodings the ROS-message readers decode
ODOMETRY = "nav_msgs/Odometry"
TF_TYPES = ("tf2_msgs/TFMessage", "tf/tfMessage")

Pose2 = tuple[float, float, float]


def normalize_msgtype(name: str) -> str:
    """``sensor_msgs/msg/LaserScan`` (ROS 2) and ``sensor_msgs/LaserScan`` (ROS 1) -> the latter;
    ``(no schema)`` for a channel without one (schemaless JSON: its type is unknown)."""
    return name.replace("/msg/", "/") if name else "(no schema)"


def ros2_typename(name: str) -> str:
    """The typestore spelling ``pkg/msg/Type`` of a ROS 1 or ROS 2 message type name."""
    if "/msg/" in name or name.count("/") != 1:
        return name
    pkg, typ = name.split("/")
    return f"{pkg}/msg/{typ}"


# --------------------------------------------------------------------------- public dataclasses


@dataclass(frozen=True)
class TopicInfo:
    """One topic (channel / connection) of a log.

    msgtype is normalized to the ROS 1 spelling (``sensor_msgs/LaserScan``); count and rate_hz
    are None when unknown. encoding: ``cdr`` | ``ros1`` | ``json`` | ``carmen``, or whatever else an
    MCAP channel declares (``protobuf``, ...: not readable, see :data:`ENCODINGS`).
    """

    name: str
    msgtype: str
    count: int | None
    rate_hz: float | None = None
    encoding: str = ""

    @property
    def encoding_note(self) -> str:
        """What ``info`` shows beside the topic: "" for the usual encodings (cdr, ros1, carmen), else
        the encoding, saying when cornerslam cannot decode it."""
        if self.encoding in ("", "cdr", "ros1", "carmen"):
            return ""
        return self.encoding if self.encoding in ENCODINGS else f"{self.encoding}: not readable"


@dataclass(frozen=True)
class LogInfo:
    """What ``cornerslam info LOG`` prints, and what a run would use.

    start, end : seconds (log time) of the first and last message, None if the log has none;
    duration = end - start. scan_topic / odom_topic are "" when none can be chosen, with the reason
    in ``problems``. odom_source: ``"nav_msgs/Odometry"``, ``"tf odom→base_link"`` (frame names as
    configured), ``"ODOM lines"`` / ``"laser odometry fields"`` (CARMEN), or "".
    """

    format: str
    path: str
    start: float | None
    end: float | None
    duration: float
    n_messages: int
    topics: tuple[TopicInfo, ...]
    scan_topic: str
    odom_topic: str
    odom_source: str
    problems: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()


@dataclass
class ReadStats:
    """Counters of one reader, updated while iterating ``messages()``."""

    scans: int = 0  # scans yielded
    odoms: int = 0  # odometry samples yielded
    beams: int = 0  # beams in the yielded scans' messages
    beams_dropped: int = 0  # of which invalid (NaN, inf, <= 0, < range_min, >= range_max)
    scans_skipped: int = 0  # scans not yielded: bad angle_increment, no beams
    size_mismatch: int = 0  # scans whose ranges count disagreed with angle_min/max/increment
    decode_failed: int = 0  # messages / lines that could not be decoded (skipped)
    warnings: list[str] = field(default_factory=list)

    def warn(self, msg: str, *args: object) -> None:
        """Log a warning and keep it (first 100) so summaries can report it.

        A text already warned is not repeated (``laser_to_base()`` and ``messages()`` read the same
        damaged bytes)."""
        text = printable(msg % args if args else msg)
        if text in self.warnings:
            return
        logger.warning(text)
        if len(self.warnings) < 100:
            self.warnings.append(text)

    def bad_odometry(self, where: str, stamp: float, pose: tuple[float, float, float]) -> bool:
        """True (counted in ``decode_failed``, warned) if an odometry sample has a non-finite field."""
        if math.isfinite(stamp) and all(math.isfinite(v) for v in pose):
            return False
        self.decode_failed += 1
        if self.decode_failed <= 5:
            self.warn("%s: odometry sample at %r has a non-finite pose %r: skipped", where, stamp, pose)
        return True

    def odometry_sample(
        self, where: str, stamp: float, x: float, y: float, q: tuple[float, float, float, float]
    ) -> OdomSample | None:
        """The sample of a pose whose orientation is the quaternion q = (x, y, z, w), counted in
        ``odoms``; None (counted in ``decode_failed``, warned) if q has no direction (length ~0) or a
        field is not finite. A q not of unit length is normalised (warned once if off by more than
        0.1 %: float32 round-off is not worth a warning)."""
        n2 = sum(v * v for v in q)
        if n2 < 1e-12:
            self.decode_failed += 1
            if self.decode_failed <= 5:
                self.warn(
                    "%s: odometry sample at %r has a zero-length orientation quaternion %r: skipped",
                    where, stamp, tuple(q),
                )  # fmt: skip
            return None
        if math.isfinite(n2) and abs(n2 - 1.0) > 1e-9:  # unit within 1e-9: used as it is
            if abs(n2 - 1.0) > 2e-3:
                self.warn("%s: odometry orientation quaternions are not of unit length: normalised", where)
            s = 1.0 / math.sqrt(n2)
            q = (q[0] * s, q[1] * s, q[2] * s, q[3] * s)
        pose = (x, y, yaw_from_quaternion(*q))
        if self.bad_odometry(where, stamp, pose):
            return None
        self.odoms += 1
        return OdomSample(stamp, *pose)

    def check_scans_yielded(self, name: str, topic: str) -> None:
        """Raise LogError at the end of a read in which scans were seen but none was usable."""
        if self.scans == 0 and self.scans_skipped > 0:
            raise LogError(
                f"log '{name}': all {self.scans_skipped} scans on '{topic}' were skipped "
                "(angle_increment <= 0 or not finite, no beams, or no valid stamp)",
                "check the LaserScan messages' angle_min/angle_increment; `cornerslam extract` shows one",
            )


class LogReader(Protocol):
    """What ``open_log`` returns. ``messages()`` may be called more than once (re-reads the log)."""

    path: Path
    format: str
    stats: ReadStats
    scan_topic: str
    odom_topic: str

    def info(self) -> LogInfo: ...

    def laser_to_base(self) -> Pose2 | None: ...

    def messages(self) -> Iterator[Scan | OdomSample]: ...

    def close(self) -> None: ...


# --------------------------------------------------------------------------- shared helpers


def make_scan(
    stats: ReadStats,
    where: str,
    stamp: float,
    angle_min: float,
    angle_max: float | None,
    angle_increment: float,
    range_min: float,
    range_max: float,
    ranges: np.ndarray,
    frame_id: str = "",
) -> Scan | None:
    """Build a :class:`Scan` of the valid beams of one message, updating ``stats``; None = skipped.

    angle_max None means "not given" (CARMEN): no size check.
    """
    n = len(ranges)
    last_angle = angle_min + max(n - 1, 0) * angle_increment  # inf for absurd increments (1e308)
    if not (math.isfinite(angle_increment) and angle_increment > 0 and math.isfinite(last_angle)):
        stats.scans_skipped += 1
        if stats.scans_skipped <= 3:
            stats.warn(
                "%s: scan at %.3f has angle_min %r, angle_increment %r: skipped",
                where, stamp, angle_min, angle_increment,
            )  # fmt: skip
        return None
    if not math.isfinite(stamp):
        stats.scans_skipped += 1
        if stats.scans_skipped <= 3:
            stats.warn("%s: scan with stamp %r: skipped", where, stamp)
        return None
    if angle_max is not None:
        expected = round((angle_max - angle_min) / angle_increment) + 1 if math.isfinite(angle_max) else -1
        if expected != n:
            stats.size_mismatch += 1
            if stats.size_mismatch <= 3:
                stats.warn(
                    "%s: scan at %.3f has %d ranges but angle_min/max/increment imply %d: "
                    "using %d beams from angle_min",
                    where,
                    stamp,
                    n,
                    expected,
                    n,
                )
    if n == 0:
        stats.scans_skipped += 1
        return None
    r = np.asarray(ranges, dtype=np.float64)
    lo = range_min if math.isfinite(range_min) else 0.0
    hi = range_max if not math.isnan(range_max) else math.inf
    with np.errstate(invalid="ignore"):
        valid = (r > 0.0) & (r >= lo) & (r < hi)  # NaN compares False; inf fails r < hi
    idx = np.flatnonzero(valid)
    stats.scans += 1
    stats.beams += n
    stats.beams_dropped += n - len(idx)
    return Scan(
        stamp=stamp,
        ranges=r[idx],
        angles=angle_min + idx * angle_increment,
        beam_index=idx.astype(np.int64),
        n_beams=n,
        range_min=float(lo),
        range_max=float(hi),
        angle_increment=float(angle_increment),
        frame_id=frame_id,
    )


def yaw_from_quaternion(x: float, y: float, z: float, w: float) -> float:
    """Yaw (rotation about z) of a unit quaternion, radians."""
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def transform_matrix(t: tuple[float, float, float], q: tuple[float, float, float, float]) -> np.ndarray:
    """4x4 homogeneous matrix of translation t and quaternion q = (x, y, z, w) (normalised; not 0)."""
    x, y, z, w = q
    nrm = math.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / nrm, y / nrm, z / nrm, w / nrm
    T = np.eye(4)
    T[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    T[:3, 3] = t
    return T


def strip_frame(frame: str) -> str:
    return frame.lstrip("/")


def chain_transform(edges: dict[tuple[str, str], np.ndarray], source: str, target: str) -> np.ndarray | None:
    """T_source_target (pose of ``target`` in ``source``) through a tree of parent→child transforms.

    edges maps (parent, child) -> T_parent_child. Breadth-first search, edges usable both ways.
    """
    if source == target:
        return np.eye(4)
    nbrs: dict[str, list[tuple[str, np.ndarray]]] = {}
    for (p, c), T in edges.items():
        nbrs.setdefault(p, []).append((c, T))
        nbrs.setdefault(c, []).append((p, np.linalg.inv(T)))
    todo = [(source, np.eye(4))]
    seen = {source}
    while todo:
        frame, T = todo.pop(0)
        for nxt, Tn in nbrs.get(frame, []):
            if nxt in seen:
                continue
            Tt = T @ Tn
            if nxt == target:
                return Tt
            seen.add(nxt)
            todo.append((nxt, Tt))
    return None


def pose2_from_matrix(T: np.ndarray) -> Pose2:
    """2D projection (x, y, yaw) of a 4x4 transform."""
    return float(T[0, 3]), float(T[1, 3]), math.atan2(T[1, 0], T[0, 0])


def listing(names: list[str]) -> str:
    """``"/a, /b"`` or ``"none"``, for error messages."""
    return ", ".join(sorted(names)) if names else "none"


# --------------------------------------------------------------------------- ROS-message readers


@dataclass(frozen=True)
class Channel:
    """A topic of a ROS-message log as a :class:`RawSource` reports it.

    msgtype is the spelling in the log (``sensor_msgs/msg/LaserScan`` or ``sensor_msgs/LaserScan``);
    encoding ``cdr`` or ``ros1``; msgdef/msgdef_format the schema text (``ros2msg``, ``ros1msg``,
    ``ros2idl``) used to register types the built-in typestore lacks.
    """

    topic: str
    msgtype: str
    encoding: str
    count: int | None = None
    msgdef: str = ""
    msgdef_format: str = ""


class RawSource(Protocol):
    """A ROS-message log opened by a format module: topics and raw serialized messages."""

    format: str

    def channels(self) -> list[Channel]: ...

    def time_range(self) -> tuple[int, int] | None:
        """(first, last) log time in ns, None if the log has no messages."""
        ...

    def raw_messages(self, topics: set[str]) -> Iterator[tuple[str, int, bytes | memoryview]]:
        """(topic, log_time_ns, data) of the given topics in log-time order, streaming."""
        ...

    def close(self) -> None: ...


@dataclass(frozen=True)
class _OdomSel:
    topic: str  # "" if none
    kind: str  # "odometry" | "tf" | ""
    problem: str = ""
    hint: str = ""


class RosLogReader:
    """A :class:`LogReader` over any :class:`RawSource` (MCAP, ROS 1 bag, ROS 2 bag).

    Topic selection (when not given): the only sensor_msgs/LaserScan topic; the only
    nav_msgs/Odometry topic (several: the one named ``/odom``, else an error), else tf
    odom_frame→base_frame transforms found on a tf2_msgs/TFMessage topic other than /tf_static.
    Errors of selection are raised by :meth:`messages`, :meth:`check` and :meth:`laser_to_base`,
    never by :meth:`info`, which reports them.
    """

    def __init__(
        self,
        source: RawSource,
        path: Path,
        scan_topic: str = "",
        odom_topic: str = "",
        odom_frame: str = "odom",
        base_frame: str = "base_link",
        stats: ReadStats | None = None,
    ):
        self.source = source
        self.path = Path(path)
        self.format = source.format
        self.stats = stats if stats is not None else ReadStats()
        self.odom_frame = strip_frame(odom_frame)
        self.base_frame = strip_frame(base_frame)
        self._want_scan = scan_topic
        self._want_odom = odom_topic
        self._channels = {c.topic: c for c in source.channels()}
        self._scan_sel = self._select_scan()
        self._odom_sel = self._select_odom()
        self.scan_topic = self._scan_sel[0]
        self.odom_topic = self._odom_sel.topic
        self._laser2base: Pose2 | None | bool = False  # False = not computed yet

    # ---------------------------------------------------------------- selection
    def _topics_of(self, *types: str) -> list[str]:
        return sorted(t for t, c in self._channels.items() if normalize_msgtype(c.msgtype) in types)

    def _select_scan(self) -> tuple[str, str, str]:
        """(topic, problem, hint)."""
        name = self.path.name
        scans = self._topics_of(LASERSCAN)
        if self._want_scan:
            c = self._channels.get(self._want_scan)
            if c is None:
                return (
                    "",
                    f"log '{name}' has no topic '{self._want_scan}' (LaserScan topics: {listing(scans)})",
                    "check --scan-topic; `cornerslam info LOG` lists the topics",
                )
            if normalize_msgtype(c.msgtype) != LASERSCAN:
                return (
                    "",
                    f"topic '{self._want_scan}' of log '{name}' is {normalize_msgtype(c.msgtype)}, "
                    "not sensor_msgs/LaserScan",
                    f"choose a LaserScan topic with --scan-topic ({listing(scans)})",
                )
            return self._want_scan, "", ""
        if not scans:
            return (
                "",
                f"log '{name}' has no sensor_msgs/LaserScan topic",
                "record the laser as sensor_msgs/LaserScan; `cornerslam info LOG` lists the topics",
            )
        if len(scans) > 1:
            return (
                "",
                f"log '{name}' has {len(scans)} LaserScan topics: {', '.join(scans)}",
                "choose one with --scan-topic",
            )
        return scans[0], "", ""

    def _select_odom(self) -> _OdomSel:
        name = self.path.name
        odoms = self._topics_of(ODOMETRY)
        tfs = [t for t in self._topics_of(*TF_TYPES) if t != "/tf_static"]
        if self._want_odom:
            c = self._channels.get(self._want_odom)
            if c is None:
                return _OdomSel(
                    "",
                    "",
                    f"log '{name}' has no topic '{self._want_odom}' "
                    f"(Odometry topics: {listing(odoms)}; tf topics: {listing(tfs)})",
                    "check --odom-topic; `cornerslam info LOG` lists the topics",
                )
            mt = normalize_msgtype(c.msgtype)
            if mt == ODOMETRY:
                return _OdomSel(self._want_odom, "odometry")
            if mt in TF_TYPES:
                return _OdomSel(self._want_odom, "tf")
            return _OdomSel(
                "",
                "",
                f"topic '{self._want_odom}' of log '{name}' is {mt}, "
                "not nav_msgs/Odometry or tf2_msgs/TFMessage",
                f"choose one with --odom-topic (Odometry: {listing(odoms)}; tf: {listing(tfs)})",
            )
        if len(odoms) == 1:
            return _OdomSel(odoms[0], "odometry")
        if len(odoms) > 1:
            if "/odom" in odoms:
                return _OdomSel("/odom", "odometry")
            return _OdomSel(
                "",
                "",
                f"log '{name}' has {len(odoms)} Odometry topics: {', '.join(odoms)}",
                "choose one with --odom-topic",
            )
        if tfs:
            return _OdomSel("/tf" if "/tf" in tfs else tfs[0], "tf")
        return _OdomSel(
            "",
            "",
            f"log '{name}' has no odometry: no nav_msgs/Odometry topic and no tf topic",
            "select an odometry topic with --odom-topic (nav_msgs/Odometry or tf with "
            f"{self.odom_frame}→{self.base_frame})",
        )

    def _odom_source_label(self) -> str:
        if self._odom_sel.kind == "odometry":
            return ODOMETRY
        if self._odom_sel.kind == "tf":
            return f"tf {self.odom_frame}→{self.base_frame}"
        return ""

    def _encoding_problem(self, topic: str) -> tuple[str, str] | None:
        """(problem, hint) if a chosen topic's messages are in an encoding we do not decode."""
        enc = self._channels[topic].encoding
        if enc in ENCODINGS:
            return None
        return (
            f"topic '{topic}' of log '{self.path.name}' has message encoding '{enc}', which cornerslam "
            f"does not decode ({', '.join(ENCODINGS)})",
            "record the ROS messages as cdr (ros2 bag record), ros1 or json (foxglove_bridge, rosbridge)",
        )

    def _problems(self) -> list[tuple[str, str]]:
        """(problem, hint) of everything that stops a run from reading this log, in the order found."""
        problems = [(self._scan_sel[1], self._scan_sel[2]), (self._odom_sel.problem, self._odom_sel.hint)]
        problems = [p for p in problems if p[0]]
        if not problems:
            problems = [p for t in (self.scan_topic, self.odom_topic) if (p := self._encoding_problem(t))]
        return problems

    def check(self) -> None:
        """Raise LogError if a run could not choose its scan and odometry topics or decode them."""
        problems = self._problems()
        if problems:
            raise LogError(*problems[0])
        for topic in (self.scan_topic, self.odom_topic):
            if self._channels[topic].count == 0:
                raise LogError(
                    f"topic '{topic}' of log '{self.path.name}' has no messages",
                    "it was declared but nothing was recorded on it; `cornerslam info LOG` shows the counts",
                )

    # ---------------------------------------------------------------- info
    def info(self) -> LogInfo:
        tr = self.source.time_range()
        start, end = (tr[0] * 1e-9, tr[1] * 1e-9) if tr else (None, None)
        duration = (end - start) if tr else 0.0
        topics = []
        for c in sorted(self._channels.values(), key=lambda c: c.topic):
            rate = None
            if c.count is not None and c.count > 1 and duration > 0:
                rate = (c.count - 1) / duration
            topics.append(TopicInfo(c.topic, normalize_msgtype(c.msgtype), c.count, rate, c.encoding))
        problems = tuple(f"{p} ({h})" for p, h in self._problems())
        n = sum(c.count or 0 for c in self._channels.values())
        return LogInfo(
            format=self.format,
            path=str(self.path),
            start=start,
            end=end,
            duration=duration,
            n_messages=n,
            topics=tuple(topics),
            scan_topic=self.scan_topic,
            odom_topic=self.odom_topic,
            odom_source=self._odom_source_label(),
            problems=problems,
        )

    # ---------------------------------------------------------------- decoding
    def _decoder(self, topic: str):
        """The decoder of a topic's messages (its encoding is one of :data:`ENCODINGS`)."""
        channel = self._channels[topic]
        if channel.encoding == "json":
            from .jsonmsg import JsonDecoder  # local: keeps `import cornerslam_cli.logs` light

            return JsonDecoder(channel)
        from .cdr import Decoder

        return Decoder(channel)

    def laser_to_base(self) -> Pose2 | None:
        """Pose (x, y, yaw) of the laser in base_frame from tf_static/tf, else None.

        Reads from the start of the log until the first scan has been seen and, after it, either all
        tf_static messages (when counts are known) or 2,000 more messages.
        """
        if self._laser2base is not False:
            return self._laser2base  # type: ignore[return-value]
        self.check()
        tf_topics = set()
        for t in self._topics_of(*TF_TYPES):
            if self._encoding_problem(t) is None:
                tf_topics.add(t)
            else:
                self.stats.warn(
                    "%s: tf topic '%s' has message encoding '%s': not read (laser mount from the config)",
                    self.path.name, t, self._channels[t].encoding,
                )  # fmt: skip
        frame = None
        edges: dict[tuple[str, str], np.ndarray] = {}
        static_left = sum(self._channels[t].count or 0 for t in tf_topics if t == "/tf_static")
        counts_known = all(self._channels[t].count is not None for t in tf_topics if t == "/tf_static")
        after = 0
        decs = {t: self._decoder(t) for t in tf_topics | {self.scan_topic}}
        for topic, _, data in self.source.raw_messages(tf_topics | {self.scan_topic}):
            try:
                if topic == self.scan_topic:
                    if frame is None:
                        frame = strip_frame(decs[topic].laserscan(data)[1])
                    continue
                static = topic == "/tf_static"
                static_left -= static
                for parent, child, _, t, q in decs[topic].transforms(data):
                    if (parent, child) == (self.odom_frame, self.base_frame) or parent == child:
                        continue
                    if sum(v * v for v in q) < 1e-12:  # no rotation at all: not a transform
                        self.stats.warn(
                            "%s: tf %s→%s has a zero-length rotation quaternion: ignored",
                            self.path.name, parent, child,
                        )  # fmt: skip
                        continue
                    edges.setdefault((parent, child), transform_matrix(t, q))
            except Exception as exc:  # noqa: BLE001 - bad bytes are counted, never raised
                logger.debug("laser_to_base: skipping undecodable %s message: %s", topic, exc)
            finally:
                if frame is not None:
                    after += 1
            if frame is not None and ((counts_known and static_left <= 0) or after > 2000):
                break
        if frame is None:
            self._laser2base = None
            return None
        T = chain_transform(edges, self.base_frame, frame)
        self._laser2base = None if T is None else pose2_from_matrix(T)
        if self._laser2base is not None and not all(math.isfinite(v) for v in self._laser2base):
            self.stats.warn("%s: the tf %s→%s is not finite: ignored", self.path.name, self.base_frame, frame)
            self._laser2base = None
        return self._laser2base  # type: ignore[return-value]

    def messages(self) -> Iterator[Scan | OdomSample]:
        """Scans and odometry samples in log-time order (raises LogError now if topics are missing)."""
        self.check()
        return self._iter()

    def _iter(self) -> Iterator[Scan | OdomSample]:
        st = self.stats
        scan_t, odom_t = self.scan_topic, self.odom_topic
        scan_dec, odom_dec = self._decoder(scan_t), self._decoder(odom_t)
        is_tf = self._odom_sel.kind == "tf"
        where, odom_where = f"{self.path.name}:{scan_t}", f"{self.path.name}:{odom_t}"
        n_tf_match = 0
        for topic, log_time, data in self.source.raw_messages({scan_t, odom_t}):
            try:
                if topic == scan_t:
                    (sec, nsec), frame, a_min, a_max, a_inc, r_min, r_max, ranges = scan_dec.laserscan(data)
                    scan = make_scan(
                        st, where, sec + nsec * 1e-9, a_min, a_max, a_inc, r_min, r_max, ranges, frame
                    )
                    if scan is not None:
                        yield scan
                    continue
                if is_tf:
                    poses = [
                        (stamp, t[0], t[1], q)
                        for parent, child, stamp, t, q in odom_dec.transforms(data)
                        if parent == self.odom_frame and child == self.base_frame
                    ]
                    n_tf_match += len(poses)
                else:
                    poses = [odom_dec.odometry(data)]
                for (sec, nsec), x, y, q in poses:
                    sample = st.odometry_sample(odom_where, sec + nsec * 1e-9, float(x), float(y), q)
                    if sample is not None:
                        yield sample
            except LogError:
                raise
            except Exception as exc:  # noqa: BLE001 - undecodable message: count, warn, go on
                st.decode_failed += 1
                if st.decode_failed <= 5:
                    st.warn(
                        "%s: cannot decode a %s message at %d ns: %s", self.path.name, topic, log_time, exc
                    )
        if is_tf and n_tf_match == 0:
            raise LogError(
                f"log '{self.path.name}': topic '{odom_t}' has no "
                f"{self.odom_frame}→{self.base_frame} transform",
                "set the frames (odom_frame/base_frame) or choose an Odometry topic with --odom-topic",
            )
        if st.decode_failed > 5:
            st.warn("%s: %d messages could not be decoded in total", self.path.name, st.decode_failed)
        st.check_scans_yielded(self.path.name, scan_t)

    def close(self) -> None:
        self.source.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()
