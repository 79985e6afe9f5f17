"""Writing an output atomically: staged beside its place, committed by rename.

:class:`StagedDir` builds the directory in a hidden sibling ``.NAME.partial-HOST-PID-flock-XXXX``
(HOST: 8 hex digits of the host name's hash; PID: the writing process) and renames it onto NAME in
:meth:`StagedDir.commit`; a file committed with it outside the directory (``--mcap-out``) is written
as a hidden ``.FILE.partial-HOST-PID-flock-XXXX`` beside its target and renamed in the same commit.
The writer holds an flock on each such sibling while it writes it, and so is told from a leftover
(report/liveness.py: the names, and who is alive). The commit holds an exclusive ``flock`` on
``.NAME.lock`` beside the target (deleted on release), checks the target again under it, and defers
SIGINT/SIGTERM across its renames; an existing directory is first renamed to
``.NAME.old-HOST-PID-flock-XXXX`` and deleted after. Before staging, under the same lock, the
leftovers of dead writers on this host are cleared (a SIGKILLed run's staging directory is removed; a
``.old`` one is renamed back if the target is missing — the kill fell between the two renames — else
removed), and a staging directory of a live writer means another run is writing the same place:
refused, exit 2. Directories are created with the permissions the umask gives (``mkdtemp`` alone would
give 0700).

A directory written in place (a batch's) is marked by a hidden ``.NAME.running-HOST-PID-flock``
beside it while it is written (:func:`alone_in`): a second writer is refused the same way.

Which places may be replaced: report/ownership.py; environment faults as one-line errors:
report/oserrors.py.
"""

from __future__ import annotations

import fcntl
import os
import secrets
import stat
import tempfile
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from ..errors import OutputError
from ..workers import signals_deferred
from .liveness import (
    BOOKKEEPING,
    NO_FLOCK,
    clear_stale,
    hold,
    make_held,
    refuse_live_writer,
    release,
    remove,
    sibling_name,
    stem,
)
from .oserrors import output_error, output_errors, resolved
from .ownership import MARKER, check_replaceable, check_same_log, is_within, mark_output, refuse_special_file

LOCK_MARK = b"cornerslam output lock\n"  # what a lock file holds (an empty one: being created)


@contextmanager
def alone_in(target: Path, shown: str | Path) -> Iterator[None]:
    """Write in the directory ``target`` in place over the ``with`` block (a batch's, resumed, never
    staged whole) as its only writer: a hidden ``.NAME.running-HOST-PID-flock`` beside it, made and held
    under its lock, marks it; another live writer's mark or staging refuses (OutputError, exit 2), as a
    staged output's does, and a staged output refuses this mark. Removed at the end; a killed process's
    is cleared."""
    with output_errors(shown), target_lock(target):  # (a read-only or full disk: its one-line error)
        refuse_live_writer(target, shown)
        mark, fd = make_held(target, "running", lambda start: _new_file(target.parent / start))
    try:
        yield
    finally:
        mark.unlink(missing_ok=True)
        release(fd)


def _new_file(path: Path) -> Path:
    os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o666))
    return path


def _umask() -> int:
    """The process's umask: read from /proc (setting it to read it back races with other threads)."""
    try:
        with open("/proc/self/status") as f:
            return next(int(line.split()[1], 8) for line in f if line.startswith("Umask:"))
    except (OSError, StopIteration, ValueError, IndexError):
        mask = os.umask(0o022)
        os.umask(mask)
        return mask


def _temp_file(parent: Path, start: str) -> Path:
    fd, tmp = tempfile.mkstemp(prefix=start + "-", dir=parent)
    os.close(fd)
    return Path(tmp)


def _missing_dirs(d: Path) -> list[Path]:
    """``d`` and the directories above it that do not exist, deepest first: those a mkdir -p makes."""
    return [p for p in (d, *d.parents) if not p.exists()]


def _staged_file(dest: Path) -> tuple[Path, int | None]:
    """A new empty hidden file beside ``dest`` to write it in, before renaming it onto ``dest`` (with the
    mode the umask gives a new file; ``mkstemp`` alone gives 0600), and the fd holding its flock."""
    tmp, fd = make_held(dest, "partial", lambda start: _temp_file(dest.parent, start))
    try:
        os.chmod(tmp, 0o666 & ~_umask())
    except BaseException:
        tmp.unlink(missing_ok=True)
        release(fd)
        raise
    return tmp, fd


@contextmanager
def staged_files(dests: Sequence[Path]) -> Iterator[dict[Path, Path]]:
    """A new hidden file beside each of ``dests`` to write it in (leftovers of killed writers cleared
    first; made before any work: an unwritable place fails at once), for the block to rename onto its
    ``dest``; what is left of them is removed, and their flocks released, when the block ends."""
    staged: dict[Path, tuple[Path, int | None]] = {}
    try:
        for dest in dests:
            clear_stale(dest)
            staged[dest] = _staged_file(dest)
        yield {dest: tmp for dest, (tmp, _) in staged.items()}
    finally:
        for tmp, fd in staged.values():
            tmp.unlink(missing_ok=True)
            release(fd)


@contextmanager
def staged_write(dest: Path) -> Iterator[Path]:
    """A hidden file beside ``dest`` to write the whole of it in (:func:`staged_files`), renamed onto
    ``dest`` when the block ends, with the mode of the file it replaces; removed when the block raises
    (an error, Ctrl-C): ``dest`` is never seen half written."""
    with staged_files([dest]) as staged:
        tmp = staged[dest]
        yield tmp
        if dest.is_file():
            os.chmod(tmp, stat.S_IMODE(os.stat(dest).st_mode))
        os.replace(tmp, dest)


def _open_lock(path: Path) -> int:
    """Open (create) the lock file ``path``; OutputError when something not cornerslam's is there (a
    symlink, a directory, a file holding anything but ``LOCK_MARK``): it is deleted on release."""
    why = "move it away (cornerslam deletes its lock file after use), or give another output name"
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o666)
    except OSError:  # a symlink (ELOOP), a directory (EISDIR), a socket (ENXIO): anything but a file
        if os.path.lexists(path) and not stat.S_ISREG(os.lstat(path).st_mode):
            raise OutputError(f"'{path}' is in the way of cornerslam's lock file there", why) from None
        raise
    regular = stat.S_ISREG(os.fstat(fd).st_mode)  # (a FIFO is not read: pread would fail on it)
    if not regular or not LOCK_MARK.startswith(os.pread(fd, len(LOCK_MARK) + 1, 0)):
        os.close(fd)
        raise OutputError(f"'{path}' exists and is not a lock file cornerslam wrote", why)
    return fd


@contextmanager
def target_lock(target: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``.NAME.lock`` beside ``target`` (waiting for another holder);
    the lock file, marked ``LOCK_MARK``, is deleted on release — one that is not cornerslam's is
    refused (:func:`_open_lock`). File systems without flock go unlocked."""
    path = target.parent / f".{stem(target.name)}.lock"
    while True:
        fd = _open_lock(path)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            if os.path.samestat(os.fstat(fd), os.stat(path)):
                break
        except FileNotFoundError:
            pass  # deleted by the holder we waited for: lock the next file
        except OSError as exc:
            if exc.errno not in NO_FLOCK:
                os.close(fd)
                raise
            break
        except BaseException:
            os.close(fd)
            raise
        os.close(fd)
    try:
        if os.fstat(fd).st_size == 0:
            os.pwrite(fd, LOCK_MARK, 0)
        yield
    finally:
        path.unlink(missing_ok=True)
        os.close(fd)


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


def refuse_directory_name(dest: str | Path, hint: str = "give a file name") -> None:
    """OutputError when ``dest``, a file's name as given, names a directory (``a.mcap/``, ``a.mcap/.``):
    Path drops what said so, and would write the file ``a.mcap``."""
    text = os.fspath(dest)
    if text.endswith(("/", os.sep)) or os.path.basename(text) in (".", ".."):
        raise OutputError(f"'{text}' names a directory", hint)


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
        inside: str | None = None,
    ):
        self.shown = Path(target)
        self.target = resolved(self.shown)
        self.kind = kind
        self.inputs = [Path(p) for p in inputs]
        self.log = None if log is None else Path(log)  # recorded in the marker
        self.own_log_only = own_log_only  # the default place: refuse another log's output there
        self.said_other = False  # a given place's output of another log has been said to be replaced
        self.inside = inside  # the kind of output this one is part of (a batch's run), or None
        self.files: list[tuple[Path, Path]] = []  # (staged, final) files renamed by commit()
        self.held: list[int | None] = []  # the fds holding the flocks of the staging directory and files
        self.committed = False
        with output_errors(self.shown):
            self._check_replaceable()
            # the directories above the target (and above each staged file) this output makes, deepest
            # first: an output not committed takes them away
            self.made: list[list[Path]] = [_missing_dirs(self.target.parent)]
            self.target.parent.mkdir(parents=True, exist_ok=True)
            try:
                self.path = self._stage()
            except BaseException:
                self._unmake()
                raise

    def _stage(self) -> Path:
        """The hidden staging directory beside the target, made under the target's lock."""
        _check_name(self.target, self.shown)
        with target_lock(self.target):
            refuse_live_writer(self.target, self.shown)
            path, fd = make_held(self.target, "partial", self._temp_dir)
        self.held.append(fd)
        try:
            os.chmod(path, 0o777 & ~_umask())
        except BaseException:
            remove(path)
            self._release()
            raise
        return path

    def _temp_dir(self, start: str) -> Path:
        return Path(tempfile.mkdtemp(prefix=start + "-", dir=self.target.parent))

    def _release(self) -> None:
        """Release the flocks of what this output staged (committed or removed)."""
        while self.held:
            release(self.held.pop())

    def _unmake(self) -> None:
        """Take away the directories above the target and the staged files this output made (``made``),
        the last made first, each deepest first; one another file has come into since is left, and
        those above it."""
        for chain in reversed(self.made):
            for d in chain:
                try:
                    d.rmdir()
                except OSError:
                    break

    def _check_replaceable(self) -> None:
        check_replaceable(self.target, self.kind, self.inputs, self.shown, self.inside)
        if self.log is not None and not self.said_other:  # (checked again at the commit: said once)
            self.said_other = check_same_log(self.target, self.log, self.shown, self.kind, self.own_log_only)

    def __enter__(self) -> StagedDir:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            if not self.committed:
                remove(self.path)
                for staged, _ in self.files:
                    remove(staged)
                self._unmake()
        finally:
            self._release()
        if self.committed and isinstance(exc, KeyboardInterrupt):
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
        return is_within(p, self.path) or p == self.target or any(p == s for s, _ in self.files)

    def _public(self, filename) -> Path:
        """The user's name for a staged path: its place in the committed output."""
        p = Path(os.fsdecode(filename)) if filename is not None else self.path
        if is_within(p, self.path):
            return self.shown / p.resolve().relative_to(self.path.resolve())
        return next((final for staged, final in self.files if staged == p), self.shown)

    def stage_file(self, dest: str | Path, ours: Callable[[Path], bool] | None = None) -> Path:
        """Where to write the file ``dest`` so that it is committed with this directory: inside the
        staging directory when ``dest`` lies in the target, else a hidden file beside ``dest`` (made
        now: an unwritable place fails before any work) that :meth:`commit` renames onto it. Outside
        the target an existing ``dest`` is replaced only when ``ours(dest)`` says cornerslam wrote it
        (``None``: any file)."""
        shown = Path(dest)
        refuse_directory_name(dest)
        final = resolved(shown)
        with output_errors(shown):
            if final.name == MARKER or BOOKKEEPING.fullmatch(final.name):
                why = "give another file name"
                raise OutputError(f"'{shown}' is a name cornerslam uses for its own bookkeeping", why)
            if is_within(final, self.target):
                staged = self.path / final.relative_to(self.target)
                staged.parent.mkdir(parents=True, exist_ok=True)
                return staged
            if any(is_within(final, p.resolve()) for p in self.inputs):
                raise OutputError(f"'{shown}' is an input of this run", "give another file name")
            if final.is_dir():
                raise OutputError(f"'{shown}' is a directory", "give a file name")
            refuse_special_file(final, shown)
            if ours is not None and final.is_file() and not ours(final):
                why = "give a new file name, or move that file away"
                raise OutputError(f"'{shown}' exists and is not a results file cornerslam wrote", why)
            self.made.append(_missing_dirs(final.parent))  # (--mcap-out new/r.mcap: new/ left after Ctrl-C)
            final.parent.mkdir(parents=True, exist_ok=True)
            clear_stale(final)
            staged, fd = _staged_file(final)
        self.held.append(fd)
        self.files.append((staged, final))
        return staged

    def commit(self) -> Path:
        """Rename the finished staging directory onto the target, and each staged file onto its own
        target, under the target's lock; returns the target."""
        with target_lock(self.target):
            self._check_replaceable()  # it may have changed
            mark_output(self.path, self.kind, self.log)
            old, held = None, None
            try:
                with signals_deferred():
                    old, held = self._swap()
                    for staged, final in self.files:
                        os.replace(staged, final)
                    self.committed = True
                if old is not None:
                    remove(old)
            finally:
                release(held)
        self._release()  # (the renames kept the inodes: held until now)
        return self.target

    def _swap(self) -> tuple[Path | None, int | None]:
        """The staging directory onto the target; returns where a replaced directory went, and the fd
        holding its flock (None: none held)."""
        if not os.path.lexists(self.target) or not any(self.target.iterdir()):
            os.rename(self.path, self.target)  # new, or over an empty directory
            return None, None
        held = hold(self.target)
        start = sibling_name(self.target, "old", held=held is not None)
        old = self.target.parent / f"{start}-{secrets.token_hex(4)}"
        try:
            os.rename(self.target, old)
            try:
                os.rename(self.path, self.target)
            except BaseException:
                os.rename(old, self.target)
                raise
        except BaseException:
            release(held)
            raise
        return old, held
