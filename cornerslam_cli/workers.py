"""Worker processes of ``batch`` and ``compare --jobs``: they end with the process that started them.

A pool's workers wait on a pipe whose writing end they share with their siblings, so when the parent
is killed (SIGKILL, the OOM killer) they never see end-of-file: they would finish their combination,
commit its output long after the run was given up, and then wait forever. Each worker instead
watches its parent and exits as soon as it is gone; its staging directory is then a dead process's
leftover, which the next run into the same place removes.
"""

from __future__ import annotations

import os
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
