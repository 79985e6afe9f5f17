"""``cornerslam simulate``: a synthetic indoor log with ground truth.

A differential-drive robot follows a closed loop of waypoints through :func:`simworld.office_world`
(rooms, a corridor loop, clutter boxes), ``laps`` times (library callers may give another world and
loop: :func:`simulate_log`'s ``world`` and ``waypoints``). It records

* ``/scan`` sensor_msgs/LaserScan from a 270° laser 0.10 m ahead of the base (published on
  ``/tf_static``), ranges ray-cast in the world with Gaussian noise σ = a + b·ρ, random dropouts
  (NaN) and no-return beams (inf) beyond the maximum range;
* ``/odom`` nav_msgs/Odometry at 50 Hz, integrated from the true motion corrupted by a scale error,
  a heading drift per metre and random noise proportional to motion — odometry that drifts the way
  wheel odometry does;

and writes beside the log ``OUT.gt.tum`` (true base poses at the scan stamps) and
``OUT.corners.csv`` (the world's true corners x, y, φ). The same seed gives the same files.
"""

from __future__ import annotations

import hashlib
import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import ConfigError, OutputError
from .geometry import compose, relative, wrap_angle
from .logs.mcap import header_library
from .logs.writers import RawScan, write_mcap
from .logs.writers.mcap import LIBRARY as LOG_LIBRARY
from .report.outdir import staged_files
from .report.ownership import refuse_special_file
from .report.tables import write_tum
from .simworld import OFFICE_LOOP, World, office_world, raycast, true_corners
from .types import OdomSample
from .workers import signals_deferred

log = logging.getLogger("cornerslam.simulate")

EPOCH = 1_700_000_000.0  # an arbitrary fixed start time, seconds


@dataclass(frozen=True)
class SimParams:
    """Robot, laser and odometry-noise parameters of the simulator."""

    rate: float = 10.0  # scans per second
    beams: int = 1081  # over fov
    fov: float = np.radians(270.0)
    max_range: float = 30.0
    sigma_a: float = 0.01  # range noise σ = a + b·ρ
    sigma_b: float = 0.002
    dropout: float = 0.02  # fraction of beams returned as NaN
    speed: float = 0.5  # m/s
    turn_rate: float = 0.6  # rad/s, maximum
    odom_rate: float = 50.0
    odom_scale: float = 0.02  # odometer reads 2 % long
    odom_drift: float = 0.01  # heading drift, rad per metre travelled
    odom_sigma_trans: float = 0.01  # m per sqrt(m)
    odom_sigma_rot: float = 0.005  # rad per sqrt(m) travelled plus per sqrt(rad) turned
    laser_x: float = 0.10


def drive(waypoints: np.ndarray, laps: int, p: SimParams, dt: float) -> np.ndarray:
    """True base poses (k, 3) every ``dt`` seconds along the closed waypoint loop.

    The robot turns on the spot towards the next waypoint when the heading error is large, and
    otherwise drives at ``speed`` while steering proportionally (rate-limited).
    """
    x, y = waypoints[0]
    th = float(np.arctan2(waypoints[1, 1] - y, waypoints[1, 0] - x))
    poses = [(x, y, th)]
    route = [waypoints[i % len(waypoints)] for i in range(1, laps * len(waypoints) + 1)]
    for goal in route:
        for _ in range(100_000):
            dx, dy = goal[0] - x, goal[1] - y
            dist = float(np.hypot(dx, dy))
            if dist < 0.05:
                break
            err = float(wrap_angle(np.arctan2(dy, dx) - th))
            w = float(np.clip(2.0 * err, -p.turn_rate, p.turn_rate))
            v = 0.0 if abs(err) > 0.5 else min(p.speed, dist / dt) * np.cos(err)
            th = float(wrap_angle(th + w * dt))
            x += v * dt * np.cos(th)
            y += v * dt * np.sin(th)
            poses.append((x, y, th))
    return np.array(poses)


def corrupt_odometry(truth: np.ndarray, p: SimParams, rng: np.random.Generator) -> np.ndarray:
    """Odometry poses integrated from the true increments with scale error, drift and noise."""
    out = np.empty_like(truth)
    out[0] = truth[0]
    for i in range(1, len(truth)):
        fwd, side, dth = relative(truth[i - 1], truth[i])  # the true increment in the robot frame
        d = float(np.hypot(fwd, side))
        fwd = fwd * (1 + p.odom_scale) + rng.normal(0, p.odom_sigma_trans * np.sqrt(d))
        dth = dth + p.odom_drift * d + rng.normal(0, p.odom_sigma_rot * (np.sqrt(d) + np.sqrt(abs(dth))))
        out[i] = compose(out[i - 1], (fwd, side, dth))
    return out


# what simulate accepts: (option, lowest, highest), said in cli.py's help too (a test keeps the two the
# same); a log's size is bounded on top (MAX_*)
RANGES = (("--laps", 1, 100), ("--rate", 0.1, 1000.0), ("--beams", 2, 100_000), ("--speed", 0.05, 5.0))
MAX_RANGES = 50_000_000  # scans × beams: ~200 MB of float32 ranges held before writing
MAX_SECONDS = 20_000.0  # 10^6 odometry samples


def check_options(seed: int, laps: int, p: SimParams, waypoints: np.ndarray = OFFICE_LOOP) -> None:
    """ConfigError naming the option when a simulate option is out of range (NaN included) or the
    log would be too large to build in memory (``laps`` times round the closed ``waypoints``)."""
    if not seed >= 0:
        raise ConfigError(f"--seed must be >= 0, got {seed}", "give a non-negative integer")
    for (name, lo, hi), value in zip(RANGES, (laps, p.rate, p.beams, p.speed), strict=True):
        if not lo <= value <= hi:
            raise ConfigError(f"{name} must be in [{lo}, {hi}], got {value}")
    loop = np.vstack((waypoints, waypoints[:1]))
    seconds = laps * float(np.hypot(*np.diff(loop, axis=0).T).sum()) / p.speed
    if seconds > MAX_SECONDS or seconds * p.rate * p.beams > MAX_RANGES:
        raise ConfigError(
            f"simulate would record {seconds:.0f} s of {p.rate:g} Hz scans of {p.beams} beams, more than "
            f"it builds in memory: at most {MAX_SECONDS:,.0f} s and {MAX_RANGES:,} ranges, scans × beams",
            "fewer --laps, a lower --rate or --beams, or a higher --speed",
        )


def _cast(
    world: World,
    waypoints: np.ndarray,
    laps: int,
    p: SimParams,
    seed: int,
    sweep: float,
    progress: Callable[[int, int], None] | None,
) -> tuple[np.ndarray, np.ndarray, list[RawScan], list[OdomSample]]:
    """The drive, its odometry and its scans (simulate_log's): scan stamps, true poses at them, the
    ray-cast scans and the odometry samples."""
    rng = np.random.default_rng(seed)
    dt = 1.0 / p.odom_rate
    truth = drive(waypoints, laps, p, dt)  # at the odometry rate
    t = EPOCH + dt * np.arange(len(truth))
    odom = corrupt_odometry(truth, p, rng)
    # scans between odometry samples (offset by a third of a period), true pose interpolated
    t_scan = np.arange(t[0] + 0.3 * dt, t[-1], 1.0 / p.rate)
    xs = np.interp(t_scan, t, truth[:, 0])
    ys = np.interp(t_scan, t, truth[:, 1])
    ths = wrap_angle(np.interp(t_scan, t, np.unwrap(truth[:, 2])))
    gt = np.column_stack((xs, ys, ths))
    angle_min = -p.fov / 2
    inc = p.fov / (p.beams - 1)
    angles = angle_min + inc * np.arange(p.beams)
    beam_time = sweep / (p.beams - 1)
    scans = []
    t0 = time.perf_counter()
    for k, (ts, (x, y, th)) in enumerate(zip(t_scan, gt, strict=True)):
        if progress is not None:
            progress(k, len(t_scan))
        if sweep > 0.0:  # the base's true pose at each beam's time
            tb = ts + beam_time * np.arange(p.beams)
            x, y = np.interp(tb, t, truth[:, 0]), np.interp(tb, t, truth[:, 1])
            th = wrap_angle(np.interp(tb, t, np.unwrap(truth[:, 2])))
        laser = np.column_stack((x + p.laser_x * np.cos(th), y + p.laser_x * np.sin(th), th))
        r = raycast(world, laser if sweep > 0.0 else laser[0], angles, p.max_range)
        r = r + rng.normal(0.0, 1.0, len(r)) * (p.sigma_a + p.sigma_b * np.where(np.isfinite(r), r, 0))
        r[rng.random(len(r)) < p.dropout] = np.nan
        r[~(r < p.max_range)] = np.inf
        r[np.isfinite(r) & (r < 0.05)] = 0.05
        scans.append(
            RawScan(float(ts), angle_min, inc, r.astype(np.float32), 0.05, p.max_range, "laser", beam_time)
        )
    if progress is not None:
        progress(len(t_scan), len(t_scan))
    log.info("ray-cast %d scans of %d beams in %.1f s", len(scans), p.beams, time.perf_counter() - t0)
    odoms = [OdomSample(float(ti), *o) for ti, o in zip(t, odom, strict=True)]
    return t_scan, gt, scans, odoms


COMPANIONS = "cornerslam simulate companions"  # the log's metadata record: suffix → sha256 of that file


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def companion_hashes(log: Path) -> dict[str, str] | None:
    """The sha256 of the ground truth and corners files simulate wrote beside ``log`` (by suffix:
    ``.tum``, ``.csv``), from its metadata; {} for a whole log without the record (an older simulate's);
    None for one whose metadata cannot be read (damaged: nothing to go by)."""
    from mcap.reader import make_reader

    try:
        with open(log, "rb") as f:
            for m in make_reader(f).iter_metadata():
                if m.name == COMPANIONS:
                    return dict(m.metadata)
    except Exception:  # noqa: BLE001 - a damaged log: no record to go by
        return None
    return {}


def simulate_log(
    out: Path,
    seed: int = 0,
    laps: int = 1,
    rate: float = 10.0,
    beams: int = 1081,
    speed: float = 0.5,
    world: World | None = None,
    waypoints: np.ndarray | None = None,
    fov: float = SimParams.fov,
    sigma_a: float = SimParams.sigma_a,
    sweep: float = 0.0,
    odometry: dict[str, float] | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> dict:
    """Write the synthetic log ``out`` (.mcap), ``out.gt.tum`` and ``out.corners.csv``.

    ``world`` and ``waypoints`` (library use, not CLI options): another world (simworld.py) and the
    closed loop (k, 2) the robot drives through it, starting at its first waypoint; both default to
    the office and its corridor loop (``OFFICE_LOOP``). The waypoints must be joined by free space:
    the robot drives straight between them and does not avoid walls. ``fov`` (rad) and ``sigma_a`` (m,
    the range noise's constant part) likewise: a laser like another log's (benchmarks/reference_check.py).
    ``sweep`` (s, library only): the time from a scan's first beam to its last — each beam is cast from
    the robot's true pose at its own time, the stamp is the first beam's and the messages carry
    ``time_increment`` (a laser whose scans are skewed by the motion: logs/deskew.py); 0 = all at once.
    ``odometry`` (library only): the odometry's error terms, any of SimParams' ``odom_scale``,
    ``odom_drift``, ``odom_sigma_trans``, ``odom_sigma_rot`` (all 0: the odometry is the truth).
    ``progress(done, total)`` is called as the scans are ray-cast (the long part).
    """
    if out.suffix != ".mcap":
        named = "has no name before .mcap" if out.name == ".mcap" else "must end in .mcap"
        raise ConfigError(f"simulate writes MCAP: '{out}' {named}")
    world = office_world() if world is None else world
    waypoints = OFFICE_LOOP if waypoints is None else np.asarray(waypoints, dtype=float).reshape(-1, 2)
    if len(waypoints) < 2:
        raise ConfigError(f"simulate needs at least 2 waypoints, got {len(waypoints)}")
    odometry = dict(odometry or {})
    unknown = set(odometry) - {"odom_scale", "odom_drift", "odom_sigma_trans", "odom_sigma_rot"}
    if unknown:
        raise ValueError(f"simulate_log: not an odometry error term: {', '.join(sorted(unknown))}")
    p = SimParams(rate=rate, beams=beams, speed=speed, fov=fov, sigma_a=sigma_a, **odometry)
    check_options(seed, laps, p, waypoints)
    if not 0.0 <= sweep <= 1.0 / rate:
        raise ConfigError(f"sweep must be in [0, 1/rate = {1.0 / rate:g}] s, got {sweep}")
    paths = (out, out.with_suffix(".gt.tum"), out.with_suffix(".corners.csv"))
    for path in paths:
        refuse_special_file(path, path)
    # replaced only as a set this command wrote: a log whose MCAP header names the log writer's library,
    # and beside it the ground truth and corners as it wrote them (their sha256 in the log's metadata)
    if any(path.exists() for path in paths):
        ours = header_library(out) == LOG_LIBRARY
        written = companion_hashes(out) if ours else None
        for there in paths if not ours else paths[1:]:
            if not there.exists():
                continue
            if there.is_dir():
                raise OutputError(f"'{there}' is a directory", "move it away, or give the log another name")
            # (an older simulate's whole log keeps no record: its set is taken as it was written)
            if ours and (written == {} or (written and written.get(there.suffix) == _sha256(there))):
                continue
            why = "give a new name, or move those files away"
            if ours and written is None:  # its log cut or damaged since: what it wrote cannot be told
                why = f"the record of it in '{out}' cannot be read (the log is damaged); {why}"
            raise OutputError(f"'{there}' exists and is not part of a log cornerslam simulate wrote", why)
    out.parent.mkdir(parents=True, exist_ok=True)  # as --out and --mcap-out do
    gt_path, corners_path = paths[1:]
    # written beside (a killed simulate's hidden files cleared first), renamed when all are written; made
    # now, so an unwritable place fails before the work; Ctrl-C or a full disk: no partial log, and an
    # earlier log is kept whole
    with staged_files(paths) as staged:
        t_scan, gt, scans, odoms = _cast(world, waypoints, laps, p, seed, sweep, progress)
        t0 = time.perf_counter()
        write_tum(staged[gt_path], t_scan, gt)
        c = true_corners(world)
        np.savetxt(staged[corners_path], c, delimiter=",", header="x,y,phi", comments="", fmt="%.6f")
        record = {path.suffix: _sha256(staged[path]) for path in (gt_path, corners_path)}
        write_mcap(staged[out], scans, odoms, tf_static=(p.laser_x, 0.0, 0.0), metadata={COMPANIONS: record})
        with signals_deferred():  # the three renamed as one: Ctrl-C now would leave a mixed set
            for path, tmp in staged.items():
                os.replace(tmp, path)
    log.info("wrote the log, ground truth and corners in %.1f s", time.perf_counter() - t0)
    return {
        "log": str(out),
        "gt": str(gt_path),
        "corners": str(corners_path),
        "scans": len(scans),
        "duration": float(t_scan[-1] - t_scan[0]),
    }
