"""A user's text file (config, ground truth, relations) read whole, or refused with one line.

:func:`read_number_rows` reads a table of numbers (TUM poses, Kümmerle relations) from one.

:func:`read_text` returns the file's text decoded as UTF-8 (a UTF-8 byte-order mark is dropped).
Everything else is a :class:`~cornerslam_cli.errors.CornerslamError` of the caller's class naming the
file: a directory, a missing or unreadable path, a file larger than the caller's limit, a binary file
(NUL bytes: an MCAP given as ground truth, random bytes, UTF-16 without a byte-order mark), UTF-16
with a byte-order mark, and bytes that are not UTF-8 (a Latin-1 comment), with the line they are on.
Anything that is not a directory is read, so ``/dev/null`` and a pipe (``<(...)``) work.
"""

from __future__ import annotations

import codecs
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .errors import CornerslamError, symlink_loop
from .ranges import plain_float

UTF16_BOMS = (codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)
SNIFF_BYTES = 1 << 16  # a binary file (a multi-GB bag given as ground truth) is refused on these
MAX_ROWS_BYTES = 256 << 20  # a table of numbers (3 million TUM poses): an endless pipe stops here
MAX_POSITION = 1e9  # metres, as odometry (logs/base.MAX_ODOM_XY): squared, 1e308 m made an ATE of "inf m"
# seconds: nanoseconds since 1970 (a ROS exporter's, ~1.7e18, said to be nanoseconds when scored) pass;
# ±1.7e308 made every interpolation overflow into a NaN score, exit 0 (a probe)
MAX_STAMP = 1e19


def read_text(
    path: str | Path,
    what: str,
    error: type[CornerslamError],
    expected: str,
    max_bytes: int | None = None,
) -> str:
    """The text of ``path``; ``what`` names the file in errors ("config file"), ``error`` is the
    exception class raised, ``expected`` says what the file should hold (the hint of the errors)."""
    p = Path(path)
    if p.is_dir():
        raise error(f"{what} '{p}' is a directory", f"give {expected}")
    if not p.exists():
        if symlink_loop(p):
            raise error(f"{what} '{p}': a symlink loop", "check the path")
        raise error(f"{what} '{p}' does not exist", f"give {expected}")
    name = f"{what} '{p}'"
    try:
        with open(p, "rb") as f:
            head = f.read(SNIFF_BYTES)
            refuse_binary(head, name, error, expected)  # before reading the rest of a huge file
            rest = f.read() if max_bytes is None else f.read(max(max_bytes + 1 - len(head), 0))
    except OSError as e:
        raise error(f"{name} cannot be read: {e.strerror or e}", "check its permissions") from None
    raw = head + rest
    if max_bytes is not None and len(raw) > max_bytes:
        raise error(
            f"{name} is larger than {max_bytes // 1024} KiB", f"is it the right file? expected {expected}"
        )
    return decode(raw, name, error, expected)


def refuse_binary(raw: bytes, name: str, error: type[CornerslamError], expected: str) -> None:
    """Raise ``error`` if ``raw`` (a file's bytes, or its first bytes) is UTF-16 or holds NUL bytes."""
    if raw.startswith(UTF16_BOMS):
        raise error(f"{name} is UTF-16 text", "convert it to UTF-8, e.g. iconv -f UTF-16 -t UTF-8")
    if b"\x00" in raw:
        raise error(f"{name} is a binary file (it contains NUL bytes), not text", f"expected {expected}")


def decode(raw: bytes, name: str, error: type[CornerslamError], expected: str) -> str:
    """``raw`` as UTF-8 text, else ``error`` naming ``name`` and what is wrong with the bytes."""
    refuse_binary(raw, name, error, expected)
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = raw[: e.start].count(b"\n") + 1
        raise error(
            f"{name} is not UTF-8 text (byte 0x{raw[e.start]:02x} at line {line})", "save it as UTF-8"
        ) from None


def read_number_rows(
    path: str | Path,
    what: str,
    error: type[CornerslamError],
    item: str,
    layout: str,
    n: int,
    more_ok: bool = False,
    cut_last: Callable[[str], None] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Rows of ``n`` finite numbers (``more_ok``: at least ``n``, the first ``n`` kept), separated by
    spaces or commas; blank lines and ``#`` comments skipped; a file (or endless pipe) beyond
    :data:`MAX_ROWS_BYTES` is refused. Returns the values (k, n) and each row's
    line number (k,). ``item`` names one row ("TUM pose"), ``layout`` its columns; ``error`` is raised
    naming the file and line. ``cut_last``: a last line with too few numbers and no newline after it (a
    file cut short mid-line) is left out, said through it, instead of an error."""
    p = Path(path)
    name = f"{what} '{p}'"
    rows, lines = [], []
    text = read_text(p, what, error, f"a text file of {layout}", MAX_ROWS_BYTES)
    all_lines = text.splitlines()
    for lineno, line in enumerate(all_lines, 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.replace(",", " ").split()
        cut = cut_last is not None and lineno == len(all_lines) and not text.endswith(("\n", "\r"))
        try:
            v = [plain_float(x) for x in parts]
        except ValueError:
            if cut:  # cut inside a number ('-', '1e'): a line cut short, not a wrong one
                cut_last(f"{name} ends mid-line (line {lineno}, no newline): left out")
                continue
            raise error(f"{name} line {lineno} is not a {item}", f"expected: {layout}") from None
        if len(v) < n and cut:
            cut_last(f"{name} ends mid-line (line {lineno}: {len(v)} of {n} values, no newline): left out")
            continue
        if len(v) < n or (len(v) > n and not more_ok):
            kitti = "; 12 values: a KITTI pose file, which has no stamps? write it as TUM"
            hint = f"expected {n}: {layout}{kitti if (len(v), n) == (12, 8) else ''}"
            raise error(f"{name} line {lineno} has {len(v)} values", hint)
        if not all(map(math.isfinite, v[:n])):
            raise error(f"{name} line {lineno} has a value that is not finite", f"expected: {layout}")
        rows.append(v[:n])
        lines.append(lineno)
    if not rows:
        raise error(f"{name} has no {item}s", f"expected: {layout}")
    return np.array(rows, dtype=float), np.array(lines, dtype=np.int64)


def refuse_far(
    values: np.ndarray,
    lines: np.ndarray,
    columns: list[int],
    name: str,
    error: type[CornerslamError],
    layout: str,
    stamps: list[int],
) -> None:
    """Raise ``error`` naming the first line of ``values`` (rows of :func:`read_number_rows`, their
    ``lines``) whose position ``columns`` (metres) reach past :data:`MAX_POSITION`, or whose ``stamps``
    columns (seconds) past :data:`MAX_STAMP`: no score of it is a number."""
    far_stamp = np.any(np.abs(values[:, stamps]) > MAX_STAMP, axis=1)
    far = np.flatnonzero(far_stamp | np.any(np.abs(values[:, columns]) > MAX_POSITION, axis=1))
    if len(far):  # the first such line, whichever it has
        if far_stamp[far[0]]:
            what, hint = f"a stamp beyond ±{MAX_STAMP:.0e} s", "stamps are seconds"
        else:
            what, hint = f"a position beyond ±{MAX_POSITION:.0e} m", "positions are metres"
        raise error(f"{name} line {lines[far[0]]} has {what}", f"{hint}; expected: {layout}")
