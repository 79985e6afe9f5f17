"""Work for tests/test_batch.py's dead-worker test, importable by name in a spawned worker: a task that
kills its own worker process every time, or only the first time (a flag file says it did); one that takes
its time ("slow N": N seconds)."""

from __future__ import annotations

import os
import time


def work(what: str, flag: str = "") -> dict:
    if what == "dies" or (what == "dies once" and not os.path.exists(flag)):
        if flag:
            open(flag, "w").close()
        os._exit(3)  # as the OOM killer would end it: no exception, no result
    if what.startswith("slow"):
        time.sleep(float(what.split()[1]))
    return {"status": "ok", "error": what}
