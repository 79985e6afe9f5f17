"""Trajectory accuracy: ATE after SE(2) alignment, RPE, and the Kümmerle et al. 2009 relation metric.

All functions take 2D trajectories as ``stamps (n,)`` and ``poses (n, 3)`` = (x, y, θ).

Over 400 lines because scoring and saying why a reference cannot score (:func:`overlap_problem`, the
coverage and sparseness notes) share the span and gap rules (``in_holes``, ``GAP_*``), and
:func:`evaluate_files` uses both: split, the two halves would import each other.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .errors import LogError, display_path
from .geometry import interpolate, relative, wrap_angle
from .report.tables import read_tum
from .results import Accuracy, Ate, RelationError, Rpe
from .textfile import read_number_rows, refuse_far

log = logging.getLogger("cornerslam.evaluate")


def inside_span(stamps: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Mask of the times ``t`` within [stamps[0], stamps[-1]]: those a trajectory can be interpolated at."""
    t = np.asarray(t, dtype=float)
    return (t >= stamps[0]) & (t <= stamps[-1])


GT_NEAR = 0.01  # s: a time this close to a ground-truth pose is scored whatever the gaps (evo's max_diff)
GAP_FACTOR = 10.0  # a ground-truth gap longer than this many times its median spacing ...
GAP_MIN = 1.0  # s: ... and than this is a hole, not interpolated across


def bracket(stamps: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The poses' ``stamps`` (sorted, two or more) either side of each time ``t``: (before, after) — the
    first two or the last two for a time outside their span."""
    j = np.clip(np.searchsorted(stamps, t), 1, len(stamps) - 1)
    return stamps[j - 1], stamps[j]


def in_holes(stamps: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Mask of the times ``t`` inside a hole of a ground truth with poses at ``stamps`` (sorted): a gap
    longer than ``GAP_FACTOR`` × its median spacing and ``GAP_MIN`` (a motion capture that lost the
    robot, a recorder stopped), more than ``GT_NEAR`` from both its ends. Interpolating there scores
    against a straight line the robot did not drive. A reference with poses only where the robot moved
    (radish: one per scan) has long gaps too, but a trajectory of those scans has its stamps on its
    poses, and those are scored. A time outside the ground truth's span is in no hole (it is outside)."""
    t = np.asarray(t, dtype=float)
    if len(stamps) < 2:
        return np.zeros(len(t), dtype=bool)
    longest = max(GAP_MIN, GAP_FACTOR * float(np.median(np.diff(stamps))))
    before, after = bracket(stamps, t)
    near = (np.abs(t - before) <= GT_NEAR) | (np.abs(after - t) <= GT_NEAR)
    return (after - before > longest) & ~near & inside_span(stamps, t)


def scorable(stamps: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Mask of the times ``t`` a ground truth with poses at ``stamps`` scores: within its span or
    ``GT_NEAR`` of its ends (as evo matches a pose within its max_diff), not in a hole (:func:`in_holes`)."""
    t = np.asarray(t, dtype=float)
    near_span = (t >= stamps[0] - GT_NEAR) & (t <= stamps[-1] + GT_NEAR)
    return near_span & ~in_holes(stamps, t)


def interpolate_inside(stamps: np.ndarray, poses: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The trajectory (``stamps``, ``poses``) at the times ``t`` it scores (:func:`scorable`): (mask of
    those t, their poses (k, 3), interpolated by :func:`~cornerslam_cli.geometry.interpolate`; a time
    just outside the span takes the end's pose)."""
    inside = scorable(stamps, t)
    at = np.clip(np.asarray(t, dtype=float)[inside], stamps[0], stamps[-1])
    return inside, interpolate(stamps, poses, at)


def align_se2(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray]:
    """Rotation angle and translation minimising Σ‖R·src_i + t − dst_i‖² (Umeyama, no scale).

    src, dst : (n, 2) corresponding points.
    """
    ms, md = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - ms, dst - md
    # for 2D rotations the optimum has a closed form: θ = atan2(Σ a×b, Σ a·b)
    ang = float(np.arctan2(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]), np.sum(a * b)))
    c, s = np.cos(ang), np.sin(ang)
    R = np.array([[c, -s], [s, c]])
    return ang, md - R @ ms


def align_sim2(src: np.ndarray, dst: np.ndarray) -> tuple[float, float, np.ndarray]:
    """Scale s, rotation angle and translation minimising Σ‖s·R·src_i + t − dst_i‖² (Umeyama with
    scale, evo's ``--correct_scale``): the rotation is :func:`align_se2`'s, s = Σ (R·a_i)·b_i / Σ‖a_i‖²
    over the centred points. s > 1: ``src`` is smaller than ``dst``. A diagnostic: a 2-D laser's
    trajectory has its scale from the ranges, so a scale off 1 says the ranges and the reference disagree.

    Raises ``LogError`` when ``src`` is all one point (Σ‖a_i‖² = 0): no scale fits it, and a NaN is not
    a score; likewise when ``dst`` is (a reference that does not move): s would be 0, every pose
    shrunk onto its point, and the ATE a perfect 0.
    """
    ang, _ = align_se2(src, dst)
    ms, md = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - ms, dst - md
    spread = float(np.sum(a * a))
    if not spread > 0.0:
        raise LogError(
            "the trajectory's positions are all one point (it does not move): no scale fits it",
            "evaluate it without --correct-scale",
        )
    if not float(np.sum(b * b)) > 0.0:
        raise LogError(
            "the ground truth's positions at the trajectory's stamps are all one point (it does not "
            "move): no scale fits the trajectory to it",
            "evaluate it without --correct-scale",
        )
    c, s = np.cos(ang), np.sin(ang)
    ra = a @ np.array([[c, s], [-s, c]])  # R·a_i as rows
    scale = float(np.sum(ra * b)) / spread
    return scale, ang, md - scale * (np.array([[c, -s], [s, c]]) @ ms)


def apply_se2(ang: float, t: np.ndarray, poses: np.ndarray) -> np.ndarray:
    c, s = np.cos(ang), np.sin(ang)
    xy = poses[:, :2] @ np.array([[c, s], [-s, c]]) + t
    return np.column_stack((xy, wrap_angle(poses[:, 2] + ang)))


def ate(
    est_t: np.ndarray, est: np.ndarray, gt_t: np.ndarray, gt: np.ndarray, correct_scale: bool = False
) -> Ate:
    """Absolute trajectory error of ``est`` against ``gt`` (interpolated at est's stamps, except in
    its holes: :func:`in_holes`, counted), after SE(2) alignment: RMSE, mean, max of the position
    error (m) and RMSE of the heading error (rad). With ``correct_scale`` after the best similarity
    instead (:func:`align_sim2`, evo's ``--correct_scale``), its scale given: a diagnostic of the
    ranges' scale against the reference's, not a 2-D laser's ATE."""
    inside, g = interpolate_inside(gt_t, gt, est_t)
    e = est[inside]
    holes = int(np.count_nonzero(in_holes(gt_t, est_t))) or None  # (absent when none)
    if len(e) < 2:
        return Ate(n=int(len(e)), rmse=float("nan"), mean=float("nan"), max=float("nan"), in_holes=holes)
    scale = None
    if correct_scale:
        scale, ang, t = align_sim2(e[:, :2], g[:, :2])
        e = np.column_stack((scale * e[:, :2], e[:, 2]))
    else:
        ang, t = align_se2(e[:, :2], g[:, :2])
    ea = apply_se2(ang, t, e)
    d = np.linalg.norm(ea[:, :2] - g[:, :2], axis=1)
    dth = wrap_angle(ea[:, 2] - g[:, 2])
    return Ate(
        n=int(len(e)),
        rmse=float(np.sqrt(np.mean(d**2))),
        mean=float(np.mean(d)),
        max=float(np.max(d)),
        rot_rmse=float(np.sqrt(np.mean(dth**2))),
        scale=scale,
        in_holes=holes,
    )


def rpe(est_t: np.ndarray, est: np.ndarray, gt_t: np.ndarray, gt: np.ndarray, delta_m: float = 1.0) -> Rpe:
    """Relative pose error. Per step: RMSE of the translational error of consecutive relative poses.
    Per metre: mean translational error of relative poses spanning ``delta_m`` metres of ground-truth
    path, divided by that span (m/m). Only pairs with no unscored pose between them (one in a hole of the
    ground truth, :func:`in_holes`): a pair across a hole is no step of the robot's the reference saw."""
    inside, g = interpolate_inside(gt_t, gt, est_t)
    e = est[inside]
    nan = float("nan")
    left_out = np.cumsum(~inside)[inside]  # unscored poses before each scored one
    steps = np.flatnonzero(left_out[1:] == left_out[:-1])  # consecutive pairs none lies between
    if len(steps) == 0:
        return Rpe(rpe_step_rmse=nan, rpe_step_rot_rmse=nan, rpe_per_m=nan)
    err = relative(relative(g[steps], g[steps + 1]), relative(e[steps], e[steps + 1]))
    step_rmse = float(np.sqrt(np.mean(np.sum(err[:, :2] ** 2, axis=1))))
    step_rot_rmse = float(np.sqrt(np.mean(err[:, 2] ** 2)))
    per_m = nan
    dist = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(g[:, :2], axis=0), axis=1))))
    j = np.searchsorted(dist, dist + delta_m)
    ok = j < len(g)
    ok[ok] &= left_out[ok] == left_out[j[ok]]
    if np.any(ok):
        i, j = np.nonzero(ok)[0], j[ok]
        span = dist[j] - dist[i]
        err = relative(relative(g[i], g[j]), relative(e[i], e[j]))
        per_m = float(np.mean(np.linalg.norm(err[:, :2], axis=1) / span))
    return Rpe(rpe_step_rmse=step_rmse, rpe_step_rot_rmse=step_rot_rmse, rpe_per_m=per_m)


RELATIONS_LAYOUT = "t1 t2 x y z roll pitch yaw"
# |q|² − 1 of every line within this: a TUM trajectory (4 decimals or more) given as relations
TUM_LIKE_NORM = 1e-3


def read_relations(path: str | Path, warn: Callable[..., None] = log.warning) -> np.ndarray:
    """Kümmerle relations file: rows ``t1 t2 x y z roll pitch yaw`` → (k, 5) [t1, t2, x, y, yaw].

    Each row stands alone, so their order does not matter; a binary file, a line that is not 8
    finite numbers (more are ignored), a file without relations or a TUM trajectory (every line's last
    four numbers a unit quaternion) raises ``LogError``; what is odd but usable is said with ``warn``."""
    v, lines = read_number_rows(
        path, "relations file", LogError, "relation", RELATIONS_LAYOUT, 8, more_ok=True
    )
    refuse_far(v, lines, [2, 3, 4], f"relations file '{path}'", LogError, RELATIONS_LAYOUT, stamps=[0, 1])
    q = v[:, 4:8]
    if len(v) >= 2 and np.all(np.abs(np.einsum("ij,ij->i", q, q) - 1.0) < TUM_LIKE_NORM):
        # every row's last four numbers a unit quaternion: z roll pitch yaw would need |yaw| = 1 on each
        raise LogError(
            f"relations file '{path}' looks like a TUM trajectory (stamp x y z qx qy qz qw: the last four "
            f"numbers of each line are a unit quaternion, not z roll pitch yaw)",
            f"give it as --ground-truth; a relations file has lines {RELATIONS_LAYOUT}",
        )
    r = v[:, [0, 1, 2, 3, 7]]
    first = np.sort(np.unique(r, axis=0, return_index=True)[1])  # each distinct row's first line, in order
    if len(first) < len(r):  # a file joined to itself, a line pasted twice: each relation counts once
        warn(
            "relations file '%s': %d of its %d relations repeat an earlier line exactly: counted once",
            path, len(r) - len(first), len(r),
        )  # fmt: skip
        r = r[first]
    pairs = np.unique(r[:, :2], axis=0)
    if len(pairs) < len(r):  # one pair measured twice, differently: both are scored, but say so
        warn(
            "relations file '%s': %d of its %d relations repeat an earlier pair (t1, t2) with other values: "
            "each is scored", path, len(r) - len(pairs), len(r),
        )  # fmt: skip
    for note in relations_notes(r):
        warn("relations file '%s': %s", path, note)
    return r


def relations_notes(r: np.ndarray) -> list[str]:
    """What looks wrong in relations ``r`` (k, 5) [t1, t2, x, y, yaw] without making them unusable:
    pairs of one instant (t1 = t2: a zero motion that scores the estimate's noise, not its drift), and
    yaws beyond ±π (degrees, or not wrapped: the rotation error is taken as given)."""
    notes = []
    if n := int(np.count_nonzero(r[:, 0] == r[:, 1])):
        notes.append(f"{n} of its {len(r)} relations join an instant to itself (t1 = t2): scored as they are")
    if n := int(np.count_nonzero(np.abs(r[:, 4]) > np.pi + 1e-6)):
        notes.append(
            f"{n} of its {len(r)} relations have a yaw beyond ±π rad (degrees? the layout is "
            f"{RELATIONS_LAYOUT}, angles in radians): their rotation errors are taken as given"
        )
    return notes


def overlap_problem(
    est_t: np.ndarray, gt_t: np.ndarray, gt_name: str, est_name: str = "the trajectory", clocks: str = ""
) -> tuple[str, str] | None:
    """Why ``gt_name`` (stamps ``gt_t``, sorted) cannot score a trajectory with stamps ``est_t``, and
    what to do about it, or None: ATE and RPE need at least two trajectory poses within the ground
    truth's time span. Stamps in nanoseconds (micro-, milli-) on either side are named so: a ROS
    exporter's, the trajectory's too (``est_name``: an ``evaluate`` of a file a user brings).
    ``clocks``: said when the two do not overlap at all (which clock the trajectory is on)."""
    if len(est_t) < 2:  # not a matter of overlap: "1 of its 1 poses fall within" read as a contradiction
        why = f"the trajectory has a single pose: ATE and RPE against {gt_name} need two or more"
        return why, "process more scans"
    if len(gt_t) < 2:  # a one-line file: its "time span" is an instant, no overlap to speak of
        return f"{gt_name} has a single pose: ATE and RPE need two or more", "give the whole ground truth"
    n = _within(est_t, gt_t)
    holes = int(np.count_nonzero(in_holes(gt_t, est_t)))
    if n - holes >= 2:
        return None
    if n >= 2:
        why = (
            f"{gt_name} has no pose near the trajectory's: {holes} of the {n} poses within its time span "
            f"fall in its gaps (longer than {GAP_FACTOR:g} times its median spacing and {GAP_MIN:g} s), "
            "where it is not interpolated"
        )
        return why, "give a ground truth with poses throughout the trajectory"
    units = (
        ()
        if _same_unit(est_t, gt_t)
        else (("nanoseconds", 1e9), ("microseconds", 1e6), ("milliseconds", 1e3))
    )
    maybe = ""  # a unit the stamps read as on weak evidence (:func:`_surely`): said beside two clocks
    for unit, scale in units:
        if _reads_as(gt_t / scale, est_t):
            why = (  # a ROS exporter's integer stamps: TUM's are seconds
                f"{gt_name} has its stamps in {unit}, not seconds ({gt_t[0]:.0f} to {gt_t[-1]:.0f}; "
                f"the trajectory {est_t[0]:.3f} to {est_t[-1]:.3f} s)"
            )
            if _surely(gt_t / scale, est_t):
                return why, UNIT_HINT
            maybe = maybe or f"{gt_name}'s stamps read in {unit} fall within the trajectory's span"
        if _reads_as(est_t / scale, gt_t):
            why = (
                f"{est_name} has its stamps in {unit}, not seconds ({est_t[0]:.0f} to {est_t[-1]:.0f}; "
                f"{gt_name} {gt_t[0]:.3f} to {gt_t[-1]:.3f} s)"
            )
            if _surely(est_t / scale, gt_t):
                return why, UNIT_HINT
            maybe = maybe or f"{est_name}'s stamps read in {unit} fall within the ground truth's span"
    why = (
        f"{gt_name} does not overlap the trajectory: {n} of its {len(est_t)} poses fall within the "
        f"ground truth's time span ({gt_t[0]:.3f} to {gt_t[-1]:.3f} s; trajectory {est_t[0]:.3f} to "
        f"{est_t[-1]:.3f} s)"
    )
    if (est_t[0] >= EPOCH_STAMPS) != (gt_t[0] >= EPOCH_STAMPS):  # one on a wall clock, one from ~0
        wall, other = (est_name, gt_name) if est_t[0] >= EPOCH_STAMPS else (gt_name, est_name)
        why += f": {wall} is stamped in wall-clock time (seconds since 1970), {other} is not — two clocks"
    if clocks:
        why += f" — {clocks}"
    if maybe:
        why += f" (or a unit: {maybe})"
    return why, "is it this log's ground truth? Its stamps must use the log's clock"


def mirror_problem(
    est_t: np.ndarray,
    est: np.ndarray,
    gt_t: np.ndarray,
    gt: np.ndarray,
    gt_name: str,
    est_name: str,
    from_scans: bool = False,
) -> tuple[str, str] | None:
    """Why ``gt_name`` cannot score ``est_name`` when it is in a mirrored frame — z down (NED/FRD, as
    PX4/MAVROS and many motion-capture setups write it): its y and yaw the negative of a z-up frame's —, and
    what to do; else None. No rotation in the plane undoes a mirror, and its ATE came out hundreds of times
    evo's, whose 3-D fit turns it over (an evo-user probe). Told by the turns, step by step: a mirror
    turns the other way at every step, a heading drift only adds to each (a review: a drifting estimate
    fitted a bent corridor better mirrored). Said when, over MIRROR_TURNS rad of the ground truth's turns
    or more, the steps' turns agree MIRRORED times better negated than as they are. ``from_scans``:
    ``est`` was made from the scans alone (input.odometry: scans), which a laser taken upright when it is
    upside down, or the other way, mirrors as much: both causes are named."""
    inside, g = interpolate_inside(gt_t, gt, est_t)
    ours, theirs = (wrap_angle(np.diff(p[:, 2])) for p in (est[inside], g))
    if np.abs(theirs).sum() < MIRROR_TURNS:
        return None
    # (each difference wrapped too: turns of 179° and -179° differ by 2°, not 358° — a probe)
    as_is, mirrored = (float(np.mean(wrap_angle(ours + sign * theirs) ** 2)) for sign in (-1.0, 1.0))
    if not as_is > MIRRORED * mirrored:
        return None
    turns = (
        f"turns the other way at its steps (their turns differ by {np.degrees(np.sqrt(as_is)):.2f}° RMS, "
        f"negated by {np.degrees(np.sqrt(mirrored)):.2f}°)"
    )
    convert = "convert it to a z-up frame by negating its y and yaw: ROS REP 103's, x forward and y left"
    if not from_scans:
        return f"{gt_name} is in a mirrored frame (z down: NED/FRD?): {est_name} {turns}", convert
    causes = (
        "a laser upside down taken as upright, or the other way (input.laser.upside_down, the tf's roll), or "
        "a ground truth in a z-down frame (NED/FRD)"
    )
    return f"{gt_name} and {est_name} are mirrored ({causes}): {est_name} {turns}", (
        f"check the laser's mount; if it is right, {convert}"
    )


def units_problem(
    est_t: np.ndarray, est: np.ndarray, gt_t: np.ndarray, gt: np.ndarray, gt_name: str, est_name: str
) -> tuple[str, str] | None:
    """Why ``gt_name`` cannot score the trajectory when one of the two is in centimetres or millimetres
    (over the same stamps its path, and the extent of its poses, 100 or 1000 times the other's, within
    UNITS_TOLERANCE), and what to do; else None. A ground truth in mm scored an ATE of 18 km with no word
    (an evo-user probe). The extent too: the jitter of a robot standing still makes paths of any ratio; and
    the shorter path UNITS_MIN_PATH or more: a run stuck in place against a moving ground truth is no unit
    (a review)."""
    inside, g = interpolate_inside(gt_t, gt, est_t)
    e = est[inside]
    ours, theirs = (float(np.hypot(*np.diff(p[:, :2], axis=0).T).sum()) for p in (e, g))
    our_extent, their_extent = (float(np.hypot(*np.ptp(p[:, :2], axis=0))) for p in (e, g))
    if min(ours, theirs) < UNITS_MIN_PATH or min(our_extent, their_extent) <= 0.0:
        return None
    sides = (  # (the one that goes farther, the other, their paths, the ratio of their extents)
        ("the ground truth", est_name, theirs, ours, their_extent / our_extent),
        (est_name, "the ground truth", ours, theirs, our_extent / their_extent),
    )
    for unit, factor in (("millimetres", 1e3), ("centimetres", 1e2)):
        for far, near, a, b, extent in sides:
            if max(abs(np.log10(a / b / factor)), abs(np.log10(extent / factor))) <= UNITS_TOLERANCE:
                why = (
                    f"{gt_name} and {est_name} are in different units: over the same stamps {far} goes "
                    f"{a / b:.4g} times as far as {near} ({a:.4g} against {b:.4g}) — {unit}?"
                )
                return why, "write both in metres, or score with evaluate --correct-scale"
    return None


UNITS_TOLERANCE = 0.15  # decades: a path 100 or 1000 times the other's within ×1.4 is read as cm or mm
# a ground truth is read as mirrored when, over this many rad of its turns, the steps' turns agree this many
# times better (mean square) negated than as they are
MIRROR_TURNS, MIRRORED = 1.0, 3.0
UNITS_MIN_PATH = 0.5  # m: the shorter path of the two at least (a run stuck in place is no unit)
FASTEST_POSES = 1e-5  # s: the closest spacing stamps are taken to have (ns since 1970 as floats: 256 ns)
DENSER = 300.0  # stamps read in another unit this many times denser than the other file's: weak evidence
UNIT_HINT = "write its stamps in seconds"
EPOCH_STAMPS = 1e8  # s: stamps from here on (1973) are read as wall-clock time
SAME_SPAN = 2.0  # two files' time spans this close in length are in one unit


def _reads_as(scaled: np.ndarray, other: np.ndarray) -> bool:
    """Whether stamps ``scaled`` (one file's, divided by a unit's scale) read as the same clock as
    ``other``'s: two or more within its span, ≥ FASTEST_POSES apart (seconds since 1970 as µs fall in a
    half-hour span from 0)."""
    return _within(scaled, other) >= 2 and _spacing(scaled) >= FASTEST_POSES


def _surely(scaled: np.ndarray, other: np.ndarray) -> bool:
    """Whether stamps ``scaled`` that :func:`_reads_as` ``other``'s clock do so on good evidence: two or
    more of ``other``'s within their span too, and no more than DENSER times as dense. Else a clock
    offset fits as well (a ground truth 100,000 s off, read as ms, put poses 2 ms apart in a run's span
    where the run's are 2 s apart — a probe; a 1 kHz motion capture is 100 times a 10 Hz laser's rate,
    a 10 Hz ground truth read as ms 1,000 times), and both are said."""
    return _within(other, scaled) >= 2 and _spacing(scaled) >= _spacing(other) / DENSER


def _same_unit(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two files' time spans, as they are, are of about one length (within SAME_SPAN): then their
    stamps are in one unit, and not overlapping is two clocks (a ground truth stamped from 0 against a
    log's 1000–1118 s: read as ms, the log's 118 s fell inside it). A run of part of the log, or a ground
    truth of part of it, may be far shorter: only then is a unit read (a review)."""
    x, y = float(a[-1] - a[0]), float(b[-1] - b[0])
    return 0.0 < min(x, y) and max(x, y) <= SAME_SPAN * min(x, y)


def _within(t: np.ndarray, span: np.ndarray) -> int:
    """How many of the stamps ``t`` fall within the span of the sorted stamps ``span``."""
    return int(np.count_nonzero(inside_span(span, t)))


def _spacing(t: np.ndarray) -> float:
    """The median spacing of the sorted stamps ``t`` (0 when none differ)."""
    d = np.diff(t)
    return float(np.median(d[d > 0])) if np.any(d > 0) else 0.0


def evaluate_files(
    trajectory: str | Path,
    ground_truth: str | Path | None = None,
    relations: str | Path | None = None,
    time_offset: float = 0.0,
    correct_scale: bool = False,
) -> Accuracy:
    """``cornerslam evaluate``: the TUM ``trajectory`` (or a run's output directory: its
    trajectory.tum) scored against a TUM ``ground_truth`` (``ate`` and the ``rpe_*`` fields) and/or a
    ``relations`` file (``relations``); ``correct_scale``: the ATE after the best similarity (:func:`ate`).

    Raises ``LogError`` when the ground truth does not overlap the trajectory in time or no relation
    falls inside it: there is nothing to score, and a NaN is not a score."""
    if Path(trajectory).is_dir():
        trajectory = Path(trajectory) / "trajectory.tum"
    t, est = read_tum(trajectory)
    out: dict = {}  # Accuracy's fields
    if ground_truth:
        gt_t, gt = read_tum(ground_truth, "ground truth")
        name = f"ground truth '{ground_truth}'"
        problem = (
            overlap_problem(t, gt_t, name, f"trajectory '{trajectory}'")
            or mirror_problem(t, est, gt_t, gt, name, "the trajectory")
            or (None if correct_scale else units_problem(t, est, gt_t, gt, name, "the trajectory"))
        )
        if problem:
            raise LogError(*problem)
        out.update(ground_truth=display_path(ground_truth), ate=ate(t, est, gt_t, gt, correct_scale))
        if note := coverage_note(f"ground truth '{ground_truth}'", gt_t, out["ate"], len(t), "trajectory"):
            log.warning("%s", note)
        if note := sparse_note(f"ground truth '{ground_truth}'", gt_t, t, "trajectory"):
            log.warning("%s", note)
        s = out["ate"].scale
        scaled = est if s is None else est * np.array([s, s, 1.0])
        # (scale corrected too, as evo_rpe -as; per metre of the trajectory: a ground truth in mm has its
        # metre's window s of its units long, not 1 — the figure moved with the unit, a probe)
        out.update(vars(rpe(t, scaled, gt_t, gt, delta_m=1.0 if s is None else s)))
    if relations:
        e = relation_error(t, est, read_relations(relations), time_offset)
        if e.n == 0:
            raise LogError(
                f"no relation in '{relations}' falls inside the trajectory's time span",
                "check --time-offset (relation time − log time)",
            )
        out.update(relations_file=display_path(relations), relations=e)
    return Accuracy(**out)


def coverage_note(what: str, gt_t: np.ndarray, a: Ate, total: int, whose: str = "run") -> str | None:
    """What to say when the ATE ``a`` scored fewer than the ``total`` poses: how many fell outside the
    ground truth's time span ``gt_t`` and in its gaps; None when it scored them all."""
    if a.n >= total:
        return None
    holes = a.in_holes or 0
    gaps = f", {holes} in its gaps" if holes else ""
    return (
        f"{what} covers {a.n} of the {whose}'s {total} poses ({total - a.n - holes} outside its time span "
        f"{gt_t[0]:.3f} to {gt_t[-1]:.3f} s{gaps}): ATE/RPE are over those {a.n} only (give a ground "
        f"truth of the whole {whose}, or --start/--end inside it)"
    )


def sparse_note(what: str, gt_t: np.ndarray, est_t: np.ndarray, whose: str = "run") -> str | None:
    """What to say when most of the ``whose``'s poses (stamps ``est_t``) that a ground truth with poses at
    ``gt_t`` scores lie more than ``GAP_MIN`` from every pose of it: they are scored against straight
    lines between its poses (a ground truth of two poses, or one per minute, has no hole by its own
    median spacing); None otherwise."""
    scored = np.asarray(est_t, dtype=float)
    scored = scored[scorable(gt_t, scored)]
    if len(gt_t) < 2 or not len(scored):
        return None
    before, after = bracket(gt_t, scored)
    far = int(np.count_nonzero(np.minimum(scored - before, after - scored) > GAP_MIN))
    if 2 * far <= len(scored):
        return None
    return (
        f"{what} is sparse: {far} of the {len(scored)} {whose} poses it scores lie more than {GAP_MIN:g} s "
        f"from every one of its {len(gt_t)} poses, and are scored against straight lines between them "
        "(give a ground truth with poses throughout the trajectory)"
    )


def relation_errors(
    est_t: np.ndarray, est: np.ndarray, relations: np.ndarray, time_offset: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per relation (t1, t2, δ) inside the trajectory's span: the error of est(t1)⁻¹ ∘ est(t2) against δ.
    Relation times are shifted by ``-time_offset`` to log time; poses between processed scans are
    interpolated. Returns (which relations were inside, their translational (m) and absolute rotational
    (deg) errors)."""
    t1 = relations[:, 0] - time_offset
    t2 = relations[:, 1] - time_offset
    both = inside_span(est_t, t1) & inside_span(est_t, t2)
    a, b = interpolate(est_t, est, t1[both]), interpolate(est_t, est, t2[both])
    err = relative(relations[both][:, 2:5], relative(a, b))
    return both, np.linalg.norm(err[:, :2], axis=1), np.degrees(np.abs(err[:, 2]))


def relation_error(
    est_t: np.ndarray, est: np.ndarray, relations: np.ndarray, time_offset: float = 0.0
) -> RelationError:
    """Kümmerle et al. 2009 metric (:func:`relation_errors`): mean ± std of the translational (m) and
    absolute rotational (deg) errors, and how many relations could be evaluated."""
    both, trans, rot = relation_errors(est_t, est, relations, time_offset)
    n = int(np.count_nonzero(both))
    if n == 0:
        return RelationError(n=0, n_total=int(len(relations)))
    return RelationError(
        n=n,
        n_total=int(len(relations)),
        trans_mean=float(trans.mean()),
        trans_std=float(trans.std()),
        rot_mean_deg=float(rot.mean()),
        rot_std_deg=float(rot.std()),
    )
