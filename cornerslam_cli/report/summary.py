"""summary.json of a run: what it counted, how long each stage took, what the fusion learnt, the
hashes batch resumes by and the versions (results.py's :class:`RunSummary`), built once by the run
writer (run_writer.py)."""

from __future__ import annotations

import functools
import hashlib
import importlib.resources
import json
import math
import os
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .. import __version__, fpenv
from ..errors import display_path
from ..logs import check_regular
from ..results import Accuracy, Counts, Hashes, OdometryModel, RunInput, RunSummary, Timing
from .text import MOUNT_SOURCES

if TYPE_CHECKING:
    from importlib.resources.abc import Traversable

    from ..config import Config
    from ..frontend import Input
    from ..hierarchy import HierarchicalSlam
    from ..results import MapConsistency
    from ..slam import StepRecord

# an odometer scale error past this is no calibration (real logs: 2–3 %): warned (warn_odometry_model)
MAX_SCALE_ERROR = 0.25
# the odometry's position "never moves" within this (m) over the run, while the scans went this far across
STILL_XY, STILL_SCANS_WENT = 1e-6, 0.3
BLIND_STEPS = 10  # steps in a row with no valid beam, warned of
COASTED_SHARE = 0.05  # scans the scan odometry placed at its guess beyond this share of them: warned of


@dataclass
class Totals:
    """What summary.json sums over the steps."""

    steps: int = 0
    times: np.ndarray = field(
        default_factory=lambda: np.zeros(6)
    )  # extract, predict, match, update, ICP, loop
    t_match_max: float = 0.0
    budget_hits: int = 0  # steps where the associator ran out of its search budget
    matched: int = 0  # corners matched to a landmark
    points: int = 0  # valid beams
    blind: int = 0  # steps in a row with no valid beam, up to the last one added
    blind_from: float = math.nan  # ... the stamp of the first of them
    blind_longest: tuple[int, float, float] = (0, math.nan, math.nan)  # the longest such run: steps, stamps

    def add(self, r: StepRecord) -> None:
        self.steps += 1
        self.times += (r.t_extract, r.t_predict, r.t_match, r.t_update, r.t_scan_match, r.t_loop)
        self.t_match_max = max(self.t_match_max, r.t_match)
        self.budget_hits += r.budget_hit
        self.matched += r.n_matched
        self.points += r.n_points
        self.blind = self.blind + 1 if r.n_points == 0 else 0
        if self.blind == 1:
            self.blind_from = r.stamp
        if self.blind > self.blind_longest[0]:
            self.blind_longest = (self.blind, self.blind_from, r.stamp)


def build_summary(
    src: Input,
    cfg: Config,
    totals: Totals,
    n_landmarks: int,
    final_pose: np.ndarray,
    accuracy: Accuracy | None,
    wall0: float,
    t_grid: float | None = None,
    consistency: MapConsistency | None = None,
    graph: HierarchicalSlam | None = None,
    gt_hash: str | None = None,
    relations_hash: str | None = None,
) -> RunSummary:
    """The summary of a run (summary.json, INTERFACE.md): input, counts, timing totals (``t_grid``:
    the occupancy grid's), accuracy, hashes, versions, map ``consistency``; with the two-level SLAM
    ``graph`` its submaps and loop closures counted and its loop-closing time."""
    info, odo = src.info, src.scan_odometry
    model = odometry_model(src.matcher)
    warn_odometry_model(src, model)
    warn_blind(src, totals)
    warn_scan_odometry(src)
    return RunSummary(
        cornerslam_version=__version__,
        mode="slam",
        input=RunInput(
            log=display_path(src.path),
            format=info.format,
            scan_topic=info.scan_topic,
            odom_topic=info.odom_topic,
            odom_source=info.odom_source,
            laser_to_base=tuple(float(v) for v in src.laser2base),
            laser_to_base_source=src.laser_source,
            odom_on_tf=src.odom_on_tf,
            span=src.span_used.record(src.span),
            beam_times=src.beam_times,
            beam_time=src.beam_time,
            laser_upside_down=src.laser_upside_down,
            laser_upside_down_source=src.laser_upside_down_source,
            base_frame=getattr(src.reader, "base_frame", None),
            odom_frame=getattr(src.reader, "odom_frame", None),
        ),
        assoc=cfg.association.method,
        counts=run_counts(src, totals, n_landmarks, graph),
        timing=run_timing(totals, wall0, t_grid, graph, src.filters_at_once, odo and odo.seconds),
        final_pose=tuple(final_pose.tolist()),
        odometry_model=model,
        consistency=consistency,
        scan_odometry=None if src.scan_odometry is None else src.scan_odometry.stats(),
        warnings=tuple(src.reader.stats.warnings),
        accuracy=accuracy,
        hashes=Hashes(
            input=input_hash(src.path),
            config=config_hash(cfg),
            version=__version__,
            ground_truth=gt_hash,
            relations=relations_hash,
            code=code_hash(),
        ),
        config=cfg.to_dict(),
        versions=_versions(),
    )


def run_counts(src: Input, totals: Totals, n_landmarks: int, graph: HierarchicalSlam | None = None) -> Counts:
    """What the run counted: the filter's steps and matches, the reader's beams and scans, the
    synchroniser's scans and odometry, the associator's budget hits, the scan matcher's outcomes,
    the submaps and loop closures of the two-level SLAM ``graph``."""
    loops = [] if graph is None else graph.loops
    stats, matcher = src.reader.stats, src.matcher
    refine = graph is not None and graph.cfg.graph.refine
    return Counts(
        steps=totals.steps,
        landmarks=n_landmarks,
        matched_total=totals.matched,
        beams_total=stats.beams,
        beams_invalid=stats.beams_dropped,
        scans_bad_geometry=stats.scans_skipped,
        scans_size_mismatch=stats.size_mismatch,
        messages_failed=stats.decode_failed,
        **src.stats.as_dict(),
        budget_hits=int(totals.budget_hits),
        scans_matched=None if matcher is None else matcher.n_matched,
        # "retried": the correlative search over the odometry's window ran (it replaced the heading retries)
        scans_match_retried=None if matcher is None else matcher.n_searched,
        scans_match_rejected=None if matcher is None else matcher.n_rejected,
        scans_match_fallback=None if matcher is None else matcher.n_fallback,
        submaps=None if graph is None else len(graph.closed),
        loops_accepted=None if graph is None else sum(r.accepted for r in loops),
        loops_rejected=None if graph is None else sum(not r.accepted for r in loops),
        refine_factors=graph.refinement.added if refine else None,
        refine_registered=graph.refinement.tried if refine else None,
        refine_fit=len(graph.refinement.found) if refine else None,
    )


def warn_odometry_model(src: Input, model: OdometryModel | None) -> None:
    """Warn when the front end learnt an odometer scale error past :data:`MAX_SCALE_ERROR`: the scans and
    the odometry disagree on how far the robot went by more than any wheel calibration is off — a laser
    mount turned the wrong way (tf, ``input.laser.yaw``: the scans then move against the odometry), or
    odometry of another robot or in other units. (Real logs: 2–3 %.)"""
    if model is not None and abs(model.odom_scale_error) > MAX_SCALE_ERROR:
        src.reader.stats.warn(
            "log '%s': the scans and the odometry disagree on distance by %.0f %% (the front end's odometer "
            "scale error, summary.json odometry_model): check the laser mount (yaw %.3f rad, %s: turned the "
            "wrong way?) and that the odometry is this robot's, in metres",
            src.path.name, 100 * abs(model.odom_scale_error), src.laser2base[2],
            MOUNT_SOURCES.get(src.laser_source, src.laser_source),
        )  # fmt: skip


def warn_blind(src: Input, totals: Totals) -> None:
    """Warn when ``BLIND_STEPS`` or more steps in a row had no valid beam (a laser covered or blinded, a
    driver writing NaN): the robot went on its odometry alone there, which only ``beams_invalid`` told (a
    ROS-user probe: 20 blind scans in a row, no word)."""
    n, first, last = totals.blind_longest
    if n >= BLIND_STEPS and n < totals.steps:  # (every step blind: the run refuses the log)
        went = "its odometry alone" if src.scan_odometry is None else "its last motion (input.odometry=scans)"
        src.reader.stats.warn(
            "log '%s': %d steps in a row had no valid beam (%.3f to %.3f s, %.1f s): the robot went on %s "
            "there (a laser covered or blinded? a driver writing NaN or inf?)",
            src.path.name, n, first, last, last - first, went,
        )  # fmt: skip


def warn_scan_odometry(src: Input) -> None:
    """Warn when the odometry made from the scans (input.odometry: scans) met gaps in time (its guess, the
    last increment, says little of the motion across one), and when it placed more than COASTED_SHARE of
    them at its constant-velocity guess, no registration fitting: there the trajectory is a guess."""
    odo = src.scan_odometry
    if odo is not None and odo.gaps:
        stamp, dt = max(odo.gaps, key=lambda g: g[1])
        src.reader.stats.warn(
            "log '%s': the scans stop for up to %.1f s (%d times, the longest before the scan at %.3f s): on "
            "the scans alone the motion across a gap is found only within scan_match.search_max_xy/_theta "
            "of the motion before it (input.odometry=scans: a log with wheel odometry is surer there)",
            src.path.name, dt, len(odo.gaps), stamp,
        )  # fmt: skip
    if odo is None or odo.coasted <= COASTED_SHARE * odo.scans:
        return
    src.reader.stats.warn(
        "log '%s': %d of the %d scans fitted no registration on the scans before them and were placed where "
        "the robot's last motion would have taken it (input.odometry=scans: the trajectory there is a guess; "
        "a log with wheel odometry is surer)",
        src.path.name, odo.coasted, odo.scans,
    )  # fmt: skip


def warn_still_odometry(src: Input, odoms: np.ndarray, motions: np.ndarray | None) -> None:
    """Warn when the odometry's position never moves over the run while the scans say the robot went
    STILL_SCANS_WENT or more across (``motions``: the scan-matched chain, the span of its positions;
    without scan matching nothing tells a parked robot from a still odometry: no word): a base driver
    that fills only the twist, or only the heading (an IMU's yaw), an odom→base_link tf left at identity.
    The run then takes the robot as standing still and moves it only as far as its scan matches correct
    that, with no word of it (a ROS-user probe: 3.7 m ATE against 0.04). CARMEN logs say so as read."""
    if src.info.format == "carmen" or len(odoms) < 2 or motions is None:
        return
    if np.ptp(odoms[:, :2], axis=0).max() > STILL_XY:
        return
    went = float(np.hypot(*np.ptp(motions[:, :2], axis=0)))
    if went < STILL_SCANS_WENT:
        return  # (the robot stood still, or its scans jittered: the odometry is right)
    src.reader.stats.warn(
        "log '%s': its odometry's position (%s, %s) never moves over the run, while its scans say the robot "
        "went %.1f m across: the run takes the robot as standing still and moves it only as far as its scan "
        "matches correct that (a base driver that fills only the twist? an odom→base_link tf left at "
        "identity? give odometry whose position moves)",
        src.path.name, src.info.odom_topic, src.info.odom_source, went,
    )  # fmt: skip


def odometry_model(matcher) -> OdometryModel | None:
    """What the fusion learnt about the odometry and the matches (motion/fusion.py) by the run's end."""
    if matcher is None:
        return None
    f = matcher.fusion
    whole = (None, None) if f.whole_run_fit is None else [float(v) for v in f.whole_run_fit[0]]
    return OdometryModel(
        odom_noise_scale=f.k,
        match_noise_scale=f.s,
        odom_scale_error=float(f.c[0]),
        heading_drift_per_m=float(f.c[1]),
        heading_drift_along_path=bool(f.along),
        scale_error_from_keyframe=f.first_taken[0],
        heading_drift_from_keyframe=f.first_taken[1],
        whole_run_scale_error=whole[0],
        whole_run_heading_drift_per_m=whole[1],
    )


def run_timing(
    totals: Totals,
    wall0: float,
    t_grid: float | None = None,
    graph: HierarchicalSlam | None = None,
    at_once: int = 1,
    scan_odometry: float | None = None,
) -> Timing:
    """The stage times summed over the steps, the slowest matching step, the wall time since ``wall0``
    and the occupancy grid's time ``t_grid``; with the two-level SLAM ``graph``, the loop closing and
    graph optimisation (over the steps and at the end, closing the last submap); ``at_once``: the filters
    that ran at the same time (compare --jobs), recorded when more than one; ``scan_odometry``: the whole
    time of the odometry made from the scans (input.odometry=scans), which the steps were charged only up
    to the last of them (its scans after it too)."""
    times = totals.times.copy()
    if scan_odometry is not None:
        times[4] = scan_odometry
    t_loop = None if graph is None else float(times[5] + graph.t_loop)
    return Timing(
        t_extract=float(times[0]),
        t_predict=float(times[1]),
        t_match=float(times[2]),
        t_update=float(times[3]),
        t_scan_match=float(times[4]),
        t_total=float(times.sum()),
        t_match_max=totals.t_match_max,
        wall_time=time.perf_counter() - wall0,
        scans_per_second=totals.steps / max(float(times.sum()), 1e-12),
        t_grid=t_grid,
        t_loop=t_loop,
        concurrent_filters=at_once if at_once > 1 else None,
    )


def config_hash(cfg: Config) -> str:
    """sha256 of the resolved config (canonical JSON): equal configs, equal hashes."""
    text = json.dumps(cfg.to_dict(), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def reference_hash(*arrays: np.ndarray) -> str:
    """sha256 of a ground truth as read (stamps and 2D poses, float64), or of relations (their (k, 5)
    array): the same poses, the same hash, however the file spells them; read once, so a ground truth
    given as a pipe is not read again."""
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a, dtype="<f8").tobytes())
    return h.hexdigest()


@functools.cache
def code_hash() -> str | None:
    """sha256 of this build's source: every .py file of the package (path and bytes, in path order; a
    package installed without its sources, its .pyc files), read through importlib.resources so a zipped
    package is read too. The version stays 0.1.0 from commit to commit while the figures change; this
    tells two builds apart, so batch does not take a run of another build's code for a finished one (its
    ``hashes.code``). None when no such file can be read: then nothing is taken as finished."""
    files: list[tuple[str, Traversable]] = []

    def walk(folder: Traversable, prefix: str) -> None:
        for entry in folder.iterdir():
            if entry.is_dir() and entry.name != "__pycache__":
                walk(entry, f"{prefix}{entry.name}/")
            elif entry.is_file():
                files.append((prefix + entry.name, entry))

    walk(importlib.resources.files("cornerslam_cli"), "")
    for suffix in (".py", ".pyc"):  # (the .pyc files of a sourceless install lie beside, not in __pycache__)
        chosen = sorted((name, f) for name, f in files if name.endswith(suffix))
        if chosen:
            h = hashlib.sha256()
            for name, f in chosen:
                h.update(name.encode() + b"\0" + f.read_bytes() + b"\0")
            return h.hexdigest()
    return None


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
    # the runtime dependencies, then those the figures also depend on: numba compiles the kernels (with
    # llvmlite), gtsam solves the pose graph, matplotlib draws the figures (appended 2026-12-05)
    names = ("numpy", "scipy", "mcap", "rosbags", "click", "pyyaml")
    for name in (*names, "numba", "llvmlite", "gtsam", "matplotlib"):
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:
            pass
    out.update(fpenv.describe())  # the BLAS kernels and numpy SIMD level: the last digits depend on them
    return out
