"""The reader of ROS-message logs (MCAP, ROS 1 bag, ROS 2 bag): :class:`RosLogReader` over the
:class:`RawSource` a format module (``mcap.py``, ``rosbag.py``) opens.

It selects the topics by message type, decodes LaserScan and Odometry messages (``cdr.py`` for CDR
and ROS 1, ``jsonmsg.py`` for JSON), takes the laser's mounting from tf, and counts what it skips;
the conventions it follows are listed in ``base.py``. Over 400 lines because it is one class whose
selection, decoding and tf steps share the reader's state.
"""

from __future__ import annotations

import difflib
import itertools
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Protocol

import numpy as np

from ..errors import LogError
from ..geometry import wrap_angle
from ..ranges import short_text
from ..types import OdomSample, Scan
from .base import (
    ENCODINGS,
    Channel,
    LogInfo,
    Pose2,
    ReadStats,
    TopicInfo,
    logger,
    make_scan,
    normalize_msgtype,
    strip_frame,
)
from .params import MOUNT_SAME, InputConfig, receive_of
from .sync import CLOCKS_APART
from .unreadable import damage_problem

LASERSCAN = "sensor_msgs/LaserScan"
ODOMETRY = "nav_msgs/Odometry"
TF_TYPES = ("tf2_msgs/TFMessage", "tf/tfMessage")
INFO_LISTS = "`cornerslam info LOG` lists the topics"
MIN_RATE_SPAN = 1e-3  # s: a topic's messages closer together than this have no rate worth showing
CLOCK_APART = 1.0  # s: a recorder clock this far from the scans' header stamps is another clock (not a delay)
MAX_TILT = 5.0  # degrees: a laser tilted more than this from level (upright or upside down) is warned about


# --------------------------------------------------------------------------- tf


def transform_matrix(t: tuple[float, float, float], q: tuple[float, float, float, float]) -> np.ndarray:
    """4x4 homogeneous matrix of translation t and quaternion q = (x, y, z, w) (normalised; not 0).

    A finite q is first divided by its largest component, then by ``math.hypot``'s length: a
    component of 1e200, or two of 1.5e308 (corrupt data), still gives its rotation, where the length
    would overflow to inf (x² + y² + z² + w² from 1e155 on; hypot itself past 1.8e308) and every
    component divided by it to 0, no rotation. A non-finite q gives a non-finite matrix (the caller
    checks the result); a zero q raises."""
    x, y, z, w = q
    if all(math.isfinite(v) for v in q) and (big := max(abs(x), abs(y), abs(z), abs(w))) > 0:
        x, y, z, w = x / big, y / big, z / big, w / big
    nrm = math.hypot(x, y, z, w)
    x, y, z, w = x / nrm, y / nrm, z / nrm, w / nrm
    T = np.eye(4)
    T[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    T[:3, 3] = t
    return T


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


WORLD_FRAMES = ("map", "odom", "world", "earth")  # REP 105's: never a robot's frame


def tf_root(edges: dict[tuple[str, str], np.ndarray], frame: str, topics: dict[tuple[str, str], str]) -> str:
    """The topmost frame above ``frame`` along the static tf ``edges`` (parent, child; ``topics``: the
    topic each came on — the mount of a laser on its robot is static, the robot's pose in odom_combined or
    map is not: a review), short of a REP 105 world frame; ``frame`` when it has no such parent (a loop of
    edges stops where it would come round)."""
    parent_of = {child: parent for (parent, child) in edges if is_static(topics[(parent, child)])}
    seen = {frame}
    while (parent := parent_of.get(frame)) is not None and parent not in seen and not _world(parent):
        seen.add(parent)
        frame = parent
    return frame


def _world(frame: str) -> bool:
    """A REP 105 world frame, also under a robot's prefix (``robot1/map``)."""
    return frame.rsplit("/", 1)[-1] in WORLD_FRAMES


def tilt_from_level(T: np.ndarray) -> float:
    """Degrees between the z axis of a 4x4 transform's child frame and the parent's z axis or its
    opposite: 0 for a level laser, upright or upside down."""
    return math.degrees(math.acos(min(1.0, abs(float(T[2, 2])))))


def missing_odom_tf(
    log: str, topic: str, odom_frame: str, base_frame: str, seen: set[tuple[str, str]]
) -> tuple[str, str]:
    """(problem, hint) of a tf odometry topic without odom_frame→base_frame: the transforms it has,
    and the key to set when one of them starts at odom_frame (nav2's odom→base_footprint) or ends at
    base_frame (another odometry frame's name)."""
    pairs = sorted(seen)
    has = ", ".join(f"{short_text(p)}→{short_text(c)}" for p, c in pairs[:10]) or "none"
    problem = (
        f"log '{log}': topic '{short_text(topic)}' has no {short_text(odom_frame)}→{short_text(base_frame)} "
        f"transform (its transforms: {has}{', …' if len(pairs) > 10 else ''})"
    )
    children = [c for p, c in pairs if p == odom_frame]
    parents = [p for p, c in pairs if c == base_frame]
    if len(children) == 1:
        hint = f"give run the robot's frame: --set input.base_frame={short_text(children[0])}"
    elif len(parents) == 1:
        hint = f"give run the odometry frame: --set input.odom_frame={short_text(parents[0])}"
    else:
        hint = (
            "set input.odom_frame / input.base_frame to the log's frames, "
            "or choose an Odometry topic with --odom-topic"
        )
    return problem, hint


DEFAULT_BASE_FRAME = InputConfig.base_frame  # input.base_frame left at this: the odometry's frame is taken
DEFAULT_ODOM_FRAME = InputConfig.odom_frame  # ... input.odom_frame: a nav_msgs/Odometry's frame_id is taken
ROBOT_FRAME_MESSAGES = 2000  # messages of the odometry topic read for the robot's frame at most


def _child_frame(decoder, data: bytes | memoryview) -> str:
    """A nav_msgs/Odometry's child_frame_id; "" when it cannot be read (the pose still can: a JSON
    message without the field)."""
    try:
        return decoder.odometry_frame(data)
    except Exception:  # noqa: BLE001 - only a warning depends on it
        return ""


def merged(span: tuple[int, int] | None, other: tuple[int, int]) -> tuple[int, int]:
    """The (first, last) span holding ``span`` (None: none yet) and ``other``: a topic's over its parts."""
    return other if span is None else (min(span[0], other[0]), max(span[1], other[1]))


def namespace(topic: str) -> str:
    """The namespace of a topic: ``/robot1/scan`` → ``/robot1``, ``/scan`` → ``""``."""
    return topic.rsplit("/", 1)[0]


def is_static(topic: str) -> bool:
    """Whether a tf topic carries static transforms: ``/tf_static``, a robot's ``/robot1/tf_static``."""
    return topic.rsplit("/", 1)[-1] == "tf_static"


def of_robot(topics: list[str], scan_topic: str) -> list[str]:
    """Of ``topics``, those of the robot whose scans are ``scan_topic``: in its namespace or one above it
    (``/robot1/scan``: ``/robot1/tf``, ``/tf``, not ``/robot2/tf``, whose frames may be named alike) —
    all of them when none is (the scans outside the robot's namespace), or no scan topic is chosen."""
    if not scan_topic:
        return topics
    ns = namespace(scan_topic)
    mine = [t for t in topics if (n := namespace(t)) == ns or ns.startswith(n + "/")]
    return mine or topics


def listing(names: list[str], most: int = 10) -> str:
    """``"/a, /b"`` or ``"none"``, for error messages: long names shortened, at most ``most`` of them."""
    shown = ", ".join(short_text(n) for n in sorted(names)[:most])
    return (shown + (f" and {len(names) - most} more" if len(names) > most else "")) if names else "none"


# --------------------------------------------------------------------------- the reader


class RawSource(Protocol):
    """A ROS-message log opened by a format module: topics and raw serialized messages."""

    format: str

    def channels(self) -> list[Channel]: ...

    def time_range(self) -> tuple[int, int] | None:
        """(first, last) log time in ns, None if the log has no messages."""
        ...

    def topic_spans(self) -> dict[str, tuple[int, int]]:
        """(first, last) log time in ns of each topic the log tells cheaply (its index), others left out."""
        ...

    def raw_messages(self, topics: set[str]) -> Iterator[tuple[str, int, bytes | memoryview]]:
        """(topic, log_time_ns, data) of the given topics in log-time order, streaming."""
        ...

    def close(self) -> None: ...


# pose topics a log may hold instead of odometry (named when it has none cornerslam reads)
POSE_TYPES = ("geometry_msgs/PoseStamped", "geometry_msgs/PoseWithCovarianceStamped")
NOT_POSES = ("goal_pose", "initialpose")  # ... but not these (navigation's goal, a localiser's start)


@dataclass(frozen=True)
class _OdomSel:
    topic: str  # "" if none
    kind: str  # "odometry" | "tf" | ""
    problem: str = ""
    hint: str = ""
    note: str = ""  # a choice among several, for ``info``'s notes


def _alike_frames(a: str, b: str) -> bool:
    """Whether two tf frames are named alike: one the other with a suffix or a prefix (``laser``,
    ``laser_link``, ``laser_frame``, ``base_laser``: a probe's scans in base_laser, the tf's laser), the
    namespace aside."""
    a, b = a.rsplit("/", 1)[-1], b.rsplit("/", 1)[-1]
    return a != b and any(x.startswith(y + "_") or x.endswith("_" + y) for x, y in ((a, b), (b, a)))


def _median_offset(stamps: list[int], log_times: list[int]) -> int | None:
    """The median of the log times less the stamps [ns], None without any."""
    offsets = sorted(t - s for s, t in zip(stamps, log_times, strict=True))
    return offsets[len(offsets) // 2] if offsets else None


class RosLogReader:
    """A :class:`LogReader` over any :class:`RawSource` (MCAP, ROS 1 bag, ROS 2 bag).

    Topic selection (when not given): the only sensor_msgs/LaserScan topic; the only
    nav_msgs/Odometry topic (several: the one named ``/odom``, noted, else an error), else tf
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
        scan_frame: str = "",
        stamps: str = "header",
        scans_alone: bool = False,
    ):
        self.scans_alone = scans_alone  # a run reads the scans only (input.odometry: scans)
        self.source = source
        # input.stamps "receive": every message taken at its log time (the recorder's), not its header stamp
        self.receive = receive_of(stamps)
        self.path = Path(path)
        self.format = source.format
        self.stats = stats if stats is not None else ReadStats()
        self.odom_frame = strip_frame(odom_frame)
        self.base_frame = strip_frame(base_frame)  # the robot's frame: the config's until resolved
        self.config_base_frame = self.base_frame
        self.scan_frame = strip_frame(scan_frame)  # input.scan_frame: the laser used ("": the first scan's)
        self._tf_edges: dict[tuple[str, str], np.ndarray] = {}  # the tf laser_to_base() read (other lasers')
        self._robot_resolved = False  # _robot_frame() has set base_frame to the odometry's frame
        self._channels = {c.topic: c for c in source.channels()}
        self._want_scan = self._resolved(scan_topic)
        self._want_odom = self._resolved(odom_topic)
        self._scan_note = ""  # why the scan topic was chosen among several (info's notes)
        self._scan_sel = self._select_scan()
        self.scan_topic = self._scan_sel[0]  # (the odometry's choice looks at its namespace)
        self._odom_sel = self._select_odom()
        self.odom_topic = self._odom_sel.topic
        self._laser2base: Pose2 | None | bool = False  # False = not computed yet
        self._laser_upside_down = False  # the tf's laser z axis points down (set with _laser2base)
        self.laser_frame: str | None = None  # the first scan's frame_id (set by laser_to_base()), None unread
        self.odom_on_tf = False  # laser_to_base() saw tf odom_frame→base_frame (a results MCAP need not)
        self._tf_pairs: set[tuple[str, str]] = set()  # (parent, child) laser_to_base() saw on odom_topic
        self._tf_read_all = False  # laser_to_base() read every tf message (not stopped at 2,000)
        self.near_frames = ""  # ": its tf has 'laser'?" when no tf links the scans' frame (laser_to_base)

    # ---------------------------------------------------------------- selection
    def _topics_of(self, *types: str) -> list[str]:
        return sorted(t for t, c in self._channels.items() if normalize_msgtype(c.msgtype) in types)

    def _cut_short(self, missing: str) -> tuple[str, str]:
        """(problem, hint) when what a run needs is ``missing`` from a file that ends early: the cut,
        not the recording's topics, is the problem."""
        return (
            f"log '{self.path.name}' is truncated: {missing} before the cut",
            "the recorder stopped early and what came after is lost; record again, or give the complete file",
        )

    def _lost(self, missing: str) -> tuple[str, str]:
        """(problem, hint) when what a run needs is ``missing`` from a file that ends early
        (:meth:`_cut_short`) or whose damaged parts were skipped (an MCAP without a summary keeps its
        topics' definitions in its chunks): the file, not the recording's topics, is the problem."""
        if self.stats.truncated:
            return self._cut_short(missing)
        return damage_problem(self.path.name, self.stats, f"{missing} in its readable parts")

    def _lossy(self) -> bool:
        """Whether part of the file could not be read (cut short, or damaged parts skipped)."""
        return self.stats.truncated or self.stats.damaged > 0

    def _cut_note(self) -> str:
        """Said of a topic that is not there, when the file ends early or has damaged parts."""
        if self.stats.truncated:
            return " before the cut (the file is truncated)"
        return " in its readable parts (some of the file is damaged)" if self.stats.damaged else ""

    def _resolved(self, want: str) -> str:
        """``want`` as ROS tools resolve a relative name in the root namespace: ``base_scan`` is
        ``/base_scan`` when the log has that topic and none named ``base_scan`` itself."""
        if want and not want.startswith("/") and want not in self._channels and f"/{want}" in self._channels:
            return f"/{want}"
        return want

    @staticmethod
    def _close_to(want: str, names: list[str]) -> str:
        """ ", did you mean '/scan'?" when a topic of ``names`` (those of the type wanted) is close to
        ``want`` — a missing leading slash, a namespace left out (each such topic named), a typo — else ""."""
        bare = want.lstrip("/")
        close = [t for t in names if t.lstrip("/") == bare or t.endswith("/" + bare)]
        close = close or difflib.get_close_matches(want, names, n=1, cutoff=0.75)
        return f", did you mean {' or '.join(repr(short_text(t)) for t in close[:3])}?" if close else ""

    def _select_scan(self) -> tuple[str, str, str]:
        """(topic, problem, hint)."""
        name = self.path.name
        scans = self._topics_of(LASERSCAN)
        if self._want_scan:
            want = short_text(self._want_scan)
            c = self._channels.get(self._want_scan)
            if c is None:  # (a typo as often as the cut: the topics there are listed either way)
                return (
                    "",
                    f"log '{name}' has no topic '{want}'{self._cut_note()} "
                    f"(LaserScan topics: {listing(scans)})",
                    f"check --scan-topic{self._close_to(self._want_scan, scans)}; {INFO_LISTS}",
                )
            if normalize_msgtype(c.msgtype) != LASERSCAN:
                return (
                    "",
                    f"topic '{want}' of log '{name}' is {normalize_msgtype(c.msgtype)}, "
                    "not sensor_msgs/LaserScan",
                    f"choose a LaserScan topic with --scan-topic ({listing(scans)})"
                    if scans
                    else "it has no LaserScan topic: cornerslam reads the laser as sensor_msgs/LaserScan",
                )
            return self._want_scan, "", ""
        if not scans and self._lossy():
            return "", *self._lost("no sensor_msgs/LaserScan topic")
        if not scans and getattr(self.source, "results_of_run", False):
            return (
                "",
                f"'{name}' is the results MCAP of a run (`cornerslam run --mcap-out`), not a log",
                "give the log the run read, which its summary.json names as input.log",
            )
        if not scans:
            return (
                "",
                f"log '{name}' has no sensor_msgs/LaserScan topic",
                "record the laser as sensor_msgs/LaserScan; `cornerslam info LOG` lists the topics",
            )
        live = [t for t in scans if self._channels[t].count != 0]  # (None: not known)
        empty = [t for t in scans if t not in live]
        if len(scans) > 1 and len(live) == 1:  # the others declared, never published (`ros2 bag record -a`)
            self._scan_note = f"{listing(empty)} has no messages: LaserScan topic {live[0]} taken"
            logger.info("log '%s': %s", name, self._scan_note)
            return live[0], "", ""
        if len(scans) > 1:
            listed = live or scans
            also = f" (and {listing(empty)} with no messages)" if live and empty else ""
            return (
                "",
                f"log '{name}' has {len(listed)} LaserScan topics: {listing(listed)}{also}",
                "choose one with --scan-topic",
            )
        return scans[0], "", ""

    def _select_odom(self) -> _OdomSel:
        name = self.path.name
        odoms = self._topics_of(ODOMETRY)
        tfs = [t for t in self._topics_of(*TF_TYPES) if not is_static(t)]
        if self._want_odom:
            want = short_text(self._want_odom)
            c = self._channels.get(self._want_odom)
            if c is None:
                return _OdomSel(
                    "",
                    "",
                    f"log '{name}' has no topic '{want}'{self._cut_note()} "
                    f"(Odometry topics: {listing(odoms)}; tf topics: {listing(tfs)})",
                    f"check --odom-topic{self._close_to(self._want_odom, odoms + tfs)}; {INFO_LISTS}",
                )
            mt = normalize_msgtype(c.msgtype)
            if mt == ODOMETRY:
                return _OdomSel(self._want_odom, "odometry")
            if mt in TF_TYPES:
                return _OdomSel(self._want_odom, "tf")
            return _OdomSel(
                "",
                "",
                f"topic '{want}' of log '{name}' is {mt}, not nav_msgs/Odometry or tf2_msgs/TFMessage",
                f"choose one with --odom-topic (Odometry: {listing(odoms)}; tf: {listing(tfs)})",
            )
        mine = [t for t in odoms if not self._other_robots(t)]  # (several robots: another's set aside)
        live = [t for t in mine if self._channels[t].count != 0]  # (None: not known)
        robot_tfs = of_robot(tfs, self.scan_topic)
        if live or (mine and not robot_tfs):  # (only empty ones and no tf: a run says so, check)
            sel = self._nearest_odom(live or mine, len(odoms))
            if sel.topic and not sel.note and len(mine) < len(odoms):  # other robots' set aside
                others = listing([t for t in odoms if t != sel.topic])
                note = f"{len(odoms)} Odometry topics: {sel.topic} taken (the scans' namespace), not {others}"
                sel = self._noted(sel, note)
            return sel
        if robot_tfs:
            why = f"{listing(mine)} has no messages" if mine else "the Odometry topics are other robots'"
            note = f"{why}: tf odometry taken" if odoms else ""
            return self._noted(_OdomSel(self._tf_odometry_topic(robot_tfs), "tf"), note)
        if len(odoms) == 1 and not self.scan_topic:  # no scan topic chosen (its problem comes first): no
            return _OdomSel(odoms[0], "odometry")  # robot to call the odometry another's (a probe)
        if len(odoms) == 1:  # only another robot's
            self.stats.warn(
                "log '%s': odometry '%s' taken, the only one, though another robot's scans are in its "
                "namespace (choose another with --odom-topic)", name, odoms[0],
            )  # fmt: skip
            return _OdomSel(odoms[0], "odometry")
        if odoms:
            return _OdomSel("", "", f"log '{name}' has {len(odoms)} Odometry topics, all of other robots': "
                            f"{listing(odoms)}", "choose one with --odom-topic")  # fmt: skip
        if self._lossy():
            return _OdomSel("", "", *self._lost("no nav_msgs/Odometry topic and no tf topic"))
        poses = [  # (with messages, and not nav2's goal and initial pose, in every `record -a`: a review)
            t
            for t, c in self._channels.items()
            if normalize_msgtype(c.msgtype) in POSE_TYPES
            and c.count != 0
            and t.rsplit("/", 1)[-1] not in NOT_POSES
        ]
        of_poses = f" ({listing(sorted(poses))}: geometry_msgs poses, not read as odometry)" if poses else ""
        # (a probe: it said "no tf topic" of a log with /tf_static)
        statics = [t for t in self._topics_of(*TF_TYPES) if is_static(t)]
        no_tf = f"only {listing(statics)}, whose transforms are fixed" if statics else "no tf topic"
        return _OdomSel(
            "",
            "",
            f"log '{name}' has no odometry: no nav_msgs/Odometry topic and {no_tf}{of_poses}",
            "select an odometry topic with --odom-topic (nav_msgs/Odometry or tf with "
            f"{short_text(self.odom_frame)}→{short_text(self.base_frame)}), or run on the scans alone: "
            "--set input.odometry=scans",
        )

    def _other_robots(self, topic: str) -> bool:
        """Whether ``topic`` is in the namespace of another LaserScan topic's robot (``/robot2/odom``
        beside ``/robot2/scan``, the scans being ``/robot1/scan``) and not in the scans' own: a log of
        several robots, whose topics are told apart by namespace only then (a TurtleBot's
        ``/mobile_base/odom`` beside ``/scan`` is its own)."""
        ns, other = namespace(self.scan_topic), namespace(topic)
        robots = {namespace(t) for t in self._topics_of(LASERSCAN) if t != self.scan_topic}
        return any(
            r and r != ns and not ns.startswith(r + "/") and (other == r or other.startswith(r + "/"))
            for r in robots
        )

    def _nearest_odom(self, candidates: list[str], n_odoms: int) -> _OdomSel:
        """Of several Odometry topics, the one whose namespace shares most with the scans'
        (``/robot1/front/scan``: ``/robot1/odom`` before ``/odom``), ties to ``<namespace>/odom`` then
        ``/odom``, noted; several still: a problem (choose one)."""
        if len(candidates) == 1:
            return _OdomSel(candidates[0], "odometry")
        ns = namespace(self.scan_topic).split("/")

        def shared(topic: str) -> int:  # namespace levels in common with the scans'
            pairs = zip(ns, namespace(topic).split("/"), strict=False)
            return sum(1 for _ in itertools.takewhile(lambda p: p[0] == p[1], pairs))

        best = max(map(shared, candidates))
        top = [t for t in candidates if shared(t) == best]
        preferred = ("/".join(ns) + "/odom", "/odom")
        pick = top[0] if len(top) == 1 else next((t for t in preferred if t in top), "")
        if not pick:
            problem = f"log '{self.path.name}' has {len(top)} Odometry topics: {listing(top)}"
            return _OdomSel("", "", problem, "choose one with --odom-topic")
        others = listing([t for t in candidates if t != pick])
        why = " (the scans' namespace)" if len(top) == 1 else ""
        note = f"{n_odoms} Odometry topics: {pick} taken{why}, not {others} (choose one with --odom-topic)"
        return self._noted(_OdomSel(pick, "odometry"), note)

    def _noted(self, sel: _OdomSel, note: str) -> _OdomSel:
        """``sel`` with ``note``, why it was chosen (none when empty), logged: info lists it."""
        if note:
            logger.info("log '%s': %s", self.path.name, note)
        return replace(sel, note=note)

    def _tf_odometry_topic(self, tfs: list[str]) -> str:
        """Of the scans' robot's (not static) tf topics ``tfs`` (:func:`of_robot`), the one tf odometry is
        read from: its namespace's ``tf``, else ``/tf``, else the first."""
        own = namespace(self.scan_topic) + "/tf"
        return own if own in tfs else "/tf" if "/tf" in tfs else tfs[0]

    def _robot_tf_topics(self) -> list[str]:
        """The log's tf topics the scans' robot's transforms are on (:func:`of_robot`)."""
        return of_robot(self._topics_of(*TF_TYPES), self.scan_topic)

    def _odom_source_label(self) -> str:
        if self._odom_sel.kind == "odometry":
            return ODOMETRY
        if self._odom_sel.kind == "tf":
            base = self.base_frame if self._problems() else self._robot_frame()
            return f"tf {self.odom_frame}→{base}"
        return ""

    def _encoding_problem(self, topic: str) -> tuple[str, str] | None:
        """(problem, hint) if a chosen topic's messages are in an encoding we do not decode."""
        enc = self._channels[topic].encoding
        if enc in ENCODINGS:
            return None
        return (
            f"topic '{short_text(topic)}' of log '{self.path.name}' has message encoding "
            f"'{short_text(enc)}', which cornerslam does not decode ({', '.join(ENCODINGS)})",
            "record the ROS messages as cdr (ros2 bag record), ros1 or json (foxglove_bridge, rosbridge)",
        )

    def _problems(self) -> list[tuple[str, str]]:
        """(problem, hint) of everything that stops a run from reading this log, in the order found."""
        problems = [(self._scan_sel[1], self._scan_sel[2]), (self._odom_sel.problem, self._odom_sel.hint)]
        problems = [p for p in problems if p[0]]
        if not problems:
            problems = [p for t in (self.scan_topic, self.odom_topic) if (p := self._encoding_problem(t))]
        return problems

    def check(self, odometry: bool | None = None) -> None:
        """Raise LogError if a run could not choose its scan and odometry topics or decode them (with
        ``odometry`` False: its scan topic alone, as ``extract`` and a run on the scans alone need; None:
        as the run reads it, ``scans_alone``)."""
        odometry = not self.scans_alone if odometry is None else odometry
        problems = self._problems() if odometry else self._scan_problems()
        if problems:
            raise LogError(*problems[0])
        for topic in (self.scan_topic, self.odom_topic) if odometry else (self.scan_topic,):
            if self._channels[topic].count == 0 and self._lossy():
                raise LogError(*self._lost(f"no message of topic '{short_text(topic)}'"))
            if self._channels[topic].count == 0:
                raise LogError(
                    f"topic '{short_text(topic)}' of log '{self.path.name}' has no messages",
                    "it was declared but nothing was recorded on it; `cornerslam info LOG` shows the counts",
                )

    def _scan_problems(self) -> list[tuple[str, str]]:
        """:meth:`_problems` of the scan topic alone."""
        if self._scan_sel[1]:
            return [(self._scan_sel[1], self._scan_sel[2])]
        p = self._encoding_problem(self.scan_topic)
        return [p] if p else []

    # ---------------------------------------------------------------- info
    def info(self, inspect: bool = True) -> LogInfo:
        """What the log holds and what a run would use; with ``inspect`` (``cornerslam info``) also what
        takes more reading: each topic's rate over its own span (else over the log's), the clock note."""
        tr = self.source.time_range()
        start, end = (tr[0] * 1e-9, tr[1] * 1e-9) if tr else (None, None)
        duration = (end - start) if tr else 0.0
        # (a /map latched 120 s before the robot started: not the laser's rate)
        spans = self.source.topic_spans() if inspect else {}
        topics = []
        for c in sorted(self._channels.values(), key=lambda c: c.topic):
            rate = None
            span = (spans[c.topic][1] - spans[c.topic][0]) * 1e-9 if c.topic in spans else duration
            # (two /tf_static messages 1 ns apart, two broadcasters latched at the start: no "1e9 Hz")
            if c.count is not None and c.count > 1 and span >= MIN_RATE_SPAN:
                rate = (c.count - 1) / span
            topics.append(TopicInfo(c.topic, normalize_msgtype(c.msgtype), c.count, rate, c.encoding))
        problems = tuple(f"{p} ({h})" for p, h in self._problems())
        counts = [c.count for c in self._channels.values()]
        n = None if None in counts else sum(counts)  # None: a source that cannot say (stale metadata)
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
            notes=tuple(
                n
                for n in (
                    self._scan_note,
                    "" if self.scans_alone else self._odom_sel.note,  # (the odometry is not read)
                    self._clock_note() if inspect else "",
                )
                if n
            ),
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

    def _clock_note(self) -> str:
        """info's note when the scans' header stamps are another clock than the recorder's (the log's
        start and duration are the recorder's; a run's stamps, --start and the outputs are the headers');
        none when the run takes the recorder's times (``input.stamps=receive``)."""
        if not self.scan_topic or self._scan_problems() or self.receive:
            return ""
        stamps, log_times = self._first_scan_stamps()
        if len(stamps) >= 2 and min(stamps) == max(stamps):  # (not another clock: none)
            return (
                f"the header stamp of its first {len(stamps)} scans is {stamps[0] * 1e-9:.3f} s, every "
                "one: the laser driver does not fill it (a run needs each scan's time: check the driver)"
            )
        if odometry := self._odometry_clock_note(stamps):
            return odometry
        offset = _median_offset(stamps, log_times)  # (the same scans: read once)
        if offset is None or abs(offset) <= CLOCK_APART * 1e9:
            return ""
        way = "behind" if offset > 0 else "ahead of"
        return (
            f"its scans' header stamps are {abs(offset) * 1e-9:.1f} s {way} its record times (start and "
            "duration above are the recorder's; a run's stamps, --start/--end and its outputs, the headers')"
        )

    def _odometry_clock_note(self, scan_stamps: list[int], n: int = 20) -> str:
        """info's note when the Odometry topic's header stamps (its first ``n``) lie more than CLOCKS_APART
        from the scans' (``scan_stamps``): two clocks, on which a run meets no scan (it said nothing, and
        run refused the log; a probe)."""
        if (
            self._odom_sel.kind != "odometry"
            or self.scans_alone  # (the odometry is not read)
            or not scan_stamps
            or self._encoding_problem(self.odom_topic)
        ):
            return ""  # (an encoding no decoder reads: info's problem, run's error)
        dec = self._decoder(self.odom_topic)
        odometry, _ = self._first_stamps(self.odom_topic, lambda data: dec.odometry(data)[0], n, 4 * n)
        if not odometry:
            return ""
        apart = (min(odometry) - min(scan_stamps)) * 1e-9  # (the first of each: near one another in a log)
        if abs(apart) <= CLOCKS_APART:
            return ""
        way = "ahead of" if apart > 0 else "behind"
        return (
            f"its odometry's header stamps are about {abs(apart):.0f} s {way} its scans': two clocks, on "
            "which a run meets no scan (--set input.stamps=receive takes each message at its record time)"
        )

    def record_offset(self, n: int = 100) -> int | None:
        """How far the recorder's clock (the messages' log times) is ahead of the scans' header stamps
        [ns]: the median over the first ``n`` scans (a Gazebo run recorded without use_sim_time: 1.7e9 s);
        None without a scan that can be read; 0 when the run takes the log times (``input.stamps``)."""
        return 0 if self.receive else _median_offset(*self._first_scan_stamps(n))

    def _first_scan_stamps(self, n: int = 100) -> tuple[list[int], list[int]]:
        """The header stamps and the log times [ns] of the first ``n`` scans that can be read."""
        dec = self._decoder(self.scan_topic)
        return self._first_stamps(self.scan_topic, lambda data: dec.laserscan(data).stamp, n)

    def _first_stamps(
        self, topic: str, stamp_of: Callable, n: int, tries: int | None = None
    ) -> tuple[list[int], list[int]]:
        """The header stamps (``stamp_of`` a message's bytes: (sec, nsec)) and the log times [ns] of the
        first ``n`` messages on ``topic`` that can be read, of its first ``tries`` (None: all)."""
        stamps, log_times = [], []
        for _, log_time, data in itertools.islice(self.source.raw_messages({topic}), tries):
            try:
                sec, nsec = stamp_of(data)
            except Exception:  # noqa: BLE001 - bad bytes: the run counts them
                continue
            stamps.append(sec * 1_000_000_000 + nsec)
            log_times.append(log_time)
            if len(stamps) >= n:
                break
        return stamps, log_times

    def parent_on_tf(self, frame: str) -> str | None:
        """The parent the log's tf gives ``frame`` (a localiser's map → odom), else None: every tf message
        read until one names it a child (a results MCAP that gives it a parent of its own is warned of)."""
        topics = {t for t in self._robot_tf_topics() if self._encoding_problem(t) is None}
        decs = {t: self._decoder(t) for t in topics}
        for topic, _, data in self.source.raw_messages(topics):
            try:
                parent = next((p for p, c, *_ in decs[topic].transforms(data) if c == frame and p != c), None)
            except Exception:  # noqa: BLE001 - bad bytes were counted when the run read them
                continue
            if parent:
                return parent
        return None

    def laser_to_base(self) -> Pose2 | None:
        """Pose (x, y, yaw) of the laser in the robot's frame from tf_static/tf, else None. The robot's
        frame is the one the odometry gives the pose of (:meth:`_robot_frame`; ``base_frame`` becomes
        it), or the configured base_frame when the tf does not link the odometry's frame to the laser
        but links that one (warned).

        Reads from the start of the log until the first scan has been seen and, after it, all tf_static
        messages (when counts are known) and, when the log has other tf topics, more messages until the
        laser's frame is linked to base_frame (ROS 1's tf static_transform_publisher sends the mount on
        /tf, now and then) and odom_frame→base_frame has been seen (``odom_on_tf``): 2,000 at most.
        """
        if self._laser2base is not False:
            return self._laser2base  # type: ignore[return-value]
        self.check()
        tf_topics = set()
        for t in self._robot_tf_topics():
            if self._encoding_problem(t) is None:
                tf_topics.add(t)
            else:
                self.stats.warn(
                    "%s: tf topic '%s' has message encoding '%s': not read (laser mount from the config)",
                    self.path.name, t, self._channels[t].encoding,
                )  # fmt: skip
        frame = None
        base = self._robot_frame()  # the frame whose pose the odometry gives
        odom_children: set[str] = set()  # odom_frame→child on tf: the robot's motion, not its mount
        base_parents: set[str] = set()  # the robot frame's parents on tf other than /tf_static
        edges: dict[tuple[str, str], np.ndarray] = {}
        static_left = sum(self._channels[t].count or 0 for t in tf_topics if is_static(t))
        counts_known = all(self._channels[t].count is not None for t in tf_topics if is_static(t))
        dynamic = any(not is_static(t) for t in tf_topics)  # tf besides /tf_static: mount, odom→base
        edge_topic: dict[tuple[str, str], str] = {}  # the tf topic each edge was first read from
        after, linked_at = 0, -1  # messages since the first scan; len(edges) when the link was looked for
        linked = False  # base_frame → the laser's frame through the edges so far
        decs = {t: self._decoder(t) for t in tf_topics | {self.scan_topic}}
        scan_frames: dict[str, None] = {}  # the scans' frames read before the laser's (input.scan_frame)
        read_all = True
        for topic, _, data in self.source.raw_messages(tf_topics | {self.scan_topic}):
            if frame is not None:
                after += 1
                if after > 2000:
                    read_all = False
                    break
                if counts_known and static_left <= 0:
                    if len(edges) != linked_at and dynamic:
                        linked_at = len(edges)
                        with np.errstate(invalid="ignore", over="ignore"):
                            linked = chain_transform(edges, base, frame) is not None
                    if not dynamic or (linked and self.odom_on_tf):
                        break
            try:
                if topic == self.scan_topic:
                    if frame is None:
                        f = strip_frame(decs[topic].laserscan(data)[1])
                        scan_frames.setdefault(f, None)
                        frame = f if not self.scan_frame or f == self.scan_frame else None
                    continue
                static = is_static(topic)
                static_left -= static
                for parent, child, _, t, q in decs[topic].transforms(data):
                    if topic == self.odom_topic and len(self._tf_pairs) < 50:
                        self._tf_pairs.add((parent, child))
                    if child == base and not static:
                        base_parents.add(parent)
                    if parent == self.odom_frame:
                        odom_children.add(child)
                        self.odom_on_tf = base in odom_children
                        continue
                    if parent == child or not parent or not child:  # (tf2 refuses a frame "")
                        continue
                    if sum(v * v for v in q) < 1e-12:  # no rotation at all: not a transform
                        self.stats.warn(
                            "%s: tf %s→%s has a zero-length rotation quaternion, no rotation (tf2 refuses "
                            "it): the transform is not used, its translation neither (write w=1 for none)",
                            self.path.name, parent, child,
                        )  # fmt: skip
                        continue
                    if (parent, child) not in edges:
                        edges[(parent, child)], edge_topic[(parent, child)] = transform_matrix(t, q), topic
                    elif edge_topic[(parent, child)] != topic:
                        self._warn_other_tf(edges[(parent, child)], transform_matrix(t, q),
                                            edge_topic[(parent, child)], topic, (parent, child))  # fmt: skip
            except Exception as exc:  # noqa: BLE001 - bad bytes are counted, never raised
                logger.debug("laser_to_base: skipping undecodable %s message: %s", topic, exc)
        self.laser_frame = frame
        self._tf_read_all = read_all
        self._tf_edges = edges
        if self.scan_frame and frame is None and scan_frames:  # input.scan_frame names none of them
            raise LogError(
                f"{self.path.name}: no scan on '{short_text(self.scan_topic)}' has frame_id "
                f"'{short_text(self.scan_frame)}' (input.scan_frame; its scans': "
                f"{', '.join(repr(short_text(f)) for f in list(scan_frames)[:5])})",
                "set input.scan_frame to one of them, or leave it empty for the first scan's",
            )
        if not frame:  # no scan read, or its frame_id empty: tf2 ignores transforms to a frame ""
            self._laser2base = None
            return None
        with np.errstate(invalid="ignore", over="ignore"):  # an inf in a tf: the result is checked below
            T = chain_transform(edges, base, frame)
            config = self.config_base_frame
            if T is None and base != config and self._odom_sel.kind == "odometry":  # is input.base_frame?
                T_config = chain_transform(edges, config, frame)
                if T_config is not None:
                    self.stats.warn(
                        "%s: odometry '%s' gives the pose of frame '%s' (its child_frame_id), which the tf "
                        "does not link to the laser's frame '%s': the mount is taken from the tf %s→%s",
                        self.path.name, self.odom_topic, base, frame, config, frame,
                    )  # fmt: skip
                    T, self.base_frame = T_config, config
        self.odom_on_tf = self.base_frame in odom_children
        untold = self.odom_frame == DEFAULT_ODOM_FRAME and not self.odom_on_tf  # (input.odom_frame not set)
        if self._odom_sel.kind == "odometry" and untold:
            self._take_odometry_parent(base_parents, {f for edge in edges for f in edge})
        self._laser2base = None if T is None else pose2_from_matrix(T)
        if T is None:  # a frame of the tf named like the scans' ('laser' for 'laser_link': a ROS-user probe)
            alike = sorted({f for edge in edges for f in edge if f != frame and _alike_frames(f, frame)})
            if alike:
                self.near_frames = f" (its tf has '{alike[0]}': the scans' frame_id '{frame}' misnamed?)"
            elif (root := tf_root(edges, frame, edge_topic)) != frame:  # under another robot frame's name
                laser, robot = short_text(frame), short_text(root)
                self.near_frames = (
                    f" (its tf places '{laser}' under '{robot}': if that is the robot's frame, --set "
                    f"input.base_frame={robot})"
                )
        if self._laser2base is not None and not all(math.isfinite(v) for v in self._laser2base):
            self.stats.warn("%s: the tf %s→%s is not finite: ignored", self.path.name, self.base_frame, frame)
            self._laser2base = None
        if self._laser2base is not None:
            self._laser_upside_down = bool(T[2, 2] < 0.0)
            if (tilt := tilt_from_level(T)) > MAX_TILT:
                self.stats.warn(
                    "%s: the tf %s→%s tilts the laser %.0f° from level: its scans are used as if level",
                    self.path.name, self.base_frame, frame, tilt,
                )  # fmt: skip
        return self._laser2base  # type: ignore[return-value]

    def _warn_other_tf(
        self, first: np.ndarray, other: np.ndarray, first_topic: str, topic: str, edge: tuple[str, str]
    ) -> None:
        """Warn when tf topic ``topic`` gives an edge that ``first_topic`` gave (``first``) another
        transform: two robots' tf with frames named alike, whose scans' namespace did not tell them apart."""
        with np.errstate(invalid="ignore", over="ignore"):
            moved = float(np.hypot(*(other[:2, 3] - first[:2, 3])))
            turned = abs(math.atan2(other[1, 0], other[0, 0]) - math.atan2(first[1, 0], first[0, 0]))
        if moved > 1e-3 or min(turned, 2 * math.pi - turned) > 1e-3:
            self.stats.warn(
                "%s: tf topics '%s' and '%s' both give %s→%s, and differently: the first's is used (two "
                "robots' tf with frames named alike? a scan topic in a robot's namespace reads its tf only)",
                self.path.name, first_topic, topic, *edge,
            )  # fmt: skip

    def _robot_frame(self) -> str:
        """The frame the odometry gives the pose of, which ``base_frame`` becomes (logged when it is
        not the config's): a nav_msgs/Odometry's child_frame_id (:meth:`_odometry_frame`); for tf
        odometry, the frame odom_frame moves on its topic when base_frame is not that but rides on it
        (:meth:`_tf_odometry_frame`); the config's when neither says, and when it is not the default
        base_link: a frame the user named (to correct a wrong child_frame_id) is the robot's."""
        if self._robot_resolved:
            return self.base_frame
        self._robot_resolved = True
        if self.base_frame != DEFAULT_BASE_FRAME or not self._odom_sel.kind:  # (no odometry: the scans alone)
            return self.base_frame
        if self._odom_sel.kind == "odometry":
            robot, how = self._odometry_frame(), "its child_frame_id"
        else:
            robot, how = self._tf_odometry_frame(), f"the one child of {self.odom_frame} on it"
        if robot and robot != self.base_frame:
            logger.info(
                "%s: odometry '%s' gives the pose of frame '%s' (%s), not of input.base_frame '%s': "
                "the laser mount is looked up from '%s'",
                self.path.name, self.odom_topic, robot, how, self.base_frame, robot,
            )  # fmt: skip
            self.base_frame = robot
        return self.base_frame

    def _tf_odometry_frame(self) -> str:
        """For tf odometry whose topic has no odom_frame→base_frame among its first
        :data:`ROBOT_FRAME_MESSAGES` messages: the one frame odom_frame is the parent of there, when
        base_frame rides on it (nav2's odom→base_footprint, base_footprint→base_link on /tf_static);
        "" otherwise — base_frame a child of odom_frame, several or no children, or a base_frame the tf
        does not link to it (a typo as likely as another tree: the read then says what the topic has).
        /tf_static is read beside the odometry topic for the links, its messages not counted. With
        ``odom_frame`` left at its default and no transform from it, a robot's prefixed frames
        (``robot2/odom → robot2/base_link``: :meth:`_prefixed_odom_frame`) are odom_frame and the robot's."""
        if self._odom_sel.kind != "tf":
            return ""
        topics = {self.odom_topic} | {t for t in self._robot_tf_topics() if is_static(t)}
        decs = {t: self._decoder(t) for t in topics if self._encoding_problem(t) is None}
        kids: dict[str, set[str]] = {}  # each parent frame's children
        links = {}  # every transform, as links
        n = 0  # messages of the odometry topic read
        for topic, _, data in self.source.raw_messages(set(decs)):
            n += topic == self.odom_topic
            if n > ROBOT_FRAME_MESSAGES or self.base_frame in kids.get(self.odom_frame, ()):
                break
            try:
                for parent, child, *_ in decs[topic].transforms(data):
                    kids.setdefault(parent, set()).add(child)
                    if parent != child:
                        links[(parent, child)] = np.eye(4)  # (only whether frames are linked is asked)
            except Exception:  # noqa: BLE001 - bad bytes: messages() counts them
                continue
        if self.odom_frame not in kids and self.odom_frame == DEFAULT_ODOM_FRAME:
            if prefixed := self._prefixed_odom_frame(kids):
                logger.info(
                    "%s: tf odometry '%s' has no %s→ transform but %s→: the scans' robot's frames taken",
                    self.path.name, self.odom_topic, self.odom_frame, prefixed,
                )  # fmt: skip
                self.odom_frame = prefixed
                own = prefixed.removesuffix(DEFAULT_ODOM_FRAME) + self.base_frame  # robot2/base_link
                if own in kids[prefixed]:
                    return own
        children = kids.get(self.odom_frame, set())
        if self.base_frame in children or len(children) != 1:
            return ""
        robot = children.pop()
        return robot if chain_transform(links, robot, self.base_frame) is not None else ""

    def _prefixed_odom_frame(self, kids: dict[str, set[str]]) -> str:
        """Of the parent frames ``kids`` of a tf odometry topic, the one that is ``odom`` under a prefix
        (``robot2/odom``): the only one, or the one whose prefix is the scans' namespace (``/robot2/scan``)
        when several robots share the topic; "" when none or not one."""
        prefixed = sorted(p for p in kids if p.endswith("/" + DEFAULT_ODOM_FRAME))
        mine = [
            p
            for p in prefixed
            if "/" + p.removesuffix("/" + DEFAULT_ODOM_FRAME) == namespace(self.scan_topic)
        ]
        return (mine or prefixed)[0] if len(mine) == 1 or len(prefixed) == 1 else ""

    def _take_odometry_parent(self, base_parents: set[str], tf_frames: set[str]) -> None:
        """``odom_frame`` (left at its default) becomes the frame the nav_msgs/Odometry messages give their
        poses in (the first header frame_id of the odometry topic's first :data:`ROBOT_FRAME_MESSAGES`
        that names one, logged) when the log's tf agrees: it is the robot's parent there
        (``base_parents``: then ``odom_on_tf``), or the robot has no parent there and the frame is on no
        tf at all (``tf_frames``: the mount's frames and the rest) — the frame a results MCAP hangs ``map``
        from. Not the robot's frame itself, nor ``map`` (the results' own)."""
        parent = self._first_frame("odometry_parent")
        if parent in ("", self.base_frame, self.odom_frame, "map"):  # ("map": the results MCAP's frame)
            return
        if parent in base_parents or not (base_parents or parent in tf_frames):
            logger.info(
                "%s: odometry '%s' gives its poses in frame '%s' (its frame_id), not input.odom_frame '%s'",
                self.path.name, self.odom_topic, parent, self.odom_frame,
            )  # fmt: skip
            self.odom_frame, self.odom_on_tf = parent, parent in base_parents

    def _odometry_frame(self) -> str:
        """The first child_frame_id ('/' stripped) among the odometry topic's first
        :data:`ROBOT_FRAME_MESSAGES` nav_msgs/Odometry messages that names a frame other than
        odom_frame: the frame whose pose the odometry gives, the robot's; "" when they leave it empty
        (``input.base_frame`` is taken then)."""
        return self._first_frame("odometry_frame", self.odom_frame)  # (odom→odom would be no robot at all)

    def _first_frame(self, field: str, other_than: str = "") -> str:
        """The first frame ('/' stripped) the decoder's ``field`` reader (``odometry_frame``: a
        child_frame_id, ``odometry_parent``: a header frame_id) names among the odometry topic's first
        :data:`ROBOT_FRAME_MESSAGES` nav_msgs/Odometry messages, other than ``other_than``; "" if none."""
        if self._channels[self.odom_topic].count == 0:
            return ""
        read = getattr(self._decoder(self.odom_topic), field)
        for i, (_, _, data) in enumerate(self.source.raw_messages({self.odom_topic})):
            if i >= ROBOT_FRAME_MESSAGES:
                break
            try:
                frame = strip_frame(read(data))
            except Exception:  # noqa: BLE001 - bad bytes: messages() counts them; try the next message
                continue
            if frame and frame != other_than:
                return frame
        return ""

    def tf_odometry_poses(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The tf's odom_frame → base_frame poses on the scans' robot's tf topics, as (stamps (n,), poses
        (n, 3)) in stamp order: what a viewer chains with a results MCAP's map → odom, which need not be the
        Odometry topic a run read (a ROS-user probe: raw wheel odometry on /odom, an EKF's on tf, the
        robot shown 0.6 m off its corrected pose). None when the tf has none."""
        self.laser_to_base()  # (base_frame resolved)
        topics = {t for t in self._robot_tf_topics() if not is_static(t)}
        topics = {t for t in topics if self._encoding_problem(t) is None}
        decs = {t: self._decoder(t) for t in topics}
        rows = []
        for topic, log_time, data in self.source.raw_messages(topics):
            try:
                odom = [
                    (stamp, t, q)
                    for parent, child, stamp, t, q in decs[topic].transforms(data)
                    if parent == self.odom_frame and child == self.base_frame and any(q)
                ]
                times = self._times(log_time, [stamp for stamp, *_ in odom])  # (as the run's samples)
                for at, (_, t, q) in zip(times, odom, strict=True):
                    with np.errstate(invalid="ignore", over="ignore"):
                        rows.append((at, *pose2_from_matrix(transform_matrix(t, q))))
            except Exception:  # noqa: BLE001 - bad bytes were counted when the run read them
                continue
        v = np.array(rows, dtype=float).reshape(-1, 4)
        v = v[np.all(np.isfinite(v), axis=1)]
        if not len(v):
            return None
        v = v[np.argsort(v[:, 0], kind="stable")]
        return v[:, 0], v[:, 1:]

    def odom_tf_problem(self) -> tuple[tuple[str, str], bool] | None:
        """When odometry is read from tf and :meth:`laser_to_base` saw no odom_frame→base_frame
        transform: ((problem, hint) as ``messages()`` would raise them at the end of the log, whether
        every tf message was read, so a run must fail); else None."""
        self.laser_to_base()
        if self._odom_sel.kind != "tf" or self.odom_on_tf:
            return None
        return self._no_odom_tf(self._tf_pairs), self._tf_read_all

    def _no_odom_tf(self, seen: set[tuple[str, str]]) -> tuple[str, str]:
        """:func:`missing_odom_tf` of the tf odometry topic, with why it was chosen (an Odometry topic that
        has no messages: the error must not be only of the tf's)."""
        problem, hint = missing_odom_tf(
            self.path.name, self.odom_topic, self.odom_frame, self.base_frame, seen
        )
        return (f"{problem}; {self._odom_sel.note}" if self._odom_sel.note else problem), hint

    def laser_upside_down(self) -> bool:
        """Whether the tf mounts the laser upside down (its z axis down: its scans are mirrored,
        :meth:`Scan.mirrored`); False without a tf for it."""
        self.laser_to_base()
        return self._laser_upside_down

    def _seconds(self, log_time: int, stamp: tuple[int, int], behind_ns: int = 0) -> float:
        """A message's time [s] as ``input.stamps`` says: its header ``stamp`` (sec, nsec), or its log time
        less ``behind_ns`` (a transform stamped that much before the newest of its message)."""
        sec, nsec = divmod(log_time - behind_ns, 1_000_000_000) if self.receive else stamp
        return sec + nsec * 1e-9

    def _times(self, log_time: int, stamps: list[tuple[int, int]]) -> list[float]:
        """:meth:`_seconds` of the transforms of one message (their header ``stamps``): with the log times,
        each keeps its spacing before the newest of them, which takes the message's log time."""
        if not self.receive:
            return [self._seconds(log_time, stamp) for stamp in stamps]
        ns = [sec * 1_000_000_000 + nsec for sec, nsec in stamps]
        newest = max(ns, default=0)
        return [self._seconds(log_time, stamp, newest - n) for stamp, n in zip(stamps, ns, strict=True)]

    @property
    def stamps_name(self) -> str:
        """What the messages' times are read from, as the refusals name it."""
        return "log times" if self.receive else "header stamps"

    def stamps_way_out(self) -> str:
        """The other ``input.stamps`` as a refusal's hint: the header stamps when the log times were read;
        the log times unless the recorder's times of the scan and odometry topics do not overlap either."""
        if self.receive:
            return ", or read the messages' header stamps: --set input.stamps=header"
        spans = self.source.topic_spans()
        s, o = spans.get(self.scan_topic), spans.get(self.odom_topic)
        if s and o and (s[1] < o[0] or o[1] < s[0]):
            return ""
        return ", or take each message at the time the recorder got it: --set input.stamps=receive"

    def messages(self) -> Iterator[Scan | OdomSample]:
        """Scans and odometry samples in log-time order (raises LogError now if topics are missing)."""
        self.check()
        self._robot_frame()  # (tf odometry is read for its frame)
        return self._iter()

    def scans(self) -> Iterator[Scan]:
        """The scans alone, in log-time order: a log without odometry serves too (``extract``)."""
        self.check(odometry=False)
        return self._iter(odometry=False)  # type: ignore[return-value]

    def _iter(self, odometry: bool = True) -> Iterator[Scan | OdomSample]:
        st = self.stats
        scan_t, odom_t = self.scan_topic, self.odom_topic if odometry else ""
        scan_dec, odom_dec = self._decoder(scan_t), self._decoder(odom_t) if odometry else None
        is_tf = odometry and self._odom_sel.kind == "tf"
        where, odom_where = f"{self.path.name}:{scan_t}", f"{self.path.name}:{odom_t}"
        n_tf_match = 0
        tf_seen: set[tuple[str, str]] = set()  # (parent, child) on the odometry tf topic
        children: dict[str, int] = {}  # nav_msgs/Odometry messages by child_frame_id
        scan_frames: dict[str, bool] = {}  # the scans' frame_ids ('/' stripped), in order: used or left out
        left_out: dict[str, int] = {}  # scans of another laser's frame (:meth:`_use_frame`), by frame
        for topic, log_time, data in self.source.raw_messages({scan_t, odom_t} if odometry else {scan_t}):
            try:
                if topic == scan_t:
                    m = scan_dec.laserscan(data)
                    if not self._use_frame(scan_frames, frame := strip_frame(m.frame_id), scan_t):
                        left_out[frame] = left_out.get(frame, 0) + 1
                        continue
                    scan = make_scan(
                        st, where, self._seconds(log_time, m.stamp), m.angle_min, m.angle_max,
                        m.angle_increment, m.range_min, m.range_max, m.ranges, m.frame_id, m.time_increment,
                    )  # fmt: skip
                    if scan is not None:
                        yield scan
                    continue
                if is_tf:
                    transforms = odom_dec.transforms(data)
                    poses = [
                        (stamp, t[0], t[1], q)
                        for parent, child, stamp, t, q in transforms
                        if parent == self.odom_frame and child == self.base_frame
                    ]
                    n_tf_match += len(poses)
                    if not n_tf_match and len(tf_seen) < 50:  # for the error if none ever matches
                        tf_seen.update((parent, child) for parent, child, *_ in transforms)
                else:
                    poses = [odom_dec.odometry(data)]
                    child = _child_frame(odom_dec, data)
                    children[child] = children.get(child, 0) + 1
                times = self._times(log_time, [stamp for stamp, *_ in poses])
                for at, (_, x, y, q) in zip(times, poses, strict=True):
                    sample = st.odometry_sample(odom_where, at, float(x), float(y), q)
                    if sample is not None:
                        yield sample
            except LogError:
                raise
            except Exception as exc:  # noqa: BLE001 - undecodable message: count, warn, go on
                from .cdr import definition_note  # (local: keeps `import cornerslam_cli.logs` light)

                note = definition_note(self._channels[topic]) if topic in self._channels else ""
                st.failed(
                    "%s: cannot decode a %s message%s at %d ns: %s",
                    self.path.name,
                    topic,
                    note,
                    log_time,
                    exc,
                )
        if is_tf and n_tf_match == 0:
            raise LogError(*self._no_odom_tf(tf_seen))
        if st.decode_failed > 5:
            what = "messages could not be decoded or held unusable values"
            st.warn("%s: %d %s in total", self.path.name, st.decode_failed, what)
        self._warn_children(children)
        self._warn_left_out(left_out, scan_t)
        st.check_scans_yielded(self.path.name, scan_t)

    def _use_frame(self, seen: dict[str, bool], frame: str, topic: str) -> bool:
        """Whether a scan of ``frame`` is used (``seen``: the frames so far, used or not). With
        ``input.scan_frame`` only its scans; else the first scan's frame's and those of any frame the tf
        does not mount elsewhere. Another laser on the same topic — a frame the tf mounts elsewhere — is
        left out: every scan placed with the first laser's mount made the map of two lasers a mess (a
        ROS-user probe: ATE 3.4 m against 0.03, worse than the odometry, with a warning). A frame the tf
        mounts alike is one laser renamed; where the tf read does not mount it (or the first), every scan
        is used, placed with the first's mount, warned."""
        if frame in seen:
            return seen[frame]
        if self.scan_frame or not seen:
            use = not self.scan_frame or frame == self.scan_frame
        else:
            first = self.laser_frame or next(iter(seen))
            mount = self._other_mount(frame)
            use = mount != "elsewhere"
            if use:
                self.stats.warn(
                    "%s: scans on '%s' come from frame '%s' besides '%s' (%s): every scan is placed with the "
                    "mount of '%s'",
                    self.path.name, short_text(topic), short_text(frame), short_text(first),
                    "the tf mounts both alike: one laser renamed" if mount == "alike" else
                    "two lasers on one topic, or a driver restarted with another frame_id", short_text(first),
                )  # fmt: skip
        seen[frame] = use
        return use

    def _other_mount(self, frame: str) -> str:
        """How the tf read mounts ``frame`` against the laser's: ``alike`` (within MOUNT_SAME, upside down
        alike), ``elsewhere``, or ``unknown`` — the laser's mount not from the tf, the tf not read, or
        ``frame`` not on the part of it read (:meth:`laser_to_base` stops once the laser is linked: a
        renamed laser's mount may come later on /tf — a review: half a log was left out for it)."""
        if self._laser2base in (None, False):
            return "unknown"
        with np.errstate(invalid="ignore", over="ignore"):
            T = chain_transform(self._tf_edges, self.base_frame, frame)
        if T is None:
            return "unknown"
        if (T[2, 2] < 0.0) != self._laser_upside_down:
            return "elsewhere"
        other = pose2_from_matrix(T)
        off = [abs(a - b) for a, b in zip(other[:2], self._laser2base[:2], strict=True)]  # type: ignore[index]
        off.append(abs(wrap_angle(other[2] - self._laser2base[2])))  # type: ignore[index]
        return "alike" if max(off) <= MOUNT_SAME else "elsewhere"

    def _warn_left_out(self, left_out: dict[str, int], topic: str) -> None:
        """Say which scans :meth:`_use_frame` left out, how many, and how to use them instead."""
        if not left_out:
            return
        used = self.scan_frame or self.laser_frame or "?"
        n = sum(left_out.values())
        frames = ", ".join(f"'{short_text(f)}'" + (f" ({k})" if len(left_out) > 1 else "")
                           for f, k in list(left_out.items())[:5])  # fmt: skip
        how = "input.scan_frame chose it" if self.scan_frame else "another laser: the tf mounts it elsewhere"
        other = short_text(next(iter(left_out)))
        self.stats.warn(
            "%s: %d scans on '%s' of frame %s left out, only those of '%s' used (%s): "
            "--set input.scan_frame=%s to map with that laser's instead",
            self.path.name, n, short_text(topic), frames, short_text(used), how, other,
        )  # fmt: skip

    def _warn_children(self, children: dict[str, int]) -> None:
        """Warn when the Odometry messages give the poses of several frames (``children``: messages by
        child_frame_id, "" and odom_frame left out): two publishers on one topic, whose poses the
        odometry then jumps between."""
        frames: dict[str, int] = {}
        for c, n in children.items():
            frames[strip_frame(c)] = frames.get(strip_frame(c), 0) + n
        named = sorted(((n, c) for c, n in frames.items() if c not in ("", self.odom_frame)), reverse=True)
        if len(named) > 1:
            self.stats.warn(
                "%s: odometry '%s' gives the poses of %d frames (%s): two publishers on one topic? its "
                "poses then jump between them; record one, or choose another topic with --odom-topic",
                self.path.name, short_text(self.odom_topic), len(named),
                ", ".join(f"'{short_text(c)}' in {n} messages" for n, c in named[:5]),
            )  # fmt: skip

    def close(self) -> None:
        self.source.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()
