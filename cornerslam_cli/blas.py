"""Single-threaded BLAS for every cornerslam process, set before numpy is first imported.

The filter's and associators' matrices are small or memory-bound: BLAS threads cost more than they
save (a run on the simulated sample takes 2x longer with two OpenBLAS threads), and in-process runs
(tests, batch workers) compute exactly what ``cornerslam run`` computes only with the same thread
count. An explicit setting in the environment wins. This module imports nothing but ``os``, so
cli.py, tests/conftest.py and batch workers can call it before anything imports numpy.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

BLAS_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def single_threaded_blas() -> None:
    """Set each of :data:`BLAS_VARS` to 1 in this process's environment unless it is already set."""
    for var in BLAS_VARS:
        os.environ.setdefault(var, "1")


@contextmanager
def single_threaded_blas_env() -> Iterator[None]:
    """:func:`single_threaded_blas` while the block runs (child processes started in it inherit
    it), the environment as it was afterwards."""
    saved = {v: os.environ.get(v) for v in BLAS_VARS}
    single_threaded_blas()
    try:
        yield
    finally:
        for v, old in saved.items():
            if old is None:
                os.environ.pop(v, None)
            else:
                os.environ[v] = old
