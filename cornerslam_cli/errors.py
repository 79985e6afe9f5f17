"""Error types. Library code raises these; only ``cli.py`` turns them into exit codes.

A :class:`CornerslamError` is a *user* problem (bad file, bad key, missing topic): the CLI prints
``error: <msg> (<hint>)`` on one line and exits with code 2. Anything else is a bug (exit 1).
:func:`printable` / :func:`display_path` make text naming a file whose name is not UTF-8 safe to print
and to write to UTF-8 files and JSON (error lines are made so by ``CornerslamError.__str__``).
"""

from __future__ import annotations

import contextlib
import difflib
import errno
import os
import re
import tempfile
import traceback
from collections.abc import Collection, Iterable
from pathlib import Path


class CornerslamError(Exception):
    """A problem with the user's input, reported as one line and exit code 2."""

    def __init__(self, msg: str, hint: str | None = None):
        super().__init__(msg)
        self.msg = msg
        self.hint = hint

    def __str__(self) -> str:
        return printable(f"{self.msg} ({self.hint})" if self.hint else self.msg)


class LogError(CornerslamError):
    """The log cannot be read or lacks what a run needs (file, format, topic)."""


class ConfigError(CornerslamError):
    """A configuration file or ``--set`` override is invalid."""


class OutputError(CornerslamError):
    """An output path cannot be written (permissions, read-only or full disk, a mount point, a name
    too long) or must not be replaced (a directory cornerslam did not write)."""


class ResultsError(CornerslamError):
    """A run's results file (summary.json) cannot be read: missing, not JSON, or a key missing,
    unknown or of the wrong type (written by another version, or edited)."""


class NumericalError(CornerslamError):
    """The filter state became invalid (non-finite or non-symmetric covariance)."""


# the config key behind each option a hint may name: any command takes a --set of it instead
OPTION_OF = {
    "association.method": "--assoc",
    "input.scan_topic": "--scan-topic",
    "input.odom_topic": "--odom-topic",
    "input.laser_preset": "--preset",  # (config)
}


def for_command(text: str, options: Collection[str], swept: Collection[str] = ()) -> str:
    """An error's line as said to a command taking ``options``: an option of :data:`OPTION_OF` that the
    command does not take (``config`` and ``batch`` have no ``--scan-topic``) named as the ``--set``
    of its key (``--set input.scan_topic=TOPIC``), or as its ``--sweep`` when the key is one of
    ``swept`` (batch refuses a ``--set`` of a swept key). Library hints name the options of ``run``."""
    for key, option in OPTION_OF.items():
        if option not in options:
            placeholder = option.rsplit("-", 1)[-1].upper()
            given = f"--sweep {key}={placeholder},..." if key in swept else f"--set {key}={placeholder}"
            text = re.sub(rf"{re.escape(option)}(?![\w-])", given, text)
    return text


def one_line(e: BaseException) -> str:
    """An error as one line: a CornerslamError's message (and hint), a bug's type and message."""
    text = str(e) if isinstance(e, CornerslamError) else f"{type(e).__name__}: {e}"
    return " ".join(text.split())


def save_traceback(exc: BaseException) -> str:
    """Write the traceback of ``exc`` (a bug) to a new temporary file and say where, for the one line
    an internal error is reported as: "traceback saved to PATH". When no file can be written (no
    writable temporary directory, a full disk) it says so instead: the report stays one line (the
    OSError escaped as a second traceback, the bug's own printed above it)."""
    path = None
    try:
        fd, path = tempfile.mkstemp(prefix="cornerslam-crash-", suffix=".txt")
        with os.fdopen(fd, "w") as f:
            traceback.print_exception(type(exc), exc, exc.__traceback__, file=f)
    except OSError as e:
        if path is not None:
            with contextlib.suppress(OSError):
                os.unlink(path)
        where = "" if path is None else f" to {display_path(path)}"
        reason = e.strerror or str(e)
        return f"traceback not saved{where}: {reason}; set TMPDIR to a writable directory to keep it"
    return f"traceback saved to {display_path(path)}"


def printable(text: str) -> str:
    """``text`` with the undecodable bytes of a file name (``os.fsdecode``'s surrogate escapes) shown
    as U+FFFD, so that it can be printed and written to UTF-8 files and strict JSON."""
    try:
        raw = text.encode("utf-8", "surrogateescape")
    except UnicodeEncodeError:  # a lone surrogate that is no escaped byte
        raw = text.encode("utf-8", "replace")
    return raw.decode("utf-8", "replace")


_CONTROL = re.compile(r"[\x00-\x08\x0a-\x1f\x7f-\x9f]")


def terminal_safe(text: str) -> str:
    """``text`` with its control characters (a newline, an escape sequence's ESC, C1 codes; not a tab)
    escaped as ``repr`` does: a line for a terminal, whatever a file name or a log's topic held (a log
    named ``$'a\\nb.clf'`` split a warning in two, ``\\x1b[31m`` in one coloured the terminal)."""
    return _CONTROL.sub(lambda m: repr(m.group())[1:-1], text)


def display_path(path: str | Path) -> str:
    """A path as text for messages and summaries (:func:`printable`)."""
    return printable(os.fsdecode(path))


def symlink_loop(p: str | Path) -> bool:
    """Whether following ``p`` runs into a symlink loop (``a -> b -> a``): ``Path.exists()`` is False
    then too, so "does not exist" would be the wrong thing to say."""
    try:
        os.stat(p)
    except OSError as exc:
        return exc.errno == errno.ELOOP
    return False


def did_you_mean(
    word: str, choices: Iterable[str], cutoff: float = 0.6, then: str = "", prefix: str = ""
) -> str:
    """``"did you mean 'jcbb'?"`` + ``then`` naming the choice closest to ``word`` (difflib ratio at
    least ``cutoff``), or ``""`` when none is that close: the start of a hint. The choice is named
    after ``prefix`` (a config section's ``input.``), which takes no part in the match."""
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=cutoff)
    return f"did you mean '{prefix}{close[0]}'?{then}" if close else ""
