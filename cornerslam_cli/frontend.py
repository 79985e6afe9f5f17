"""The front end of a run: log → synchronised keyframes → features → scan-matched motion.

:func:`open_input` opens the log and finds the laser mount; :func:`frames` streams its keyframes as
:class:`Frame` s, each with its corners in the base frame, the odometry jump flag of the synchroniser
(logs/sync.py) and, with ``scan_match.enabled``, the scan-matched pose chain (motion/icp.py) that the
filter (slam.py) takes as its motion input.
"""

from __future__ import annotations

import dataclasses
import itertools
import logging
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path

import numpy as np

from .association import load_kernels as load_association_kernels
from .config import Config
from .errors import ConfigError, LogError
from .features import extract, load_kernels
from .filter import load_kernels as load_filter_kernels
from .filter.models import increment_noise
from .geometry import matrix_from_pose, transform_points
from .lasers import invalid_beams, laser_mount
from .logs import ReadStats, alone_info, open_configured, read_alone
from .logs.deskew import deskew
from .logs.keyframes import select_keyframes
from .logs.order import in_stamp_order
from .logs.sync import Synced, SyncStats, clocks_hint, reanchor_odometry, spans_apart, synchronise
from .logs.unreadable import damaged_error, no_scan_read, raise_if_undecoded
from .motion import ScanMatcher
from .motion.fusion import BiasTaken, OdometryFusion
from .motion.icp import load_kernels as load_motion_kernels
from .motion.scan_odometry import ScanOdometry, with_scan_odometry
from .ranges import short_text
from .span import Span, SpanUsed, select
from .types import Corners, Scan, Segments
from .workers import signals_deferred

log = logging.getLogger("cornerslam.frontend")


def corners_to_base(
    corners: Corners, laser2base: tuple[float, float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """Corner measurements and covariances moved from the sensor frame to the base frame.

    z_base = [t + R z_xy; φ] (φ, an angle between two lines, is frame-invariant); C_base = J C Jᵀ with
    J = blockdiag(R, 1).
    """
    x, y, yaw = laser2base
    J = np.eye(3)
    J[:2, :2] = matrix_from_pose((0.0, 0.0, yaw))[:2, :2]
    z = corners.z @ J.T
    z[:, 0] += x
    z[:, 1] += y
    C = J @ corners.cov @ J.T
    return z, C


@dataclass(frozen=True)
class Frame:
    """One keyframe after feature extraction: all that the filter and the associators need.

    odom : (3,) odometry pose at the scan's stamp; segments in the sensor frame;
    z : (m, 3), C : (m, 3, 3) corners and their covariances in the base frame.
    Extraction does not depend on the associator, so ``compare`` computes frames once for all.
    """

    stamp: float
    odom: np.ndarray
    n_points: int
    segments: Segments
    z: np.ndarray
    C: np.ndarray
    t_extract: float
    odom_jump: bool = False  # the odometry jumped since the previous keyframe (logs/sync.py)
    # motion input of the filter: the pose chain fused from odometry and scan matches (motion/), or
    # None = ``odom``; ``motion_cov``: the covariance of the increment into this frame (previous frame's
    # frame), None = the filter's odometry noise model
    motion: np.ndarray | None = None
    motion_cov: np.ndarray | None = None
    scan_matched: bool = False  # a scan match was fused into the increment into this frame
    scan_fit: float = float("nan")  # share of the scan's points on the local map after matching
    t_scan_match: float = 0.0
    # how much too small the scan matcher has found its fits' covariances (motion/fusion.py's learnt s,
    # 1 without scan matching): a fit's covariance misses what makes real matches wrong
    match_scale: float = 1.0
    bias_taken: BiasTaken | None = None  # how the increment was fused, for graph.recalibrate (only then)
    points: np.ndarray | None = None  # (k, 2) float32 valid beam end points, sensor frame (occupancy grid)


def extract_frame(scan: Scan, odom: np.ndarray, cfg: Config, laser2base: tuple[float, float, float]) -> Frame:
    t0 = time.perf_counter()
    segments, corners = extract(scan, cfg.sensor, cfg.lines, cfg.corners)  # Alg 1-2
    z, C = corners_to_base(corners, laser2base)
    C[:, 0, 0] += cfg.corners.model_sigma**2
    C[:, 1, 1] += cfg.corners.model_sigma**2
    t_extract = time.perf_counter() - t0
    points = scan.points().astype(np.float32)
    return Frame(scan.stamp, odom, len(scan.ranges), segments, z, C, t_extract, points=points)


@dataclass
class Input:
    """An opened log and what a run takes from it besides the frames."""

    path: Path
    reader: object
    info: object
    laser2base: tuple[float, float, float]
    laser_source: str  # where laser2base came from: tf, config, preset or default (lasers.mount_source)
    laser_upside_down: bool  # mounted z axis down: each scan is mirrored (Scan.mirrored) as it is read
    total_scans: int
    stats: SyncStats
    matcher: ScanMatcher | None = None  # scan matching of the motion input (scan_match.enabled)
    odom_on_tf: bool = False  # the log's tf carries odom→base (odometry from tf, or seen beside it)
    span: Span = dataclasses.field(default_factory=Span)  # the part of the log to process (span.py)
    span_used: SpanUsed = dataclasses.field(default_factory=SpanUsed)  # the scans it kept
    # where the beams' times of the deskewed keyframes came from: the log's time_increment, the config's
    # input.beam_time, none known (scans as they are) or off (input.deskew false); and the first one's value
    beam_times: str = "none"
    beam_time: float = 0.0
    # where laser_upside_down came from, which need not be where laser2base did: tf (the log's tf) or
    # config (input.laser.upside_down: a log without tf, input.laser.from_tf off, or a planar CARMEN mount)
    laser_upside_down_source: str = "config"
    # compare --jobs: the filters running at once over these frames (summary.json timing.concurrent_filters:
    # their times include waiting for the CPU)
    filters_at_once: int = 1
    # input.odometry=scans: the odometry made from the scans (motion/scan_odometry.py); None: the log's
    scan_odometry: ScanOdometry | None = None


def open_input(
    log_path: str | Path, cfg: Config, span: Span | None = None, compiling: Callable[[], None] | None = None
) -> Input:
    """Open the log, check its topics (exit-2 errors before any work), find the laser mount and load the
    extractor's and the scan matcher's compiled kernels (start-up work, not the first step's); ``span``:
    the part to process; ``compiling``: called just before the kernels load (the command line's note that a
    first run compiles them: after the log's checks, so that a bad log's error comes alone)."""
    reader = open_configured(Path(log_path), cfg.input)
    scans_alone = read_alone(cfg.input)
    reader.check()  # (on the scans alone, open_configured's reader asks no odometry)
    info = reader.info(inspect=False)  # (a run needs its topics, not its rates)
    laser2base, source, upside_down, upside_down_source = laser_mount(reader, cfg)
    # on the scans alone their odometry is already scan-matched (motion/scan_odometry.py): matching each
    # keyframe again, on a map of the same scans, and fusing the two as if independent would only make the
    # motion look surer than it is — the filter takes the odometry with its motion model (ekf.alpha*)
    fuse = cfg.scan_match.enabled and not scans_alone
    matcher = ScanMatcher(cfg.scan_match, odometry_noise(cfg)) if fuse else None
    if matcher is not None and cfg.submaps.enabled and cfg.graph.recalibrate:  # (before any use)
        matcher.fusion = OdometryFusion(cfg.scan_match, whole_run=True)  # keeps every sample
    if compiling is not None:
        compiling()
    load_kernels(cfg.sensor, cfg.lines)
    with signals_deferred():
        load_association_kernels()
        load_filter_kernels()
    # loop closing and the keyframe graph's refinement run ICP too
    if (
        scans_alone
        or matcher is not None
        or (cfg.submaps.enabled and (cfg.loops.enabled or cfg.graph.refine))
    ):
        with signals_deferred():
            load_motion_kernels()
    odom_on_tf = info.odom_source.startswith("tf") or reader.odom_on_tf
    if scans_alone:  # the log's odometry, if any, is not read (a results MCAP hangs map from its tf's)
        info = alone_info(reader, info)
    span = span or Span()
    total = _scan_count(info)
    log.info(
        "log %s (%s): %d scans on %s, odometry from %s; laser mount x=%.3f y=%.3f yaw=%.3f (%s)%s, preset %s",
        Path(log_path).name, info.format, total, short_text(info.scan_topic), info.odom_source or "-",
        *laser2base, source, f" upside down ({upside_down_source})" if upside_down else "",
        cfg.input.laser_preset,
    )  # fmt: skip
    if span.given:
        total = span.expected_scans(total, info.duration)
        log.info("processing %s: about %d scans", span.describe(), total)
    return Input(
        Path(log_path), reader, info, laser2base, source, upside_down, total, SyncStats(), matcher,
        odom_on_tf, span, laser_upside_down_source=upside_down_source,
        scan_odometry=ScanOdometry(cfg.scan_match) if scans_alone else None,
    )  # fmt: skip


def odometry_noise(cfg: Config) -> Callable[[np.ndarray], np.ndarray]:
    """The covariance of an odometry increment under the filter's noise model (``ekf.alpha*`` and its
    floor): the prior the scan matcher fuses its matches with."""
    e = cfg.ekf
    return partial(
        increment_noise,
        alphas=e.alphas,
        min_sigma_xy=e.min_sigma_xy,
        min_sigma_theta=e.min_sigma_theta,
        eps_trans=e.pure_rotation_eps,
        reverse=e.reverse_motion,
    )


def keyframe_pairs(src: Input, cfg: Config) -> Iterator[Synced]:
    """The log's keyframes (streaming): scans prepared (logs/sync.py's synchroniser, keyframe selection)
    with the odometry at their stamps, deskewed."""
    msgs = src.reader.messages() if src.scan_odometry is None else src.reader.scans()
    if src.span.given:  # on the scans as read: those left out give their beams back to the reader's counts
        left_out = partial(_uncount, src.reader.stats)
        msgs = select(msgs, src.span, src.span_used, src.path.name, left_out, cfg.input.scan_time_offset)
    # (after the span: it reads ahead, and a scan read past the span's end would be counted as processed)
    msgs = scans_prepared(src.reader, cfg, src.laser_upside_down, in_stamp_order(msgs))
    if src.scan_odometry is not None:
        msgs = with_scan_odometry(msgs, src.scan_odometry, src.laser2base)
    msgs = reanchor_odometry(msgs, cfg.input.odom_jump, src.stats, src.reader.stats.warn)
    synced = synchronise(msgs, src.stats, src.reader.stats.warn)  # its warning lands in summary.json too
    return _deskewed(select_keyframes(synced, cfg.keyframes, src.stats), src, cfg)


def _uncount(stats: ReadStats, scan: Scan) -> None:
    """Take a scan the span left out off the reader's beam counts: summary.json's describe the span."""
    stats.beams -= scan.n_beams
    stats.beams_dropped -= scan.n_invalid


def frames(src: Input, cfg: Config, progress: Callable[[int, int], None] | None = None) -> Iterator[Frame]:
    """Synchronised keyframes of the log, features extracted, motion scan-matched (streaming)."""
    pairs = keyframe_pairs(src, cfg)
    if src.matcher is not None and cfg.scan_match.warmup > 0:
        head = list(itertools.islice(pairs, cfg.scan_match.warmup))
        src.matcher.warm_up([(transform_points(p.scan.points(), src.laser2base), p.odom) for p in head])
        pairs = itertools.chain(head, pairs)
    charged = 0.0  # the scan odometry's seconds charged to the steps so far
    for pair in pairs:
        frame = replace(extract_frame(pair.scan, pair.odom, cfg, src.laser2base), odom_jump=pair.odom_jump)
        if src.matcher is not None:
            frame = _scan_matched(frame, pair.scan, src.matcher, src.laser2base)
        elif src.scan_odometry is not None:  # its time since the last step (it runs a few scans ahead)
            frame, charged = (
                replace(frame, t_scan_match=src.scan_odometry.seconds - charged),
                src.scan_odometry.seconds,
            )
        yield frame
        if progress is not None:
            progress(src.stats.scans_in, src.total_scans)


def _deskewed(pairs: Iterator[Synced], src: Input, cfg: Config) -> Iterator[Synced]:
    """The pairs with their scans corrected for the robot's motion during the sweep (logs/deskew.py):
    the beams' times from each message's own time_increment, else ``input.beam_time``; where they came
    from (the first keyframe's) noted on ``src`` for summary.json."""
    if not cfg.input.deskew:
        src.beam_times = "off"
        yield from pairs
        return
    first = True
    for pair in pairs:
        dt = pair.scan.time_increment or cfg.input.beam_time
        if first:
            src.beam_times = "log" if pair.scan.time_increment else "config" if dt else "none"
            src.beam_time, first = dt, False
        yield replace(pair, scan=deskew(pair.scan, pair.twist, dt, src.laser2base)) if dt else pair


def check_processed(src: Input, n_frames: int, n_points: int) -> None:
    """A LogError when the log gave no frame, only its first scan's (every other scan's stamp repeated or
    went back: unstamped scans), or frames whose every beam was invalid (``n_points`` valid beams in
    ``n_frames`` frames): the synchroniser's counts say why."""
    stats = src.stats
    if n_frames > 0 and n_points == 0:
        why, hint = invalid_beams(src.reader)
        raise LogError(f"log '{src.path}': every beam of every scan is invalid{why}", hint)
    reader = src.reader
    if n_frames == 1 and stats.scans_in > 1 and stats.scan_time_backwards >= stats.scans_in - 1:
        if reader.format == "carmen":
            check = reader.stamp_hint
        else:
            check = (
                "check that the recorder stamped each message"
                if reader.receive
                else "check that the laser driver fills them"
            )
        raise LogError(  # one pose is no trajectory: every scan's header stamp is the first one's (zero?)
            f"log '{src.path}': only its first scan could be processed: the {reader.stamps_name} of the "
            f"other {stats.scan_time_backwards} repeated or went backwards",
            check + reader.stamps_way_out(),  # (the other input.stamps, where it can help)
        )
    if n_frames == 0:
        rs = src.reader.stats
        if rs.damaged or not (stats.scans_in or rs.decode_failed):  # damage, none read: not the stamps
            what = "no scan could be processed"
            raise damaged_error(src.path, rs, what) if rs.damaged else no_scan_read(src.path, what, stats=rs)
        raise_if_undecoded(src.path, rs)
        way_out = reader.stamps_way_out()
        if clocks := stats.other_clocks(reader.receive):
            check = "check that one recorder wrote both topics" if reader.receive else clocks_hint(stats)
            raise LogError(f"log '{src.path}': no scan could be processed: {clocks}", check + way_out)
        skipped = f"; skipped: {why}" if (why := stats.skipped_why()) else ""
        if apart := spans_apart(stats):
            skipped += f"; {apart}"
        raise LogError(
            f"log '{src.path}': no scan could be processed ({stats.scans_in} scans read{skipped})",
            f"check that the scan and odometry topics overlap in time and that their {reader.stamps_name} "
            "increase" + way_out,
        )


def _scan_matched(
    frame: Frame, scan: Scan, matcher: ScanMatcher, laser2base: tuple[float, float, float]
) -> Frame:
    """The frame with its motion input from the scan matcher (motion/icp.py), timed."""
    t0 = time.perf_counter()
    m = matcher.step(transform_points(scan.points(), laser2base), frame.odom)
    return replace(
        frame,
        motion=m.pose,
        motion_cov=m.cov,
        scan_matched=m.matched,
        scan_fit=m.fit,
        match_scale=matcher.fusion.s,
        bias_taken=m.taken,
        t_scan_match=time.perf_counter() - t0,
    )


def scans_prepared(reader, cfg: Config, upside_down: bool = False, msgs=None):
    """The reader's messages with each scan prepared as configured: mirrored when the laser is
    ``upside_down`` (:meth:`Scan.mirrored`), beams at the ends removed (robot body; the ends of the
    message), beams at or beyond ``input.max_range`` dropped, ``input.scan_time_offset`` added to the
    stamp (a laser whose stamps lag or lead the odometry clock). Skipping every beam of the first
    scan is a ConfigError naming the keys; of a later, shorter scan, counted and warned at the end.
    ``msgs``: the messages to prepare instead of all the reader's (``reader.scans()`` for extract)."""
    inp = cfg.input
    lo, hi, max_range, dt = inp.skip_beams_start, inp.skip_beams_end, inp.max_range, inp.scan_time_offset
    msgs = reader.messages() if msgs is None else msgs
    if upside_down:
        msgs = (msg.mirrored() if isinstance(msg, Scan) else msg for msg in msgs)
    if lo == 0 and hi == 0 and max_range <= 0.0 and dt == 0.0:
        yield from msgs
        return
    first, emptied = True, 0
    for msg in msgs:
        if isinstance(msg, Scan):
            emptied += not first and lo + hi >= msg.n_beams
            if first and (error := skipped_all(inp, msg.n_beams, reader.scan_topic)):
                raise error
            first = False
            keep = (msg.beam_index >= lo) & (msg.beam_index < msg.n_beams - hi)
            if max_range > 0.0:
                keep &= msg.ranges < max_range
            msg = dataclasses.replace(
                msg,
                stamp=msg.stamp + dt,
                ranges=msg.ranges[keep],
                angles=msg.angles[keep],
                beam_index=msg.beam_index[keep],
                range_max=msg.range_max if max_range <= 0.0 else min(max_range, msg.range_max),
            )
        yield msg
    if emptied:
        reader.stats.warn(
            "input.skip_beams_start=%d and input.skip_beams_end=%d skip all beams of %d shorter scans on "
            "'%s': processed without beams (odometry only)",
            lo, hi, emptied, short_text(reader.scan_topic),
        )  # fmt: skip


def skipped_all(inp, n_beams: int, topic: str) -> ConfigError | None:
    """The error of ``input.skip_beams_*`` (``inp``: the config's input section) that skip every one of a
    first scan's ``n_beams`` on ``topic``, else None: run refuses it, info says so as run would."""
    lo, hi = inp.skip_beams_start, inp.skip_beams_end
    if lo + hi < n_beams:
        return None
    return ConfigError(
        f"input.skip_beams_start={lo} and input.skip_beams_end={hi} skip all {n_beams} beams of the scans "
        f"on '{short_text(topic)}'",
        f"keep their sum below {n_beams} (beams skipped at each end of a scan)",
    )


def _scan_count(info) -> int:
    for t in info.topics:
        if t.name == info.scan_topic:
            return int(t.count or 0)
    return 0
