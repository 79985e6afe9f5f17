"""Motion correction of a scan ("deskewing"): each beam moved to where the laser was at the stamp.

A 2D laser measures its beams one after the other while its mirror turns: a Hokuyo URG-04LX takes
67 ms for its 240° (1,024 steps a 100 ms turn), a SICK LMS 7 ms for 180°. A robot turning at 1 rad/s
turns 3.8° during one URG scan, so a straight wall seen while turning comes out bent, and the scans
of a turn disagree with each other by centimetres at a few metres' range. The beams' times are
known: beam ``i`` (its index in the message) at ``stamp + i · time_increment`` (the ROS LaserScan
convention: the stamp is the first beam's time). With the robot's velocity from the odometry
(logs/sync.py, ``Synced.twist``: the body-frame mean over the 0.1 s after the stamp), each beam's end
point is moved from the laser's pose at its own time into the laser's pose at the stamp — as ROS's
laser_geometry "high fidelity" projection and KISS-ICP's deskewing do. The motion during one scan is
taken as constant (a scan lasts 7–67 ms).

The corrected scan keeps its beams' order and indices; their ranges and bearings change (bearings are
no longer exactly evenly spaced: extraction works on each beam's own bearing).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..geometry import wrap_angle
from ..types import Scan

MAX_SWEEP = 1.0  # s: a scan whose beams would span longer than this has a broken time_increment


def time_increment_problem(time_increment: float, n_beams: int) -> str:
    """Why a message's ``time_increment`` (s between beams) cannot give the times of its ``n_beams``
    beams, for a warning; "" when it can."""
    if not math.isfinite(time_increment):
        return "not a finite number"
    if abs(time_increment) * n_beams > MAX_SWEEP:
        return f"its {n_beams} beams would take longer than {MAX_SWEEP:g} s"
    return ""


def motion(twist: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(n, 3) the pose after time(s) ``t`` (n,) of constant body-frame velocity ``twist`` (vx, vy, ω)
    from the identity: θ = ωt, translation ∫₀ᵗ R(ωs) v ds = R(θ/2) · v t · sinc(θ/2) (exact)."""
    vx, vy, w = (float(v) for v in twist)
    th = w * np.asarray(t, dtype=float)
    k = np.asarray(t, dtype=float) * np.sinc(th / (2.0 * np.pi))  # t · sin(θ/2) / (θ/2)
    c, s = np.cos(0.5 * th), np.sin(0.5 * th)
    return np.column_stack((k * (c * vx - s * vy), k * (s * vx + c * vy), th))


def velocity(rel: np.ndarray, dt: float) -> np.ndarray:
    """(3,) the constant body-frame velocity (vx, vy, ω) that moves the robot by ``rel`` (x, y, θ: the
    second pose in the first's frame) in ``dt`` seconds: the inverse of :func:`motion` (SE(2)'s log)."""
    x, y, th = (float(v) for v in rel)
    k = dt * float(np.sinc(th / (2.0 * np.pi)))  # t(dt) = R(θ/2) · v · k
    c, s = math.cos(0.5 * th), math.sin(0.5 * th)
    return np.array([(c * x + s * y) / k, (-s * x + c * y) / k, th / dt])


def beam_times(scan: Scan, time_increment: float) -> np.ndarray:
    """(k,) each valid beam's time after the scan's stamp (s): its index in the message × the
    time between beams (negative for a laser whose beams run against their index)."""
    return scan.beam_index * float(time_increment)


def deskew(
    scan: Scan, twist: np.ndarray, time_increment: float, laser2base: tuple[float, float, float]
) -> Scan:
    """``scan`` with every beam's end point moved into the laser's frame at the stamp, the robot moving
    at ``twist`` (vx, vy, ω: base frame, m/s and rad/s) during it; ``laser2base`` the laser's mount.
    Returned as it is when there is nothing to correct (no time between beams, no motion)."""
    if time_increment == 0.0 or not np.any(twist) or not len(scan.ranges):
        return scan
    lx, ly, lyaw = laser2base
    cl, sl = math.cos(lyaw), math.sin(lyaw)
    # the beam end points in the base frame at the beam's own time
    a = scan.angles + lyaw
    bx, by = lx + scan.ranges * np.cos(a), ly + scan.ranges * np.sin(a)
    # ... in the base frame at the stamp: the base's pose at the beam's time, relative to the stamp's
    m = motion(twist, beam_times(scan, time_increment))
    c, s = np.cos(m[:, 2]), np.sin(m[:, 2])
    px, py = m[:, 0] + c * bx - s * by, m[:, 1] + s * bx + c * by
    # ... and in the laser's frame at the stamp
    dx, dy = px - lx, py - ly
    qx, qy = cl * dx + sl * dy, -sl * dx + cl * dy
    angles = scan.angles + wrap_angle(np.arctan2(qy, qx) - scan.angles)  # (a 360° laser's stay unwrapped)
    return dataclasses.replace(scan, ranges=np.hypot(qx, qy), angles=angles)
