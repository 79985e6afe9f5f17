"""Worker processes of ``batch`` and ``compare --jobs``: they end with the process that started them.

A pool's workers wait on a pipe whose writing end they share with their siblings, so when the parent
is killed (SIGKILL, the OOM killer) they never see end-of-file: they would finish their combination,
commit its output long after the run was given up, and then wait forever. Each worker instead
watches its parent and exits as soon as it is gone; its staging directory is then a dead process's
leftover, which the next run into the same place removes.

A ``batch`` worker also leaves Ctrl-C to the batch (:func:`stopped_by_parent`): interrupted, the batch
ends its workers with SIGTERM, on which each unwinds as a Python exit (a run under way removes its
staging) and then exits instead of starting the combination queued to it next.
"""

from __future__ import annotations

import os
import signal
import threading
import time


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

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, on_sigterm)
