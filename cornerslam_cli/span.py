"""Part of a log: the scans a run or compare processes with ``--start``, ``--end`` and ``--max-scans``.

A bound is seconds from the log's first scan (``--start 12.5``) or, with a ``#`` prefix, the index of
a scan on the scan topic (``--end '#300'``: 0 is the first scan). ``--start`` is inclusive, ``--end``
exclusive; ``--max-scans N`` keeps at most N scans from the start. :func:`select` filters the
reader's messages: scans outside the span are dropped (handed to ``left_out``: the reader's beam counts
give them back, so summary.json's describe the span), odometry passes (the synchroniser needs the
samples around each scan), and reading stops at the first odometry sample at or after the last scan
kept, so ``--end`` or ``--max-scans`` near the start of a long log reads little of it. What was
used is recorded in :class:`SpanUsed` (summary.json ``input.span``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass

from .errors import CornerslamError
from .ranges import plain_float, short_text
from .results import ScanSpan
from .types import Scan

INDEX_DIGITS = 100  # a '#INDEX' of more digits is refused (past any log; int() stops at 4,300 anyway)


STAMP_NEAR = 3600.0  # s: a bound within the stamps of a log not stamped from 0, or this near: a stamp


def seconds(t: float) -> str:
    """``t`` to the microsecond, without float noise: compared in an error with a bound given to more
    digits than one, "907.7" beside a "--end 907.7" it is past said nothing."""
    return repr(round(float(t), 6))


@dataclass(frozen=True)
class Bound:
    """One end of a span: ``value`` seconds from the first scan, or a scan index when ``index``."""

    value: float | int  # an index is kept an int: '#<20 digits>' is echoed as given, not via a float
    index: bool

    def text(self) -> str:
        return f"#{self.value}" if self.index else f"{self.value:.15g}"  # as given (:g cut it to 6 digits)

    def reached(self, i: int, t: float) -> bool:
        """Whether scan ``i`` at ``t`` seconds from the first scan is at or past this bound."""
        return (i if self.index else t) >= self.value


def parse_bound(text: str) -> Bound:
    """``'12.5'`` (seconds, ≥ 0) or ``'#40'`` (scan index, ≥ 0); ValueError saying what is wrong."""
    s = text.strip()
    if s.startswith("#"):
        digits = s[1:]
        if not (digits.isascii() and digits.isdigit()):  # ('²' is a digit to str.isdigit, not to int)
            raise ValueError(f"'{short_text(text)}' is not a scan index (# followed by digits, e.g. #100)")
        if len(digits) > INDEX_DIGITS:
            raise ValueError(f"'#{digits[:10]}...' ({len(digits):,} digits) is past any scan of a log")
        return Bound(int(digits), True)
    try:
        v = plain_float(s)
    except ValueError:
        raise ValueError(
            f"'{text}' is not seconds from the first scan or #INDEX (e.g. 12.5 or #100)"
        ) from None
    if not math.isfinite(v) or v < 0:
        raise ValueError(f"'{text}' must be finite seconds ≥ 0 from the first scan")
    return Bound(v, False)


@dataclass(frozen=True)
class Span:
    """The part of a log to process; every field None = all of it."""

    start: Bound | None = None
    end: Bound | None = None
    max_scans: int | None = None

    @property
    def given(self) -> bool:
        return self.start is not None or self.end is not None or self.max_scans is not None

    def describe(self) -> str:
        """The options as given, e.g. ``--start 10 --max-scans 200``."""
        parts = [
            f"--start {self.start.text()}" if self.start else "",
            f"--end {self.end.text()}" if self.end else "",
        ]
        parts.append(f"--max-scans {self.max_scans}" if self.max_scans is not None else "")
        return " ".join(p for p in parts if p)

    def order_problem(self) -> str | None:
        """Why ``--end`` cannot come after ``--start`` when both are of the same kind, or at the first
        scan (``--end 0``, ``--end '#0'``: before any start), else None."""
        s, e = self.start, self.end
        if e is not None and e.value == 0:
            return f"'{e.text()}' is the log's first scan: a span ending before it holds none"
        if s is not None and e is not None and s.index == e.index and e.value <= s.value:
            return f"'{e.text()}' is not after --start {s.text()}"
        return None

    def expected_scans(self, total: int, duration: float) -> int:
        """Scans the span should hold in a log of ``total`` scans over ``duration`` seconds (progress)."""
        rate = total / duration if duration > 0 else 0.0
        lo = _as_index(self.start, rate, 0, total)
        hi = _as_index(self.end, rate, total, total)
        n = max(hi - lo, 0)
        return min(n, self.max_scans) if self.max_scans is not None else n


def _as_index(b: Bound | None, rate: float, default: int, total: int) -> int:
    """The scan index ``b`` falls at, clamped to ``total`` before any int() (``--start 1e308`` times
    the scan rate is inf: int(inf) raised OverflowError)."""
    if b is None:
        return default
    x = b.value if b.index else b.value * rate
    return int(x) if x < total else total


@dataclass
class SpanUsed:
    """The scans a span kept: indices and seconds from the log's first scan (None: none kept)."""

    first_index: int | None = None
    last_index: int | None = None
    first_time: float | None = None
    last_time: float | None = None
    scans: int = 0

    def keep(self, i: int, t: float) -> None:
        if self.first_index is None:
            self.first_index, self.first_time = i, t
        self.last_index, self.last_time = i, t
        self.scans += 1

    def record(self, span: Span) -> ScanSpan | None:
        """summary.json's ``input.span``: None when the whole log was processed."""
        if not span.given or self.first_index is None:
            return None
        return ScanSpan(
            options=span.describe(),
            first_index=self.first_index,
            last_index=self.last_index,
            first_time=self.first_time,
            last_time=self.last_time,
            scans=self.scans,
        )


def select(
    messages: Iterable,
    span: Span,
    used: SpanUsed,
    log_name: str,
    left_out: Callable[[Scan], None] | None = None,
    stamp_offset: float = 0.0,
) -> Iterator:
    """The messages of ``span``: scans inside it (counted in ``used``), odometry until the first
    sample at or after the last scan kept, its stamp plus ``stamp_offset`` (``input.scan_time_offset``,
    added to the scans' stamps after the selection). Each scan read but dropped goes to ``left_out``.
    A span that holds no scan of the log is a CornerslamError naming the options and the log's extent."""
    drop = left_out or (lambda scan: None)
    t0 = stop_at = None
    ended_at: tuple[int, float] | None = None  # the scan where the end came before any was kept
    i = -1
    for msg in messages:
        if not isinstance(msg, Scan):
            if stop_at is None or msg.stamp < stop_at:
                yield msg
                continue
            yield msg  # the sample after the last scan: its pose is interpolated
            break
        i += 1
        t0 = msg.stamp if t0 is None else t0
        t = msg.stamp - t0
        if stop_at is not None or (span.start is not None and not span.start.reached(i, t)):
            drop(msg)
            continue
        if (span.end is not None and span.end.reached(i, t)) or used.scans == span.max_scans:
            stop_at = used.last_time + t0 + stamp_offset if used.last_time is not None else -math.inf
            ended_at = (i, t) if used.scans == 0 else None
            drop(msg)
            continue
        used.keep(i, t)
        yield msg
    if used.scans == 0 and ended_at is not None:  # the log was not read to its end: no extent to give
        raise CornerslamError(
            f"{span.describe()} selects no scan of log '{log_name}': the first scan its start lets in "
            f"(#{ended_at[0]}, {seconds(ended_at[1])} s from the first) is already past its end",
            "give an end after the start",
        )
    if used.scans == 0:
        extent = f"{i + 1} scan{'s' if i else ''} over {seconds(t)} s" if t0 is not None else "no scans"
        hint = "choose a span inside the log: seconds from its first scan, or #INDEX"
        given = [b for b in (span.start, span.end) if b is not None and not b.index]
        if t0 is not None and t0 > STAMP_NEAR and any(abs(b.value - t0) <= t + STAMP_NEAR for b in given):
            hint = f"its first scan is stamped {t0:.3f}: {hint}"  # a stamp given for seconds from it
        raise CornerslamError(f"{span.describe()} selects no scan of log '{log_name}' ({extent})", hint)
