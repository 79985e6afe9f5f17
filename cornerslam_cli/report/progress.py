"""Progress on stderr while a command works: a run's scans (``Progress``) and a batch's combinations
(``BatchProgress``). Library code reports progress through a callback; these are the CLI's callbacks.
And the log records written below them (:func:`log_to_stderr`)."""

from __future__ import annotations

import logging
import os
import shutil
import sys
import time
from collections import deque

from ..errors import terminal_safe

SHOW_AFTER = 2.0  # seconds: shorter commands show no status line
EVERY_TTY, EVERY_LOG = 0.1, 10.0  # seconds between redraws on a terminal, lines otherwise (CI logs)
ETA_WINDOW = 30.0  # seconds of recent progress the ETA's rate is measured over


class StatusLine:
    """One status line on stderr: redrawn in place on a terminal, a line every 10 s otherwise (CI
    logs). Silent when not enabled (-q)."""

    def __init__(self, enabled: bool, clock=time.monotonic):
        self.enabled = enabled
        self.clock = clock
        self.t0 = clock()
        self.last = 0.0
        self.tty = sys.stderr.isatty()
        self.drawn = False
        # on a terminal the line has no newline: a log message (a warning) would be written after it
        self.clearer = _ClearFirst(self) if enabled and self.tty else None
        for handler in logging.getLogger().handlers if self.clearer else ():
            handler.addFilter(self.clearer)

    def _due(self, now: float) -> bool:
        return now - self.last >= (EVERY_TTY if self.tty else EVERY_LOG)

    def _write(self, text: str) -> None:
        try:
            sys.stderr.write(text)
            sys.stderr.flush()
        except OSError:  # stderr closed (`2>&1 | head`): the run goes on without a status line
            self.enabled = False

    def _draw(self, text: str) -> None:
        if self.tty:
            self._write(_erase() + text)
            self.drawn = True
        else:
            self._write(text + "\n")

    def clear(self) -> None:
        """Erase the line (a terminal's), so that what is written next starts a clean line: whether it
        is drawn or not (a worker process of ``compare --jobs`` cannot know its parent's line)."""
        self._write(_erase())
        self.drawn = False

    def close(self) -> None:
        if self.drawn:
            self._write("\n")
            self.drawn = False
        for handler in logging.getLogger().handlers if self.clearer else ():
            handler.removeFilter(self.clearer)


class _ClearFirst(logging.Filter):
    """A log handler's filter clearing a status line before the handler writes a record below it."""

    def __init__(self, line: StatusLine):
        super().__init__()
        self.line = line

    def filter(self, record: logging.LogRecord) -> bool:
        self.line.clear()
        return True


class Progress(StatusLine):
    """Work done of a run's log (scans read, or with ``unit`` another stage's steps: ``compare``'s
    filters), with a bar and an ETA, for commands longer than ``SHOW_AFTER``.

    The ETA is the remaining work at the rate of the last ``ETA_WINDOW`` seconds, not the average
    since the start: a step costs more as the map grows (a long real log's last steps cost ~3× its
    first), so the whole-run average promised too early an end. A new ``unit`` starts a new rate.
    """

    def __init__(self, label: str, enabled: bool, clock=time.monotonic):
        super().__init__(enabled, clock)
        self.label = label
        self.unit = "scans"
        self.recent: deque[tuple[float, int]] = deque()  # (time, done) over the last ETA_WINDOW s

    def __call__(self, done: int, total: int, unit: str = "scans", doing: str = "") -> None:
        """``doing``: what of the stage runs now (compare's associator), shown beside the unit without
        starting a new rate."""
        if not self.enabled:
            return
        now = self.clock()
        self._sample(now, done, unit)
        el = now - self.t0
        if el < SHOW_AFTER or not self._due(now):
            return
        self.last = now
        if total > 0:
            frac = min(done / total, 1.0)
            bar = "#" * int(30 * frac)
            unit += f" ({doing})" if doing else ""
            self._draw(f"{self.label} [{bar:<30}] {done}/{total} {unit} {el:5.0f}s eta {self.eta(total):>5}")
        else:
            self._draw(f"{self.label} {done} {unit} {el:5.0f}s")

    def finishing(self, what: str) -> None:
        """Say what the command does after its last step (work with no count): drawn at once, in place
        of the bar, which stood at its last count while the run closed loops, smoothed and wrote (a
        long log: seconds without a sign)."""
        if not self.enabled:
            return
        now = self.clock()
        el = now - self.t0
        if el < SHOW_AFTER:
            return
        self.last = now
        self._draw(f"{self.label} finishing: {what} {el:5.0f}s")

    def _sample(self, now: float, done: int, unit: str) -> None:
        if unit != self.unit:
            self.unit = unit
            self.recent.clear()
        self.recent.append((now, done))
        while len(self.recent) > 2 and now - self.recent[1][0] >= ETA_WINDOW:
            self.recent.popleft()

    def eta(self, total: int) -> str:
        """Seconds left at the recent rate, e.g. ``"  42s"``; ``"?"`` before a rate is known."""
        (t_old, d_old), (t_new, d_new) = self.recent[0], self.recent[-1]
        if d_new <= d_old or t_new <= t_old:
            return "?"
        return f"{(total - d_new) * (t_new - t_old) / (d_new - d_old):4.0f}s"


class BatchProgress(StatusLine):
    """The whole batch's progress: finished/failed/skipped/remaining and an ETA from the rate of the
    combinations run so far (skipped ones cost nothing)."""

    def __call__(self, s) -> None:
        now = self.clock()
        if not self.enabled or (s.remaining and not self._due(now)):
            return
        self.last = now
        el = now - self.t0
        ran = s.ok + s.failed
        eta = f"eta {el / ran * s.remaining:4.0f}s" if ran and s.remaining else "eta    ?"
        text = (
            f"batch {s.finished}/{s.total}: {s.ok} ok, {s.failed} failed, {s.skipped} skipped, "
            f"{s.remaining} remaining {el:5.0f}s {eta if s.remaining else ''}"
        ).rstrip()
        self._draw(text)


def log_to_stderr(level: int) -> None:
    """Records at ``level`` and above to stderr as "LEVEL: message", one line each (a worker process
    of ``batch`` too, at its parent's level)."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_TerminalFormatter("%(levelname)s: %(message)s"))
    logging.basicConfig(level=level, handlers=[handler], force=True)


class _TerminalFormatter(logging.Formatter):
    """Each record one line, its control characters escaped (errors.terminal_safe: a log's file name
    may hold a newline or an escape sequence)."""

    def format(self, record: logging.LogRecord) -> str:
        return terminal_safe(super().format(record))


def _erase() -> str:
    """What erases the terminal's line: carriage return and ANSI erase-line, or on a terminal that says it
    has no such codes (TERM=dumb: Emacs's shell, some CI log viewers) a line of spaces between two CRs."""
    if os.environ.get("TERM") == "dumb":
        return "\r" + " " * (shutil.get_terminal_size().columns - 1) + "\r"
    return "\r\033[K"
