"""The floating-point kernels this process runs on: which BLAS kernel set and which numpy SIMD level.

A run's digits depend on them. OpenBLAS picks its kernels for the CPU at load time (or as
``OPENBLAS_CORETYPE`` says) and numpy dispatches its loops to the widest SIMD level the CPU has (unless
``NPY_DISABLE_CPU_FEATURES`` says otherwise); different kernels round differently in the last bit, and
on the Intel log such a bit can flip a discrete decision of the scan matcher and move the relation error
by centimetres (docs/results/intel_spread.md). summary.json records both so two runs that disagree can
be told apart from a bug.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

# symbol name patterns of openblas_get_corename/openblas_get_config: plain OpenBLAS, and the scipy-openblas
# builds that numpy and scipy wheels bundle (prefix scipy_, suffix 64_ for the ILP64 one)
_AFFIXES = (("", ""), ("scipy_", ""), ("scipy_", "64_"))


def _loaded_openblas() -> list[str]:
    """Paths of the OpenBLAS libraries mapped into this process (Linux; empty elsewhere)."""
    try:
        maps = Path("/proc/self/maps").read_text().splitlines()
    except OSError:
        return []
    paths = {line.split(None, 5)[-1] for line in maps if "openblas" in line.lower() and "/" in line}
    return sorted(p for p in paths if p.startswith("/"))


def _call_str(lib: ctypes.CDLL, name: str) -> str | None:
    for prefix, suffix in _AFFIXES:
        fn = getattr(lib, f"{prefix}openblas_{name}{suffix}", None)
        if fn is not None:
            fn.restype = ctypes.c_char_p
            out = fn()
            return out.decode(errors="replace") if out else None
    return None


def blas_kernels() -> list[str]:
    """One ``"OpenBLAS <version> <kernel set>"`` per OpenBLAS library loaded (numpy and scipy each
    bundle one); empty if numpy is linked to another BLAS or the platform has no /proc."""
    import numpy  # noqa: F401  (loads numpy's BLAS)
    import scipy.linalg  # noqa: F401  (and scipy's)

    out = []
    for path in _loaded_openblas():
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        config, core = _call_str(lib, "get_config"), _call_str(lib, "get_corename")
        if config is None or core is None:
            continue
        version = config.split()[1] if config.startswith("OpenBLAS ") else "?"
        out.append(f"OpenBLAS {version} {core}")
    return sorted(set(out))


def _umath():
    try:
        from numpy._core import _multiarray_umath as um
    except ImportError:  # numpy < 2
        from numpy.core import _multiarray_umath as um
    return um


def simd_targets() -> list[str]:
    """numpy's SIMD dispatch targets in use: compiled in and enabled on this CPU (and not disabled by
    ``NPY_DISABLE_CPU_FEATURES``), narrowest first."""
    um = _umath()
    return [t for t in um.__cpu_dispatch__ if um.__cpu_features__.get(t)]


def simd_baseline() -> str:
    """The widest SIMD level numpy was compiled for unconditionally (used when no target is)."""
    return (_umath().__cpu_baseline__ or ["none"])[-1]


def numpy_simd() -> str:
    """The SIMD targets in use, or ``baseline <level>`` when none is."""
    return " ".join(simd_targets()) or f"baseline {simd_baseline()}"


def describe() -> dict:
    """``{"blas": ..., "numpy_simd": ...}`` for summary.json's ``versions``."""
    return {"blas": "; ".join(blas_kernels()) or "unknown", "numpy_simd": numpy_simd()}
