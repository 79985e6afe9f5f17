"""A run's results as frozen dataclasses: :class:`RunSummary` (summary.json) and :class:`Accuracy`
(ATE, RPE and the relation metric, also what ``cornerslam evaluate`` scores).

The run writer (report/run_writer.py) builds a ``RunSummary`` once; every consumer — the printed
summary, compare's table, batch's figures and resume check, the figures, report.html, the results
MCAP — reads it by attribute, so a misspelt field fails loudly (``AttributeError``) rather than as a
silent ``.get`` default. summary.json is its serialisation: :meth:`RunSummary.to_json` gives the JSON
data (fields in declaration order, which is the file's key order), :meth:`RunSummary.from_json` reads
it back, refusing a file with a missing, unknown or mistyped key with a :class:`ResultsError` naming
the dotted key (e.g. one written by an older version). A field declared with :func:`optional` is left
out of the file when it is None (a relation error without relations in the run has no means); a
float field written as ``null`` (non-finite: strict JSON) reads back as NaN.
"""

from __future__ import annotations

import json
import math
import types
import typing
from dataclasses import dataclass, field, fields, is_dataclass, replace
from pathlib import Path
from typing import Any

from .errors import ResultsError, display_path


class JsonResult:
    """A results dataclass with its JSON form: :meth:`to_json` and :meth:`from_json`."""

    def to_json(self) -> dict:
        """The JSON data (write it with ``report.tables.write_json``)."""
        return to_json(self)

    @classmethod
    def from_json(cls, data: Any, where: str | None = None) -> Any:
        """The result of its JSON data; ResultsError naming the key (``where``: the dotted key of
        ``data`` itself) that is missing, unknown or of the wrong type."""
        return from_json(cls, data, where or cls.__name__)


def optional() -> Any:
    """A field that is left out of the JSON data when it is None (and may be absent when read)."""
    return field(default=None, metadata={"optional": True})


@dataclass(frozen=True, kw_only=True)
class Ate(JsonResult):
    """Absolute trajectory error after SE(2) alignment (``evaluate.ate``): position error RMSE, mean,
    max [m] over ``n`` poses, heading error RMSE [rad] (absent with fewer than two poses); ``scale``:
    present when aligned by a similarity instead (``evaluate --correct-scale``), its scale; ``in_holes``:
    poses not scored for a hole in the ground truth (absent when none)."""

    n: int
    rmse: float
    mean: float
    max: float
    rot_rmse: float | None = optional()
    scale: float | None = optional()
    # appended: poses inside the ground truth's span but in a hole of it (evaluate.in_holes), not
    # scored; absent when none
    in_holes: int | None = optional()


@dataclass(frozen=True, kw_only=True)
class Rpe(JsonResult):
    """Relative pose error (``evaluate.rpe``): per step [m, rad] and per metre of path [m/m]."""

    rpe_step_rmse: float
    rpe_step_rot_rmse: float
    rpe_per_m: float


@dataclass(frozen=True, kw_only=True)
class RelationError(JsonResult):
    """The Kümmerle et al. 2009 relation metric (``evaluate.relation_error``): ``n`` of ``n_total``
    relations inside the trajectory; mean ± std of the translational [m] and rotational [deg] error
    (absent when ``n`` is 0)."""

    n: int
    n_total: int
    trans_mean: float | None = optional()
    trans_std: float | None = optional()
    rot_mean_deg: float | None = optional()
    rot_std_deg: float | None = optional()


@dataclass(frozen=True, kw_only=True)
class Accuracy(JsonResult):
    """A trajectory scored against a ground truth (ATE, RPE) and/or relations, for the estimate and,
    in a run, for the odometry and the scan-matched odometry (the filter's motion input)."""

    ground_truth: str | None = optional()
    ate: Ate | None = optional()
    odom_ate: Ate | None = optional()
    rpe_step_rmse: float | None = optional()
    rpe_step_rot_rmse: float | None = optional()
    rpe_per_m: float | None = optional()
    scan_odom_ate: Ate | None = optional()
    relations_file: str | None = optional()
    relations: RelationError | None = optional()
    odom_relations: RelationError | None = optional()
    scan_odom_relations: RelationError | None = optional()
    online_ate: Ate | None = (
        optional()
    )  # appended (issue 16): the causal estimate, when the output was smoothed
    # appended (2026-12-06): --time-offset the relations were read with (relation time − log time), so
    # `evaluate OUTDIR` can score against them again unasked
    relations_time_offset: float | None = optional()


@dataclass(frozen=True, kw_only=True)
class ScanSpan(JsonResult):
    """The part of the log a run processed (``--start``/``--end``/``--max-scans``, span.py): the
    options as given; the first and last scan kept, by index on the scan topic and in seconds from
    the log's first scan; how many scans that is."""

    options: str
    first_index: int
    last_index: int
    first_time: float
    last_time: float
    scans: int


@dataclass(frozen=True, kw_only=True)
class RunInput(JsonResult):
    """What a run read: the log, its format and topics, the laser mount and where it came from."""

    log: str
    format: str
    scan_topic: str | None
    odom_topic: str | None
    odom_source: str | None
    laser_to_base: tuple[float, float, float]
    laser_to_base_source: str  # tf, config, preset or default (lasers.mount_source)
    odom_on_tf: bool | None = optional()  # the log's tf carries odom → base (absent before issue 17)
    span: ScanSpan | None = optional()  # absent when the whole log was processed
    # appended: where the beams' times of the deskewing came from — log (the messages' time_increment),
    # config (input.beam_time), none (not known: scans as recorded) or off (input.deskew false) — and the
    # first keyframe's time between beams, s
    beam_times: str | None = optional()
    beam_time: float | None = optional()
    laser_upside_down: bool | None = optional()  # appended: the laser's z axis down, its scans mirrored
    # appended: where laser_upside_down came from — tf (the log's tf) or config (input.laser.upside_down)
    # — not always laser_to_base_source's (a CARMEN ROBOTLASER1 mount is planar: its flag is the config's)
    laser_upside_down_source: str | None = optional()
    # appended: the robot's frame, which the odometry gives the pose of and the laser mount is in — a
    # nav_msgs/Odometry's child_frame_id, else input.base_frame; absent for a CARMEN log (no frames)
    base_frame: str | None = optional()
    # appended: the odometry's frame, which it gives the robot's pose in and a results MCAP hangs map from —
    # a nav_msgs/Odometry's header frame_id, else input.odom_frame; absent for a CARMEN log (no frames)
    odom_frame: str | None = optional()


@dataclass(frozen=True, kw_only=True)
class Counts(JsonResult):
    """How many of each thing a run saw: steps, landmarks, matches; the reader's beams (those of the scans
    in ``--start``/``--end``/``--max-scans``, as ``scans_in``) and scans; the synchroniser's scans and
    odometry (``logs.sync.SyncStats``); associator budget hits; the scan matcher's outcomes (absent when
    scan matching was off)."""

    steps: int
    landmarks: int
    matched_total: int
    beams_total: int
    beams_invalid: int
    scans_bad_geometry: int
    scans_size_mismatch: int
    messages_failed: int
    scans_in: int
    scans_out: int
    before_first_odom: int
    after_last_odom: int
    odom_gap: int
    scan_time_backwards: int
    odom_time_backwards: int
    keyframes_skipped: int
    odom_jumps: int
    scans_skipped: int
    budget_hits: int
    scans_matched: int | None = optional()
    scans_match_retried: int | None = optional()
    scans_match_fallback: int | None = optional()
    scans_match_rejected: int | None = optional()  # appended (issue 15): matches the fusion's gate refused
    # appended (issue 16), absent without submaps: submaps closed, loop closures accepted / refused
    submaps: int | None = optional()
    loops_accepted: int | None = optional()
    loops_rejected: int | None = optional()
    # appended, present with graph.refine: scan pairs the dense refinement added to the keyframe graph
    refine_factors: int | None = optional()
    # appended after it: node pairs registered, and those whose fit reached refine_min_fitness (of which
    # refine_factors moved their pair within refine_max_xy / refine_max_theta of the solved graph)
    refine_registered: int | None = optional()
    refine_fit: int | None = optional()


@dataclass(frozen=True, kw_only=True)
class ScanOdometryStats(JsonResult):
    """The odometry a run on the scans alone made (``input.odometry: scans``, motion/scan_odometry.py): its
    scans, searched, coasted (no registration fitted: the guess taken), after a gap, and its seconds."""

    scans: int
    searched: int
    coasted: int
    gaps: int  # scans after a gap of GAP times the scans' usual spacing (motion/scan_odometry.py), warned
    seconds: float


@dataclass(frozen=True, kw_only=True)
class OdometryModel(JsonResult):
    """What the front end learnt by the end of the run (motion/fusion.py): the odometry's noise scale
    and the scan match's (times their models), the odometer scale error and the heading drift (rad/m);
    appended, whether that drift acts along each increment (the odometry integrated along the path)."""

    odom_noise_scale: float
    match_noise_scale: float
    odom_scale_error: float
    heading_drift_per_m: float
    heading_drift_along_path: bool | None = optional()
    # appended: the step (trajectory.csv's) whose increment first had the scale error / the drift taken
    # out (left out: never) — the increments before it carried that term in the odometry's share of them
    scale_error_from_keyframe: int | None = optional()
    heading_drift_from_keyframe: int | None = optional()
    # appended, with graph.recalibrate only: the scale error and drift fitted on every keyframe of the run,
    # which the smoothed chain carried back to the steps before each was first taken (unless dropped once
    # taken: motion/fusion.py carry_back; the fields above are the last window's)
    whole_run_scale_error: float | None = optional()
    whole_run_heading_drift_per_m: float | None = optional()


@dataclass(frozen=True, kw_only=True)
class MapConsistency(JsonResult):
    """How well the map agrees with itself, without ground truth (report/consistency.py): the scans'
    points placed with the estimate and with the odometry — occupied ``cell``-sized cells (fewer is
    crisper; ``cells_vs_odom`` their ratio) and the revisit misalignment [m] with the share of points
    revisited (null and 0 when the run never comes back to a place)."""

    cell: float
    scans: int
    points: int
    occupied_cells: int
    odom_occupied_cells: int
    cells_vs_odom: float
    revisit_mean: float
    revisit_share: float
    odom_revisit_mean: float
    odom_revisit_share: float


@dataclass(frozen=True, kw_only=True)
class Timing(JsonResult):
    """Stage times summed over the steps [s], the slowest matching step, the wall time of the run (in
    a comparison: the associator's own filter run; its stage times include the shared extraction)."""

    t_extract: float
    t_predict: float
    t_match: float
    t_update: float
    t_scan_match: float | None = optional()  # absent in a summary written before scan matching
    t_total: float
    t_match_max: float
    wall_time: float
    scans_per_second: float
    t_grid: float | None = optional()  # ray tracing and writing the occupancy grid (absent before it)
    t_loop: float | None = optional()  # loop closing and the pose graph (issue 16; absent without submaps)
    # compare --jobs: the filters that ran at once, this one among them (absent when it ran alone): its
    # times include waiting for the CPU, so they compare with no other run's
    concurrent_filters: int | None = optional()


@dataclass(frozen=True, kw_only=True)
class Hashes(JsonResult):
    """sha256 of the log's bytes and of the resolved config, the version and the source's sha256 (``code``:
    the version does not change with every commit): what batch resumes by;
    ``ground_truth``: sha256 of the ground truth's poses the run was scored against (absent without
    one), so a ground truth replaced or edited beside the log is not reported with the old ATE."""

    input: str
    config: str
    version: str
    ground_truth: str | None = optional()  # appended (2026-12-03)
    code: str | None = optional()  # appended (2026-12-05): sha256 of the build's source (summary.code_hash)
    relations: str | None = optional()  # appended (2026-12-06): sha256 of the relations as read


@dataclass(frozen=True, kw_only=True)
class RunSummary(JsonResult):
    """summary.json of a run (INTERFACE.md). ``out_dir``, the committed output directory, is set on
    the summary ``run`` returns and is not part of the file."""

    cornerslam_version: str
    mode: str
    input: RunInput
    assoc: str
    counts: Counts
    timing: Timing
    final_pose: tuple[float, float, float]
    warnings: tuple[str, ...]
    accuracy: Accuracy | None
    hashes: Hashes
    config: dict
    versions: dict
    odometry_model: OdometryModel | None = optional()  # appended (issue 15): what the front end learnt
    consistency: MapConsistency | None = optional()  # appended (issue 17): map consistency, no ground truth
    # appended: the odometry made from the scans (input.odometry: scans); absent: the log's odometry
    scan_odometry: ScanOdometryStats | None = optional()
    out_dir: str | None = field(default=None, metadata={"json": False})

    @classmethod
    def read(cls, path: str | Path) -> RunSummary:
        """A run directory's summary.json (or the file itself); ResultsError when it cannot be read."""
        path = Path(path)
        if path.is_dir():
            path = path / "summary.json"
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, ValueError) as e:
            raise ResultsError(
                f"cannot read the run summary '{display_path(path)}': {e}", "is it a cornerslam run output?"
            ) from None
        try:
            return cls.from_json(data, "summary")
        except ResultsError as e:
            raise ResultsError(f"'{display_path(path)}': {e.msg}", e.hint) from None

    @property
    def scan_matching(self) -> bool:
        """Scan matching gave the filter its motion input (``scan_match.enabled``)."""
        return self.counts.scans_matched is not None

    def with_out_dir(self, out_dir: str | Path) -> RunSummary:
        return replace(self, out_dir=str(out_dir))


def to_json(obj: Any) -> Any:
    """A results dataclass as JSON data (dicts in field order, lists): an :func:`optional` field that
    is None is left out, a field marked ``json=False`` always."""
    if is_dataclass(obj) and not isinstance(obj, type):
        out = {}
        for f in fields(obj):
            value = getattr(obj, f.name)
            if f.metadata.get("json", True) and not (value is None and f.metadata.get("optional")):
                out[f.name] = to_json(value)
        return out
    if isinstance(obj, (tuple, list)):
        return [to_json(v) for v in obj]
    return obj


def from_json(cls: type, data: Any, where: str) -> Any:
    """The dataclass ``cls`` from its JSON object ``data`` (``where``: its dotted key, for errors)."""
    hint = "it was written by another cornerslam version or edited; run it again"
    if not isinstance(data, dict):
        raise ResultsError(f"{where} is {type(data).__name__}, not an object", hint)
    names = [f.name for f in fields(cls) if f.metadata.get("json", True)]
    unknown = [k for k in data if k not in names]
    if unknown:
        raise ResultsError(f"{where} has the unknown key '{unknown[0]}'", hint)
    hints = typing.get_type_hints(cls)
    kwargs = {}
    for f in fields(cls):
        if f.name not in names:
            continue
        if f.name not in data:
            if f.metadata.get("optional"):
                continue
            raise ResultsError(f"{where} has no '{f.name}'", hint)
        kwargs[f.name] = _value(hints[f.name], data[f.name], f"{where}.{f.name}", hint)
    return cls(**kwargs)


def _value(tp: Any, v: Any, where: str, hint: str) -> Any:
    """``v`` as the field type ``tp`` (a dataclass, a tuple, int, float, str, bool, dict, or X | None)."""
    options = typing.get_args(tp) if isinstance(tp, types.UnionType) else (tp,)
    if v is None:
        if float in options:
            return math.nan  # strict JSON writes a non-finite float as null
        if type(None) in options:
            return None
        raise ResultsError(f"{where} is null", hint)
    tp = next(t for t in options if t is not type(None))
    if is_dataclass(tp):
        return from_json(tp, v, where)
    origin = typing.get_origin(tp) or tp
    expect = {
        tuple: list,
        int: int,
        float: (int, float),
        str: str,
        bool: bool,
        dict: dict,
    }[origin]
    if not isinstance(v, expect) or (isinstance(v, bool) and origin is not bool):
        raise ResultsError(f"{where} is {type(v).__name__}, not {origin.__name__}", hint)
    if origin is tuple:  # tuple[float, float, float] or tuple[str, ...]: every item of its type
        item = typing.get_args(tp)[0]
        return tuple(_value(item, x, f"{where}[{i}]", hint) for i, x in enumerate(v))
    return v
