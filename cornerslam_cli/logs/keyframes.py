"""Keyframe selection: which of the synchronised scans a run processes (``keyframes.*``).

:func:`select_keyframes` keeps a scan when the robot moved or turned enough since the last kept one
(gmapping's linearUpdate/angularUpdate), or enough time passed; a laser faster than
``keyframes.min_interval`` is thinned to a scan at most that often (:func:`faster_than`).
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Iterable, Iterator
from dataclasses import replace

import numpy as np

from ..geometry import wrap_angle
from .params import KeyframeConfig
from .sync import Synced, SyncStats

log = logging.getLogger(__name__)

RATE_SCANS = 21  # the scans whose median interval tells a fast laser (keyframes.min_interval)


def faster_than(stamps: list[float], interval: float) -> bool:
    """Whether scans stamped ``stamps`` come more often than every ``interval`` s, by their median
    interval (jitter, or two scans 5 ms apart now and then, does not make a 10 Hz laser fast)."""
    gaps = np.diff(stamps)
    return interval > 0.0 and len(gaps) > 0 and float(np.median(gaps)) < interval


def select_keyframes(
    pairs: Iterable[Synced], cfg: KeyframeConfig, stats: SyncStats | None = None
) -> Iterator[Synced]:
    """Keep a scan when the robot moved ``linear_update`` metres or turned ``angular_update`` radians
    since the last kept one (gmapping's linearUpdate/angularUpdate), or ``max_interval`` seconds
    passed. The first scan is always kept; with all three at 0 every scan is kept. A laser faster than
    ``min_interval`` (the median interval of its first ``RATE_SCANS`` scans: :func:`faster_than`) keeps
    a scan at most that often. A kept pair carries the odometry jumps of the pairs skipped before it."""
    every = cfg.linear_update <= 0.0 and cfg.angular_update <= 0.0 and cfg.max_interval <= 0.0
    pairs = iter(pairs)
    head = list(itertools.islice(pairs, RATE_SCANS))  # (streaming: only the first few are held)
    fast = faster_than([p.scan.stamp for p in head], cfg.min_interval)
    if fast:
        log.info("scans every %.3f s (median): one kept at most every %g s (keyframes.min_interval)",
                 float(np.median(np.diff([p.scan.stamp for p in head]))), cfg.min_interval)  # fmt: skip
    pairs = itertools.chain(head, pairs)
    last: np.ndarray | None = None
    last_t = 0.0
    jumped = False
    for pair in pairs:
        scan, pose = pair.scan, pair.odom
        jumped |= pair.odom_jump
        if fast and last is not None and scan.stamp - last_t < cfg.min_interval:
            keep = False
        elif every or last is None:
            keep = True
        else:
            moved = float(np.hypot(pose[0] - last[0], pose[1] - last[1]))
            turned = abs(float(wrap_angle(pose[2] - last[2])))
            keep = (
                (cfg.linear_update > 0.0 and moved >= cfg.linear_update)
                or (cfg.angular_update > 0.0 and turned >= cfg.angular_update)
                or (cfg.max_interval > 0.0 and scan.stamp - last_t >= cfg.max_interval)
            )
        if keep:
            last, last_t = pose, scan.stamp
            yield replace(pair, odom_jump=jumped)
            jumped = False
        elif stats is not None:
            stats.keyframes_skipped += 1
