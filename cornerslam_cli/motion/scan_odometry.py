"""Odometry from the scans alone (``input.odometry: scans``): for a log without wheel odometry.

Each scan is registered (point-to-line ICP, :func:`icp.register`) on a local map of the last ``window``
scans that moved the robot far enough, from a constant-velocity guess: the robot is taken to repeat its
last increment, KISS-ICP's motion model (Vizzo et al. 2023) in 2-D — per scan, not per second: logs thinned
by distance keep a scan a metre, not a time, apart. Where the scans leave a direction free (a featureless
corridor) ICP's weak prior keeps the guess along it: the robot coasts as it moved. When the last increment
is larger than ICP's basin (half its length, or half its turn plus TURN_PER_METRE of it, beyond
``search_min_*``: scans far apart), when ICP fits under ``min_fit``, after a gap in time (GAP times the
scans' usual spacing: counted, the run warns) and on the first START scans, a
correlative search (motion/correlative.py) over ``search_max_*`` runs around the guess and around the robot
standing still (a stop, a turn the other way), and ICP from its best pose replaces ICP from the guess
when it fits better by FIT_MARGIN. When no registration fits, the guess is taken (counted:
:attr:`ScanOdometry.coasted`). The settings are the scan matcher's (``scan_match.*``).

The poses become the run's odometry, one sample at each scan's stamp (:func:`with_scan_odometry`):
keyframes, deskewing and the filter's motion input (with its motion noise model, ``ekf.alpha*``: the front
end does not match the scans a second time) take them as they would wheel odometry. Their frame starts at
the first scan's base, at the origin.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Iterable, Iterator

import numpy as np

from ..geometry import apart, compose, relative, transform_points, within_range
from ..results import ScanOdometryStats
from ..types import OdomSample, Scan
from .correlative import Window, search
from .icp import LocalMap, Registration, register, voxel_thin
from .params import ScanMatchConfig

# How far the motion may differ from the last increment, unforeseen by the model — half its length, and in
# heading half its turn plus this much per metre of it (rad/m): when that exceeds ICP's basin
# (``search_min_*``) the correlative search runs, over ``search_max_*``; under it (small steps: a laser at
# 10 Hz and more) ICP from the guess alone
CHANGE = 0.5
TURN_PER_METRE = 0.25
START = 3  # scans before the increment is known: each searched
FIT_MARGIN = 0.02  # a search's registration replaces the guess's when it fits better by more than this
# a scan this many times later than the median spacing of the last GAP_WINDOW, when none of those was more
# than REGULAR times it (a laser's steady rate: scans dropped, a recording paused — not a log thinned by
# distance, whose scans come seconds apart when the robot stood): the last increment says little of the
# motion across it — searched as if lost, and counted
GAP = 5.0
GAP_WINDOW = 20
REGULAR = 2.0


class ScanOdometry:
    """The pose of each scan in turn, from registering it on the scans before (module docstring)."""

    def __init__(self, cfg: ScanMatchConfig):
        self.cfg = cfg
        self.map_points: deque[np.ndarray] = deque(maxlen=cfg.window)  # the map scans, placed and thinned
        self.local: LocalMap | None = None
        self.pose: np.ndarray | None = None  # the previous scan's
        self.stamp = 0.0  # the previous scan's
        self.increment = np.zeros(3)  # the last one, in the previous scan's frame
        self.last_map_pose: np.ndarray | None = None
        self.scans = 0  # scans given a pose
        self.coasted = 0  # of them, placed at the guess: no registration fitted
        self.searched = 0  # of them, registered from a correlative search's pose
        self.gaps: list[tuple[float, float]] = []  # (stamp, seconds) of the scans after a gap (GAP)
        self.spacing: deque[float] = deque(maxlen=GAP_WINDOW)  # the last scans' time apart
        self.seconds = 0.0  # spent in :meth:`step`

    def step(self, points: np.ndarray, stamp: float) -> np.ndarray | None:
        """The pose of the scan with ``points`` (base frame) stamped ``stamp``; None for a stamp not after
        the previous scan's (the synchroniser skips that scan as going backwards)."""
        t0 = time.perf_counter()
        if not np.isfinite(stamp):
            return None
        if self.pose is None:
            pose = np.zeros(3)
        elif not stamp > self.stamp:
            return None
        else:
            dt = stamp - self.stamp
            usual = float(np.median(self.spacing)) if len(self.spacing) == self.spacing.maxlen else np.inf
            gap = dt > GAP * usual and max(self.spacing) <= REGULAR * usual
            if gap:
                self.gaps.append((stamp, dt))
            self.spacing.append(dt)
            pose = self._register(points, compose(self.pose, self.increment), gap)
            self.increment = relative(self.pose, pose)
        self.pose, self.stamp = pose, stamp
        self.scans += 1
        self._grow_map(points, pose)
        self.seconds += time.perf_counter() - t0
        return pose.copy()

    def _register(self, points: np.ndarray, guess: np.ndarray, gap: bool = False) -> np.ndarray:
        cfg = self.cfg
        points = points[voxel_thin(points, cfg.scan_voxel)]
        if self.local is None or len(points) < 3:
            self.coasted += 1
            return guess
        reg = first = register(points, self.local, guess, cfg)
        length = float(np.hypot(*self.increment[:2]))
        change = (CHANGE * length, CHANGE * abs(self.increment[2]) + TURN_PER_METRE * length)
        if (
            reg.fit < cfg.min_fit
            or gap
            or self.scans < START
            or change[0] > cfg.search_min_xy
            or change[1] > cfg.search_min_theta
        ):
            # the whole window, around the guess and around the robot standing still: a stop, or a turn
            # the other way (sparse logs: a scan a metre, tens of degrees of turn, apart)
            window = Window(cfg.search_max_xy, cfg.search_max_theta)
            near = within_range(points, cfg.search_range)  # (as ScanMatcher's: a 20 km beam's grid)
            for centre in (guess, self.pose) if np.any(self.increment) else (guess,):
                reg = self._searched(points, near, centre, window, guess, reg)
        if reg.fit < cfg.min_fit:
            self.coasted += 1
            return guess
        self.searched += reg is not first
        return reg.pose

    def _searched(
        self,
        points: np.ndarray,
        near: np.ndarray,
        centre: np.ndarray,
        window: Window,
        guess: np.ndarray,
        reg: Registration,
    ) -> Registration:
        """``reg``, or the registration of ``points`` from the best pose of a correlative search of
        ``window`` around ``centre`` (of the points ``near``) if it fits better by FIT_MARGIN."""
        cfg = self.cfg
        if len(near) < 3:
            return reg
        found = search(near, self.local.points, centre, window, cfg.search_resolution, cfg.search_sigma)
        other = register(points, self.local, found.pose, cfg, prior=guess)
        return other if other.fit > reg.fit + FIT_MARGIN else reg

    def _grow_map(self, points: np.ndarray, pose: np.ndarray) -> None:
        """Add the scan to the local map when the robot moved ``map_update_*`` since the last that joined."""
        cfg = self.cfg
        last, apart_enough = self.last_map_pose, (cfg.map_update_distance, cfg.map_update_angle)
        if len(points) < 3 or (last is not None and not apart(pose, last, *apart_enough)):
            return
        self.last_map_pose = pose.copy()
        placed = transform_points(points, pose)
        self.map_points.append(placed[voxel_thin(placed, cfg.voxel)])
        pts = np.concatenate(self.map_points)
        self.local = LocalMap.build(pts[voxel_thin(pts, cfg.voxel)])

    def stats(self) -> ScanOdometryStats:
        """summary.json's ``scan_odometry``."""
        return ScanOdometryStats(
            scans=self.scans,
            searched=self.searched,
            coasted=self.coasted,
            gaps=len(self.gaps),
            seconds=round(self.seconds, 6),
        )


def with_scan_odometry(
    messages: Iterable[Scan | OdomSample],
    odometry: ScanOdometry,
    laser2base: tuple[float, float, float],
) -> Iterator[Scan | OdomSample]:
    """The scans of ``messages`` each followed by an odometry sample at its stamp, posed by ``odometry``
    (the messages' own odometry samples, if any, are left out: the run reads the scans alone)."""
    for msg in messages:
        if isinstance(msg, Scan):
            yield msg
            pose = odometry.step(transform_points(msg.points(), laser2base), msg.stamp)
            if pose is not None:
                yield OdomSample(msg.stamp, *pose)
