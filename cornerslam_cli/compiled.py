"""A line before a first run's silent minute: Numba compiles cornerslam's kernels at their first call and
caches them on disk (features/jit.py), so a run on a fresh install shows nothing, not even its progress
line, for about a minute. :func:`compile_note` says so when the caches are empty."""

from __future__ import annotations

import importlib

from .features import jit

KERNEL_MODULES = (  # every module with kernels (tests/test_compiled.py checks the list)
    "cornerslam_cli.smallmat",
    "cornerslam_cli.association.kernels",
    "cornerslam_cli.association.search_kernels",
    "cornerslam_cli.features.corner_kernels",
    "cornerslam_cli.features.fit_kernels",
    "cornerslam_cli.features.segment_kernels",
    "cornerslam_cli.filter.kernels",
    "cornerslam_cli.motion.fusion",
    "cornerslam_cli.motion.kernels",
    "cornerslam_cli.motion.nearest",
    "cornerslam_cli.motion.search_kernels",
    "cornerslam_cli.report.occupancy",
    "cornerslam_cli.report.revisit_grid",
)


def compile_note() -> str:
    """The line to say when some kernel has no cached compilation yet ("compiling N …"), else ""."""
    for name in KERNEL_MODULES:  # (a run imports them all anyway)
        importlib.import_module(name)
    n = jit.uncached()
    if not n:
        return ""
    return (
        f"compiling {n} numerical kernels for this machine before the first step: about a minute, "
        "this once (they are cached for later runs)"
    )
