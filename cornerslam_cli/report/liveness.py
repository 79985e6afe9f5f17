"""The hidden siblings an output is written through, and whether their writers are alive.

A writer stages beside its target NAME: ``.NAME.partial-HOST-PID-flock-XXXX`` (a staging directory,
or a file staged beside its target), ``.NAME.running-HOST-PID-flock`` (a batch's directory written in
place) and, inside a commit, ``.NAME.old-HOST-PID-flock-XXXX`` (the replaced directory) — HOST: 8 hex
digits of the host name's hash, PID: the writer's. It holds a shared ``flock`` on each of them for as
long as it writes it (:func:`make_held`; the fd is close-on-exec, kept by forked children). Whether the
writer lives is whether someone holds that flock (:func:`_judged` tries an exclusive one without
waiting): that holds across pid namespaces on one kernel, where a pid says nothing — a container
restarted after a SIGKILL is pid 1 again, and its leftover ``…-1-flock-…`` held by nobody is cleared,
while two containers sharing a host name and a volume both write as pid 1, and the other's held
staging is a live writer's, never deleted. A name without ``-flock`` is judged by its pid alive in
this pid namespace, as before: an older cornerslam's (it holds no flock), or one made where the file
system has no flock (ENOLCK, EOPNOTSUPP, ENOSYS; renamed to the name without the tag). Siblings of
other hosts (a shared file system) are left alone. Names over 200 bytes are shortened in these
sibling names (their start plus a hash), so a legal 255-byte name still stages.
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import os
import re
import shutil
import socket
import stat
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from ..errors import OutputError

_NAME_KEEP = 200  # bytes of a name kept in its sibling names (+ at most 51 of suffix: within 255)
HOST = hashlib.sha1(socket.gethostname().encode()).hexdigest()[:8]  # leftovers are judged on their host
TAG = "flock"  # after the pid in a sibling's name: its writer holds an flock on it while it lives
NO_FLOCK = (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS)  # a file system without flock
SIBLING = re.compile(rf"(partial|old|running)-([0-9a-f]{{8}})-(\d+)(-{TAG})?(?:-.+)?")
BOOKKEEPING = re.compile(rf"\..+\.(lock|{SIBLING.pattern})")  # a lock's name, a staging sibling's
HELD, ALIVE, LEFTOVER, GONE = "held", "alive", "leftover", "gone"  # a sibling's writer (see _judged)


def stem(name: str) -> str:
    """``name`` as it appears in its sibling names: shortened (start + hash) when it is long."""
    raw = os.fsencode(name)
    if len(raw) <= _NAME_KEEP:
        return name
    return os.fsdecode(raw[: _NAME_KEEP - 9]) + "~" + hashlib.sha1(raw).hexdigest()[:8]


def sibling_name(target: Path, what: str, held: bool = False) -> str:
    """The start of a hidden sibling's name owned by this process: ``.NAME.WHAT-HOST-PID``, then
    ``-flock`` when it is ``held`` (:func:`make_held`)."""
    return f".{stem(target.name)}.{what}-{HOST}-{os.getpid()}" + (f"-{TAG}" if held else "")


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # someone else's process
    return True


def remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def release(fd: int | None) -> None:
    """Close the fd holding a sibling's flock (None: none was held)."""
    if fd is not None:
        os.close(fd)


# ---------------------------------------------------------------------------- this process's siblings
def _lock_shared(fd: int) -> bool:
    """A shared flock on ``fd`` (waiting while a process clearing it as a leftover holds it); False
    where the file system has no flock."""
    try:
        fcntl.flock(fd, fcntl.LOCK_SH)
    except OSError as exc:
        if exc.errno not in NO_FLOCK:
            raise
        return False
    return True


def make_held(target: Path, what: str, make: Callable[[str], Path]) -> tuple[Path, int | None]:
    """A new hidden sibling of ``target`` made by ``make(start of its name)`` (owner-readable), and an
    fd holding a shared flock on it as long as this process writes it: close it (:func:`release`) once
    the sibling is committed or removed. Where there is no flock (or the sibling cannot be opened) it is
    renamed to the name without ``-flock``, judged by its pid, and the fd is None. One cleared in the
    instant before it was locked (another process found nobody holding it) is made again."""
    tagged, plain = sibling_name(target, what, held=True), sibling_name(target, what)
    while True:
        path = make(tagged)
        fd = None
        try:
            fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
            if _lock_shared(fd):
                if os.path.samestat(os.fstat(fd), os.lstat(path)):
                    return path, fd
                raise FileNotFoundError(path)  # (not the one made: it was cleared)
        except FileNotFoundError:
            release(fd)
            continue
        except OSError:
            pass  # cannot be opened (a umask without the owner's read): judged by its pid
        except BaseException:
            release(fd)
            remove(path)
            raise
        release(fd)
        untagged = path.with_name(plain + path.name[len(tagged) :])
        os.rename(path, untagged)
        return untagged, None


def hold(path: Path) -> int | None:
    """An fd holding a shared flock on the directory ``path`` (the output a commit replaces, about to
    be renamed to a sibling under the target's lock), or None when it cannot be held — without
    waiting: another process may hold an exclusive flock on a user's directory for as long as it likes
    (``flock DIR cmd``), and a commit waiting on it, its signals deferred, could not be interrupted."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        return fd
    except OSError:  # held exclusively by someone (BlockingIOError), or no flock there
        os.close(fd)
        return None


# ---------------------------------------------------------------------------- others' siblings
def _siblings(target: Path) -> Iterator[tuple[Path, str, str, int, bool]]:
    """(path, "partial", "old" or "running", host hash, pid, whether its name says it is held) of each
    hidden sibling beside ``target``."""
    prefix = f".{stem(target.name)}."
    try:
        names = os.listdir(target.parent)
    except OSError:
        return
    for name in names:
        m = SIBLING.fullmatch(name[len(prefix) :]) if name.startswith(prefix) else None
        if m is not None:
            yield target.parent / name, m[1], m[2], int(m[3]), m[4] is not None


def _probe(path: Path) -> tuple[int | None, str | None]:
    """Try an exclusive flock on ``path`` without waiting: (its fd, LEFTOVER) when nobody held it, the
    flock now this process's; (None, HELD) when someone holds it; (None, GONE); (None, None) when
    flock cannot tell (no flock there, not a file or directory — a device is not opened — unreadable)."""
    try:
        st = os.lstat(path)
        if not (stat.S_ISDIR(st.st_mode) or stat.S_ISREG(st.st_mode)):
            return None, None
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except FileNotFoundError:
        return None, GONE
    except OSError:
        return None, None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        if os.path.samestat(os.fstat(fd), os.lstat(path)):
            return fd, LEFTOVER
        state = GONE
    except BlockingIOError:
        state = HELD
    except FileNotFoundError:
        state = GONE
    except OSError:
        state = None
    except BaseException:
        os.close(fd)
        raise
    os.close(fd)
    return None, state


@contextmanager
def _judged(path: Path, pid: int, held: bool) -> Iterator[str]:
    """The writer of the hidden sibling ``path`` named with ``pid`` (``held``: its name says its writer
    holds its flock): HELD (someone holds the flock: a live writer, in any pid namespace of this
    kernel), ALIVE (no flock to tell by — an older cornerslam's name, no flock on its file system — and
    ``pid`` is alive in this pid namespace), LEFTOVER (nobody holds the flock, whatever ``pid`` says;
    or no flock to tell by and ``pid`` is dead) or GONE. A LEFTOVER's block runs holding its flock, so
    a writer that has just made it, not locked yet, waits and finds it gone (:func:`make_held`)."""
    fd, state = _probe(path) if held else (None, None)
    try:
        yield state or (ALIVE if alive(pid) else LEFTOVER)
    finally:
        release(fd)


def clear_stale(target: Path) -> None:
    """Clear the leftovers of dead writers on this host beside ``target`` (a ``.old`` directory comes
    back as ``target`` when that is missing). Those of live writers, or of other hosts (a shared file
    system), are left alone."""
    for path, what, host, pid, held in _siblings(target):
        if host != HOST:
            continue
        with _judged(path, pid, held) as state:
            if state != LEFTOVER:
                continue
            if what == "old" and not os.path.lexists(target):
                os.rename(path, target)
            else:
                remove(path)


def live_writer(target: Path) -> tuple[int, Path, bool] | None:
    """A live writer on this host staging ``target`` or writing in it (a batch): the pid its sibling
    names, that sibling, and whether it holds the sibling's flock (else only its pid, in this pid
    namespace, is alive: :func:`_judged`); None if there is none."""
    for path, what, host, pid, held in _siblings(target):
        if what in ("partial", "running") and host == HOST:
            with _judged(path, pid, held) as state:
                if state in (HELD, ALIVE):
                    return pid, path, state == HELD
    return None


def refuse_live_writer(target: Path, shown: str | Path) -> None:
    """Clear the leftovers beside ``target``, then OutputError when a live process on this host writes
    it (called under its lock: this process has made no sibling of it yet)."""
    clear_stale(target)
    if (found := live_writer(target)) is None:
        return
    pid, path, held = found
    if held:  # (its pid not this process's nor alive here: the writer is another pid namespace's)
        where = "" if pid != os.getpid() and alive(pid) else " in another container"
        raise OutputError(
            f"another cornerslam process (pid {pid}{where}) is writing '{shown}'",
            "wait for it to finish, or give another output directory",
        )
    if pid == os.getpid():  # an older cornerslam's name (no flock) or a file system without flock
        raise OutputError(
            f"another writer of '{shown}' has this process's pid {pid} ('{path.name}' beside it, holding no "
            "lock): a container's killed before a restart gave this one its pid, or a live one's in another "
            "container",
            f"if no other cornerslam writes '{shown}', remove '{path}'; else give another output directory",
        )
    raise OutputError(
        f"another cornerslam process (pid {pid}) is writing '{shown}'",
        f"wait for it to finish, or give another output directory (if pid {pid} is no cornerslam, remove "
        f"'{path}')",
    )
