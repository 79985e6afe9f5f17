"""Config sections of the log stage: the input (``input``: topics, beams, the laser mount, deskewing),
odometry jumps (``input.odom_jump``) and keyframe selection (``keyframes``), used by ``sync.py`` and
the front end; ``config.py`` assembles them into the full config."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

from ..ranges import check_ranges, num

TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class OdomJumpConfig:
    """Odometry jumps and resets (``logs/sync.py reanchor_odometry``).

    Between two odometry samples dt seconds apart, a move farther than ``distance`` or a turn larger
    than ``angle`` per ``period`` seconds (scaled by dt / period when dt > period) is not motion the
    robot can make: it is a jump (a reset of the odometry to zero, a relocalisation). The jump is
    not applied as motion: the odometry after it is re-anchored to continue from the pose before it,
    and the step across it adds diag(sigma_xy², sigma_xy², sigma_theta²) to the robot covariance.
    """

    distance: float = num(2.0, ge=0.0, le=1000.0)  # metres per period; 0 = no jump detection
    angle: float = num(math.pi / 2, ge=0.0, le=TWO_PI)  # radians per period
    period: float = num(0.1, gt=0.0, le=1000.0)  # seconds
    sigma_xy: float = num(0.1, ge=0.0, le=100.0)  # metres, added robot uncertainty across a jump
    sigma_theta: float = num(0.05, ge=0.0, le=TWO_PI)  # radians

    def __post_init__(self) -> None:
        check_ranges(self)


@dataclass(frozen=True)
class KeyframeConfig:
    """Process a scan only after the robot moved this much (gmapping linearUpdate/angularUpdate)."""

    linear_update: float = num(0.0, ge=0.0, le=1000.0)  # metres; 0 with angular_update 0 = every scan
    angular_update: float = num(0.0, ge=0.0, le=TWO_PI)  # radians
    max_interval: float = num(0.0, ge=0.0, le=1e6)  # seconds; 0 = no time-based keyframes
    # seconds: a laser faster than this (the median interval of its first RATE_SCANS scans) is thinned to a
    # scan at most this often — the front end learns the odometry's bias over a window of keyframes, and
    # at 20–100 Hz that window spans so little travel that an odometer's scale error went unlearnt
    # (benchmarks/scan_rate.py); a ~10 Hz laser, whose stamps jitter (Mines: 5 ms apart at times), is not
    # touched. 0 = off
    min_interval: float = num(0.08, ge=0.0, le=1e6)

    def __post_init__(self) -> None:
        check_ranges(self)


@dataclass(frozen=True)
class LaserMountConfig:
    """Pose of the laser in the robot base frame (used when the log has no tf for it). ``x``, ``y``,
    ``yaw`` None (null): not set, the built-in 0 (a run warns, lasers.mount_source); 0 set is the
    config's."""

    x: float | None = num(None, ge=-100.0, le=100.0)  # metres
    y: float | None = num(None, ge=-100.0, le=100.0)  # metres
    yaw: float | None = num(None, ge=-TWO_PI, le=TWO_PI)  # radians
    from_tf: bool = True  # prefer a static transform base→laser found in the log
    # mounted upside down (z axis down, roll π: its scans are mirrored); from a ROS tf when it is used
    # (a CARMEN ROBOTLASER1 laser pose is planar: this key says it there too)
    upside_down: bool = False

    def __post_init__(self) -> None:
        check_ranges(self)


# m or rad: two laser mounts this close are the same (input.laser.x/y/yaw against the log's, two scan frames
# of one topic on tf)
MOUNT_SAME = 1e-4


@dataclass(frozen=True)
class InputConfig:
    """Which topics to read and how to treat beams."""

    scan_topic: str = ""  # "" = choose by message type
    odom_topic: str = ""  # "" = nav_msgs/Odometry topic, else tf odom→base
    # where the motion between scans comes from: the log's odometry (odom_topic), or the scans alone —
    # each registered on the ones before (motion/scan_odometry.py), for a log without wheel odometry
    odometry: Literal["log", "scans"] = "log"
    odom_frame: str = "odom"
    base_frame: str = "base_link"
    # the laser whose scans are used when two publish on one topic (their frame_ids differ and the tf
    # mounts them apart): "" = the first scan's frame; the other's scans are left out, warned
    scan_frame: str = ""
    # metres; 0 = use the scan's range_max; beams at or beyond are "no return"
    max_range: float = num(0.0, ge=0.0, le=10_000.0)
    # beams at the start of each scan to ignore (e.g. robot body)
    skip_beams_start: int = num(0, ge=0, le=100_000)
    skip_beams_end: int = num(0, ge=0, le=100_000)
    # the time each scan and odometry sample is taken at: its header stamp, or when the recorder received
    # it (a ROS log's log time; a CARMEN line's logger_timestamp) — for a log whose laser and odometry
    # stamp on different clocks, or not at all
    stamps: Literal["header", "receive"] = "header"
    # seconds added to every scan stamp before syncing with odometry (large enough to bridge two clocks)
    scan_time_offset: float = num(0.0, ge=-1e10, le=1e10)
    # correct each beam for the robot's motion while the laser swept (logs/deskew.py), when the beams'
    # times are known: the scan message's time_increment, else ``beam_time``
    deskew: bool = True
    # seconds between two beams when the log does not say (0 = not known: no correction), e.g. from
    # the laser's data sheet (a URG-04LX: 0.1 s a turn of 1,024 steps); negative: beams numbered
    # against time
    beam_time: float = num(0.0, ge=-0.001, le=0.001)
    laser_preset: str = "auto"  # auto (by the scan's geometry) | none | a name in lasers.PRESETS
    laser: LaserMountConfig = field(default_factory=LaserMountConfig)
    odom_jump: OdomJumpConfig = field(default_factory=OdomJumpConfig)

    def __post_init__(self) -> None:
        check_ranges(self)


STAMPS = ("header", "receive")  # input.stamps


def receive_of(stamps: str) -> bool:
    """Whether ``input.stamps`` (``stamps``, one of STAMPS) takes the recorder's times."""
    if stamps not in STAMPS:
        raise ValueError(f"stamps must be one of {', '.join(STAMPS)}, not {stamps!r}")
    return stamps == "receive"
