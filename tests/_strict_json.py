"""Strict JSON for the tests: what a non-Python reader accepts (RFC 8259 has no NaN or Infinity)."""

from __future__ import annotations

import json
from pathlib import Path


def strict(constant: str):
    """``parse_constant`` hook: Python's json accepts NaN, Infinity and -Infinity; strict JSON does not."""
    raise ValueError(f"not strict JSON: bare {constant}")


def strict_load(path: str | Path):
    """The JSON file at ``path``, refused unless strict."""
    return json.loads(Path(path).read_text(), parse_constant=strict)
