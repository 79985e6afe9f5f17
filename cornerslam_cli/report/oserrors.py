"""An output's OSErrors as one-line errors (exit 2): the environment faults of writing.

:func:`output_error` maps the OSErrors of a hostile environment — read-only file
system, permission denied, disk full or over quota, a busy mount point, a cross-device rename, a name
too long, a file where a directory should be, a directory that refuses new entries (``/proc``) — to
an OutputError naming the path; others stay bugs.
"""

from __future__ import annotations

import errno
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from ..errors import OutputError

_DISK = "free some space, or write to another disk"
_MOUNT = "give a new directory inside it"
_LOOP = ("a symlink loop", "check the path")
_REASONS = {
    errno.EROFS: ("read-only file system", "write to a writable file system"),
    errno.EACCES: ("permission denied", "write where you have permission, or fix the permissions"),
    errno.EPERM: ("operation not permitted", "write where you have permission, or fix the permissions"),
    errno.ENOSPC: ("no space left on device", _DISK),
    errno.EDQUOT: ("disk quota exceeded", _DISK),
    errno.EBUSY: ("busy (a mount point?)", _MOUNT),
    errno.EXDEV: ("on another file system than its parent (a mount point?)", _MOUNT),
    errno.ENAMETOOLONG: ("name too long", "use a shorter name: at most 255 bytes"),
    errno.ENOTDIR: ("a part of the path is a file, not a directory", "check the path"),
    errno.EEXIST: ("a part of the path is a file, not a directory", "check the path"),
    errno.EISDIR: ("it is a directory", "give a file name"),
    errno.ELOOP: (_LOOP[0], _LOOP[1]),
}
# ENOENT where a file was to be created in a directory that exists but creates none (procfs)
_NO_NEW_FILES = ("its directory accepts no new files, as in /proc", "write to a directory on a disk")


def output_error(exc: OSError, path: str | Path) -> OutputError | None:
    """The one-line error for an OSError while writing ``path``; None when ``exc`` is not an
    environment fault (a bug stays a bug)."""
    reason = _REASONS.get(exc.errno)  # type: ignore[arg-type]
    if exc.errno == errno.ENOENT and exc.filename is not None and _creates_no_files(exc.filename):
        reason = _NO_NEW_FILES  # else a file or directory that should be there is not: a bug stays a bug
    if reason is None:
        return None
    return OutputError(f"cannot write '{path}': {reason[0]}", reason[1])


def _creates_no_files(filename: str | bytes) -> bool:
    """Whether ENOENT on ``filename`` is its directory refusing new files (/proc): the directory exists
    and creating a fresh file in it fails with ENOENT too (a read of a missing file, or a vanished
    directory, is not that)."""
    folder = os.path.dirname(os.fsdecode(filename)) or "."
    if not os.path.isdir(folder):
        return False
    probe = os.path.join(folder, f".cornerslam-probe-{os.getpid()}")
    try:
        os.close(os.open(probe, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600))
    except OSError as e:
        return e.errno == errno.ENOENT
    os.unlink(probe)
    return False


def resolved(path: Path) -> Path:
    """``path.resolve()``; a symlink loop on it (``out -> b -> out``) is the OutputError naming
    ``path`` (Python < 3.13 raises RuntimeError there; 3.13 returns the path and writing it gives ELOOP)."""
    try:
        return path.resolve()
    except RuntimeError:
        raise OutputError(f"cannot write '{path}': {_LOOP[0]}", _LOOP[1]) from None


@contextmanager
def output_errors(path: str | Path) -> Iterator[None]:
    """Turn an environment fault while writing ``path`` into its OutputError."""
    try:
        yield
    except OSError as exc:
        err = output_error(exc, path)
        if err is None:
            raise
        raise err from None
