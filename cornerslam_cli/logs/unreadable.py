"""The errors of a log nothing could be read from: no scan at all (every MCAP chunk corrupt, every
message undecodable), or parts of the file skipped as damaged — said as such, with what to do, not as
a problem of the topics or stamps the run would otherwise blame."""

from __future__ import annotations

import re
from pathlib import Path

from ..errors import LogError
from .base import ReadStats


def no_scan_read(
    log: str | Path, so: str, topics_hint: bool = True, stats: ReadStats | None = None
) -> LogError:
    """The error of a log whose scan topic yields no scan at all though it lists messages (every
    MCAP chunk corrupt, every message undecodable: its warnings say which), ``so`` saying what the
    command cannot do; ``topics_hint``: point at ``cornerslam info`` for the topics. With the reader's
    ``stats`` showing damaged parts skipped, the error is :func:`damaged_error`'s."""
    if stats is not None and stats.damaged:  # the scans' messages were not read: no odometry count
        return damaged_error(log, stats, f"no scan could be read, so {so}", odometry=False)
    if stats is not None and stats.warnings:  # -q does not show them: the first in the line itself
        hint = f"its first warning: {stats.warnings[0]}"
    else:  # none to point at (a ROS 2 bag whose metadata.yaml names topics its storage file lacks)
        hint = "the reader found none of the scan messages its index lists: reindex it or copy it again"
    return LogError(
        f"log '{log}' has no scan that could be read, so {so}",
        hint + ("; `cornerslam info LOG` lists its topics" if topics_hint else ""),
    )


def damaged_error(log: str | Path, stats: ReadStats, what: str, odometry: bool = True) -> LogError:
    """The error of a log ``what`` happened to (no scan could be read / processed) when parts of the
    file were skipped as damaged: :func:`damage_problem` with the scans (and, ``odometry``, the odometry
    samples) that were usable."""
    usable = _count(stats.scans, "scan")
    if odometry:
        usable += f" and {_count(stats.odoms, 'odometry sample')}"
    return LogError(*damage_problem(log, stats, f"{what} ({usable} usable)"))


def _count(n: int, what: str) -> str:
    return f"{n} {what}{'s' if n != 1 else ''}"


def damage_problem(log: str | Path, stats: ReadStats, what: str) -> tuple[str, str]:
    """(problem, hint) of a log ``what`` happened to when parts of the file were skipped as damaged:
    how many, what the first was, and that the file needs replacing — not the topics or stamps, which
    is what the error would otherwise point at; or, when every skipped part is compressed with a codec
    this reader lacks, that."""
    n, name = stats.damaged, Path(log).name
    first = stats.first_damage.removeprefix(f"{name}: ")
    first = re.sub(r": (?:rest skipped|skipped|its messages are lost|stopped reading)$", "", first)
    if stats.unsupported == n:
        return (
            f"log '{log}': {what}; {_count(n, 'chunk')} in a compression this reader does not support, "
            f"the first: {first}",
            "write the log with zstd, lz4 or no chunk compression",
        )
    return (
        f"log '{log}': {what}; {_count(n, 'damaged part')} of the file skipped, the first: {first}",
        f"the file is damaged: copy it again from its source, or salvage its intact parts with "
        f"`mcap recover {log} -o FIXED.mcap`",
    )


def raise_if_undecoded(log_path: Path, rs: ReadStats) -> None:
    """Raise LogError naming the decoding failures when they left no scan or no odometry sample (then
    they, not the stamps, are why no scan could be processed)."""
    if rs.decode_failed and not (rs.scans and rs.odoms):
        raise LogError(
            f"log '{log_path}': no scan could be processed: {rs.decode_failed} messages could not be decoded "
            f"or held unusable values ({rs.scans} scans and {rs.odoms} odometry samples were usable; the "
            f"first failure: {rs.first_failure})",
            "check the scan and odometry messages; `cornerslam info LOG` lists the topics and their types",
        )
