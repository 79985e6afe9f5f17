"""CARMEN logs: ODOM lines and FLASER or ROBOTLASER1 laser lines, optionally gzipped."""

from __future__ import annotations

import gzip as _gzip
import math
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from ...types import OdomSample
from ..carmen import DEFAULT_MAX_RANGE, flaser_increment
from .base import RawScan, merged


def _fmt(values) -> str:
    return " ".join(repr(float(v)) for v in values)


class _Separated:
    """A text file whose writes have their spaces replaced by ``sep``."""

    def __init__(self, f, sep: str):
        self.f, self.sep = f, sep

    def write(self, line: str) -> None:
        self.f.write(line if self.sep == " " else line.replace(" ", self.sep))


def write_carmen(
    path: str | Path,
    scans: Iterable[RawScan],
    odoms: Iterable[OdomSample],
    *,
    gzip: bool = False,
    odom_lines: bool = True,
    laser: str = "auto",
    hostname: str = "cornerslam",
    sep: str = " ",
) -> Path:
    """Write a CARMEN log: ODOM lines (unless ``odom_lines=False``) and one laser line per scan.

    laser ``FLASER`` needs CARMEN's implied angles (angle_min = −π/2, the increment of
    :func:`~cornerslam_cli.logs.carmen.flaser_increment`) and no-return = 81.83 m; ``ROBOTLASER1``
    stores angles and max range; ``auto`` picks FLASER when the scan fits it. The laser line's pose
    fields hold the latest odometry pose (so a log without ODOM lines still has odometry).
    No-return readings (inf, NaN, >= range_max) are written as the max range. ``sep`` separates the
    fields (logs in the wild also use tabs).
    """
    path = Path(path)
    opener = _gzip.open if gzip else open
    pose = (0.0, 0.0, 0.0)
    with opener(path, "wt", encoding="ascii") as out:
        f = _Separated(out, sep)
        f.write("# written by cornerslam write_carmen\n")
        for m in merged(scans, odoms):
            ts = repr(float(m.stamp))
            if isinstance(m, OdomSample):
                pose = (m.x, m.y, m.theta)
                if odom_lines:
                    f.write(f"ODOM {_fmt(pose)} 0 0 0 {ts} {hostname} {ts}\n")
                continue
            n = len(m.ranges)
            flaser_ok = (
                abs(m.angle_min + math.pi / 2) < 1e-9
                and abs(m.angle_increment - flaser_increment(n)) < 1e-9
                and m.range_max == DEFAULT_MAX_RANGE
            )
            tag = ("FLASER" if flaser_ok else "ROBOTLASER1") if laser == "auto" else laser
            if tag == "FLASER" and not flaser_ok:
                raise ValueError("scan does not fit FLASER's implied angles / max range; use ROBOTLASER1")
            r = np.asarray(m.ranges, dtype=np.float64).copy()
            r[~np.isfinite(r) | (r >= m.range_max)] = m.range_max
            if tag == "FLASER":
                f.write(f"FLASER {n} {_fmt(r)} {_fmt(pose)} {_fmt(pose)} {ts} {hostname} {ts}\n")
            else:
                fov = n * m.angle_increment
                head = f"ROBOTLASER1 0 {_fmt((m.angle_min, fov, m.angle_increment, m.range_max))} 0.01 0"
                f.write(f"{head} {n} {_fmt(r)} 0 {_fmt(pose)} {_fmt(pose)} 0 0 0 0 0 {ts} {hostname} {ts}\n")
    return path
