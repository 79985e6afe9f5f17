"""Allowed ranges of the numeric config keys, declared beside each key and checked in one place.

A numeric key of a config section is declared with :func:`num` (default and range) and the section's
``__post_init__`` calls :func:`check_ranges`::

    alpha1: float = num(0.05, ge=0.0, le=100.0)  # rot variance per rot²

Every numeric key must be a finite number inside its range: NaN and ±inf are never allowed (no key
uses inf to mean "off"; keys that can be switched off use 0). The bounds also keep values away from
overflow and from huge allocations (an EKF preallocated for 10¹⁰ landmarks, a σ of 1e300 whose
square is inf). ``config.load_config`` turns a :class:`RangeError` into a ``ConfigError`` naming the
dotted key; ``tests/test_config_ranges.py`` checks that every numeric key of every section has a
range and that a value outside it is refused.
"""

from __future__ import annotations

import dataclasses
import math
import reprlib
from dataclasses import dataclass
from typing import Any

_SHORT = reprlib.Repr()
_SHORT.maxlevel, _SHORT.maxlist, _SHORT.maxdict, _SHORT.maxstring, _SHORT.maxother = 2, 4, 4, 40, 40


def short_repr(value: Any, limit: int = 60) -> str:
    """``repr(value)`` cut to ``limit`` characters, without ever building the repr of a huge or deeply
    nested value (reprlib visits a bounded number of items: safe on a YAML alias bomb)."""
    text = _SHORT.repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def short_text(text: str, limit: int = 60) -> str:
    """``text`` cut to about ``limit`` characters (its start and end kept, ``...`` between them; escaped
    as ``repr`` does), without quotes: for names given by the user or read from a file (a topic name of
    100,000 characters) in one-line messages."""
    r = reprlib.Repr()
    r.maxstring = limit
    return r.repr(text)[1:-1]


def cut_text(text: str, limit: int = 200) -> str:
    """``text`` as it is when at most ``limit`` characters, else its start and ``...`` (``limit`` in all):
    a message kept to be quoted in an error."""
    return text if len(text) <= limit else text[: limit - 3] + "..."


@dataclass(frozen=True)
class Range:
    """An interval of allowed values: ``lo`` and ``hi`` included unless ``lo_open`` / ``hi_open``."""

    lo: float
    hi: float
    lo_open: bool = False
    hi_open: bool = False

    def __contains__(self, v: float) -> bool:
        above = v > self.lo if self.lo_open else v >= self.lo
        below = v < self.hi if self.hi_open else v <= self.hi
        return above and below

    def __str__(self) -> str:
        return f"{'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}{')' if self.hi_open else ']'}"


class RangeError(ValueError):
    """A numeric key outside its range; ``key`` is the field name, ``allowed`` its :class:`Range`."""

    def __init__(self, key: str, value: Any, allowed: Range):
        self.key, self.value, self.allowed = key, value, allowed
        self.problem = "is not a finite number" if _non_finite(value) else "is out of range"
        super().__init__(f"{key} = {short_repr(value)} {self.problem} (allowed: {allowed})")


def _non_finite(v: Any) -> bool:
    return isinstance(v, float) and not math.isfinite(v)


def num(
    default: float | None,
    *,
    ge: float | None = None,
    gt: float | None = None,
    le: float | None = None,
    lt: float | None = None,
) -> Any:
    """A numeric dataclass field with its allowed range: one of ``ge``/``gt`` (lower bound, included /
    excluded) and one of ``le``/``lt`` (upper bound). A ``None`` default (a ``float | None`` field)
    means not set: None is then allowed besides the range."""
    if (ge is None) == (gt is None) or (le is None) == (lt is None):
        raise TypeError("num() needs one lower bound (ge or gt) and one upper bound (le or lt)")
    lo, hi = (ge if gt is None else gt), (le if lt is None else lt)
    allowed = Range(float(lo), float(hi), lo_open=gt is not None, hi_open=lt is not None)
    if default is not None and default not in allowed:
        raise ValueError(f"default {default} outside {allowed}")  # a bug in a section class
    return dataclasses.field(default=default, metadata={"range": allowed})


def field_range(f: dataclasses.Field) -> Range | None:
    """The :class:`Range` a field was declared with (None for non-numeric fields)."""
    return f.metadata.get("range")


def check_ranges(section: Any) -> None:
    """Raise :class:`RangeError` for the first numeric field of ``section`` that is not a finite
    number inside its declared range."""
    for f in dataclasses.fields(section):
        allowed = field_range(f)
        if allowed is None:
            continue
        v = getattr(section, f.name)
        if v is None and f.default is None:  # not set (num(None, ...))
            continue
        if isinstance(v, bool) or not isinstance(v, (int, float)) or _non_finite(v) or v not in allowed:
            raise RangeError(f.name, v, allowed)


def plain_float(text: str) -> float:
    """``float(text)`` for a number as written in a file or on a command line: ASCII, no ``_`` —
    Python's float also takes ``1_0`` (10) and other scripts' digits (``'٣'``: 3), which a user's
    text never means, and an error echoing the value back would show it altered. ValueError else."""
    if not text.isascii() or "_" in text:
        raise ValueError(f"not a plain number: {text!r}")
    return float(text)
