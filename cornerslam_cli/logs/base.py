"""What every log reader provides: the :class:`LogReader` protocol, :class:`ReadStats`, scans from
raw ranges, and the topic names and :class:`Channel` the ROS-message decoders share.

A reader yields :class:`~cornerslam_cli.types.Scan` and :class:`~cornerslam_cli.types.OdomSample`
objects in log-time order, streaming (memory does not grow with the log). Format modules
(``mcap.py``, ``rosbag.py``) only provide a :class:`~.ros.RawSource`: topics and raw serialized
messages. :class:`~.ros.RosLogReader` (``ros.py``) does the rest once: topic selection by message
type, decoding (``cdr.py``, ``jsonmsg.py``), tf handling, counters. ``carmen.py`` implements
:class:`LogReader` directly (text lines, no topics). Nothing here imports a format module.

Conventions (all formats)
-------------------------
* Stamps are the *header* stamp of each message (sensor time; ``input.stamps: receive``: the recorder's
  time), in seconds. Zero is a valid stamp (simulated time starts at 0). Messages in log-time order.
* Message encodings: ``cdr`` (ROS 2), ``ros1`` and ``json`` (foxglove_bridge / rosbridge
  recordings, :mod:`.jsonmsg`); a chosen topic in another encoding (protobuf, flatbuffer, ...) is a
  LogError naming it, a tf topic in one is skipped with a warning.
* Odometry orientation quaternions are normalised before the yaw is taken; a degenerate one (norm
  ~0, or a non-finite component) skips its sample (counted in ``stats.decode_failed``, warned), and
  so does a position beyond ``MAX_ODOM_XY`` (damaged bytes).
* A beam is valid when finite, > 0, >= range_min and < range_max (a reading equal to range_max
  is the driver's "no return"). Invalid beams are dropped and counted.
* A scan whose ranges count differs from ``(angle_max - angle_min) / angle_increment + 1`` is kept:
  ``len(ranges)`` beams from angle_min with angle_increment (counted in ``stats.size_mismatch``).
  A scan with a negative angle_increment (beams clockwise) is read in increasing bearing order, its
  ``beam_index`` decreasing (:meth:`Scan.reversed`). A scan with angle_increment 0 or non-finite is
  skipped (``stats.scans_skipped``), and so is one
  whose beams span more than a full turn (angles in degrees: 1081 beams of 0.25 "rad").
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
from ..geometry import normalize_quaternion, yaw_from_quaternion
from ..ranges import cut_text, short_text
from ..types import OdomSample, Scan
from .deskew import time_increment_problem

logger = logging.getLogger("cornerslam.logs")

ENCODINGS = ("cdr", "ros1", "json")  # message encodings the ROS-message readers decode
MAX_ODOM_XY = 1e9  # metres: odometry in UTM or ECEF coordinates stays below 1e7
LASERSCAN_FIELDS = "the LaserScans' angle_min/angle_increment"  # what to check of unusable scans

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
    n_messages: int | None  # None: not known (a bag's stale metadata)
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
    beams: int = 0  # beams in the yielded scans' messages (a run's: less a span's left out)
    beams_dropped: int = 0  # of which invalid (NaN, inf, <= 0, < range_min, >= range_max)
    scans_skipped: int = 0  # scans not yielded: bad angle_increment, no beams
    size_mismatch: int = 0  # scans whose ranges count disagreed with angle_min/max/increment
    bad_time_increment: int = 0  # scans whose time_increment was unusable (taken as not given)
    decode_failed: int = 0  # messages / lines that could not be decoded (skipped)
    first_failure: str = ""  # what the first of them was (the error names it when nothing was usable)
    damaged: int = 0  # parts of the file skipped as unreadable (an MCAP chunk that fails its CRC, …)
    first_damage: str = ""  # what the first of them was (the error names it when nothing was usable)
    damage_seen: set[str] = field(default_factory=set)  # their texts: a part read twice counts once
    unsupported: int = 0  # of the damaged parts, those compressed with a codec this reader lacks
    truncated: bool = False  # the file ends early (a recorder stopped): what came after the cut is lost
    warnings: list[str] = field(default_factory=list)
    said: set[str] = field(default_factory=set)  # every text logged: a summary's list may be reset, not this
    quiet: bool = False  # keep warnings, do not log them (compare's workers: the parent says them)

    def skip_scan(self, msg: str, *args: object) -> None:
        """Count a scan skipped (``scans_skipped``) and warn why, for the first three; None, the scan."""
        self.scans_skipped += 1
        if self.scans_skipped <= 3:
            self.warn(msg, *args)

    def warn(self, msg: str, *args: object) -> None:
        """Log a warning and keep it (first 100) so summaries can report it.

        A text already warned is not repeated (``laser_to_base()`` and ``messages()`` read the same
        damaged bytes), on the console even when ``warnings`` was reset since: compare's runs share
        one input and each summary gets its own warnings, but a ground truth's note is said once."""
        text = printable(msg % args if args else msg)
        if not self.quiet:
            self.say(text)
        if text not in self.warnings and len(self.warnings) < 100:
            self.warnings.append(text)

    def say(self, text: str) -> None:
        """Log the warning ``text`` unless it was already (not kept: :meth:`warn` keeps)."""
        if text not in self.said:
            logger.warning(text)
            self.said.add(text)

    def failed(self, msg: str, *args: object) -> None:
        """Count one message / line that could not be decoded (skipped); warn about the first five and
        keep the first's text (its first 200 characters) in ``first_failure``."""
        self.decode_failed += 1
        if self.decode_failed == 1:
            text = printable(msg % args if args else msg)
            self.first_failure = cut_text(text)
        if self.decode_failed <= 5:
            self.warn(msg, *args)

    def skip_damaged(self, msg: str, *args: object, unsupported: bool = False) -> None:
        """Count one part of the file skipped as unreadable (damaged bytes; ``unsupported``: compressed
        with a codec this reader lacks), keep the first's text (its first 200 characters) in
        ``first_damage`` and warn. A part met again (``laser_to_base()`` and ``messages()`` read the
        same bytes) is counted once."""
        text = printable(msg % args if args else msg)
        if text in self.damage_seen:
            return
        self.damage_seen.add(text)
        self.damaged += 1
        self.unsupported += unsupported
        if self.damaged == 1:
            self.first_damage = cut_text(text)
        self.warn(text)

    def bad_odometry(self, where: str, stamp: float, pose: tuple[float, float, float]) -> bool:
        """True (counted in ``decode_failed``, warned) if an odometry sample has a non-finite field or
        a position farther than ``MAX_ODOM_XY`` from the origin (damaged bytes: 1e300 m)."""
        if not (math.isfinite(stamp) and all(math.isfinite(v) for v in pose)):
            self.failed("%s: odometry sample at %r has a non-finite pose %r: skipped", where, stamp, pose)
            return True
        if max(abs(pose[0]), abs(pose[1])) > MAX_ODOM_XY:
            self.failed(
                "%s: odometry sample at %r has a position %r farther than %g m: skipped",
                where, stamp, pose[:2], MAX_ODOM_XY,
            )  # fmt: skip
            return True
        return False

    def odometry_sample(
        self, where: str, stamp: float, x: float, y: float, q: tuple[float, float, float, float]
    ) -> OdomSample | None:
        """The sample of a pose whose orientation is the quaternion q = (x, y, z, w), counted in
        ``odoms``; None (counted in ``decode_failed``, warned) if q has no direction (length ~0), a
        component of q is not finite, or a field is not finite. A q not of unit length is normalised
        (warned once if off by more than 0.1 %: float32 round-off is not worth a warning); one so long
        that its squared length overflows is first divided by its largest component."""
        finite = all(math.isfinite(v) for v in q)
        n2 = sum(v * v for v in q) if finite else math.nan
        if finite and not math.isfinite(n2):
            big = max(abs(v) for v in q)
            q = tuple(v / big for v in q)
            n2 = sum(v * v for v in q)
        if not n2 >= 1e-12:  # zero length, or NaN/inf in q
            what = "a zero-length orientation quaternion" if finite else "a non-finite pose (quaternion"
            self.failed(
                "%s: odometry sample at %r has %s %r%s: skipped",
                where,
                stamp,
                what,
                tuple(q),
                "" if finite else ")",
            )
            return None
        if abs(n2 - 1.0) > 2e-3:
            self.warn("%s: odometry orientation quaternions are not of unit length: normalised", where)
        pose = (x, y, yaw_from_quaternion(*normalize_quaternion(*q)))  # unit within 1e-9: used as it is
        if self.bad_odometry(where, stamp, pose):
            return None
        self.odoms += 1
        return OdomSample(stamp, *pose)

    def check_scans_yielded(self, name: str, topic: str, fields: str = LASERSCAN_FIELDS) -> None:
        """Raise LogError at the end of a read in which scans were seen but none was usable; ``fields``:
        what of the messages to check, in the log format's words."""
        if self.scans == 0 and self.scans_skipped > 0:
            raise LogError(
                f"log '{name}': all {self.scans_skipped} scans on '{short_text(topic)}' were skipped "
                "(angle_increment 0 or not finite, beams over more than a full turn, no beams, or no stamp)",
                f"check {fields}: the warnings give the first ones' values",
            )


class LogReader(Protocol):
    """What ``open_log`` returns. ``messages()`` may be called more than once (re-reads the log)."""

    path: Path
    format: str
    stats: ReadStats
    scan_topic: str
    odom_topic: str
    odom_on_tf: bool  # the log's tf carries odom→base (seen by laser_to_base())
    receive: bool  # input.stamps "receive": messages taken at the recorder's time, not their header stamps
    stamps_name: str  # what the messages' times are read from, as refusals name it ("header stamps", …)
    scans_alone: bool  # a run reads the scans only (input.odometry: scans): check() asks no odometry

    def check(self, odometry: bool | None = None) -> None: ...  # LogError; odometry None: as scans_alone says
    def info(self, inspect: bool = True) -> LogInfo: ...  # inspect: as `cornerslam info` shows (reads more)
    def laser_to_base(self) -> Pose2 | None: ...
    def laser_upside_down(self) -> bool | None: ...  # None: the log's mount cannot say (the config's)
    def stamps_way_out(self) -> str: ...  # the other input.stamps, as a refusal's hint, where it can help
    def messages(self) -> Iterator[Scan | OdomSample]: ...
    def scans(self) -> Iterator[Scan]: ...  # the scans alone: needs no odometry topic
    def close(self) -> None: ...


# --------------------------------------------------------------------------- shared helpers


def _size_disagreement(n: int, angle_min: float, angle_max: float, angle_increment: float) -> str:
    """What a message's angle_min/max/increment (the increment finite, not 0) imply against its ``n``
    ranges, for a warning; "" when they agree. The count is the span's magnitude over the step's, so
    clockwise beams (a negative increment) count as many as counter-clockwise ones; an angle_max on
    the other side of angle_min from where the beams turn disagrees whatever the count."""
    if not math.isfinite(angle_max):
        return f"angle_max is {angle_max!r}"
    span = angle_max - angle_min
    steps = abs(span / angle_increment)  # inf for a denormal increment: round() would raise
    implied = round(steps) + 1 if steps < 1e15 else None
    text = f"angle_min/max/increment imply {f'{steps:.3g}' if implied is None else implied}"
    if span * angle_increment < 0:
        ccw, cw = "counter-clockwise", "clockwise"
        max_at, beams = (ccw, cw) if angle_increment < 0 else (cw, ccw)
        turn = f"angle_max is {max_at} of angle_min, angle_increment {beams}"
        return turn if implied == n else f"{text} ({turn})"  # (not "has 10 ranges but ... imply 10")
    return "" if implied == n else text


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
    time_increment: float = 0.0,
) -> Scan | None:
    """Build a :class:`Scan` of the valid beams of one message, updating ``stats``; None = skipped.

    angle_max None means "not given" (CARMEN): no size check. A ``time_increment`` that is not finite
    or would spread the beams over more than ``deskew.MAX_SWEEP`` seconds is taken as not given (0),
    counted in ``stats.bad_time_increment`` and warned about once.
    """
    n = len(ranges)
    last_angle = angle_min + max(n - 1, 0) * angle_increment  # inf for absurd increments (1e308)
    if not (math.isfinite(angle_increment) and angle_increment != 0 and math.isfinite(last_angle)):
        return stats.skip_scan(
            "%s: scan at %.3f has angle_min %r, angle_increment %r: skipped",
            where,
            stamp,
            angle_min,
            angle_increment,
        )
    step = abs(angle_increment)
    if (n - 1) * step > 2.0 * math.pi + step:  # (one more: a 360° scan's repeated beam)
        return stats.skip_scan(
            "%s: scan at %.3f has %d beams of angle_increment %r, %.1f turns (degrees?): skipped",
            where, stamp, n, angle_increment, (n - 1) * step / (2.0 * math.pi),
        )  # fmt: skip
    if not math.isfinite(stamp):
        return stats.skip_scan("%s: scan with stamp %r: skipped", where, stamp)
    if angle_max is not None and (implied := _size_disagreement(n, angle_min, angle_max, angle_increment)):
        stats.size_mismatch += 1
        if stats.size_mismatch <= 3:
            stats.warn(
                "%s: scan at %.3f has %d ranges but %s: using %d beams from angle_min",
                where,
                stamp,
                n,
                implied,
                n,
            )
    if n == 0:
        return stats.skip_scan("%s: scan at %.3f has no beams: skipped", where, stamp)
    lo = range_min if math.isfinite(range_min) else 0.0
    hi = range_max if not math.isnan(range_max) else math.inf
    with np.errstate(invalid="ignore"):  # a signalling NaN (damaged bytes) raises "invalid" in the cast
        r = np.asarray(ranges, dtype=np.float64)
        valid = (r > 0.0) & (r >= lo) & (r < hi)  # NaN compares False; inf fails r < hi
    idx = np.flatnonzero(valid)
    if time_increment and (problem := time_increment_problem(time_increment, n)):
        stats.bad_time_increment += 1
        if stats.bad_time_increment == 1:
            stats.warn(
                "%s: scan at %.3f has time_increment %r s (%s): taken as not given, the beams' times from "
                "input.beam_time when set, else the scan is not corrected for motion", where, stamp,
                time_increment, problem,
            )  # fmt: skip
        time_increment = 0.0
    stats.scans += 1
    stats.beams += n
    stats.beams_dropped += n - len(idx)
    scan = Scan(
        stamp=stamp,
        ranges=r[idx],
        angles=angle_min + idx * angle_increment,
        beam_index=idx.astype(np.int64),
        n_beams=n,
        range_min=float(lo),
        range_max=float(hi),
        angle_increment=step,
        frame_id=frame_id,
        time_increment=float(time_increment),
    )
    return scan if angle_increment > 0 else scan.reversed()  # beams clockwise: bearings made increasing


def strip_frame(frame: str) -> str:
    return frame.lstrip("/")


# --------------------------------------------------------------------------- ROS topics


@dataclass(frozen=True)
class Channel:
    """A topic of a ROS-message log as a :class:`~.ros.RawSource` reports it.

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
