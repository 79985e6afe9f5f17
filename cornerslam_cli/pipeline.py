"""The SLAM pipeline: log → synchronised keyframes → extract → predict → associate → update/augment.

``run()`` reads as the table of contents of a cornerslam run; :class:`Slam.step` is one step of
the paper's loop (Fig 1), each stage timed for ``timing.csv``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import os
import platform
import time
from array import array
from collections.abc import Callable, Iterable, Iterator
from contextlib import ExitStack
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from . import __version__, fpenv
from .association import make_associator
from .config import Config
from .errors import ConfigError, LogError, OutputError, display_path
from .evaluate import ate, overlap_problem, read_relations, relation_error, rpe
from .features import extract
from .filter import Ekf
from .geometry import matrix_from_pose, transform_points
from .logs import ReadStats, check_regular, open_log
from .logs.sync import SyncStats, reanchor_odometry, select_keyframes, synchronise
from .motion import ScanMatcher
from .ranges import short_text
from .report.outdir import StagedDir, output_errors
from .report.tables import (
    LINES_COLUMNS,
    MAP_COLUMNS,
    TIMING_COLUMNS,
    TRAJECTORY_COLUMNS,
    CsvTable,
    read_tum,
    write_json,
    write_tum,
)
from .types import Corners, Scan, Segments

log = logging.getLogger(__name__)


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


def segments_to_map(segments: Segments, sensor2map: np.ndarray) -> np.ndarray:
    """(k, 4) segment end points x1, y1, x2, y2 in the map frame."""
    R, t = sensor2map[:2, :2], sensor2map[:2, 2]
    return np.hstack((segments.p1 @ R.T + t, segments.p2 @ R.T + t))


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
    # motion input of the filter: the scan-matched pose chain (motion/icp.py), or None = ``odom``
    motion: np.ndarray | None = None
    scan_matched: bool = False  # the increment into this frame came from scan matching
    scan_fit: float = float("nan")  # share of the scan's points on the local map after matching
    t_scan_match: float = 0.0


def extract_frame(scan: Scan, odom: np.ndarray, cfg: Config, laser2base: tuple[float, float, float]) -> Frame:
    t0 = time.perf_counter()
    segments, corners = extract(scan, cfg.sensor, cfg.lines, cfg.corners)  # Alg 1-2
    z, C = corners_to_base(corners, laser2base)
    C[:, 0, 0] += cfg.corners.model_sigma**2
    C[:, 1, 1] += cfg.corners.model_sigma**2
    return Frame(scan.stamp, odom, len(scan.ranges), segments, z, C, time.perf_counter() - t0)


@dataclass
class StepRecord:
    """What one step produced (one row of trajectory.csv and timing.csv)."""

    step: int
    stamp: float
    pose: np.ndarray
    pose_var: np.ndarray
    odom: np.ndarray
    motion: np.ndarray  # the filter's motion input: scan-matched odometry, or odom
    n_points: int
    n_lines: int
    n_corners: int
    n_candidates: int
    n_matched: int
    n_new: int
    n_landmarks: int
    t_extract: float
    t_predict: float
    t_match: float
    t_update: float
    segments_map: np.ndarray
    nodes: int = 0
    budget_hit: bool = False
    t_scan_match: float = 0.0
    scan_fit: float = float("nan")

    @property
    def t_total(self) -> float:
        return self.t_extract + self.t_scan_match + self.t_predict + self.t_match + self.t_update


class Slam:
    """Corner EKF-SLAM state across steps: the filter, the associator, landmark bookkeeping."""

    def __init__(self, cfg: Config, laser2base: tuple[float, float, float]):
        self.cfg = cfg
        self.laser2base = laser2base
        self.ekf = Ekf(cfg.ekf)
        self.associate = make_associator(cfg.association)
        self.first_step = np.zeros(0, dtype=np.int64)  # per landmark id, kept in step with the filter's ids
        self.last_step = np.zeros(0, dtype=np.int64)
        self.prev_motion: np.ndarray | None = None  # the previous frame's motion input
        self.n_steps = 0

    def step(self, frame: Frame) -> StepRecord:
        """One step of the paper's loop on an extracted frame: predict, associate, update, augment."""
        k = self.n_steps
        odom, z, C = frame.odom, frame.z, frame.C
        motion = odom if frame.motion is None else frame.motion
        t1 = time.perf_counter()
        if self.prev_motion is not None:
            sm = self.cfg.scan_match
            noise = (sm.alphas, sm.floor) if frame.scan_matched else (None, None)
            self.ekf.predict(self.prev_motion, motion, *noise)  # eq 19-22, O(N)
            if frame.odom_jump and not frame.scan_matched:  # re-anchored across a jump: motion unknown
                self.ekf.inflate_pose(self.cfg.input.odom_jump.sigma_xy, self.cfg.input.odom_jump.sigma_theta)
        self.prev_motion = motion
        t2 = time.perf_counter()
        result = self.associate(z, C, self.ekf.predict_observations())  # Alg 3-5
        t3 = time.perf_counter()
        matched = result.pairs >= 0
        ids = result.pairs[matched]
        if len(ids):
            self.ekf.update(ids, z[matched], C[matched])  # eq 23-32, block update
        new_ids = self.ekf.augment(z[~matched], C[~matched])
        self.last_step[ids] = k
        self.first_step = np.concatenate((self.first_step, np.full(len(new_ids), k)))
        self.last_step = np.concatenate((self.last_step, np.full(len(new_ids), k)))
        remap = self.ekf.prune_tentative()  # identity unless ekf.tentative_sightings > 1
        if np.any(remap < 0):
            kept = remap >= 0
            self.first_step, self.last_step = self.first_step[kept], self.last_step[kept]
        self.ekf.check_health(k)
        t4 = time.perf_counter()
        pose = np.array(self.ekf.pose, dtype=float)
        sensor2map = matrix_from_pose(pose) @ matrix_from_pose(self.laser2base)
        self.n_steps += 1
        return StepRecord(
            step=k,
            stamp=frame.stamp,
            pose=pose,
            pose_var=np.diag(self.ekf.P[:3, :3]).copy(),
            odom=odom,
            motion=motion,
            n_points=frame.n_points,
            n_lines=len(frame.segments),
            n_corners=len(z),
            n_candidates=int(np.sum(result.n_candidates)),
            n_matched=int(len(ids)),
            n_new=int(len(new_ids)),
            n_landmarks=self.ekf.n_landmarks,
            t_extract=frame.t_extract,
            t_scan_match=frame.t_scan_match,
            scan_fit=frame.scan_fit,
            t_predict=t2 - t1,
            t_match=t3 - t2,
            t_update=t4 - t3,
            segments_map=segments_to_map(frame.segments, sensor2map),
            nodes=int(result.nodes),
            budget_hit=bool(result.budget_hit),
        )

    def landmark_table(self) -> np.ndarray:
        """(n, 11) rows of map.csv: the confirmed landmarks (all of them without a tentative stage)."""
        ids = np.flatnonzero(~self.ekf.tentative)
        L = np.asarray(self.ekf.landmarks).reshape(-1, 3)[ids]
        P = self.ekf.P
        idx = 3 + 3 * ids
        return np.column_stack(
            (
                ids,
                L,
                P[idx, idx],
                P[idx + 1, idx + 1],
                P[idx, idx + 1],
                P[idx + 2, idx + 2],
                self.first_step[ids],
                self.last_step[ids],
                self.ekf.n_obs[ids],
            )
        )


def find_ground_truth(log_path: Path) -> Path | None:
    """``LOG.gt.tum`` beside the log (also without the log's extension), if present."""
    candidates = [log_path.with_name(log_path.name + ".gt.tum"), log_path.with_suffix(".gt.tum")]
    return next((c for c in candidates if c.is_file()), None)


def default_out_dir(log_path: Path, assoc: str) -> Path:
    stem = display_path(log_path.name.split(".")[0]) or "log"  # a name that is not UTF-8: printable
    return Path("cornerslam_out") / f"{stem}_{assoc}"


@dataclass
class Input:
    """An opened log and what a run takes from it besides the frames."""

    path: Path
    reader: object
    info: object
    laser2base: tuple[float, float, float]
    laser_source: str
    total_scans: int
    stats: SyncStats
    matcher: ScanMatcher | None = None  # scan matching of the motion input (scan_match.enabled)


def open_input(log_path: str | Path, cfg: Config) -> Input:
    """Open the log, check its topics (exit-2 errors before any work) and find the laser mount."""
    inp = cfg.input
    reader = open_log(
        Path(log_path),
        scan_topic=inp.scan_topic,
        odom_topic=inp.odom_topic,
        odom_frame=inp.odom_frame,
        base_frame=inp.base_frame,
    )
    reader.check()
    info = reader.info()
    laser2base, source = _laser_mount(reader, cfg)
    matcher = ScanMatcher(cfg.scan_match) if cfg.scan_match.enabled else None
    return Input(Path(log_path), reader, info, laser2base, source, _scan_count(info), SyncStats(), matcher)


def frames(src: Input, cfg: Config, progress: Callable[[int, int], None] | None = None) -> Iterator[Frame]:
    """Synchronised keyframes of the log, features extracted (streaming)."""
    msgs = reanchor_odometry(
        _scans_prepared(src.reader, cfg), cfg.input.odom_jump, src.stats, src.reader.stats.warn
    )
    synced = synchronise(msgs, src.stats, src.reader.stats.warn)  # its warning lands in summary.json too
    pairs = select_keyframes(synced, cfg.keyframes, src.stats)
    jumps = 0
    for scan, odom in pairs:
        frame = extract_frame(scan, odom, cfg, src.laser2base)
        if src.stats.odom_jumps > jumps:
            jumps = src.stats.odom_jumps
            frame = replace(frame, odom_jump=True)
        if src.matcher is not None:
            t0 = time.perf_counter()
            m = src.matcher.step(transform_points(scan.points(), src.laser2base), odom)
            frame = replace(
                frame,
                motion=m.pose,
                scan_matched=m.matched,
                scan_fit=m.fit,
                t_scan_match=time.perf_counter() - t0,
            )
        yield frame
        if progress is not None:
            progress(src.stats.scans_in, src.total_scans)


def run(
    log_path: str | Path,
    cfg: Config,
    out: str | Path | None = None,
    ground_truth: str | Path | None = None,
    progress: Callable[[int, int], None] | None = None,
    relations: str | Path | None = None,
    time_offset: float = 0.0,
    plot: bool = False,
    mcap_out: str | Path | None = None,
    config_path: str | Path | None = None,
) -> dict:
    """Run corner EKF-SLAM on one log and write the output directory atomically: the tables, with
    ``plot`` the figures and report.html, and ``mcap_out`` beside it, all committed at once.

    The output places are checked before any work (report/outdir.py); the run's inputs — the log,
    the ground truth (also LOG.gt.tum found beside the log), the relations, the config file
    ``config_path`` — are never written over. Returns the summary (also written to summary.json)
    with ``out_dir``, the committed directory.
    """
    wall0 = time.perf_counter()
    out_dir = Path(out) if out else default_out_dir(Path(log_path), cfg.association.method)
    gt = ground_truth or find_ground_truth(Path(log_path))
    inputs = [p for p in (log_path, gt, relations, config_path) if p]
    with StagedDir(out_dir, "run", inputs) as stage:
        mcap_path = stage.stage_file(mcap_out) if mcap_out else None
        ref = load_reference(Path(log_path), ground_truth, relations, time_offset)  # bad files fail first
        src = open_input(log_path, cfg)
        summary = run_frames(frames(src, cfg, progress), src, cfg, stage.path, ref, wall0)
        write_extras(stage, plot, mcap_out, mcap_path, ref.gt_path)
        summary["out_dir"] = str(stage.commit())
    return summary


def write_extras(
    stage: StagedDir,
    plot: bool,
    mcap_out: str | Path | None,
    mcap_path: Path | None,
    ground_truth: Path | None = None,
) -> None:
    """What a run writes besides its tables, staged before the commit: with ``plot`` the figures and
    report.html; the results MCAP into ``mcap_path``, the staged place of ``mcap_out``. Both draw
    the ``ground_truth`` file the run was scored against."""
    if plot:
        from .report.html import write_report
        from .report.plots import plot_run

        plot_run(stage.path, ground_truth)
        write_report(stage.path)
    if mcap_path is not None:
        from .report.mcap_out import write_results_mcap

        if mcap_path.is_relative_to(stage.path) and mcap_path.exists():
            raise OutputError(f"--mcap-out '{mcap_out}' is a file of the run itself", "give another name")
        with output_errors(mcap_out):
            write_results_mcap(stage.path, mcap_path, results=stage.target, ground_truth=ground_truth)


@dataclass(frozen=True)
class Reference:
    """What a run's accuracy is measured against: a TUM ground truth (stamps, poses) and/or a
    Kümmerle et al. 2009 relations table with its time offset (relation time − log time)."""

    gt_path: Path | None = None
    gt: tuple[np.ndarray, np.ndarray] | None = None
    relations_path: Path | None = None
    relations: np.ndarray | None = None
    time_offset: float = 0.0
    notes: tuple[str, ...] = ()  # warnings from reading them (ground truth out of time order)


def load_reference(
    log_path: Path,
    ground_truth: str | Path | None = None,
    relations: str | Path | None = None,
    time_offset: float = 0.0,
) -> Reference:
    """The given ground truth, else LOG.gt.tum if present; the given relations file, if any."""
    gt_path = Path(ground_truth) if ground_truth else find_ground_truth(log_path)
    rel_path = Path(relations) if relations else None
    notes: list[str] = []
    return Reference(
        gt_path,
        read_tum(gt_path, "ground truth", notes.append) if gt_path else None,
        rel_path,
        read_relations(rel_path) if rel_path else None,
        time_offset,
        tuple(notes),
    )


def accuracy_of(
    stamps: np.ndarray,
    poses: np.ndarray,
    odoms: np.ndarray,
    ref: Reference,
    scan_odoms: np.ndarray | None = None,
) -> tuple[dict | None, list[str]]:
    """ATE/RPE against the ground truth and the relation metric, for the estimate and for odometry (and
    for the scan-matched odometry when there is one: what the corners add on top of it), and the
    warnings about them: a ground truth read out of time order, a ground truth that does not overlap
    the run in time (then there is no ATE/RPE, rather than NaN), no relation inside the run."""
    acc: dict = {}
    notes = list(ref.notes)
    problem = ref.gt is not None and overlap_problem(stamps, ref.gt[0], f"ground truth '{ref.gt_path}'")
    if problem:
        notes.append(f"{problem}: no ATE/RPE")
    elif ref.gt is not None:
        acc.update(
            ground_truth=display_path(ref.gt_path),
            ate=ate(stamps, poses, *ref.gt),
            odom_ate=ate(stamps, odoms, *ref.gt),
            **rpe(stamps, poses, *ref.gt),
        )
        if scan_odoms is not None:
            acc["scan_odom_ate"] = ate(stamps, scan_odoms, *ref.gt)
    if ref.relations is not None:
        acc.update(
            relations_file=display_path(ref.relations_path),
            relations=relation_error(stamps, poses, ref.relations, ref.time_offset),
            odom_relations=relation_error(stamps, odoms, ref.relations, ref.time_offset),
        )
        if scan_odoms is not None:
            acc["scan_odom_relations"] = relation_error(stamps, scan_odoms, ref.relations, ref.time_offset)
        if acc["relations"]["n"] == 0:
            notes.append(f"no relation in '{ref.relations_path}' falls inside the run (check --time-offset)")
    return acc or None, notes


def undecoded_error(log_path: Path, rs: ReadStats) -> None:
    """Raise LogError naming the decoding failures when they left no scan or no odometry sample (then
    they, not the stamps, are why no scan could be processed)."""
    if rs.decode_failed and not (rs.scans and rs.odoms):
        raise LogError(
            f"log '{log_path}': no scan could be processed: {rs.decode_failed} messages could not be decoded "
            f"({rs.scans} scans and {rs.odoms} odometry samples were usable; the first failure: "
            f"{rs.first_failure})",
            "check the scan and odometry messages; `cornerslam info LOG` lists the topics and their types",
        )


def run_frames(
    frame_iter: Iterable[Frame],
    src: Input,
    cfg: Config,
    dest: Path,
    ref: Reference,
    wall0: float,
) -> dict:
    """The filter over extracted frames; writes a run's files into the (staging) directory ``dest``,
    returns the summary."""
    log_path, stats, reader, info = src.path, src.stats, src.reader, src.info
    slam = Slam(cfg, src.laser2base)
    with ExitStack() as tables:
        traj = tables.enter_context(CsvTable(dest / "trajectory.csv", TRAJECTORY_COLUMNS))
        timing = tables.enter_context(CsvTable(dest / "timing.csv", TIMING_COLUMNS))
        lines = tables.enter_context(CsvTable(dest / "lines.csv", LINES_COLUMNS))
        track = array("d")  # stamp, pose, odom, motion per step: 80 bytes a step (a list of arrays: ~400)
        totals = np.zeros(5)
        t_match_max, budget_hits, matched_total, points_total = 0.0, 0, 0, 0
        for frame in frame_iter:
            r = slam.step(frame)
            traj.row(r.step, f"{r.stamp:.9f}", *r.pose, *r.odom, *r.pose_var, *r.motion)
            timing.row(
                r.step, f"{r.stamp:.9f}", r.n_points, r.n_lines, r.n_corners, r.n_candidates, r.n_matched,
                r.n_new, r.n_landmarks, r.t_extract, r.t_predict, r.t_match, r.t_update, r.t_total,
                r.t_scan_match, r.scan_fit,
            )  # fmt: skip
            lines.rows(r.segments_map, lead=(r.step,))
            track.append(r.stamp)
            track.extend(r.pose)
            track.extend(r.odom)
            track.extend(r.motion)
            totals += (r.t_extract, r.t_predict, r.t_match, r.t_update, r.t_scan_match)
            t_match_max = max(t_match_max, r.t_match)
            budget_hits += r.budget_hit
            matched_total += r.n_matched
            points_total += r.n_points
        for table in (traj, timing, lines):
            table.close()
        if slam.n_steps > 0 and points_total == 0:
            raise LogError(
                f"log '{log_path}': every beam of every scan is invalid (NaN, inf, zero or out of range)",
                "check the scan topic, range_min/range_max and input.max_range",
            )
        if slam.n_steps == 0:
            undecoded_error(log_path, reader.stats)
            raise LogError(
                f"log '{log_path}': no scan could be processed ({stats.scans_in} scans read, "
                f"{stats.before_first_odom} before the first and {stats.after_last_odom} "
                f"after the last odometry sample, {stats.odom_gap} in gaps of the odometry, "
                f"{stats.scan_time_backwards} with a stamp that went backwards or repeated)",
                "check that the scan and odometry topics overlap in time and that their header stamps "
                "increase",
            )
        lm = slam.landmark_table()
        mp = tables.enter_context(CsvTable(dest / "map.csv", MAP_COLUMNS))
        for row in lm:
            mp.row(*(int(v) if i in (0, 8, 9, 10) else v for i, v in enumerate(row)))
        mp.close()
        track_a = np.frombuffer(track, dtype=float).reshape(-1, 10)
        stamps_a, poses_a, odoms_a = track_a[:, 0], track_a[:, 1:4], track_a[:, 4:7]
        motion_a = track_a[:, 7:10] if src.matcher is not None else None
        write_tum(dest / "trajectory.tum", stamps_a, poses_a)
        accuracy, notes = accuracy_of(stamps_a, poses_a, odoms_a, ref, motion_a)
        for text in notes:
            reader.stats.warn(text)
        summary = {
            "cornerslam_version": __version__,
            "mode": "slam",
            "input": {
                "log": display_path(log_path),
                "format": info.format,
                "scan_topic": info.scan_topic,
                "odom_topic": info.odom_topic,
                "odom_source": info.odom_source,
                "laser_to_base": list(src.laser2base),
                "laser_to_base_source": src.laser_source,
            },
            "assoc": cfg.association.method,
            "counts": {
                "steps": slam.n_steps,
                "landmarks": len(lm),
                "matched_total": matched_total,
                "beams_total": reader.stats.beams,
                "beams_invalid": reader.stats.beams_dropped,
                "scans_bad_geometry": reader.stats.scans_skipped,
                "scans_size_mismatch": reader.stats.size_mismatch,
                "messages_failed": reader.stats.decode_failed,
                **stats.as_dict(),
                "budget_hits": int(budget_hits),
                **_scan_match_counts(src.matcher),
            },
            "timing": {
                "t_extract": totals[0],
                "t_predict": totals[1],
                "t_match": totals[2],
                "t_update": totals[3],
                "t_scan_match": totals[4],
                "t_total": float(totals.sum()),
                "t_match_max": t_match_max,
                "wall_time": time.perf_counter() - wall0,
                "scans_per_second": slam.n_steps / max(float(totals.sum()), 1e-12),
            },
            "final_pose": poses_a[-1].tolist(),
            "warnings": list(reader.stats.warnings),
            "accuracy": accuracy,
            "hashes": {"input": input_hash(log_path), "config": config_hash(cfg), "version": __version__},
            "config": cfg.to_dict(),
            "versions": _versions(),
        }
        write_json(dest / "summary.json", summary)
    return summary


def _scans_prepared(reader, cfg: Config):
    """The reader's messages with each scan prepared as configured: beams at the ends removed (robot
    body), beams at or beyond ``input.max_range`` dropped, ``input.scan_time_offset`` added to the
    stamp (a laser whose stamps lag or lead the odometry clock). Skipping every beam of the first
    scan is a ConfigError naming the keys; of a later, shorter scan, counted and warned at the end."""
    inp = cfg.input
    lo, hi, max_range, dt = inp.skip_beams_start, inp.skip_beams_end, inp.max_range, inp.scan_time_offset
    if lo == 0 and hi == 0 and max_range <= 0.0 and dt == 0.0:
        yield from reader.messages()
        return
    first, emptied = True, 0
    for msg in reader.messages():
        if isinstance(msg, Scan):
            emptied += not first and lo + hi >= msg.n_beams
            if first and lo + hi >= msg.n_beams:
                raise ConfigError(
                    f"input.skip_beams_start={lo} and input.skip_beams_end={hi} skip all "
                    f"{msg.n_beams} beams of the scans on '{short_text(reader.scan_topic)}'",
                    f"keep their sum below {msg.n_beams} (beams skipped at each end of a scan)",
                )
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


def _scan_match_counts(matcher: ScanMatcher | None) -> dict:
    if matcher is None:
        return {}
    return {"scans_matched": matcher.n_matched, "scans_match_retried": matcher.n_retried,
            "scans_match_fallback": matcher.n_fallback}  # fmt: skip


def _laser_mount(reader, cfg: Config) -> tuple[tuple[float, float, float], str]:
    mount = cfg.input.laser
    if mount.from_tf:
        tf = reader.laser_to_base()
        if tf is not None:
            return (float(tf[0]), float(tf[1]), float(tf[2])), "tf"
    return (mount.x, mount.y, mount.yaw), "config"


def _scan_count(info) -> int:
    for t in info.topics:
        if t.name == info.scan_topic:
            return int(t.count or 0)
    return 0


def config_hash(cfg: Config) -> str:
    """sha256 of the resolved config (canonical JSON): equal configs, equal hashes."""
    text = json.dumps(cfg.to_dict(), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def input_hash(path: Path) -> str:
    """sha256 of the log's bytes (every file, in name order, for a ROS 2 bag directory); a LogError
    for a pipe or a device (reading it would consume or hang on it)."""
    check_regular(path)
    h = hashlib.sha256()
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    for f in files:
        h.update(os.fsencode(f.relative_to(path) if path.is_dir() else f.name))
        with open(f, "rb") as fh:
            while chunk := fh.read(1 << 20):
                h.update(chunk)
    return h.hexdigest()


def _versions() -> dict:
    import importlib.metadata as md

    out = {"python": platform.python_version()}
    for name in ("numpy", "scipy", "mcap", "rosbags", "click", "pyyaml"):
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:
            pass
    out.update(fpenv.describe())  # the BLAS kernels and numpy SIMD level: the last digits depend on them
    return out
