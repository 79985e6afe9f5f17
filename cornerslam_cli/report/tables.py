"""Output tables (INTERFACE.md): ``write_*`` / ``read_*`` pairs.

A run streams its per-step rows into a hidden staging directory (outdir.py's :class:`StagedDir`),
renamed onto ``--out`` only once every file is complete.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np

from ..geometry import yaw_from_quaternion

log = logging.getLogger("cornerslam.report")

# INTERFACE.md's columns, then (an extension) the scan-matched odometry the filter used as motion input
# (= odom_* when scan matching is off)
# (appended, issue 16) the causal online estimate — x, y, theta are the smoothed trajectory with submaps
# — and the submap of the step
TRAJECTORY_COLUMNS = (
    "step,stamp,x,y,theta,odom_x,odom_y,odom_theta,var_x,var_y,var_theta,scan_odom_x,scan_odom_y,scan_odom_theta,"
    "online_x,online_y,online_theta,submap"
).split(",")
# (appended, issue 16) the landmark's submap and the id of the corner it was matched to across a loop closure
MAP_COLUMNS = "id,x,y,phi,var_x,var_y,cov_xy,var_phi,first_step,last_step,n_obs,submap,linked_to".split(",")
# INTERFACE.md's: ``submap`` the one that closed, ``other_submap`` the earlier one, (dx, dy, dtheta) the
# first's origin in the other's frame; then (appended) inlier, chi2, reason
LOOP_COLUMNS = "step,submap,other_submap,dx,dy,dtheta,n_corners,fitness,accepted".split(",")
LOOP_COLUMNS += ["inlier", "chi2", "reason"]
LINES_COLUMNS = ["step", "x1", "y1", "x2", "y2"]
TIMING_COLUMNS = (
    "step,stamp,n_points,n_lines,n_corners,n_candidates,n_matched,n_new,n_landmarks,"
    "t_extract,t_predict,t_match,t_update,t_total,t_scan_match,scan_fit,t_loop"
).split(",")
# (appended, issue 16) the associators on loop closing: empty cells when the runs had no submaps
# (t_loop appended 2026-12-05: summary.json's timing.t_loop, all loop closing and the graph's solves)
COMPARISON_LOOP_COLUMNS = [
    "submaps",
    "loops_accepted",
    "loops_rejected",
    "online_ate_rmse",
    "refine_factors",
    "t_loop",
]
COMPARISON_COLUMNS = (
    "assoc,steps,landmarks,matched_total,t_match_total,t_match_max,t_total,ate_rmse,"
    "odom_ate_rmse,rpe_trans_per_m,wall_time,budget_hits,rel_trans_mean,rel_trans_std,rel_rot_mean_deg,"
    "odom_rel_trans_mean,scan_odom_ate_rmse,scan_odom_rel_trans_mean"
).split(",") + COMPARISON_LOOP_COLUMNS


def csv_value(v) -> str:
    """One CSV cell: bools and integers as integers, floats rounded to 9 decimals (``nan`` for NaN;
    ``repr`` from 1e15 up; one that rounds to zero is 0.0 whatever its sign: a last-bit -1e-30 is not
    news), anything else as ``str``."""
    if type(v) is float:  # the common case first (same result as the branch below)
        return "nan" if v != v else repr(round(v, 9) + 0.0) if abs(v) < 1e15 else repr(v)
    if isinstance(v, (bool, np.bool_)):
        return str(int(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        v = float(v)
        if v != v:
            return "nan"
        return repr(round(v, 9) + 0.0) if abs(v) < 1e15 else repr(v)
    return str(v)


class CsvTable:
    """A CSV file written row by row (streaming), header first."""

    def __init__(self, path: Path, columns: Sequence[str]):
        self.path = path
        self.columns = list(columns)
        self._f = open(path, "w", newline="")
        self._f.write(",".join(self.columns) + "\n")

    def row(self, *values) -> None:
        self._f.write(",".join(csv_value(v) for v in values) + "\n")

    def write(self, row: Mapping[str, object]) -> None:
        """One row given by column name: a value for every column and for no other name."""
        if len(row) != len(self.columns):
            raise ValueError(f"{self.path.name}: row {sorted(row)} is not the columns {self.columns}")
        self.row(*(row[name] for name in self.columns))

    def rows(self, array: np.ndarray, lead: Sequence = ()) -> None:
        """Write each row of a 2D array, prefixed by the ``lead`` values."""
        prefix = "".join(csv_value(v) + "," for v in lead)
        buf = io.StringIO()
        for r in np.asarray(array, dtype=float).tolist():  # Python floats: the same cells, faster
            buf.write(prefix + ",".join(csv_value(v) for v in r) + "\n")
        self._f.write(buf.getvalue())

    def close(self) -> None:
        if not self._f.closed:
            self._f.flush()
            os.fsync(self._f.fileno())
            self._f.close()

    def __enter__(self) -> CsvTable:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        """Closed either way; after an error (a full disk) without a second one from the close."""
        if exc is None:
            self.close()
            return
        try:
            self._f.close()
        except OSError:
            pass


def read_csv(path: str | Path) -> dict[str, np.ndarray]:
    """Read one of our tables into columns (float arrays; non-numeric columns stay strings)."""
    with open(path, newline="") as f:
        reader = csv.reader(f)
        header = next(reader)
        rows = list(reader)
    out: dict[str, np.ndarray] = {}
    for i, name in enumerate(header):
        col = [r[i] for r in rows]
        try:
            out[name] = np.array([float(v) for v in col], dtype=float)
        except ValueError:
            out[name] = np.array(col, dtype=object)
    return out


def write_tum(path: Path, stamps: np.ndarray, poses: np.ndarray) -> None:
    """TUM trajectory: ``stamp x y z qx qy qz qw`` with z = 0 and a yaw-only quaternion (9 decimals; a
    value that rounds to zero is written without a sign)."""
    th = poses[:, 2]
    with open(path, "w") as f:
        for t, x, y, a in zip(stamps, poses[:, 0], poses[:, 1], th, strict=True):
            x, y, qz, qw = (round(float(v), 9) + 0.0 for v in (x, y, np.sin(a / 2), np.cos(a / 2)))
            f.write(f"{t:.9f} {x:.9f} {y:.9f} 0 0 0 {qz:.9f} {qw:.9f}\n")


TUM_LAYOUT = "stamp x y z qx qy qz qw"


def read_tum(
    path: str | Path, what: str = "trajectory file", warn: Callable[[str], None] = log.warning
) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM file; returns stamps (n,) in time order and 2D poses (n, 3) (yaw from the quaternion).

    Lines out of time order are sorted (a stable sort) and repeated lines dropped, each with a warning
    through ``warn``; two different poses at one stamp cannot be ordered and raise ``LogError``, as do
    binary files and lines that are not 8 finite numbers. ``what`` names the file in messages."""
    from ..errors import LogError
    from ..textfile import read_number_rows, refuse_far

    a, lines = read_number_rows(path, what, LogError, "TUM pose", TUM_LAYOUT, 8, cut_last=warn)
    name = f"{what} '{path}'"
    q, later = a[:, 4:8], a[:, 1] - a[:, 0]  # a relations file's t2 − t1 where x should be
    if (
        len(a) >= 2
        and not np.any(q[:, :3])
        and np.all(np.abs(q[:, 3]) <= np.pi)
        and np.any(np.abs(np.abs(q[:, 3]) - 1.0) > 1e-3)
        and np.all((np.abs(later) < 1e4) & (np.abs(a[:, 1]) > 1e5))
    ):  # its z roll pitch yaw read as qx qy qz qw: (0, 0, 0, yaw), and a clock's t2 near t1 as x
        raise LogError(
            f"{name} looks like a relations file (t1 t2 x y z roll pitch yaw: where its quaternions "
            "should be, each line has 0 0 0 and a number that is not ±1)",
            f"give it as --relations; a TUM file has lines {TUM_LAYOUT}",
        )
    refuse_far(a, lines, [1, 2, 3], name, LogError, TUM_LAYOUT, stamps=[0])
    back = np.flatnonzero(np.diff(a[:, 0]) < 0)
    if len(back):
        i = int(back[0])
        warn(
            f"{name} is not in time order (line {lines[i + 1]} at {a[i + 1, 0]:.6f} s comes after line "
            f"{lines[i]} at {a[i, 0]:.6f} s; {len(back)} line(s) go back): sorted by stamp"
        )
        order = np.argsort(a[:, 0], kind="stable")
        a, lines = a[order], lines[order]
    same = np.flatnonzero(np.diff(a[:, 0]) == 0)
    differ = same[np.any(a[same, 1:] != a[same + 1, 1:], axis=1)]
    if len(differ):
        i = int(differ[0])
        raise LogError(
            f"{name} has two different poses at stamp {a[i, 0]:.9f} (lines {lines[i]} and {lines[i + 1]})",
            "remove one of them",
        )
    if len(same):
        warn(f"{name} repeats {len(same)} line(s) (first: line {lines[same[0] + 1]}): dropped")
        keep = np.ones(len(a), dtype=bool)
        keep[same + 1] = False
        a = a[keep]
    qx, qy, qz, qw = _unit_quaternions(a[:, 4:8], name, lines)
    # > 60° out of the plane as read (sin of half the tilt), exactly in it read qw qx qy qz, and turning
    # then (a body upside down, z down, has qz = qw = 0: read as it is)
    tilt, tilt_w_first = np.median(np.hypot(qx, qy)), np.max(np.hypot(qy, qz))
    if tilt > 0.5 and tilt_w_first < 0.02 and np.max(np.abs(qw)) > 0.05:
        degrees = np.degrees(2 * np.arcsin(min(tilt, 1.0)))
        raise LogError(
            f"{name}: its quaternions turn the poses out of the plane (by {degrees:.0f}° on the median line) "
            "and would not as qw qx qy qz: written with qw first?",
            f"reorder each line to {TUM_LAYOUT}",
        )
    yaw = yaw_from_quaternion(qx, qy, qz, qw)
    return a[:, 0], np.column_stack((a[:, 1], a[:, 2], yaw))


def _unit_quaternions(q: np.ndarray, name: str, lines: np.ndarray) -> np.ndarray:
    """The quaternion columns (n, 4) as rows of (qx, qy, qz, qw) columns, each of unit length: the
    yaw formula assumes it (a ×2 quaternion gives another yaw). Ones within 1e-6 of unit length are
    kept bit for bit; a zero-length one has no orientation and raises LogError naming its line."""
    from ..errors import LogError

    norm = np.linalg.norm(q, axis=1)
    zero = np.flatnonzero(norm < 1e-9)
    if len(zero):
        raise LogError(
            f"{name} line {lines[zero[0]]} has a zero-length quaternion (no orientation)",
            "give qx qy qz qw of unit length",
        )
    off = np.abs(norm - 1) > 1e-6
    q = q.copy()
    q[off] /= norm[off, None]
    return q.T


def write_json(path: Path, data: dict) -> None:
    """Strict JSON (RFC 8259, what every non-Python reader expects): a non-finite float is written as
    null, never as NaN or Infinity."""
    with open(path, "w") as f:
        f.write(json_text(data, indent=2) + "\n")


def json_text(data, **kwargs) -> str:
    """``json.dumps`` of ``data`` with non-finite floats (also numpy's, also in arrays) as null."""
    return json.dumps(_finite_or_none(data), allow_nan=False, default=_json_default, **kwargs)


def _finite_or_none(o):
    if isinstance(o, dict):
        return {k: _finite_or_none(v) for k, v in o.items()}
    if isinstance(o, (list, tuple, np.ndarray)):
        return [_finite_or_none(v) for v in o]
    if isinstance(o, (float, np.floating)):
        return float(o) if np.isfinite(o) else None
    return o


def _json_default(o):
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.bool_):
        return bool(o)
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o)}")


# comparison.csv columns where one direction is better (the best cell is highlighted). Not matched_total:
# more matches is better only when they are right (an associator that takes wrong ones matches most)
BETTER: dict[str, Callable[[Iterable[float]], float]] = {
    "t_match_total": min,
    "t_match_max": min,
    "t_total": min,
    "ate_rmse": min,
    "rpe_trans_per_m": min,
    "wall_time": min,
    "budget_hits": min,
    "online_ate_rmse": min,
    "t_loop": min,
    "rel_trans_mean": min,  # the relation metric (--relations): Intel's accuracy figure
    "rel_rot_mean_deg": min,
}


TIMES = {k for k in BETTER if k.startswith("t_") or k == "wall_time"}  # BETTER's columns that are times


def best_cells(
    columns: dict, n_rows: int, names: list[str] = COMPARISON_COLUMNS, timed: bool = True
) -> set[tuple[int, int]]:
    """(row, col) of the best value in each BETTER column of ``names`` (the table's columns, in
    order), when the values differ; not of the times unless ``timed`` (runs timed apart)."""
    best = set()
    for j, name in enumerate(names):
        pick = BETTER.get(name) if timed or name not in TIMES else None
        col = columns.get(name)
        if pick is None or col is None or col.dtype == object:
            continue
        vals = [float(v) for v in col]
        finite = [v for v in vals if math.isfinite(v)]
        if len(set(finite)) < 2:  # nothing to choose between
            continue
        target = pick(finite)
        best |= {(i, j) for i, v in enumerate(vals) if v == target}
    return best
