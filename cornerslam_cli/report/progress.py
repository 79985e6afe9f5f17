"""Progress on stderr while a command works: a run's scans (``Progress``) and a batch's combinations
(``BatchProgress``). Library code reports progress through a callback; these are the CLI's callbacks."""

from __future__ import annotations

import sys
import time


class StatusLine:
    """One status line on stderr: redrawn in place on a terminal, a line every 10 s otherwise (CI
    logs). Silent when not enabled (-q)."""

    def __init__(self, enabled: bool):
        self.enabled = enabled
        self.t0 = time.monotonic()
        self.last = 0.0
        self.tty = sys.stderr.isatty()
        self.drawn = False

    def _due(self, now: float) -> bool:
        return now - self.last >= (0.1 if self.tty else 10.0)

    def _write(self, text: str) -> None:
        try:
            sys.stderr.write(text)
            sys.stderr.flush()
        except OSError:  # stderr closed (`2>&1 | head`): the run goes on without a status line
            self.enabled = False

    def _draw(self, text: str) -> None:
        if self.tty:
            self._write("\r\033[K" + text)
            self.drawn = True
        else:
            self._write(text + "\n")

    def close(self) -> None:
        if self.drawn:
            self._write("\n")


class Progress(StatusLine):
    """Scans done of a run's log, with a bar and an ETA, for runs longer than ~2 s."""

    def __init__(self, label: str, enabled: bool):
        super().__init__(enabled)
        self.label = label

    def __call__(self, done: int, total: int) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        el = now - self.t0
        if el < 2.0 or not self._due(now):
            return
        self.last = now
        if total > 0:
            frac = min(done / total, 1.0)
            eta = el * (1 - frac) / max(frac, 1e-9)
            bar = "#" * int(30 * frac)
            self._draw(f"{self.label} [{bar:<30}] {done}/{total} scans {el:5.0f}s eta {eta:4.0f}s")
        else:
            self._draw(f"{self.label} {done} scans {el:5.0f}s")


class BatchProgress(StatusLine):
    """The whole batch's progress: finished/failed/skipped/remaining and an ETA from the rate of the
    combinations run so far (skipped ones cost nothing)."""

    def __call__(self, s) -> None:
        now = time.monotonic()
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
