"""Worker processes of ``batch`` and ``compare --jobs``: they end with the process that started them.

A pool's workers wait on a pipe whose writing end they share with their siblings, so when the parent
is killed (SIGKILL, the OOM killer) they never see end-of-file: they would finish their combination,
commit its output long after the run was given up, and then wait forever. Each worker instead
watches its parent and exits as soon as it is gone; its staging directory is then a dead process's
leftover, which the next run into the same place removes.

A ``batch`` worker also leaves Ctrl-C to the batch (:func:`stopped_by_parent`): interrupted, the batch
ends its workers with SIGTERM, on which each unwinds as a Python exit (a run under way removes its
staging) and then exits instead of starting the combination queued to it next.

A ``batch`` says each distinct warning once (:func:`warnings_once`): every combination loads the same
keys and runs the same log, and would say the same thing again; its workers keep their warnings
(:func:`warnings_kept`) and the batch says them as each combination finishes.

What must not be cut by Ctrl-C — several renames that make one output, loading the kernels' cache —
runs with SIGINT and SIGTERM held back (:func:`signals_deferred`).
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

RETRY_SIGTERM = 0.01  # s: a SIGTERM that landed in a callback from C is sent again this much later


def exit_with_parent(interval: float = 0.5) -> None:
    """Start a daemon thread that ends this process (exit status 1) once its parent has gone."""
    parent = os.getppid()

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(interval)
        os._exit(1)  # no clean-up: the parent's run is over, and it owned the output

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def stopped_by_parent() -> None:
    """Ignore Ctrl-C (the terminal sends it to the whole process group; the parent decides) and take
    SIGTERM as ``SystemExit(143)``, so a run under way removes its staging on the way out (the task
    catches it and ends the process; an idle worker just exits, quietly)."""

    def on_sigterm(signum, frame):
        signal.signal(signal.SIGTERM, signal.SIG_IGN)  # a second one must not interrupt the clean-up
        raise SystemExit(143)

    def unraisable(args) -> None:
        """The SystemExit landed in Python code called back from C (llvmlite's, while Numba compiles),
        where it cannot unwind: C drops it and Python would print it as a traceback. Send SIGTERM again
        in a moment instead, to land after the callback (a sender thread: a signal is handled in the
        main thread, at its next bytecode)."""
        if not isinstance(args.exc_value, SystemExit):
            default(args)
            return
        signal.signal(signal.SIGTERM, on_sigterm)
        threading.Timer(RETRY_SIGTERM, os.kill, (os.getpid(), signal.SIGTERM)).start()

    default = sys.unraisablehook
    sys.unraisablehook = unraisable
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, on_sigterm)


_said: set[str] | None = None  # the warnings said within the outermost warnings_once()


@contextmanager
def warnings_once() -> Iterator[None]:
    """Within it, a warning whose text was already logged is not logged again (the root logger's
    handlers drop the repeat); other levels pass. A use inside another shares what the outer one said."""
    global _said
    if _said is not None:
        yield
        return
    said = _said = set()

    def first_time(record: logging.LogRecord) -> bool:
        text = record.getMessage()
        first = text not in said
        said.add(text)
        return first

    try:
        with _warnings_to(first_time):
            yield
    finally:
        _said = None


@contextmanager
def warnings_kept() -> Iterator[list[str]]:
    """Within it, this thread's warnings are kept, in the order logged, in the list it gives instead of
    being printed (a worker's run returns them for the batch to say once); other levels pass, and other
    threads' warnings (a Dask worker runs two combinations at once in its threads: each keeps its own;
    one kept them all, credited to the other's log)."""
    kept: list[str] = []
    me = threading.get_ident()

    def keep(record: logging.LogRecord) -> bool:
        if record.thread != me:
            return True  # (another thread's own warnings_kept, if any, decides it)
        kept.append(record.getMessage())
        return False

    with _warnings_to(keep):
        yield kept


@contextmanager
def warnings_copied() -> Iterator[list[str]]:
    """Within it, warnings are kept, in the order logged, in the list it gives — also under ``-q``, which
    does not print them — and printed as the handlers would anyway (the config's warnings, for
    summary.json: pipeline.keep_notes)."""
    kept: list[str] = []
    root = logging.getLogger()
    level, handlers = root.level, list(root.handlers)
    levels = [h.level for h in handlers]

    class Copy(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            if record.levelno == logging.WARNING:
                kept.append(record.getMessage())

    copy = Copy(logging.WARNING)
    for h, own in zip(handlers, levels, strict=True):  # each prints no more than it did
        h.setLevel(max(own, level))
    # (no handler: the last resort printed them, and must still)
    added = [copy] if handlers or logging.lastResort is None else [copy, logging.lastResort]
    for h in added:
        root.addHandler(h)
    root.setLevel(min(level, logging.WARNING) if handlers else level)
    try:
        yield kept
    finally:
        for h in added:
            root.removeHandler(h)
        root.setLevel(level)
        for h, own in zip(handlers, levels, strict=True):
            h.setLevel(own)


@contextmanager
def _warnings_to(decide: Callable[[logging.LogRecord], bool]) -> Iterator[None]:
    """Each warning record reaching the root logger's handlers is passed to ``decide`` once (not once
    per handler); every handler prints it only if ``decide`` returned True."""
    mark = f"cornerslam_verdict_{id(decide)}"  # the record's verdict, for the handlers after the first

    def only_if(record: logging.LogRecord) -> bool:
        if record.levelno != logging.WARNING:
            return True
        if not hasattr(record, mark):
            setattr(record, mark, decide(record))
        return getattr(record, mark)

    handlers = list(logging.getLogger().handlers) or [h for h in (logging.lastResort,) if h is not None]
    # each list replaced, not changed in place: another thread's emit iterating the old one sees it whole
    # (an insert or a remove under its iteration skipped a filter: a warning escaped about once in 20,000)
    with _FILTERS_CHANGED:
        for h in handlers:  # first: a filter that writes (the status line's clearing) sees no dropped one
            h.filters = [only_if, *h.filters]
    try:
        yield
    finally:
        with _FILTERS_CHANGED:
            for h in handlers:
                h.filters = [f for f in h.filters if f is not only_if]


_FILTERS_CHANGED = threading.Lock()  # one thread at a time replaces the handlers' filter lists


@contextmanager
def signals_deferred() -> Iterator[None]:
    """SIGINT and SIGTERM blocked in the block (delivered when it ends); a no-op where signals cannot be
    blocked (not POSIX, not the main thread)."""
    block = getattr(signal, "pthread_sigmask", None)
    if block is None or threading.current_thread() is not threading.main_thread():
        yield
        return
    old = block(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        yield
    finally:
        block(signal.SIG_SETMASK, old)


def end_children(grace: float = 2.0) -> None:
    """End this process's child processes (an interrupted batch's or comparison's pool workers): SIGTERM,
    then SIGKILL for any still there after ``grace`` seconds — a worker that took a SIGTERM between two
    tasks, where nothing ends it, ignores the next one and would keep the pool's join waiting forever."""
    children = multiprocessing.active_children()
    for child in children:
        child.terminate()
    end = time.monotonic() + grace
    for child in children:
        child.join(max(0.0, end - time.monotonic()))
        if child.is_alive():
            child.kill()
