"""CARMEN logs (``.clf``, ``.log``, optionally gzip-compressed): FLASER / RLASER / ROBOTLASER1 / ODOM.

Line formats (one message per line, fields separated by any whitespace (spaces or tabs), ``#`` comments
and PARAM lines ignored)::

    FLASER n r1..rn x y theta odom_x odom_y odom_theta timestamp hostname logger_timestamp
    RLASER (as FLASER, rear laser)
    ROBOTLASER1 laser_type start_angle fov angular_resolution maximum_range accuracy remission_mode
        n r1..rn n_rem rem1..rem_nrem laser_x laser_y laser_theta robot_x robot_y robot_theta
        tv rv forward_safety_dist side_safety_dist turn_axis timestamp hostname logger_timestamp
    ODOM x y theta tv rv accel timestamp hostname logger_timestamp

A log written by an older CARMEN or a converter may end its lines at the timestamp or its hostname: each
tag's lines are read in the layout most of them have (``TAIL`` fields after the stamp, or fewer).

Conventions (as CARMEN's own ``carmen_string_to_laser_laser_message_orig``):

* FLASER/RLASER angles start at −π/2; the increment is 1° for 180/181 beams, 0.5° for 360/361,
  0.25° for 400/401 and π/(n − 1) otherwise (so 180 beams cover −90°..+89°, 181 beams −90°..+90°).
  ROBOTLASER1 carries start_angle and angular_resolution.
* Max range: ROBOTLASER1 maximum_range; FLASER/RLASER the ``robot_front_laser_max`` /
  ``robot_rear_laser_max`` PARAM if the log has one, else 81.83 m (the SICK "no return" value of the
  classic Radish logs). Readings >= max range are no-return and dropped.
* Stamps: the message timestamp field (sensor time), not the logger timestamp (unless ``input.stamps:
  receive``: a tag read whose lines lack it is refused); lines in file order. A log whose every laser and
  ODOM tag has one timestamp on all its lines (0: a converter that wrote none) and logger timestamps that
  move is read on its logger timestamps, every tag alike, warned.
* Odometry: ODOM lines when the log has any; otherwise the odometry pose fields of the laser lines (FLASER
  odom_x/y/theta, ROBOTLASER1 robot_x/y/theta), yielded just before their scan. Also those fields when ODOM
  lines go back in time more often than the laser lines do (a merged or re-stamped log: intel.gfs.log's 1,498
  of 14,541 ODOM lines, 4 of 910 laser lines) and those fields move: they are the pose the logger stamped with
  each scan, while odometry interpolated between out-of-order ODOM lines is wrong at the scans' times. Also
  when the whole ODOM lines stop well before the laser lines do (``ODOM_UNCOVERED``: lines cut, or
  unreadable past a point), where the run would drop the scans after them.
  ``odom_topic`` ``ODOM`` keeps the ODOM lines.
* The laser offset is not in FLASER lines: ``laser_to_base()`` returns the mean laser-minus-robot
  offset of ROBOTLASER1 lines, None for FLASER logs (configure it) and for ROBOTLASER1 lines whose offsets
  are not one place on the robot (``MOUNT_SPREAD``: corrected poses in the laser pose fields), then
  saying why in ``mount_problem``.

Over 400 lines because it is one reader of four line formats whose choices (which laser, which
odometry source, the pre-read's stamps) each depend on the others.

"Topics" are the line tags (``FLASER``, ``ODOM``, ...): ``scan_topic`` selects the laser tag (default:
ROBOTLASER1, else FLASER, else RLASER, else ROBOTLASER2, among the tags with at least half as many whole
lines as the one with the most), ``odom_topic`` ``ODOM`` or a laser tag.
"""

from __future__ import annotations

import codecs
import gzip
import io
import math
import re
import zlib
from array import array
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..errors import LogError
from ..ranges import short_text
from ..types import OdomSample, Scan
from .base import LogInfo, Pose2, ReadStats, TopicInfo, make_scan
from .params import receive_of

LASER_TAGS = ("ROBOTLASER1", "FLASER", "RLASER", "ROBOTLASER2")
ODOM_TAG = "ODOM"
# ODOM lines that end more than this many seconds before more than this share of the laser lines give
# way to the laser lines' own poses (the run would drop those scans)
ODOM_UNCOVERED, ODOM_UNCOVERED_S = 0.1, 1.0
DEFAULT_MAX_RANGE = 81.83
POSE_NAMES = ("x", "y", "theta", "odom_x", "odom_y", "odom_theta")  # FLASER's after its readings
ROBOTLASER_NAMES = ("start_angle", "fov", "angular_resolution", "maximum_range")  # its 2nd–5th fields
ROBOTLASER_POSES = tuple((w, n) for w in ("laser", "robot") for n in ("x", "y", "theta"))  # after remissions
GZIP_MAGIC = b"\x1f\x8b"
BOM = codecs.BOM_UTF8.decode("latin-1")  # a UTF-8 byte-order mark as read here: 'ï»¿'
# fields after a line's timestamp: hostname logger_timestamp. Logs written by older or other tools end
# with the timestamp or its hostname: each tag's layout is the one most of its lines have (CarmenReader)
TAIL = 2
# m, rad: ROBOTLASER1 laser poses whose offsets from the robot poses spread wider than this (from their
# median) are no mount: a laser pose computed from the robot's is the same offset to its printed digits
MOUNT_SPREAD = (0.1, math.radians(5.0))
MOUNT_SHARE = 0.9  # ... unless at least this share of them lies within it (the mount: their mean)


# a run of NUL bytes before a tag (FLASER, ODOM, #…): a crash's padding, where a line starts (_lines)
NULS = re.compile("\x00+(?=[A-Z][A-Z0-9_]*[ \t]|#)")


def flaser_increment(n: int) -> float:
    """Angle between beams of an old-style FLASER/RLASER line of n beams (CARMEN's guess)."""
    if n in (180, 181):
        return math.pi / 180.0
    if n in (360, 361):
        return math.pi / 360.0
    if n in (400, 401):
        return math.pi / 720.0
    return math.pi / max(n - 1, 1)


def _open_text(path: Path) -> io.TextIOBase:
    with open(path, "rb") as f:
        if f.read(2) == GZIP_MAGIC:
            return io.TextIOWrapper(gzip.open(path, "rb"), encoding="latin-1")
    return open(path, encoding="latin-1")  # noqa: SIM115 - caller closes


def _lines(path: Path, stats: ReadStats | None, fault: list[str] | None = None) -> Iterator[str]:
    """Lines of a (possibly gzip-compressed) text log; a cut/damaged gzip ends the lines with a warning
    (``stats``) and what ended them appended to ``fault`` ("damaged after 12 lines").
    A UTF-8 byte-order mark (an editor saving as 'UTF-8 with BOM') is dropped: it made the first
    line's tag 'ï»¿FLASER', a topic of its own, and the line was lost without a word. A run of NUL bytes
    before a tag (the padding a crash leaves where the file system had grown the file: block-aligned,
    from mid-line) ends a line, with a warning: a line after it was '\\x00…FLASER', lost, or glued to the
    cut one before; NULs elsewhere (inside a field, before the rest of a line) are dropped."""
    n = nul = 0
    try:
        with _open_text(path) as f:
            for line in f:
                n += 1
                if n == 1:
                    line = line.removeprefix(BOM)
                if "\x00" in line:  # the padding ends a line before a tag; other NULs are dropped
                    nul += 1
                    parts = (part.replace("\x00", "") for part in NULS.split(line))
                    yield from (part for part in parts if part.strip())
                else:
                    yield line
    except (EOFError, gzip.BadGzipFile, zlib.error) as exc:
        why = "cut short" if isinstance(exc, EOFError) else "damaged"
        if stats is not None:
            stats.warn("%s ends early after %d lines: its gzip data is %s", path.name, n, why)
        if fault is not None:
            fault.append(f"{why} after {_many(n, 'line')}" if n else f"{why} before its first line")
    if nul and stats is not None:
        stats.warn(
            "%s: NUL bytes in %s (a crash's padding?): dropped, a run of them before a tag read as a line "
            "break",
            path.name,
            _many(nul, "line"),
        )


def _rate(n: int, span: tuple[float, float] | None) -> float | None:
    """Lines a second: ``n`` lines over their ``span`` of stamps; None without one."""
    return (n - 1) / (span[1] - span[0]) if span and n > 1 and span[1] > span[0] else None


def _through_stamp(tag: str, tok: list[str]) -> int:
    """How many of an ODOM or laser line's fields after its tag (``tok``) run up to its timestamp, that
    included: ODOM 7, a laser line as many as its reading (and remission) counts imply; -1 when a count
    is not a whole number >= 0 or the line ends before it."""
    try:
        if tag == ODOM_TAG:
            return 7
        if tag in ("FLASER", "RLASER"):
            n = int(tok[0])
            return n + 8 if n >= 0 else -1
        n = int(tok[7])  # ROBOTLASERx: n readings, n_rem remissions, 12 fields after them to the stamp
        n_rem = int(tok[8 + n]) if n >= 0 else -1
        return n + n_rem + 21 if n_rem >= 0 else -1
    except (ValueError, IndexError):
        return -1


def _odometry_fields(tag: str, tok: list[str], through: int) -> tuple[float, ...] | None:
    """The robot pose of a whole laser line (its fields after the tag, ``through`` of them up to its
    stamp): FLASER/RLASER ``odom_x odom_y odom_theta`` just before the timestamp, ROBOTLASERx ``robot_x
    robot_y robot_theta`` 8th–6th before it; None when they are not numbers."""
    fields = tok[through - 4 : through - 1] if tag in ("FLASER", "RLASER") else tok[through - 9 : through - 6]
    try:
        return tuple(float(v) for v in fields)
    except ValueError:
        return None


class _Laser:
    """Parsed fields of one laser line."""

    __slots__ = ("stamp", "angle_min", "angle_increment", "range_max", "ranges", "laser", "robot")

    def __init__(self, stamp, angle_min, angle_increment, range_max, ranges, laser, robot):
        self.stamp, self.angle_min, self.angle_increment = stamp, angle_min, angle_increment
        self.range_max, self.ranges, self.laser, self.robot = range_max, ranges, laser, robot


class _Layout:
    """What the pre-read saw of one tag's whole lines with one number of fields after the stamp."""

    __slots__ = ("lines", "start", "end", "back", "last", "first_pose", "moving", "logger", "times")

    def __init__(self, logger: bool = False):
        self.lines, self.back = 0, 0  # lines; lines stamped before the line above them
        self.start, self.end, self.last = math.inf, -math.inf, -math.inf
        self.times = array("d")  # the finite stamps, in file order (how many lines lie past a time)
        self.first_pose: tuple[float, ...] | None = None
        self.moving = False  # (laser lines) their odometry fields are not all the same pose
        # the same of the logger timestamps (a layout with them), for a log whose timestamps never move
        self.logger = None if logger else _Layout(logger=True)

    def see(self, tag: str, tok: list[str], through: int) -> None:
        try:
            t = float(tok[through - 1])
        except ValueError:
            return
        self.lines += 1
        self._span(t)
        if self.logger is not None and len(tok) == through + TAIL:
            try:
                self.logger._span(float(tok[-1]))
                self.logger.lines += 1
            except ValueError:
                pass
        if tag != ODOM_TAG and not self.moving:
            pose = _odometry_fields(tag, tok, through)
            if pose is not None:
                self.first_pose = self.first_pose or pose
                self.moving = self.first_pose != pose

    def _span(self, t: float) -> None:
        if math.isfinite(t):
            self.times.append(t)
            self.start, self.end = min(self.start, t), max(self.end, t)
            self.back += t < self.last
            self.last = t


def _stamps_stand_still(layouts: dict[str, _Layout]) -> bool:
    """Whether a log is read on its logger timestamps: each laser and ODOM tag of two lines or more has
    one timestamp on all of them (a converter's 0), a logger timestamp on every one, and those move."""
    many = [n for n in layouts.values() if n.lines >= 2]
    return bool(many) and all(
        n.start == n.end and (g := n.logger) is not None and n.lines == g.lines and g.start < g.end
        for n in many
    )


class BadLine(ValueError):
    """What makes a line unreadable, in the words of its format (the warning and the error quote it):
    its field count against the one its tag and counts need, or the field that is not a number."""


def _fields(tok: list[str], want: int, of: str = "", at_least: bool = False) -> None:
    """BadLine unless the fields after the tag are ``want`` (or more, ``at_least``), as a line of its
    tag (``of`` its counts: " of N readings") needs."""
    has = len(tok) - 1
    if has < want if at_least else has != want:
        raise BadLine(
            f"{'an' if tok[0][0] in 'AEIOU' else 'a'} {tok[0]} line{of} needs {'at least ' * at_least}{want} "
            f"fields after its tag, has {has}"
        )


def _many(n: int, what: str) -> str:
    """``"1 reading"``, ``"3 readings"``."""
    return f"{n} {what}{'s' * (n != 1)}"


def _number(tok: list[str], i: int, name: str) -> float:
    """Field ``i`` (the format's ``name`` for it) as a float; BadLine when it is not a number."""
    try:
        return float(tok[i])
    except ValueError:
        raise BadLine(f"its {name} '{short_text(tok[i], 40)}' is not a number") from None


def _count(tok: list[str], i: int, name: str, least: int, of: str = "") -> int:
    """Field ``i``, a count (of readings, remissions); BadLine when the line ends before it (a line
    with it needs ``least`` fields), or it is not a whole number >= 0."""
    if len(tok) <= i:
        _fields(tok, least, of, at_least=True)
    try:
        n = int(tok[i])
    except ValueError:
        n = -1
    if n < 0:
        raise BadLine(f"its {name} '{short_text(tok[i], 40)}' is not a whole number >= 0")
    return n


def _readings(tok: list[str], i: int, n: int) -> np.ndarray:
    """The ``n`` range readings from field ``i``; BadLine naming the first that is not a number."""
    try:
        return np.array(tok[i : i + n], dtype=np.float64)
    except ValueError:
        for k in range(n):
            _number(tok, i + k, f"reading {k + 1}")
        raise BadLine("its readings are not all numbers") from None


def parse_laser(tok: list[str], max_range: float, tail: int = TAIL) -> _Laser:
    """Fields of a FLASER/RLASER/ROBOTLASERx line split into tokens, ``tail`` fields after its timestamp
    (the log's layout: CarmenReader; raises BadLine)."""
    if tok[0] in ("FLASER", "RLASER"):  # n, n readings, laser x y theta, odom x y theta, the stamp, tail
        n = _count(tok, 1, "reading count", 8 + tail)
        _fields(tok, _through_stamp(tok[0], tok[1:]) + tail, f" of {_many(n, 'reading')}")
        ranges = _readings(tok, 2, n)
        p = [_number(tok, 2 + n + k, name) for k, name in enumerate(POSE_NAMES)]
        stamp = _number(tok, 8 + n, "timestamp")
        return _Laser(stamp, -math.pi / 2, flaser_increment(n), max_range, ranges, tuple(p[:3]), tuple(p[3:]))
    # ROBOTLASER1 / ROBOTLASER2: 7 laser fields, n, n readings, n_rem, n_rem remissions, 12 after them to
    # the stamp, tail
    n = _count(tok, 8, "reading count", 21 + tail)
    n_rem = _count(tok, 9 + n, "remission count", n + 21 + tail, f" of {_many(n, 'reading')}")
    of = f" of {_many(n, 'reading')} and {_many(n_rem, 'remission')}"
    _fields(tok, _through_stamp(tok[0], tok[1:]) + tail, of)
    start, _fov, res, rmax = (_number(tok, i, name) for i, name in enumerate(ROBOTLASER_NAMES, 2))
    ranges = _readings(tok, 9, n)
    rest = 10 + n + n_rem
    p = [_number(tok, rest + k, f"{which}_{name}") for k, (which, name) in enumerate(ROBOTLASER_POSES)]
    stamp = _number(tok, rest + 11, "timestamp")
    return _Laser(stamp, start, res, rmax, ranges, tuple(p[:3]), tuple(p[3:]))


def parse_odom(tok: list[str], tail: int = TAIL) -> tuple[float, float, float, float]:
    """(timestamp, x, y, theta) of an ODOM line split into tokens, ``tail`` fields after its timestamp
    (raises BadLine)."""
    _fields(tok, 7 + tail)
    x, y, th = (_number(tok, i, name) for i, name in enumerate(("x", "y", "theta"), 1))
    return _number(tok, 7, "timestamp"), x, y, th


class CarmenReader:
    """A :class:`~cornerslam_cli.logs.base.LogReader` over one CARMEN log."""

    format = "carmen"

    def __init__(
        self,
        path: Path,
        scan_topic: str = "",
        odom_topic: str = "",
        stamps: str = "header",
        scans_alone: bool = False,
        **_frames,
    ):
        self.path = Path(path)
        self.scans_alone = scans_alone  # a run reads the scans only (input.odometry: scans)
        self.receive = receive_of(stamps)  # input.stamps: the logger timestamps asked for
        self._has_logger: dict[str, bool] = {}  # per laser / ODOM tag: a logger timestamp on every whole line
        self.stats = ReadStats()
        self._counts: dict[str, int] = {}
        self._whole: dict[str, int] = {}  # per laser / ODOM tag: whole lines with a stamp (the rest skipped)
        self._tail: dict[str, int] = {}  # per laser / ODOM tag: the fields after its stamp (TAIL)
        self._params: dict[str, str] = {}
        self._span: dict[str, tuple[float, float]] = {}  # per laser / ODOM tag: its whole lines' first, last
        self._times: dict[str, np.ndarray] = {}  # ... and every stamp of them, in file order
        self._start: float | None = None
        self._end: float | None = None
        self._back: dict[str, int] = {}  # per tag: lines stamped before the line of that tag above them
        self._moving: set[str] = set()  # laser tags whose odometry fields are not all the same pose
        # the logger timestamps are read (input.stamps=receive, or timestamps that stand still on every tag)
        self._logger_stamps = False
        self._prescan()
        self._want_scan, self._want_odom = scan_topic, odom_topic
        self.scan_topic, self.odom_topic, self._problems = self._select()
        if self.receive and (
            short := [
                t
                for t in (self.scan_topic, "" if scans_alone else self.odom_topic)  # (the tags a run reads)
                if t and not self._has_logger[t]
            ]
        ):
            raise LogError(  # (the tags read: another tag's lines may lack them)
                f"log '{self.path.name}': input.stamps=receive reads the lines' logger timestamps, which its "
                f"{' and '.join(sorted(set(short)))} lines do not all carry",
                "set input.stamps=header",
            )

    def _prescan(self) -> None:
        """Count line tags, read PARAMs, each tag's layout (the number of fields after the stamp most of
        its lines have: a line whose counts disagree with its fields has another) and, on the lines of
        that layout, the time span (cheap: no number parsing of readings)."""
        name = self.path.name
        layouts: dict[tuple[str, int], _Layout] = {}
        fault: list[str] = []
        try:
            for line in _lines(self.path, self.stats, fault):
                tag, rest = (line.split(None, 1) + ["", ""])[:2]
                if not tag or tag[0] == "#":
                    continue
                if tag == "PARAM":
                    kv = rest.split()
                    if len(kv) >= 2:
                        self._params[kv[0]] = kv[1]
                    continue
                self._counts[tag] = self._counts.get(tag, 0) + 1
                if tag in LASER_TAGS or tag == ODOM_TAG:
                    tok = rest.split()
                    through = _through_stamp(tag, tok)
                    if 0 <= through <= len(tok) <= through + TAIL:  # (else cut or malformed)
                        layouts.setdefault((tag, len(tok) - through), _Layout()).see(tag, tok, through)
        except OSError as exc:
            raise LogError(
                f"cannot read CARMEN log '{name}': {exc.strerror or exc}", "check the file (gzip damaged?)"
            ) from exc
        if not any(t in self._counts for t in LASER_TAGS + (ODOM_TAG,)):
            if fault:  # not "not a CARMEN log": the damage came before any laser or odometry line
                raise LogError(
                    f"cannot read CARMEN log '{name}': its gzip data is {fault[0]}, before any laser or "
                    "odometry line",
                    "copy the log again from its source (`gzip -t FILE` tests a copy)",
                )
            raise LogError(
                f"'{name}' is not a CARMEN log: no FLASER/RLASER/ROBOTLASER1/ODOM lines",
                "give a CARMEN log (.clf/.log), an .mcap, a .bag or a ROS 2 bag directory",
            )
        # each tag's layout: the standard one, unless another has more lines (and two at least: a log's
        # one cut line is no layout)
        chosen = {}
        for tag in {tag for tag, _ in layouts}:
            standard = layouts.get((tag, TAIL))
            lines, tail = max(
                ((n.lines, t) for (g, t), n in layouts.items() if g == tag and t != TAIL and n.lines >= 2),
                default=(0, TAIL),
            )
            self._tail[tag] = tail if lines > (standard.lines if standard else 0) else TAIL
            if (layout := layouts.get((tag, self._tail[tag]))) and layout.lines:
                chosen[tag] = layout
        self._has_logger = {t: n.logger is not None and n.logger.lines >= n.lines for t, n in chosen.items()}
        self._logger_stamps = self.receive or _stamps_stand_still(chosen)
        for tag, layout in chosen.items():
            stamps = layout.logger if self._logger_stamps else layout  # (spans and order: those read)
            self._whole[tag], self._back[tag] = layout.lines, stamps.back
            self._span[tag] = (stamps.start, stamps.end)
            self._times[tag] = np.frombuffer(stamps.times, dtype=np.float64)
            if layout.moving:
                self._moving.add(tag)
            if stamps.start <= stamps.end:
                self._start = min(stamps.start, self._start if self._start is not None else math.inf)
                self._end = max(stamps.end, self._end if self._end is not None else -math.inf)

    def _select(self) -> tuple[str, str, list[tuple[str, str]]]:
        name = self.path.name
        lasers = [t for t in LASER_TAGS if self._counts.get(t)]
        problems = []
        scan = ""
        if self._want_scan:
            if self._want_scan in lasers:
                scan = self._want_scan
            else:
                want, present = short_text(self._want_scan), self._counts.get(self._want_scan)
                what = f": its '{want}' lines are not laser lines" if present else f" has no '{want}' lines"
                if present and self._want_scan.startswith("RAWLASER"):  # raw lines: no pose, no angles read
                    what = f": its '{want}' lines are raw laser lines, which cornerslam does not read"
                listed = f" (laser lines: {', '.join(lasers)})" if lasers else ""
                hint = "choose one of them with --scan-topic" if lasers else "give a log with laser lines"
                problems.append((f"CARMEN log '{name}'{what}{listed}", hint))
        elif lasers:  # the first in order of preference with at least half as many whole lines as the
            most = max(self._whole.get(t, 0) for t in lasers)  # most: one damaged line is no laser, and
            usable = [t for t in lasers if 2 * self._whole.get(t, 0) >= most]  # 3 lines beside 150 no scans
            scan = next(t for t in ("ROBOTLASER1", "FLASER", "RLASER", "ROBOTLASER2") if t in usable)
        else:
            raw = sorted(t for t in self._counts if t.startswith("RAWLASER"))
            unread = (
                f" (its {', '.join(raw)} lines are raw laser lines, which cornerslam does not read)"
                * bool(raw)
            )
            problems.append(
                (
                    f"CARMEN log '{name}' has no laser lines (FLASER/ROBOTLASER1){unread}",
                    "give a log with scans",
                )
            )
        odom = ""
        if self._want_odom:
            if self._want_odom == ODOM_TAG and self._counts.get(ODOM_TAG) or self._want_odom in lasers:
                odom = self._want_odom
            else:
                problems.append(
                    (
                        f"CARMEN log '{name}' has no '{short_text(self._want_odom)}' lines",
                        f"choose one with --odom-topic: ODOM or a laser tag ({', '.join(lasers) or 'none'})",
                    )
                )
        elif self._whole.get(ODOM_TAG) and not self._odom_lines_worse(scan):
            odom = ODOM_TAG
        elif scan:
            odom = scan
        else:
            problems.append((f"CARMEN log '{name}' has no odometry", "select one with --odom-topic"))
        return scan, odom, problems

    def _odom_lines_worse(self, scan: str) -> str:
        """Why the ``scan`` lines' own robot poses, which move, are a better odometry than the ODOM lines,
        or "": the ODOM lines go back in time more often than the scan lines (a log whose lines are merely
        out of order together keeps its ODOM lines), or end before more than ``ODOM_UNCOVERED`` of the scan
        lines (ODOM lines cut, or unreadable past a point: the run would drop those scans). Not ODOM lines
        that start late: before a robot's odometry starts, its laser lines' odometry fields hold
        placeholders (0 0 0), which taken as poses jump the robot metres. Counted in lines, not seconds:
        one laser line stamped far in the future is one line."""
        if scan not in self._moving:
            return ""
        if self._back.get(ODOM_TAG, 0) > self._back.get(scan, 0):
            return f"ODOM lines go back in time: {self._back[ODOM_TAG]} of {self._counts[ODOM_TAG]}"
        (s0, s1), (o0, o1) = self._span[scan], self._span[ODOM_TAG]
        overlap = o0 < s1 and s0 < o1  # (spans apart: two clocks, or stamps that never move, said elsewhere)
        times = self._times[scan]  # (lines counted: one stamped far in the future is one line, not a span)
        after = int(np.count_nonzero(times > o1 + ODOM_UNCOVERED_S))
        if overlap and after > ODOM_UNCOVERED * len(times):
            return f"the whole ODOM lines end at {o1:.3f} s, before {after} of the {len(times)} {scan} lines"
        return ""

    def check(self, odometry: bool | None = None) -> None:
        """Raise LogError if a run could not read this log's scans and odometry. ``odometry`` False (the
        scans alone) asks no less: a log without laser lines fails on them first, and one with them has
        their odometry fields; only a missing --odom-topic is an odometry problem, and a run on the scans
        alone refuses that option before."""
        if self._problems:
            raise LogError(*self._problems[0])

    def info(self, inspect: bool = True) -> LogInfo:  # (the pre-read has every figure: inspect costs nothing)
        dur = (self._end - self._start) if self._start is not None else 0.0
        topics = tuple(  # rates over each tag's own span, of its whole lines (NEFF, PARAM… are not read)
            TopicInfo(tag, f"carmen/{tag}", n, _rate(self._whole.get(tag, 0), self._span.get(tag)), "carmen")
            for tag, n in sorted(self._counts.items())
        )
        src = ""
        if self.odom_topic == ODOM_TAG:
            src = "ODOM lines"
        elif self.odom_topic:
            src = f"{self.odom_topic} odometry fields"
            if not self._want_odom and not self._whole.get(ODOM_TAG, 0) and self._counts.get(ODOM_TAG):
                src += f"; no ODOM line is whole: {self._counts[ODOM_TAG]} skipped"
            elif not self._want_odom and self._counts.get(ODOM_TAG):
                src += f"; {self._odom_lines_worse(self.scan_topic)}"
        return LogInfo(
            format=self.format,
            path=str(self.path),
            start=self._start,
            end=self._end,
            duration=dur,
            n_messages=sum(self._counts.values()),
            topics=topics,
            scan_topic=self.scan_topic,
            odom_topic=self.odom_topic,
            odom_source=src,
            problems=tuple(f"{m} ({h})" for m, h in self._problems),
            notes=(
                *(
                    f"its {t} lines ({self._whole[t]}) are not used (--scan-topic {t} reads them instead)"
                    for t in LASER_TAGS
                    if self.scan_topic and t != self.scan_topic and self._whole.get(t)
                ),
                *(  # the topics' counts above hold them
                    f"{bad} of its {self._counts[t]} {t} lines {'is' if bad == 1 else 'are'} cut or "
                    "malformed: a run skips them"
                    for t in dict.fromkeys((self.scan_topic, self.odom_topic))
                    if (bad := self._counts.get(t, 0) - self._whole.get(t, 0)) > 0
                ),
            ),
        )

    def _max_range(self, tag: str) -> float:
        key = "robot_rear_laser_max" if tag == "RLASER" else "robot_front_laser_max"
        try:
            v = float(self._params[key])
            return v if v > 0 else DEFAULT_MAX_RANGE
        except (KeyError, ValueError):
            return DEFAULT_MAX_RANGE

    odom_on_tf = False  # CARMEN has no tf
    mount_problem = ""  # why laser_to_base() found no mount in the laser poses (lasers.warn_mount says it)

    def laser_upside_down(self) -> bool | None:  # a CARMEN laser pose is planar: input.laser.upside_down
        return None

    def laser_to_base(self) -> Pose2 | None:
        """Laser pose in the robot frame from ROBOTLASER1 laser/robot poses (first 50 lines), else None."""
        self.check()
        if not self.scan_topic.startswith("ROBOTLASER"):
            return None
        offs = []
        for line in _lines(self.path, None):
            tok = line.split()
            if not tok or tok[0] != self.scan_topic:
                continue
            try:
                las = parse_laser(tok, 0.0, self._tail.get(self.scan_topic, TAIL))
            except BadLine:
                continue
            (lx, ly, lt), (rx, ry, rt) = las.laser, las.robot
            if not all(math.isfinite(v) for v in (lx, ly, lt, rx, ry, rt)):
                continue
            c, s = math.cos(rt), math.sin(rt)
            dx, dy = lx - rx, ly - ry
            offs.append((c * dx + s * dy, -s * dx + c * dy, math.atan2(math.sin(lt - rt), math.cos(lt - rt))))
            if len(offs) >= 50:
                break
        if not offs:
            return None
        a = np.array(offs)
        mid = np.median(a, axis=0)
        xy = np.hypot(*(a[:, :2] - mid[:2]).T)
        turn = np.abs(np.arctan2(np.sin(a[:, 2] - mid[2]), np.cos(a[:, 2] - mid[2])))
        near = (xy <= MOUNT_SPREAD[0]) & (turn <= MOUNT_SPREAD[1])
        if near.mean() < MOUNT_SHARE:  # not one place on the robot: no mount
            self.mount_problem = (
                f"gives no laser mount: its {self.scan_topic} laser poses are not at one place on the robot "
                f"(over its first {len(a)} lines their offsets from the robot poses spread over "
                f"{xy.max():.2f} m and {math.degrees(turn.max()):.1f}°: corrected poses in their fields?)"
            )
            return None
        a = a[near]  # (a line or two with a glitched pose left out)
        return (
            float(a[:, 0].mean()),
            float(a[:, 1].mean()),
            float(np.arctan2(np.sin(a[:, 2]).mean(), np.cos(a[:, 2]).mean())),
        )

    def _warn_odometry(self) -> None:
        """Warn when the odometry is a laser tag's pose fields for want of whole ODOM lines, or those
        fields never move (the run then has none: the scans alone)."""
        odom, n_odom = self.odom_topic, self._counts.get(ODOM_TAG, 0)
        if odom == ODOM_TAG:
            return
        if n_odom and not self._whole.get(ODOM_TAG) and not self._want_odom:
            self.stats.warn(
                "%s: none of its %d ODOM lines is whole (their fields do not match the format): the odometry "
                "is its %s lines' pose fields instead",
                self.path.name, n_odom, odom,
            )  # fmt: skip
        if self._whole.get(odom, 0) > 1 and odom not in self._moving:
            self.stats.warn(
                "%s: the odometry pose fields of its %s lines never move: the run takes the robot as "
                "standing still and moves it only as far as its scan matches correct that (give a log with "
                "odometry, or run on the scans alone: --set input.odometry=scans)",
                self.path.name, odom,
            )  # fmt: skip

    @property
    def stamps_name(self) -> str:
        """What the lines' times are read from, as the refusals name it."""
        return "logger timestamps" if self._logger_stamps else "timestamps"

    def stamps_way_out(self) -> str:
        """The other ``input.stamps`` as a refusal's hint: the timestamps when the logger timestamps were
        asked for; the logger timestamps when every line read carries one (and they are not read already)."""
        if self.receive:
            return ", or read the lines' timestamps: --set input.stamps=header"
        if self._logger_stamps:  # (read on them already: the timestamps stand still)
            return ""
        if all(self._has_logger.get(t, False) for t in (self.scan_topic, self.odom_topic) if t):
            return ", or take each line at its logger timestamp: --set input.stamps=receive"
        return ""

    @property
    def stamp_hint(self) -> str:
        """What to check when the scans' stamps repeat or go back: the field they are read from."""
        if self._logger_stamps:
            why = "input.stamps=receive" if self.receive else "their timestamps never change"
            return f"check the laser lines' logger timestamps ({why})"
        return "check the laser lines' timestamp field"

    def _stamps_note(self) -> str:
        """What is said of a log read on its logger timestamps (``_logger_stamps``)."""
        tags = " and ".join(t for t in (*LASER_TAGS, ODOM_TAG) if self._whole.get(t, 0) >= 2)
        return f"the timestamps of its {tags} lines never change: read on their logger timestamps instead"

    @staticmethod
    def _logger_stamp(tok: list[str]) -> float:
        """A line's logger timestamp: its last field (a log is read on them only when its layouts have
        all TAIL fields, and a line of another layout fails to parse before this)."""
        return _number(tok, len(tok) - 1, "logger timestamp")

    def messages(self) -> Iterator[Scan | OdomSample]:
        self.check()
        return self._iter()

    def scans(self) -> Iterator[Scan]:
        """The scans alone (``extract``, ``info``'s first scan: the odometry read and warned of as a run
        would; on the scans alone, ``scans_alone``, it is neither read nor warned of)."""
        if not self.scans_alone:
            return (m for m in self.messages() if isinstance(m, Scan))
        self.check()
        return self._iter(odometry=False)  # type: ignore[return-value]

    def _iter(self, odometry: bool = True) -> Iterator[Scan | OdomSample]:
        st = self.stats
        scan_tag, odom_tag = self.scan_topic, self.odom_topic if odometry else None
        max_range = self._max_range(scan_tag)
        where = self.path.name
        if odometry:
            self._warn_odometry()
        if self._logger_stamps and not self.receive:  # (asked for: nothing to say)
            st.warn("%s: %s", where, self._stamps_note())
        unread, first_unread = 0, ""  # laser lines that could not be read; the first's number and why
        for lineno, line in enumerate(_lines(self.path, st), 1):
            tok = line.split()
            tag = tok[0] if tok else ""
            if tag != scan_tag and tag != odom_tag:
                continue
            try:
                if tag == ODOM_TAG:
                    stamp, x, y, th = parse_odom(tok, self._tail.get(ODOM_TAG, TAIL))
                    stamp = self._logger_stamp(tok) if self._logger_stamps else stamp
                    if st.bad_odometry(f"{where}:{lineno}", stamp, (x, y, th)):
                        continue
                    st.odoms += 1
                    yield OdomSample(stamp, x, y, th)
                    continue
                las = parse_laser(tok, max_range, self._tail.get(tag, TAIL))
                las.stamp = self._logger_stamp(tok) if self._logger_stamps else las.stamp
            except BadLine as exc:
                st.failed("%s:%d: malformed %s line skipped (%s)", where, lineno, tag, exc)
                if tag == scan_tag:
                    unread += 1
                    first_unread = first_unread or f"line {lineno}: {short_text(str(exc), 100)}"
                continue
            if tag == odom_tag and not st.bad_odometry(f"{where}:{lineno}", las.stamp, las.robot):
                st.odoms += 1
                yield OdomSample(las.stamp, *las.robot)
            if tag != scan_tag:  # odometry from another laser's lines: not scans
                continue
            scan = make_scan(
                st, f"{where}:{lineno}", las.stamp, las.angle_min, None, las.angle_increment, 0.0,
                las.range_max, las.ranges,
            )  # fmt: skip
            if scan is not None:
                yield scan
        if st.decode_failed > 5:
            st.warn("%s: %d malformed lines skipped in total", where, st.decode_failed)
        if unread and st.scans == st.scans_skipped == 0:  # the log's fault, whatever span was asked for
            which = (
                f"its only {scan_tag} line cannot"
                if unread == 1
                else f"none of its {unread} {scan_tag} lines can"
            )
            raise LogError(
                f"CARMEN log '{where}' has no complete laser line: {which} be read ({first_unread})",
                "a recorder stopped mid-line, the file is damaged, or its lines are not CARMEN's (each ends "
                "with its timestamp, hostname and logger timestamp, or the timestamp (and hostname) alone): "
                "give a log with whole laser lines",
            )
        fields = (  # (a FLASER/RLASER line's angles are the laser preset's: only its count can be off)
            f"the {scan_tag} lines' start_angle/angular_resolution, in radians, and reading counts"
            if scan_tag.startswith("ROBOTLASER")
            else f"the {scan_tag} lines' reading counts and timestamps"
        )
        st.check_scans_yielded(where, scan_tag, fields)

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()
