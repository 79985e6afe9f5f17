"""A run's output files: timing.csv written row by row, trajectory.csv and lines.csv at the end (at
the smoothed poses when the run had submaps, hierarchy.py), map.csv, loops.csv, trajectory.tum (with
odometry.tum and scan_matched.tum beside it), the occupancy grid (report/occupancy.py) and
summary.json (report/summary.py).

Frames: every pose, segment and landmark is written in the log's odometry frame. The filter works in
its map frame, the base at the first scan (the EKF starts at zero); placed in the odometry frame, that
is the first odometry pose, ``map2odom``, so the first pose written equals the first odometry pose and
``evo_traj tum odometry.tum trajectory.tum --ref gt.tum`` needs no alignment to compare them.

Every row is a dict keyed by its table's column names (report/tables.py ``*_COLUMNS``), so a column
is written by name, never by position. The accuracy is measured against a :class:`Reference`
(ground truth and/or relations) read before the run starts.
"""

from __future__ import annotations

import os
import time
from array import array
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import CornerslamError, display_path
from ..evaluate import (
    ate,
    coverage_note,
    mirror_problem,
    overlap_problem,
    read_relations,
    relation_error,
    rpe,
    sparse_note,
    units_problem,
)
from ..geometry import compose, compose_inverse
from ..results import Accuracy, RunSummary
from .consistency import store_consistency
from .occupancy import ScanStore, build_grid, draw_grid, write_grid
from .odom_frame import in_odom_frame, landmarks_in_odom_frame
from .summary import Totals, build_summary, reference_hash, warn_still_odometry
from .tables import (
    LINES_COLUMNS,
    LOOP_COLUMNS,
    MAP_COLUMNS,
    TIMING_COLUMNS,
    TRAJECTORY_COLUMNS,
    CsvTable,
    read_tum,
    write_json,
    write_tum,
)

if TYPE_CHECKING:
    from ..config import Config, GridConfig
    from ..frontend import Input
    from ..hierarchy import HierarchicalSlam
    from ..slam import StepRecord


def trajectory_row(r: StepRecord | TrackRow, online: np.ndarray | None = None) -> dict:
    """One row of trajectory.csv: the pose, odometry, the pose variances, the motion input, the online
    (causal) pose — ``online``, or the pose itself when the trajectory was not smoothed — and the submap."""
    pose = r.pose.tolist()
    return {
        "step": r.step,
        "stamp": f"{r.stamp:.9f}",
        # Python floats (tolist): the same cells, formatted without numpy-scalar overhead
        **dict(zip(("x", "y", "theta"), pose, strict=True)),
        **dict(zip(("odom_x", "odom_y", "odom_theta"), np.asarray(r.odom).tolist(), strict=True)),
        **dict(zip(("var_x", "var_y", "var_theta"), r.pose_var.tolist(), strict=True)),
        **dict(
            zip(("scan_odom_x", "scan_odom_y", "scan_odom_theta"), np.asarray(r.motion).tolist(), strict=True)
        ),
        **dict(
            zip(
                ("online_x", "online_y", "online_theta"),
                pose if online is None else online.tolist(),
                strict=True,
            )
        ),
        "submap": r.submap,
    }


@dataclass(frozen=True)
class TrackRow:
    """What trajectory.csv and lines.csv need of one step, as kept by :class:`RunWriter`."""

    step: int
    stamp: float
    pose: np.ndarray
    odom: np.ndarray
    motion: np.ndarray
    pose_var: np.ndarray
    cov_xy: float
    submap: int
    segments_map: np.ndarray


def track_record(t: np.ndarray, segments: np.ndarray, step: int) -> TrackRow:
    """A kept step (``RunWriter.TRACK`` doubles) and its segments as a row."""
    return TrackRow(step, float(t[0]), t[1:4], t[4:7], t[7:10], t[10:13], float(t[13]), int(t[14]), segments)


def timing_row(r: StepRecord) -> dict:
    """One row of timing.csv: the step's counts and stage times (every column is a StepRecord field)."""
    return {name: f"{r.stamp:.9f}" if name == "stamp" else getattr(r, name) for name in TIMING_COLUMNS}


class RunWriter:
    """A run's files in the (staging) directory ``dest``: :meth:`step` takes one step (its timing row
    is written at once; its trajectory and lines rows are kept, since a smoothed trajectory is only
    known at the end), :meth:`close_steps` completes timing.csv, :meth:`finish` writes the rest —
    trajectory.csv, lines.csv, map.csv, the TUM files, with submaps loops.csv, the grid, summary.json.
    A context manager: on an error the open files are closed without a second error.
    The scans given to :meth:`step` (the laser at ``laser2base`` on the robot) make the occupancy
    grid (``grid``: its resolution and size cap); they are kept in ``scans`` (a new store if None)."""

    TRACK = 15  # doubles kept per step: stamp, pose, odom, motion, pose variances, cov_xy, submap

    def __init__(
        self,
        dest: Path,
        laser2base: tuple[float, float, float],
        grid: GridConfig,
        scans: ScanStore | None = None,
    ):
        self.dest = dest
        self.laser2base = laser2base
        self.grid = grid
        self.scans = ScanStore() if scans is None else scans
        self._files = ExitStack()
        self.timing = self._open("timing.csv", TIMING_COLUMNS)
        self.track = array("d")  # TRACK doubles per step (a list of arrays would take ~5× the memory)
        self.segments: list[np.ndarray] = []  # per step its segments (k, 4), odometry frame
        self.scan_steps = array("l")  # the steps whose scans the store kept
        self.totals = Totals()
        self.map2odom: np.ndarray | None = None  # the filter's map frame in the odometry frame
        self.scan_odoms = array("d")  # the laser's pose by the odometry, per scan kept (x, y, θ)

    def _open(self, name: str, columns: list[str]) -> CsvTable:
        return self._files.enter_context(CsvTable(self.dest / name, columns))

    def __enter__(self) -> RunWriter:
        return self

    def __exit__(self, *exc) -> None:
        self._files.__exit__(*exc)

    def step(self, r: StepRecord, points: np.ndarray | None = None) -> None:
        """Take one step, in the odometry frame (the first step's odometry pose places it); keep its
        scan's ``points`` (k, 2, laser frame) for the occupancy grid."""
        if self.map2odom is None:
            self.map2odom = np.array(r.odom, dtype=float)
        r = in_odom_frame(r, self.map2odom)
        if points is not None:
            self.scans.add(compose(r.pose, self.laser2base), points)
            self.scan_odoms.extend(compose(r.odom, self.laser2base))
            self.scan_steps.append(len(self.segments))
        self.timing.write(timing_row(r))
        self.segments.append(r.segments_map)
        self.track.append(r.stamp)
        for v in (r.pose, r.odom, r.motion, r.pose_var):
            self.track.extend(v)
        self.track.extend((r.cov_xy, r.submap))
        self.totals.add(r)

    def close_steps(self) -> None:
        self.timing.close()

    def finish(
        self,
        landmarks: dict[str, np.ndarray],
        src: Input,
        cfg: Config,
        ref: Reference,
        wall0: float,
        graph: HierarchicalSlam | None = None,
    ) -> RunSummary:
        """trajectory.csv and lines.csv (at the smoothed poses of ``graph``, the two-level SLAM, when
        given), map.csv from ``landmarks`` (columns by name), loops.csv with a graph, trajectory.tum,
        odometry.tum and (with scan matching) scan_matched.tum, the occupancy grid, the accuracy
        against ``ref`` and summary.json; returns the summary."""
        if self.map2odom is not None:
            landmarks = landmarks_in_odom_frame(landmarks, self.map2odom)
        track = np.frombuffer(self.track, dtype=float).reshape(-1, self.TRACK)
        stamps, online, odoms = track[:, 0], track[:, 1:4], track[:, 4:7]
        poses = online if graph is None else self._placed(graph.final_poses())
        self.write_steps(track, poses)
        with self._open("map.csv", MAP_COLUMNS) as mp:
            for i in range(len(landmarks["id"])):
                mp.write({name: landmarks[name][i] for name in MAP_COLUMNS})
        if graph is not None:
            with self._open("loops.csv", LOOP_COLUMNS) as lp:
                for row in graph.loop_rows():
                    lp.write(row)
        motions = track[:, 7:10] if src.matcher is not None else None
        write_tum(self.dest / "trajectory.tum", stamps, poses)
        write_tum(self.dest / "odometry.tum", stamps, odoms)
        if motions is not None:
            write_tum(self.dest / "scan_matched.tum", stamps, motions)
        warn_still_odometry(src, odoms, motions)
        accuracy, notes = accuracy_of(
            stamps,
            poses,
            odoms,
            ref,
            motions,
            None if graph is None else online,
            src.reader.receive,
            alone=src.scan_odometry is not None,
        )
        for text in notes:
            src.reader.stats.warn(text)
        t_grid = time.perf_counter()
        self.write_grid(poses, src.reader.stats.warn)
        t_grid = time.perf_counter() - t_grid
        consistency = store_consistency(self.scans, np.frombuffer(self.scan_odoms).reshape(-1, 3))
        summary = build_summary(
            src,
            cfg,
            self.totals,
            len(landmarks["id"]),
            poses[-1],
            accuracy,
            wall0,
            t_grid,
            consistency,
            graph,
            None if ref.gt is None else reference_hash(*ref.gt),
            None if ref.relations is None else reference_hash(ref.relations),
        )
        write_json(self.dest / "summary.json", summary.to_json())
        return summary

    def _placed(self, poses: np.ndarray) -> np.ndarray:
        """Map-frame poses in the odometry frame (as :func:`in_odom_frame` places each step)."""
        return poses if self.map2odom is None or not np.any(self.map2odom) else compose(self.map2odom, poses)

    def write_steps(self, track: np.ndarray, poses: np.ndarray) -> None:
        """trajectory.csv and lines.csv at ``poses``; a step moved from its online pose has its
        segments, position covariance and kept scan moved with it."""
        online = track[:, 1:4]
        moved = np.flatnonzero(np.any(poses != online, axis=1))
        delta = compose_inverse(poses, online)  # online → smoothed, per step
        if len(moved) and len(self.scan_steps):
            self.scans.move(np.frombuffer(self.scan_steps, dtype=np.int64), delta)
        with (
            self._open("trajectory.csv", TRAJECTORY_COLUMNS) as tr,
            self._open("lines.csv", LINES_COLUMNS) as ln,
        ):
            is_moved = np.zeros(len(track), dtype=bool)
            is_moved[moved] = True
            for k, t in enumerate(track):
                r = track_record(t, self.segments[k], k)
                if is_moved[k]:
                    r = in_odom_frame(r, delta[k])  # moved by a pose: the same change of frame
                tr.write(trajectory_row(r, t[1:4] if is_moved[k] else None))
                ln.rows(r.segments_map, lead=(r.step,))

    def write_grid(self, poses: np.ndarray, warn) -> None:
        """map.pgm, map.yaml and map_grid.png from the kept scans (their warnings through ``warn``)."""
        grid = build_grid(self.scans, self.grid.resolution, self.grid.max_cells, warn)
        write_grid(self.dest, grid)
        draw_grid(self.dest / "map_grid.png", grid, poses)


def find_ground_truth(log_path: Path) -> Path | None:
    """``LOG.gt.tum`` beside the log (also without the log's extension, and for a gzipped log without
    ``.gz`` too: NAME.log.gz finds NAME.gt.tum), if present; for ``.`` or ``..`` (a ROS 2 bag directory
    run from inside it), beside that directory."""
    if log_path.name in ("", ".."):
        log_path = Path(os.path.abspath(log_path))
        if not log_path.name:  # the root directory
            return None
    names = [log_path] + ([log_path.with_suffix("")] if log_path.suffix == ".gz" else [])
    candidates = [c for p in names for c in (p.with_name(p.name + ".gt.tum"), p.with_suffix(".gt.tum"))]
    # (os.path.isfile, not Path.is_file: a log named with 249-255 bytes puts LOG.gt.tum's name over the
    # limit, and Python 3.11's is_file raises ENAMETOOLONG — info and run exited 1, a review)
    return next((c for c in candidates if os.path.isfile(c)), None)


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


def ground_truth_path(log_path: Path, ground_truth: str | Path | None | bool) -> Path | None:
    """The ground truth a run reads: ``ground_truth`` as given, LOG.gt.tum beside the log when it is None
    (:func:`find_ground_truth`), none when it is False (--no-ground-truth)."""
    if ground_truth is False:
        return None
    return Path(ground_truth) if ground_truth else find_ground_truth(Path(log_path))


def load_reference(
    log_path: Path,
    ground_truth: str | Path | None | bool = None,
    relations: str | Path | None = None,
    time_offset: float = 0.0,
) -> Reference:
    """The given ground truth, else LOG.gt.tum if present (none when ``ground_truth`` is False:
    --no-ground-truth); the given relations file, if any. A LOG.gt.tum that cannot be read says in its
    error that it was read for lying beside the log (the user gave no ground truth, and the error named a
    file they had not asked for), and how to run without it."""
    gt_path = ground_truth_path(log_path, ground_truth)
    rel_path = Path(relations) if relations else None
    notes: list[str] = []
    try:
        gt = read_tum(gt_path, "ground truth", notes.append) if gt_path else None
    except CornerslamError as e:
        if ground_truth:
            raise
        why = (
            "read as the log's ground truth for lying beside it: fix it, or run without it: --no-ground-truth"
        )
        raise type(e)(e.msg, f"{e.hint}; {why}" if e.hint else why) from None
    return Reference(
        gt_path,
        gt,
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
    online: np.ndarray | None = None,
    receive: bool = False,
    alone: bool = False,
) -> tuple[Accuracy | None, list[str]]:
    """ATE/RPE against the ground truth and the relation metric, for the estimate and for odometry (and
    for the scan-matched odometry when there is one: what the corners add on top of it), and the
    warnings about them: a ground truth read out of time order, a ground truth that does not overlap
    the run in time (then there is no ATE/RPE, rather than NaN), no relation inside the run. ``online``:
    the causal estimate when ``poses`` were smoothed (two-level SLAM), scored beside them; ``receive``:
    the run's stamps are the recorder's (``input.stamps=receive``), which a ground truth stamped on the
    sensors' clock may not meet (said so); ``alone``: the odometry is the scans' (input.odometry=scans):
    a mirror names the laser's mount as a cause too; the units check holds (LaserScan ranges are metres)."""
    acc: dict = {}  # Accuracy's fields
    notes = list(ref.notes)
    name = f"ground truth '{ref.gt_path}'"
    odometry = "the scans' odometry" if alone else "the log's odometry"
    clocks = "the run is stamped on the recorder's clock (input.stamps=receive), the ground truth perhaps on"
    problem = ref.gt is not None and (
        overlap_problem(stamps, ref.gt[0], name, clocks=f"{clocks} the sensors'" if receive else "")
        # (on the log's odometry: what the log says, the same for every associator of a compare, and
        # not the estimate's failure — a stuck or drifting run is scored, not taken for a bad reference)
        or mirror_problem(stamps, odoms, *ref.gt, name, odometry, from_scans=alone)
        or units_problem(stamps, odoms, *ref.gt, name, odometry)
    )
    if problem:
        notes.append(f"{problem[0]}: no ATE/RPE")
    elif ref.gt is not None:
        acc.update(
            ground_truth=display_path(ref.gt_path),
            ate=ate(stamps, poses, *ref.gt),
            odom_ate=ate(stamps, odoms, *ref.gt),
            **vars(rpe(stamps, poses, *ref.gt)),
            scan_odom_ate=None if scan_odoms is None else ate(stamps, scan_odoms, *ref.gt),
            online_ate=None if online is None else ate(stamps, online, *ref.gt),
        )
        if note := coverage_note(f"ground truth '{ref.gt_path}'", ref.gt[0], acc["ate"], len(stamps)):
            notes.append(note)  # a number over part of the run, said so
        if note := sparse_note(f"ground truth '{ref.gt_path}'", ref.gt[0], stamps):
            notes.append(note)  # a number against straight lines, said so
    if ref.relations is not None:
        rel, offset = ref.relations, ref.time_offset
        relations = relation_error(stamps, poses, rel, offset)
        acc.update(
            relations_file=display_path(ref.relations_path),
            relations=relations,
            relations_time_offset=offset,
            odom_relations=relation_error(stamps, odoms, rel, offset),
            scan_odom_relations=None
            if scan_odoms is None
            else relation_error(stamps, scan_odoms, rel, offset),
        )
        if relations.n == 0:
            notes.append(f"no relation in '{ref.relations_path}' falls inside the run (check --time-offset)")
    return Accuracy(**acc) if acc else None, notes
