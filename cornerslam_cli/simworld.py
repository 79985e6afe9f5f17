"""A simulated 2D world of wall segments, a vectorised ray caster and the world's true corners.

Used by the tests, the extraction benchmark and ``cornerslam simulate``. Walls have no thickness; a box
is four walls. Poses are (x, y, θ) of the sensor in the world frame; beam angles are in the sensor frame.

    world = office_world()
    angles = np.linspace(-3 * np.pi / 4, 3 * np.pi / 4, 1081)
    ranges = raycast(world, (5.0, 5.0, 0.0), angles, max_range=30.0)   # inf where nothing is hit
    seen = visible_corners(world, (5.0, 5.0, 0.0), angles, max_range=8.0)  # (c, 3) in the world frame

Over 400 lines because the world, its ray caster, its true corners and the ready-made worlds are one
vocabulary the tests and ``simulate`` use together; each part is a few short functions.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from .geometry import wrap_angle
from .types import Scan

#: two wall end points closer than this are one vertex, metres
VERTEX_TOL = 1e-6


@dataclass(frozen=True)
class World:
    """walls : (N, 2, 2) float64, wall i runs from walls[i, 0] to walls[i, 1], metres, world frame."""

    walls: np.ndarray
    name: str = ""

    def __add__(self, other: World) -> World:
        return World(np.concatenate((self.walls, other.walls)), self.name or other.name)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of all walls."""
        p = self.walls.reshape(-1, 2)
        return float(p[:, 0].min()), float(p[:, 1].min()), float(p[:, 0].max()), float(p[:, 1].max())


def make_world(walls: Iterable, name: str = "") -> World:
    """World from any iterable of ((x0, y0), (x1, y1)) walls or of (k, 2, 2) arrays."""
    parts = [np.asarray(w, dtype=float).reshape(-1, 2, 2) for w in walls]
    arr = np.concatenate(parts) if parts else np.zeros((0, 2, 2))
    keep = np.hypot(*(arr[:, 1] - arr[:, 0]).T) > VERTEX_TOL
    return World(arr[keep], name)


def _cross(a, b):
    """z component of the 2D cross product, broadcasting over leading axes."""
    a, b = np.asarray(a), np.asarray(b)
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


# --- building blocks --------------------------------------------------------------------------------------


def polyline(points: Sequence, closed: bool = False) -> np.ndarray:
    """Walls along consecutive points, (k, 2, 2)."""
    p = np.asarray(points, dtype=float)
    if closed:
        p = np.vstack((p, p[:1]))
    return np.stack((p[:-1], p[1:]), axis=1)


def wall(p: Sequence[float], q: Sequence[float], doors: Sequence[tuple[float, float]] = ()) -> np.ndarray:
    """A straight wall from p to q with door gaps, each (distance of the gap's centre from p, width)."""
    p, q = np.asarray(p, dtype=float), np.asarray(q, dtype=float)
    length = float(np.hypot(*(q - p)))
    u = (q - p) / length
    cuts = [0.0]
    for centre, width in sorted(doors):
        cuts += [max(0.0, centre - width / 2), min(length, centre + width / 2)]
    cuts.append(length)
    pieces = [
        (p + a * u, p + b * u) for a, b in zip(cuts[::2], cuts[1::2], strict=True) if b - a > VERTEX_TOL
    ]
    return np.asarray(pieces, dtype=float).reshape(-1, 2, 2)


def rectangle(cx: float, cy: float, w: float, h: float, angle: float = 0.0) -> np.ndarray:
    """Four walls of a w × h rectangle centred on (cx, cy), rotated by ``angle`` (a box, a pillar, a room)."""
    corners = np.array([[-w, -h], [w, -h], [w, h], [-w, h]]) / 2
    c, s = math.cos(angle), math.sin(angle)
    return polyline(corners @ np.array([[c, s], [-s, c]]) + (cx, cy), closed=True)


def room(
    x0: float, y0: float, x1: float, y1: float, doors: dict[str, Sequence[tuple[float, float]]] | None = None
):
    """Axis-aligned room walls; ``doors`` maps a side ('S', 'E', 'N', 'W') to its door gaps (see ``wall``)."""
    doors = doors or {}
    sides = {
        "S": ((x0, y0), (x1, y0)),
        "E": ((x1, y0), (x1, y1)),
        "N": ((x1, y1), (x0, y1)),
        "W": ((x0, y1), (x0, y0)),
    }
    return np.concatenate([wall(p, q, doors.get(k, ())) for k, (p, q) in sides.items()])


# --- ray casting ------------------------------------------------------------------------------------------


def raycast(
    world: World, pose: Sequence[float] | np.ndarray, angles: np.ndarray, max_range: float = np.inf
) -> np.ndarray:
    """Range of the first wall hit along each beam, (k,) metres; inf where nothing within ``max_range``.

    pose : (x, y, θ) of the sensor in the world frame, or (k, 3) one per beam (a laser that moves while
    it sweeps);  angles : (k,) beam bearings in the sensor frame.
    Vectorised over beams × walls: solve o + t·d = a + s·(b − a) for t > 0, s in [0, 1].
    """
    angles = np.asarray(angles, dtype=float)
    if len(world.walls) == 0 or angles.size == 0:
        return np.full(angles.shape, np.inf)
    ox, oy, oth = (v[:, None] if np.ndim(v) else float(v) for v in np.asarray(pose, dtype=float).T)
    dx, dy = np.cos(angles[:, None] + oth), np.sin(angles[:, None] + oth)
    a = world.walls[:, 0]
    ex, ey = (world.walls[:, 1] - a).T
    ax, ay = a[:, 0] - ox, a[:, 1] - oy
    den = dx * ey - dy * ex  # cross(d, e)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ax * ey - ay * ex) / den  # cross(a − o, e) / cross(d, e)
        s = (ax * dy - ay * dx) / den  # cross(a − o, d) / cross(d, e)
        hit = (np.abs(den) > 1e-12) & (t > 1e-9) & (s >= -1e-12) & (s <= 1 + 1e-12)
    t = np.where(hit, t, np.inf).min(axis=1)
    return np.where(t <= max_range, t, np.inf)


def scan_from_ranges(
    ranges: np.ndarray,
    angles: np.ndarray,
    range_min: float = 0.02,
    range_max: float = 30.0,
    stamp: float = 0.0,
) -> Scan:
    """A :class:`Scan` keeping the beams with a finite range inside [range_min, range_max]."""
    ranges, angles = np.asarray(ranges, dtype=float), np.asarray(angles, dtype=float)
    valid = np.isfinite(ranges) & (ranges >= range_min) & (ranges <= range_max)
    inc = float(np.median(np.diff(angles))) if len(angles) > 1 else 0.0
    return Scan(
        stamp=stamp,
        ranges=ranges[valid],
        angles=angles[valid],
        beam_index=np.flatnonzero(valid).astype(np.int64),
        n_beams=len(ranges),
        range_min=range_min,
        range_max=range_max,
        angle_increment=inc,
    )


def simulate_scan(
    world: World,
    pose: Sequence[float],
    angles: np.ndarray,
    max_range: float = 30.0,
    sigma_range=None,
    sigma_bearing: float = 0.0,
    rng: np.random.Generator | None = None,
    range_min: float = 0.02,
    stamp: float = 0.0,
) -> Scan:
    """Ray-cast a scan and add Gaussian noise: ρ += N(0, σρ(ρ)²) with ``sigma_range`` a float or a callable
    of the true range, and the true bearing θ + N(0, σθ²) (the reported bearing stays nominal)."""
    angles = np.asarray(angles, dtype=float)
    rng = rng if rng is not None else np.random.default_rng(0)
    true_angles = angles + (rng.normal(0.0, sigma_bearing, angles.shape) if sigma_bearing > 0 else 0.0)
    ranges = raycast(world, pose, true_angles, max_range)
    if sigma_range is not None:
        sig = (
            sigma_range(np.where(np.isfinite(ranges), ranges, 0.0)) if callable(sigma_range) else sigma_range
        )
        ranges = ranges + rng.normal(0.0, 1.0, ranges.shape) * sig
    return scan_from_ranges(ranges, angles, range_min, max_range, stamp)


# --- true corners -----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TrueCorners:
    """Physical corners of a world, one per wedge of free space between two walls meeting at a point.

    z : (c, 3) (x, y, φ) world frame, φ = π − (angle of the wedge between the two walls), the angle between
        the lines' normals the extractor reports, the same whichever side both walls are seen from
    arms : (c, 2, 2) unit directions from the corner along each of the two walls
    arm_len : (c, 2) length of wall along each arm, metres
    """

    z: np.ndarray
    arms: np.ndarray
    arm_len: np.ndarray

    def __len__(self) -> int:
        return len(self.z)


def corner_table(world: World, min_angle: float = math.radians(20.0)) -> TrueCorners:
    """Every point where walls meet (end to end, or an end on another wall), split into its wedges.

    At a meeting point the arms (directions along the walls away from it) are sorted by angle; each wedge
    between consecutive arms narrower than π − min_angle is a corner. With only two arms the two wedges
    describe one physical corner (concave one side, convex the other), so only the narrower is listed.
    Flat joints (wedge ≈ π) and crossings' reflex wedges are not corners.
    """
    walls = world.walls
    pts: list[np.ndarray] = []
    for i, (a, b) in enumerate(walls):
        for p in (a, b):
            pts.append(p)
        # ends of other walls lying inside wall i
        e = b - a
        L2 = float(e @ e)
        t = ((walls.reshape(-1, 2) - a) @ e) / L2
        d = np.abs(_cross(e, walls.reshape(-1, 2) - a)) / math.sqrt(L2)
        inside = (t > 1e-9) & (t < 1 - 1e-9) & (d < VERTEX_TOL)
        inside[2 * i : 2 * i + 2] = False
        pts.extend(walls.reshape(-1, 2)[inside])
    if not pts:
        return TrueCorners(np.zeros((0, 3)), np.zeros((0, 2, 2)), np.zeros((0, 2)))
    pts_arr = np.asarray(pts)
    # unique meeting points
    uniq: list[np.ndarray] = []
    for p in pts_arr:
        if not any(np.hypot(*(p - q)) < 1e-6 for q in uniq):
            uniq.append(p)
    z, arms, lens = [], [], []
    for c in uniq:
        arm_dirs, arm_lens = [], []
        for a, b in walls:
            e = b - a
            L = float(np.hypot(*e))
            t = float((c - a) @ e) / L**2
            if abs(float(_cross(e, c - a))) / L > VERTEX_TOL or t < -1e-9 or t > 1 + 1e-9:
                continue
            if t * L > VERTEX_TOL:  # arm towards a
                arm_dirs.append(-e / L)
                arm_lens.append(t * L)
            if (1 - t) * L > VERTEX_TOL:  # arm towards b
                arm_dirs.append(e / L)
                arm_lens.append((1 - t) * L)
        if len(arm_dirs) < 2:
            continue
        ang = np.arctan2(np.asarray(arm_dirs)[:, 1], np.asarray(arm_dirs)[:, 0])
        order = np.argsort(ang)
        wedges = np.diff(np.append(ang[order], ang[order][0] + 2 * np.pi))
        pairs = [(order[k], order[(k + 1) % len(order)], wedges[k]) for k in range(len(order))]
        if len(arm_dirs) == 2:
            pairs = [min(pairs, key=lambda p: p[2])]
        for i, j, wedge in pairs:
            if wedge < math.pi - min_angle and wedge > min_angle:
                z.append((c[0], c[1], math.pi - wedge))
                arms.append((arm_dirs[i], arm_dirs[j]))
                lens.append((arm_lens[i], arm_lens[j]))
    return TrueCorners(
        np.asarray(z).reshape(-1, 3), np.asarray(arms).reshape(-1, 2, 2), np.asarray(lens).reshape(-1, 2)
    )


def true_corners(world: World) -> np.ndarray:
    """(c, 3) physical corners (x, y, φ) where two walls meet, world frame (see ``corner_table``)."""
    return corner_table(world).z


def visible_corners(
    world: World,
    pose: Sequence[float],
    angles: np.ndarray,
    max_range: float,
    arm: float = 0.5,
    min_incidence: float = math.radians(15.0),
    tol: float = 1e-3,
) -> np.ndarray:
    """(c, 3) true corners (x, y, φ), world frame, that a sensor at ``pose`` sees with both walls.

    A corner counts when its point and probe points along each of its two walls (out to ``arm`` metres,
    or 90 % of a shorter wall) are in the field of view of ``angles`` and within ``max_range``, have a clear
    line of sight (the ray cast reaches them within ``tol``), and each wall is seen at an incidence of at
    least ``min_incidence`` (grazing walls give no segment). When more than two walls meet at the point the
    sensor must also lie in the corner's wedge.
    """
    tc = corner_table(world)
    if len(tc) == 0:
        return np.zeros((0, 3))
    angles = np.asarray(angles, dtype=float)
    o = np.asarray(pose[:2], dtype=float)
    th = float(pose[2])
    fracs = np.array([0.0, 0.1, 0.3, 0.6, 1.0])
    keep = np.ones(len(tc), dtype=bool)
    for c_i in range(len(tc)):
        c = tc.z[c_i, :2]
        probes = [c]
        for k in range(2):
            reach = min(arm, 0.9 * tc.arm_len[c_i, k])
            probes += [c + f * reach * tc.arms[c_i, k] for f in fracs[1:]]
            v = c + 0.5 * reach * tc.arms[c_i, k] - o
            sin_inc = abs(float(_cross(tc.arms[c_i, k], v))) / max(float(np.hypot(*v)), 1e-12)
            if sin_inc < math.sin(min_incidence):
                keep[c_i] = False
        P = np.asarray(probes) - o
        dist = np.hypot(P[:, 0], P[:, 1])
        bearing = np.arctan2(P[:, 1], P[:, 0]) - th
        bearing = wrap_angle(bearing)
        if np.any(dist > max_range) or np.any(bearing < angles.min()) or np.any(bearing > angles.max()):
            keep[c_i] = False
            continue
        hits = np.array([raycast(world, (o[0], o[1], 0.0), np.array([b + th]))[0] for b in bearing])
        if np.any(hits < dist - tol):
            keep[c_i] = False
            continue
        # the sensor must be inside the wedge when the point has more than two arms (T junctions)
        a0, a1 = tc.arms[c_i]
        to_s = o - c
        if float(_cross(a0, a1)) > 0:  # wedge runs counter-clockwise from a0 to a1
            inside = float(_cross(a0, to_s)) >= 0 and float(_cross(to_s, a1)) >= 0
        else:
            inside = float(_cross(a0, to_s)) <= 0 and float(_cross(to_s, a1)) <= 0
        n_arms_here = np.sum(np.hypot(*(tc.z[:, :2] - c).T) < 1e-6)
        if n_arms_here > 1 and not inside:
            keep[c_i] = False
    return tc.z[keep]


# --- ready-made worlds --------------------------------------------------------------------------------------


def office_world() -> World:
    """About 30 × 20 m: a 2 m corridor loop around a central block of rooms, rooms outside it, doors and
    clutter boxes (in the corridor, clear of its centre line, and in the rooms).

    The corridor centre line is the loop ``OFFICE_LOOP`` (a rectangle from (5, 5) to (25, 15)).
    """
    walls = [
        room(0, 0, 30, 20),  # outer shell
        # corridor's outer edge, doors into the outer rooms
        wall((4, 4), (26, 4), [(3.0, 1.0), (9.0, 1.0), (15.0, 1.0), (19.5, 1.0)]),
        wall((26, 4), (26, 16), [(6.0, 1.0)]),
        wall((26, 16), (4, 16), [(2.0, 1.0), (8.0, 1.0), (14.0, 1.0), (20.0, 1.0)]),
        wall((4, 16), (4, 4), [(6.0, 1.0)]),
        # outer rooms' dividers (T junctions with the shell and the corridor)
        polyline([(10, 0), (10, 4)]),
        polyline([(16, 0), (16, 4)]),
        polyline([(21, 0), (21, 4)]),
        polyline([(9, 16), (9, 20)]),
        polyline([(15, 16), (15, 20)]),
        polyline([(21, 16), (21, 20)]),
        polyline([(0, 4), (4, 4)]),
        polyline([(0, 16), (4, 16)]),
        polyline([(26, 4), (30, 4)]),
        polyline([(26, 16), (30, 16)]),
        # central block, doors to the corridor, a divider with a door
        wall((6, 6), (24, 6), [(4.0, 1.0), (14.0, 1.2)]),
        wall((24, 6), (24, 14), [(3.0, 1.0)]),
        wall((24, 14), (6, 14), [(9.0, 1.2)]),
        wall((6, 14), (6, 6), []),
        wall((15, 6), (15, 14), [(4.0, 1.0)]),
        polyline([(6, 10), (10.5, 10)]),
        # clutter in the corridor, clear of the centre line
        rectangle(9.0, 4.4, 1.0, 0.5),
        rectangle(25.6, 9.0, 0.5, 0.8),
        rectangle(18.0, 15.6, 1.2, 0.5),
        rectangle(4.4, 12.0, 0.5, 0.6),
        # clutter in the rooms: boxes, a rotated crate, pillars
        rectangle(12.0, 8.0, 1.0, 0.6),
        rectangle(20.0, 11.0, 0.8, 0.8, math.radians(30.0)),
        rectangle(2.0, 10.0, 0.4, 0.4),
        rectangle(28.0, 12.0, 0.4, 0.4),
        rectangle(6.5, 18.5, 1.0, 0.6, math.radians(-20.0)),
        rectangle(13.0, 2.0, 0.8, 0.8),
        rectangle(24.0, 2.0, 1.2, 0.6),
    ]
    return make_world(walls, "office")


#: corridor centre line of ``office_world`` (closed loop, metres)
OFFICE_LOOP = np.array([(5.0, 5.0), (25.0, 5.0), (25.0, 15.0), (5.0, 15.0)])


def corridor_world(length: float = 20.0, width: float = 2.0) -> World:
    """A straight corridor along x with side openings and a few boxes: a simple, feature-poor world."""
    walls = [
        wall((0, 0), (length, 0), [(length * 0.3, 1.0), (length * 0.7, 1.0)]),
        wall((length, width), (0, width), [(length * 0.5, 1.0)]),
        polyline([(0, 0), (0, width)]),
        polyline([(length, 0), (length, width)]),
        rectangle(length * 0.45, 0.3, 0.6, 0.4),
        rectangle(length * 0.8, width - 0.3, 0.6, 0.4),
    ]
    return make_world(walls, "corridor")


WORLDS = {"office": office_world, "corridor": corridor_world}


def path_poses(waypoints: np.ndarray, step: float, closed: bool = True) -> np.ndarray:
    """Poses (x, y, θ), (k, 3), every ``step`` metres along the polyline ``waypoints``, heading along it."""
    wp = np.asarray(waypoints, dtype=float)
    if closed:
        wp = np.vstack((wp, wp[:1]))
    seg = np.diff(wp, axis=0)
    seg_len = np.hypot(seg[:, 0], seg[:, 1])
    cum = np.concatenate(([0.0], np.cumsum(seg_len)))
    s = np.arange(0.0, cum[-1], step)
    i = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1)
    f = (s - cum[i]) / seg_len[i]
    xy = wp[i] + f[:, None] * seg[i]
    return np.column_stack((xy, np.arctan2(seg[i, 1], seg[i, 0])))
