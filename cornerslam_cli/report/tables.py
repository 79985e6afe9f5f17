"""Output tables (INTERFACE.md): ``write_*`` / ``read_*`` pairs.

A run streams its per-step rows into a hidden staging directory (outdir.py's :class:`StagedDir`),
renamed onto ``--out`` only once every file is complete.
"""

from __future__ import annotations

import csv
import io
import json
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

# INTERFACE.md's columns, then (an extension) the scan-matched odometry the filter used as motion input
# (= odom_* when scan matching is off)
TRAJECTORY_COLUMNS = (
    "step,stamp,x,y,theta,odom_x,odom_y,odom_theta,var_x,var_y,var_theta,scan_odom_x,scan_odom_y,scan_odom_theta"
).split(",")
MAP_COLUMNS = "id,x,y,phi,var_x,var_y,cov_xy,var_phi,first_step,last_step,n_obs".split(",")
LINES_COLUMNS = ["step", "x1", "y1", "x2", "y2"]
TIMING_COLUMNS = (
    "step,stamp,n_points,n_lines,n_corners,n_candidates,n_matched,n_new,n_landmarks,"
    "t_extract,t_predict,t_match,t_update,t_total,t_scan_match,scan_fit"
).split(",")
COMPARISON_COLUMNS = (
    "assoc,steps,landmarks,matched_total,t_match_total,t_match_max,t_total,ate_rmse,"
    "odom_ate_rmse,rpe_trans_per_m,wall_time,budget_hits,rel_trans_mean,rel_trans_std,rel_rot_mean_deg,"
    "odom_rel_trans_mean,scan_odom_ate_rmse,scan_odom_rel_trans_mean"
).split(",")


def _fmt(v) -> str:
    if isinstance(v, (bool, np.bool_)):
        return str(int(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        v = float(v)
        if v != v:
            return "nan"
        return repr(round(v, 9)) if abs(v) < 1e15 else repr(v)
    return str(v)


class CsvTable:
    """A CSV file written row by row (streaming), header first."""

    def __init__(self, path: Path, columns: Sequence[str]):
        self.path = path
        self.columns = list(columns)
        self._f = open(path, "w", newline="")
        self._f.write(",".join(self.columns) + "\n")

    def row(self, *values) -> None:
        self._f.write(",".join(_fmt(v) for v in values) + "\n")

    def rows(self, array: np.ndarray, lead: Sequence = ()) -> None:
        """Write each row of a 2D array, prefixed by the ``lead`` values."""
        prefix = "".join(_fmt(v) + "," for v in lead)
        buf = io.StringIO()
        for r in np.asarray(array, dtype=float):
            buf.write(prefix + ",".join(_fmt(v) for v in r) + "\n")
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
    """TUM trajectory: ``stamp x y z qx qy qz qw`` with z = 0 and a yaw-only quaternion."""
    th = poses[:, 2]
    with open(path, "w") as f:
        for t, x, y, a in zip(stamps, poses[:, 0], poses[:, 1], th, strict=True):
            f.write(f"{t:.9f} {x:.9f} {y:.9f} 0 0 0 {np.sin(a / 2):.9f} {np.cos(a / 2):.9f}\n")


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM file; returns stamps (n,) and 2D poses (n, 3) (yaw from the quaternion)."""
    from ..errors import LogError

    p = Path(path)
    if not p.is_file():
        raise LogError(f"trajectory file '{p}' does not exist", "give a TUM file: stamp x y z qx qy qz qw")
    rows = []
    for lineno, line in enumerate(p.read_text().splitlines(), 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.replace(",", " ").split()
        try:
            vals = [float(v) for v in parts]
        except ValueError:
            raise LogError(f"'{p}' line {lineno} is not a TUM pose", "expected 8 numbers per line") from None
        if len(vals) != 8:
            raise LogError(
                f"'{p}' line {lineno} has {len(vals)} values", "TUM needs 8: stamp x y z qx qy qz qw"
            )
        rows.append(vals)
    if not rows:
        raise LogError(f"trajectory file '{p}' has no poses")
    a = np.array(rows)
    qx, qy, qz, qw = a[:, 4], a[:, 5], a[:, 6], a[:, 7]
    yaw = np.arctan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
    return a[:, 0], np.column_stack((a[:, 1], a[:, 2], yaw))


def write_json(path: Path, data: dict) -> None:
    with open(path, "w") as f:
        json.dump(data, f, indent=2, sort_keys=False, default=_json_default)
        f.write("\n")


def _json_default(o):
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.floating):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o)}")
