"""``kernel``: Numba's ``njit`` with its on-disk cache, or without one where none can be written.

Numba caches compiled kernels beside their source (``__pycache__``), else in the user's cache directory
(or ``NUMBA_CACHE_DIR``). Where neither is writable (a read-only install run by a user without a home
directory) ``njit(cache=True)`` would raise at import; the kernels are then compiled in every process
(~15 s at the first extraction), with one warning saying how to avoid it.
"""

from __future__ import annotations

import logging
import os

from numba import njit

log = logging.getLogger("cornerslam.features")
_warned: list[bool] = []
_CACHED: list = []  # every kernel made with an on-disk cache (for uncached())


def kernel(fn):
    """``njit(cache=True)(fn)``; ``njit(fn)`` when Numba finds no writable cache location for it."""
    try:
        compiled = njit(cache=True)(fn)
        _CACHED.append(compiled)
        return compiled
    except RuntimeError as exc:  # numba: "cannot cache function ...: no locator available for file ..."
        if not _warned:
            _warned.append(True)
            log.warning(
                "compiled kernels cannot be cached (%s): they are compiled again in every process; "
                "set NUMBA_CACHE_DIR to a writable directory",
                exc,
            )
        return njit(fn)


def uncached() -> int:
    """How many of the cached kernels made so far have nothing in their cache yet: each is compiled at
    its first call (a first run compiles them all, about a minute). Read from Numba's private cache
    layout (its index file's path); 0 where that layout is not the one read here."""
    try:
        return sum(not os.path.exists(k._cache._cache_file._index_path) for k in _CACHED)
    except AttributeError:
        return 0
