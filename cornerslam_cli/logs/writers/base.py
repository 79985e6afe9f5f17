"""What every log writer shares: the scan to write (:class:`RawScan`), stamps as ROS (sec, nsec) and
nanoseconds, scans and odometry merged into one stream by stamp (odometry first on ties)."""

from __future__ import annotations

import heapq
import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np

from ...types import OdomSample


@dataclass(frozen=True)
class RawScan:
    """A scan to write: every beam of the message, in bearing order.

    ranges : (n,) metres, inf/NaN or >= range_max = no return; beam i at angle_min + i * angle_increment.
    time_increment : seconds between two beams (beam i at stamp + i · time_increment; 0 = not given).
    """

    stamp: float
    angle_min: float
    angle_increment: float
    ranges: np.ndarray
    range_min: float = 0.0
    range_max: float = 30.0
    frame_id: str = "laser"
    time_increment: float = 0.0

    @property
    def angle_max(self) -> float:
        return self.angle_min + (len(self.ranges) - 1) * self.angle_increment


def stamp_parts(t: float) -> tuple[int, int]:
    """A stamp in seconds as ROS (sec, nsec), nsec rounded and below 10⁹."""
    sec = math.floor(t)
    nsec = int(round((t - sec) * 1e9))
    if nsec >= 1_000_000_000:
        sec, nsec = sec + 1, nsec - 1_000_000_000
    return sec, nsec


def stamp_ns(t: float) -> int:
    """A stamp in seconds as integer nanoseconds (an MCAP or bag log time)."""
    sec, nsec = stamp_parts(t)
    return sec * 1_000_000_000 + nsec


def merged(scans: Iterable[RawScan], odoms: Iterable[OdomSample]) -> Iterator[RawScan | OdomSample]:
    """Scans and odometry samples (each sorted by stamp) as one stream in stamp order, odometry first."""
    return heapq.merge(odoms, scans, key=lambda m: m.stamp)
