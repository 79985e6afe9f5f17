"""One scan's features (``cornerslam extract``): the step-th scan of a log and its segments and corners."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from .config import Config
from .errors import ConfigError, LogError
from .features import extract
from .logs import open_configured, read_alone
from .logs.unreadable import no_scan_read
from .types import Corners, Scan, Segments

AT_WITHIN = 1e-3  # s: ``--at STAMP`` takes the scan stamped within this of it (trajectory.csv's 9 digits)


def extract_step(
    log_path: str | Path,
    step: int | None,
    cfg: Config,
    prepare: Callable[[Any], Iterable[Scan]] | None = None,
    at: float | None = None,
) -> tuple[int, Scan, Segments, Corners]:
    """The log's scan number ``step`` (0 = first, counting the scans the reader yields) — or, with
    ``at``, the scan stamped within AT_WITHIN of it (a run's step: trajectory.csv's ``stamp``; a run's
    step numbers skip scans, between keyframes or without odometry) — as (its number, the scan, its line
    segments, its natural corners in the sensor frame), extracted with ``cfg``'s sensor, lines and
    corners sections. ``prepare``: the reader's scans as a run prepares them (``input.skip_beams_*``,
    ``input.max_range``: ``cornerslam extract`` passes the front end's), else as read. ConfigError
    when the log has no such scan, naming the valid range; LogError when it yields no scan at all
    (every chunk corrupt, every scan undecodable: there is no range to name)."""
    inp = cfg.input
    read_alone(inp)  # (--odom-topic beside input.odometry=scans: refused, as run refuses it)
    with open_configured(Path(log_path), inp) as reader:
        if inp.odom_topic:  # given though not needed: a wrong one is refused as run refuses it
            reader.check()
        if hasattr(reader, "scan_frame") and not _odometry_problem(reader):
            # the tf read as a run reads it, so that the scans a run leaves out (another laser on the
            # topic, mounted elsewhere) are left out here too and '#N' is the same scan (a review)
            reader.laser_to_base()
        n, first, last = 0, None, None
        scans = reader.scans() if prepare is None else prepare(reader)
        for scan in scans:  # odometry is not needed for one scan's features
            first, last = scan.stamp if first is None else first, scan.stamp
            if (n == step) if at is None else (abs(scan.stamp - at) <= AT_WITHIN):
                return (n, scan, *extract(scan, cfg.sensor, cfg.lines, cfg.corners))
            n += 1
    if n == 0:
        raise no_scan_read(log_path, "none to extract", stats=reader.stats)
    if at is not None:
        raise ConfigError(
            f"no scan of '{log_path}' is stamped --at {at:.6f} (within {AT_WITHIN * 1e3:g} ms; its scans "
            f"{first:.6f} to {last:.6f} s)",
            "give a stamp from a run's trajectory.csv stamp column, or --step N",
        )
    raise ConfigError(f"--step {step} is past the end of '{log_path}' ({n} scans)", f"use 0..{n - 1}")


def _odometry_problem(reader: Any) -> bool:
    """Whether a run would refuse ``reader``'s topics (no odometry: extract needs none, and then reads no
    tf either — every scan of the topic is extracted)."""
    try:
        reader.check()
    except LogError:
        return True
    return False
