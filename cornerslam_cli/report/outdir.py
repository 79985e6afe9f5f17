"""Output places: which directories cornerslam may replace, and writing one atomically.

Ownership. Every output directory cornerslam writes carries a marker file, ``.cornerslam-output``:
JSON with the version, the kind (``run``, ``compare``, ``batch``), the log it was made from (resolved
path) and, for runs and comparisons, the names of the entries written. An existing directory is
replaced only when it is empty, or when it is a cornerslam output of the same kind that holds nothing
its marker does not list (subdirectories with their own marker are checked against theirs); never
when it holds an input of the run or the working directory, and never at a mount point. Outputs of
versions before the marker count by their own files: a ``summary.json`` beginning with
``cornerslam_version`` (run), ``comparison.csv`` or ``batch.csv`` with our header. Anything else is
refused with an :class:`OutputError` (exit 2) before any work. Replacing one's own output needs no
flag: rerunning into the same ``--out`` is the usual case. The default place
(``cornerslam_out/<stem>_<assoc>``) is named after the log's stem, which two logs can share
(``a/aces.log``, ``b/aces.log``): there, an output of another log is refused too, naming both
(:func:`check_same_log`), rather than silently replaced.

Staging. :class:`StagedDir` builds the directory in a hidden sibling ``.NAME.partial-HOST-PID-XXXX``
(HOST: 8 hex digits of the host name's hash; PID: the writing process) and renames it onto NAME in
:meth:`StagedDir.commit`; a file committed with it outside the directory (``--mcap-out``) is written
as a hidden ``.FILE.partial-HOST-PID-XXXX`` beside its target and renamed in the same commit. The
commit holds an exclusive ``flock`` on ``.NAME.lock`` beside the target (deleted on release), checks
the target again under it, and defers SIGINT/SIGTERM across its renames; an existing directory is
first renamed to ``.NAME.old-HOST-PID-XXXX`` and deleted after. Before staging, under the same lock,
the leftovers of dead processes on this host are cleared (a SIGKILLed run's staging directory is
removed; a ``.old`` one is renamed back if the target is missing — the kill fell between the two
renames — else removed), and a staging directory of a live process means another run is writing the
same place: refused, exit 2. Names over 200 bytes are shortened in these sibling names (their start
plus a hash), so a legal 255-byte name still stages. Directories are created with the permissions
the umask gives (``mkdtemp`` alone would give 0700).

Environment faults. :func:`output_error` maps the OSErrors of a hostile environment — read-only file
system, permission denied, disk full or over quota, a busy mount point, a cross-device rename, a name
too long, a file where a directory should be — to an OutputError naming the path; others stay bugs.
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import json
import os
import re
import secrets
import shutil
import signal
import socket
import tempfile
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from .. import __version__
from ..errors import OutputError

MARKER = ".cornerslam-output"
KINDS = ("run", "compare", "batch")
_LEGACY = (  # outputs written before the marker: (file, how it begins, kind)
    ("summary.json", b'{\n  "cornerslam_version"', "run"),
    ("comparison.csv", b"assoc,steps,landmarks,", "compare"),
    ("batch.csv", b"log,assoc,", "batch"),
)
_NAME_KEEP = 200  # bytes of a name kept in its sibling names (+ at most 45 of suffix: within 255)
HOST = hashlib.sha1(socket.gethostname().encode()).hexdigest()[:8]  # leftovers are judged on their host
_SIBLING = re.compile(r"(partial|old)-([0-9a-f]{8})-(\d+)(?:-.+)?")
_DISK = "free some space, or write to another disk"
_MOUNT = "give a new directory inside it"
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
}


# ---------------------------------------------------------------------------- environment faults
def output_error(exc: OSError, path: str | Path) -> OutputError | None:
    """The one-line error for an OSError while writing ``path``; None when ``exc`` is not an
    environment fault (a bug stays a bug)."""
    reason = _REASONS.get(exc.errno)  # type: ignore[arg-type]
    if reason is None:
        return None
    return OutputError(f"cannot write '{path}': {reason[0]}", reason[1])


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


# ---------------------------------------------------------------------------- ownership
def read_marker(path: Path) -> dict | None:
    """The marker of the directory ``path``, or None when it has none (or not ours)."""
    try:
        with open(path / MARKER, "rb") as f:
            marker = json.loads(f.read(1 << 20))
    except (OSError, ValueError):
        return None
    ok = isinstance(marker, dict) and "cornerslam" in marker and marker.get("kind") in KINDS
    return marker if ok else None


def output_kind(path: Path) -> str | None:
    """The kind of cornerslam output the directory ``path`` holds, or None (not ours)."""
    marker = read_marker(path)
    if marker is not None:
        return marker["kind"]
    for name, head, kind in _LEGACY:
        try:
            with open(path / name, "rb") as f:
                if f.read(len(head)) == head:
                    return kind
        except OSError:
            continue
    return None


def mark_output(path: Path, kind: str, log: Path | None = None) -> None:
    """Mark the directory ``path`` as a cornerslam output of ``kind`` made from ``log`` (recorded
    resolved); a run or comparison lists the entries it holds now (its complete contents)."""
    marker: dict = {"cornerslam": __version__, "kind": kind}
    if log is not None:
        marker["log"] = os.fsdecode(log.resolve())
    if kind != "batch":  # a batch directory grows as it runs: its own rows are checked one by one
        marker["files"] = [rel for rel, _ in _entries(path)]
    (path / MARKER).write_text(json.dumps(marker, indent=1) + "\n")


def _entries(path: Path, prefix: str = "") -> Iterator[tuple[str, Path]]:
    """(relative path, path) of every entry under ``path`` but the marker, sorted; a subdirectory
    is entered unless it is a symlink or carries its own marker (a compare's run directories)."""
    for entry in sorted(path.iterdir()):
        if entry.name == MARKER:
            continue
        rel = prefix + entry.name
        yield rel, entry
        if entry.is_dir() and not entry.is_symlink() and read_marker(entry) is None:
            yield from _entries(entry, rel + "/")


# what a run or compare directory held before the marker existed (version 0.1.0 and earlier)
_LEGACY_RUN_FILES = frozenset(
    "trajectory.tum trajectory.csv map.csv lines.csv timing.csv summary.json report.html "
    "map.png segments.png timing.png corners.png".split()
)
_LEGACY_COMPARE_FILES = frozenset(
    "comparison.csv report.html compare_matching.png compare_maps.png compare_timing.png".split()
)


def foreign_entries(path: Path) -> list[str]:
    """Entries of an output directory that cornerslam did not write, as relative paths: those its
    marker does not list (also inside its plain subdirectories, e.g. one made by ``--mcap-out
    OUT/sub/r.mcap``, and inside subdirectories that carry their own marker); for an output of a
    version before the marker, every entry but the files such a version wrote. The contents of a
    foreign directory are not listed."""
    marker = read_marker(path)
    if marker is None:
        return _foreign_legacy(path, output_kind(path))
    if "files" not in marker:
        return []
    listed = set(marker["files"])
    out: list[str] = []
    for rel, entry in _entries(path):
        if any(rel.startswith(f + "/") for f in out):
            continue  # inside a foreign directory: that one is named
        if rel not in listed:
            out.append(rel)
        elif entry.is_dir() and not entry.is_symlink() and read_marker(entry) is not None:
            out += [f"{rel}/{sub}" for sub in foreign_entries(entry)]
    return out


def _foreign_legacy(path: Path, kind: str | None) -> list[str]:
    """Entries of an unmarked run or compare directory that such a version did not write (a
    compare's run directories are checked as runs); a batch directory is checked row by row."""
    if kind not in ("run", "compare"):
        return []
    own = _LEGACY_RUN_FILES if kind == "run" else _LEGACY_COMPARE_FILES
    out: list[str] = []
    for entry in sorted(path.iterdir()):
        if entry.name in own and entry.is_file() and not entry.is_symlink():
            continue
        run_dir = kind == "compare" and entry.is_dir() and not entry.is_symlink()
        if run_dir and output_kind(entry) == "run":
            out += [f"{entry.name}/{sub}" for sub in foreign_entries(entry)]
        else:
            out.append(entry.name)
    return out


def _within(path: Path, directory: Path) -> bool:
    p = path.resolve()
    return p == directory or directory in p.parents


def _refuse_foreign(target: Path, kind: str, shown: Path) -> None:
    """Refuse an existing ``target`` that is a file, or a non-empty directory other than a
    cornerslam output of ``kind``."""
    if not os.path.lexists(target):
        return
    if not target.is_dir():
        raise OutputError(f"'{shown}' is a file, not a directory", "give a new directory")
    if not any(target.iterdir()):
        return  # an empty directory may be used
    owner = output_kind(target)
    if owner is None:
        raise OutputError(
            f"'{shown}' is not empty and was not written by cornerslam",
            "cornerslam replaces only its own outputs: give a new or empty directory",
        )
    if owner != kind:
        raise OutputError(
            f"'{shown}' holds a cornerslam {owner} output, not a {kind} output",
            "give another directory, or remove it yourself",
        )


def check_replaceable(
    target: Path, kind: str, inputs: Sequence[Path] = (), shown: Path | None = None
) -> None:
    """Refuse (OutputError) to replace ``target`` (resolved) by a ``kind`` output unless the module
    doc's rules allow it. ``inputs`` are the run's input files; ``shown`` names the target in errors."""
    shown = target if shown is None else shown
    _refuse_foreign(target, kind, shown)
    if not target.is_dir():
        return
    if os.path.ismount(target):
        raise OutputError(
            f"'{shown}' is a mount point: an output directory is renamed into place, which a mount "
            "point cannot be",
            f"give a new directory inside it, e.g. {shown / 'run1'}",
        )
    try:
        held = [(Path.cwd(), "the working directory")]
    except OSError:
        held = []
    held += [(Path(p), f"the input '{p}'") for p in inputs]
    for path, what in held:
        if _within(path, target):
            raise OutputError(f"'{shown}' holds {what}", "give another output directory")
    extra = foreign_entries(target)
    if extra:
        more = f" (and {len(extra) - 1} more)" if len(extra) > 1 else ""
        raise OutputError(
            f"'{shown}' holds '{extra[0]}'{more}, which cornerslam did not write",
            "move it out first, or give another output directory",
        )


def recorded_log(path: Path) -> Path | None:
    """The log the output directory ``path`` was made from: its marker's, else (an output of a
    version before it was recorded) the one its run's summary.json names, resolved from the working
    directory; None when neither says."""
    marker = read_marker(path) or {}
    if isinstance(marker.get("log"), str):
        return Path(marker["log"])
    summaries = [path / "summary.json", *sorted(path.glob("*/summary.json"))]  # a run; a compare's runs
    for summary in summaries:
        try:
            log = json.loads(summary.read_bytes()[: 1 << 24])["input"]["log"]
        except (OSError, ValueError, KeyError, TypeError):
            continue
        return Path(log).resolve() if isinstance(log, str) else None
    return None


def check_same_log(target: Path, log: Path, shown: Path) -> None:
    """Refuse (OutputError) to replace at ``target`` an output made from another log than ``log``:
    for the default place, named after the log's stem, which two logs may share."""
    other = recorded_log(target) if target.is_dir() else None
    if other is not None and other != log.resolve():
        raise OutputError(
            f"'{shown}' holds the output of '{other}', not of '{log}': the default output "
            "directory of both logs",
            "give this run its own --out, or remove the other output first",
        )


def refuse_special_file(path: Path, shown: str | Path) -> None:
    """Refuse (OutputError) to write the file ``path`` over a device, a pipe or a socket: writing one
    hangs or goes nowhere, and renaming a file onto it would replace the node (``/dev/null``)."""
    if os.path.exists(path) and not (path.is_file() or path.is_dir()):
        raise OutputError(
            f"'{shown}' is not a regular file (a device, pipe or socket)",
            "give the name of a file to write",
        )


def check_claimable(path: str | Path, kind: str) -> Path:
    """Refuse (OutputError) a ``path`` that :func:`claim_dir` would refuse, creating nothing;
    returns it resolved."""
    shown = Path(path)
    with output_errors(shown):
        target = shown.resolve()
        _refuse_foreign(target, kind, shown)
    return target


def claim_dir(path: str | Path, kind: str) -> Path:
    """Create or reuse the directory ``path`` for a ``kind`` output written in place (a batch: it
    is resumed, never replaced): refuse a file or a non-empty directory that is not ours, mark it."""
    target = check_claimable(path, kind)
    with output_errors(path):
        target.mkdir(parents=True, exist_ok=True)
        if read_marker(target) is None:
            mark_output(target, kind)
    return target


# ---------------------------------------------------------------------------- sibling names
def _stem(name: str) -> str:
    """``name`` as it appears in its sibling names: shortened (start + hash) when it is long."""
    raw = os.fsencode(name)
    if len(raw) <= _NAME_KEEP:
        return name
    return os.fsdecode(raw[: _NAME_KEEP - 9]) + "~" + hashlib.sha1(raw).hexdigest()[:8]


def _sibling(target: Path, what: str) -> str:
    """The start of a hidden sibling's name owned by this process: ``.NAME.WHAT-HOST-PID``."""
    return f".{_stem(target.name)}.{what}-{HOST}-{os.getpid()}"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # someone else's process
    return True


def _siblings(target: Path) -> Iterator[tuple[Path, str, str, int]]:
    """(path, "partial" or "old", host hash, pid) of each staging leftover beside ``target``."""
    prefix = f".{_stem(target.name)}."
    try:
        names = os.listdir(target.parent)
    except OSError:
        return
    for name in names:
        m = _SIBLING.fullmatch(name[len(prefix) :]) if name.startswith(prefix) else None
        if m is not None:
            yield target.parent / name, m[1], m[2], int(m[3])


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def clear_stale(target: Path) -> None:
    """Clear the staging leftovers of dead processes on this host beside ``target`` (a ``.old``
    directory comes back as ``target`` when that is missing). Those of live processes, or of other
    hosts (a shared file system), are left alone."""
    for path, what, host, pid in _siblings(target):
        if host != HOST or _alive(pid):
            continue
        if what == "old" and not os.path.lexists(target):
            os.rename(path, target)
        else:
            _remove(path)


def live_writer(target: Path) -> int | None:
    """The pid of a live process on this host staging ``target``, if any."""
    for _, what, host, pid in _siblings(target):
        if what == "partial" and host == HOST and _alive(pid):
            return pid
    return None


def _umask() -> int:
    """The process's umask: read from /proc (setting it to read it back races with other threads)."""
    try:
        with open("/proc/self/status") as f:
            return next(int(line.split()[1], 8) for line in f if line.startswith("Umask:"))
    except (OSError, StopIteration, ValueError, IndexError):
        mask = os.umask(0o022)
        os.umask(mask)
        return mask


def staged_file(dest: Path) -> Path:
    """A new empty hidden file beside ``dest`` to write it in, before renaming it onto ``dest``
    (with the mode the umask gives a new file; ``mkstemp`` alone gives 0600)."""
    fd, tmp = tempfile.mkstemp(prefix=_sibling(dest, "partial") + "-", dir=dest.parent)
    try:
        os.fchmod(fd, 0o666 & ~_umask())
    finally:
        os.close(fd)
    return Path(tmp)


@contextmanager
def target_lock(target: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``.NAME.lock`` beside ``target`` (waiting for another holder);
    the lock file is deleted on release. File systems without flock go unlocked."""
    path = target.parent / f".{_stem(target.name)}.lock"
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            if os.path.samestat(os.fstat(fd), os.stat(path)):
                break
        except FileNotFoundError:
            pass  # deleted by the holder we waited for: lock the next file
        except OSError as exc:
            if exc.errno not in (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS):
                os.close(fd)
                raise
            break
        except BaseException:
            os.close(fd)
            raise
        os.close(fd)
    try:
        yield
    finally:
        path.unlink(missing_ok=True)
        os.close(fd)


@contextmanager
def _signals_deferred() -> Iterator[None]:
    """SIGINT and SIGTERM wait until the block is done (then arrive as usual)."""
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _check_name(target: Path, shown: Path) -> None:
    try:
        limit = os.pathconf(target.parent, "PC_NAME_MAX")
    except (OSError, ValueError):
        limit = 255
    n = len(os.fsencode(target.name))
    if n > limit:
        raise OutputError(
            f"the name of '{shown}' is {n} bytes long, longer than the file system allows ({limit})",
            "use a shorter name",
        )


# ---------------------------------------------------------------------------- the staged directory
class StagedDir:
    """A ``kind`` output directory built in a hidden sibling and renamed onto ``target`` on
    :meth:`commit` (see the module doc).

    Creating it checks the place first (OutputError: not ours, an input inside, a mount point,
    unwritable, another run writing there). Use as a context manager: leaving the block without
    ``commit()`` (an exception, Ctrl-C) removes what was staged and leaves ``target`` as it was; an
    environment fault inside the block (disk full, ...) leaves as the OutputError naming the path.
    """

    def __init__(
        self,
        target: str | Path,
        kind: str = "run",
        inputs: Sequence[str | Path] = (),
        log: str | Path | None = None,
        own_log_only: bool = False,
    ):
        self.shown = Path(target)
        self.target = self.shown.resolve()
        self.kind = kind
        self.inputs = [Path(p) for p in inputs]
        self.log = None if log is None else Path(log)  # recorded in the marker
        self.own_log_only = own_log_only  # the default place: refuse another log's output there
        self.files: list[tuple[Path, Path]] = []  # (staged, final) files renamed by commit()
        self.committed = False
        with output_errors(self.shown):
            self._check_replaceable()
            self.target.parent.mkdir(parents=True, exist_ok=True)
            _check_name(self.target, self.shown)
            with target_lock(self.target):
                clear_stale(self.target)
                pid = live_writer(self.target)
                if pid is not None:
                    raise OutputError(
                        f"another cornerslam process (pid {pid}) is writing '{self.shown}'",
                        "wait for it to finish, or give another output directory",
                    )
                path = tempfile.mkdtemp(prefix=_sibling(self.target, "partial") + "-", dir=self.target.parent)
            self.path = Path(path)
            try:
                os.chmod(self.path, 0o777 & ~_umask())
            except BaseException:
                _remove(self.path)
                raise

    def _check_replaceable(self) -> None:
        check_replaceable(self.target, self.kind, self.inputs, self.shown)
        if self.own_log_only and self.log is not None:
            check_same_log(self.target, self.log, self.shown)

    def __enter__(self) -> StagedDir:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if not self.committed:
            _remove(self.path)
            for staged, _ in self.files:
                _remove(staged)
        elif isinstance(exc, KeyboardInterrupt):
            exc.output_written = self.shown  # type: ignore[attr-defined]  # the CLI says so
        if isinstance(exc, OSError) and self._ours(exc.filename):
            err = output_error(exc, self._public(exc.filename))
            if err is not None:
                raise err from None

    def _ours(self, filename) -> bool:
        """Whether an OSError's file is one this directory writes (None: a write to an open file)."""
        if filename is None:
            return True
        p = Path(os.fsdecode(filename))
        return _within(p, self.path) or p == self.target or any(p == s for s, _ in self.files)

    def _public(self, filename) -> Path:
        """The user's name for a staged path: its place in the committed output."""
        p = Path(os.fsdecode(filename)) if filename is not None else self.path
        if _within(p, self.path):
            return self.shown / p.resolve().relative_to(self.path.resolve())
        return next((final for staged, final in self.files if staged == p), self.shown)

    def stage_file(self, dest: str | Path) -> Path:
        """Where to write the file ``dest`` so that it is committed with this directory: inside the
        staging directory when ``dest`` lies in the target, else a hidden file beside ``dest`` (made
        now: an unwritable place fails before any work) that :meth:`commit` renames onto it."""
        shown = Path(dest)
        final = shown.resolve()
        with output_errors(shown):
            if _within(final, self.target):
                staged = self.path / final.relative_to(self.target)
                staged.parent.mkdir(parents=True, exist_ok=True)
                return staged
            if any(_within(final, p.resolve()) for p in self.inputs):
                raise OutputError(f"'{shown}' is an input of this run", "give another file name")
            if final.is_dir():
                raise OutputError(f"'{shown}' is a directory", "give a file name")
            refuse_special_file(final, shown)
            final.parent.mkdir(parents=True, exist_ok=True)
            clear_stale(final)
            staged = staged_file(final)
        self.files.append((staged, final))
        return staged

    def commit(self) -> Path:
        """Rename the finished staging directory onto the target, and each staged file onto its own
        target, under the target's lock; returns the target."""
        with target_lock(self.target):
            self._check_replaceable()  # it may have changed
            mark_output(self.path, self.kind, self.log)
            with _signals_deferred():
                old = self._swap()
                for staged, final in self.files:
                    os.replace(staged, final)
                self.committed = True
            if old is not None:
                _remove(old)
        return self.target

    def _swap(self) -> Path | None:
        """The staging directory onto the target; returns where a replaced directory went."""
        if not os.path.lexists(self.target) or not any(self.target.iterdir()):
            os.rename(self.path, self.target)  # new, or over an empty directory
            return None
        old = self.target.parent / f"{_sibling(self.target, 'old')}-{secrets.token_hex(4)}"
        os.rename(self.target, old)
        try:
            os.rename(self.path, self.target)
        except BaseException:
            os.rename(old, self.target)
            raise
        return old
