"""Whose hidden siblings beside an output are alive (report/liveness.py): a writer holds an flock on its
staging directory, its staged files and a batch's mark, so a leftover of a killed writer is told from a
live writer whatever pid its name carries — the pid a container restarted after a SIGKILL gets again
(pid 1), or a live writer's in another pid namespace (two containers sharing a host name and a volume).
Another pid namespace is played here by a process that makes a sibling carrying a pid it does not have
and holds its flock. Names without the tag (an older cornerslam's) keep the pid rule, as does a file
system without flock."""

from __future__ import annotations

import errno
import fcntl
import os
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from cornerslam_cli.cli import cli
from cornerslam_cli.errors import OutputError
from cornerslam_cli.report import liveness
from cornerslam_cli.report.liveness import HOST, TAG, clear_stale, make_held
from cornerslam_cli.report.outdir import StagedDir, alone_in, staged_files, staged_write

HOLDER = """
import fcntl, os, sys, time
path = sys.argv[1]
os.mkdir(path) if sys.argv[2] == "partial" else open(path, "w").close()
fcntl.flock(os.open(path, os.O_RDONLY), fcntl.LOCK_SH)
print("held", flush=True)
time.sleep(120)
"""


def dead_pid() -> int:
    """The pid of a process that has just exited."""
    proc = subprocess.Popen(["true"])
    proc.wait()
    return proc.pid


def left(out: Path, what: str, pid: int, tag: bool = True) -> Path:
    """The name a writer with ``pid`` gives its sibling ``what`` beside ``out`` (``tag``: this version's)."""
    name = f".{out.name}.{what}-{HOST}-{pid}" + (f"-{TAG}" if tag else "")
    return out.parent / (name + ("-abcd1234" if what in ("partial", "old") else ""))


def make(path: Path) -> Path:
    path.mkdir() if ".partial-" in path.name or ".old-" in path.name else path.touch()
    return path


def writes(out: Path, what: str) -> None:
    """Write ``out`` as a run does (``partial``: staged and committed) or as a batch does (``running``)."""
    if what == "partial":
        with StagedDir(out) as st:
            (st.path / "a.csv").write_text("x\n")
            st.commit()
        assert (out / "a.csv").read_text() == "x\n"
    else:
        with alone_in(out, out):
            pass


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


def siblings(d: Path) -> list[str]:
    return sorted(p.name for p in d.iterdir() if p.name.startswith("."))


@pytest.fixture
def held(tmp_path):
    """Start a process that makes the sibling at a path and holds its flock (another container's writer,
    whatever pid its name says); ended after the test."""
    procs = []

    def start(path: Path) -> Path:
        what = "partial" if ".partial-" in path.name else "running"
        proc = subprocess.Popen([sys.executable, "-c", HOLDER, str(path), what], stdout=subprocess.PIPE)
        procs.append(proc)
        assert proc.stdout.readline() == b"held\n"
        return path

    yield start
    for proc in procs:
        proc.kill()
        proc.communicate()


# ---------------------------------------------------------------------------- leftovers: held by nobody
@pytest.mark.parametrize("what", ["partial", "running"])
@pytest.mark.parametrize("whose", ["this process's pid", "pid 1", "a live pid"])
def test_a_leftover_nobody_holds_is_cleared_whatever_pid_it_names(tmp_path, what, whose):
    """A container restarted after a SIGKILL is pid 1 again: its leftover carries a live pid (its own,
    or any running one), and nobody holds its flock — cleared, the output written (before: refused,
    'remove it by hand')."""
    pid = {"this process's pid": os.getpid(), "pid 1": 1, "a live pid": os.getppid()}[whose]
    out = tmp_path / "out"
    stale = make(left(out, what, pid))
    writes(out, what)
    assert not stale.exists() and siblings(tmp_path) == []


@pytest.mark.parametrize("what", ["partial", "running"])
def test_a_run_and_a_batch_clear_a_leftover_of_their_own_pid(tmp_path, sim_log, what):
    """The same through the command line: `run` and `batch` into a place beside a leftover with this
    process's pid (a restarted container's) write it."""
    for cmd in (["run", sim_log], ["batch", sim_log, "--assoc", "icnn", "--jobs", "1"]):
        out = tmp_path / cmd[0]
        stale = make(left(out, what, os.getpid()))
        res = invoke(*cmd, "--out", out, "-q")
        assert res.exit_code == 0, res.output
        assert not stale.exists() and siblings(tmp_path) == []


def test_a_commit_killed_between_its_renames_with_this_processs_pid_is_put_back(tmp_path):
    """A ``.old`` directory of a commit killed between its two renames, its name carrying this process's
    pid (a restarted container) and nobody holding it: renamed back onto the missing target."""
    out = tmp_path / "out"
    aside = make(left(out, "old", os.getpid()))
    (aside / "summary.json").write_text("{}\n")
    clear_stale(out)
    assert (out / "summary.json").is_file() and not aside.exists()


# ---------------------------------------------------------------------------- live writers: held
@pytest.mark.parametrize("what", ["partial", "running"])
@pytest.mark.parametrize("whose", ["this process's pid", "a pid dead here"])
def test_a_sibling_held_by_a_live_writer_is_refused_and_never_deleted(tmp_path, held, what, whose):
    """Another container's live writer, sharing the host name and the volume: its sibling names a pid
    that says nothing here (this process's own, or one dead in this pid namespace — the pid rule deleted
    that one's staging: data loss), but it holds the flock: refused, exit 2, saying so; kept."""
    pid = os.getpid() if whose == "this process's pid" else dead_pid()
    out = tmp_path / "out"
    theirs = held(left(out, what, pid))
    refused = f"another cornerslam process (pid {pid} in another container) is writing '{out}'"
    for other in ("partial", "running"):
        with pytest.raises(OutputError) as err:
            writes(out, other)
        assert str(err.value).startswith(refused), str(err.value)
        assert "wait for it to finish, or give another output directory" in str(err.value)
    clear_stale(out)
    assert theirs.exists() and siblings(tmp_path) == [theirs.name] and not out.exists()


@pytest.mark.parametrize("what", ["partial", "running"])
def test_a_run_and_a_batch_beside_a_held_sibling_of_their_own_pid_exit_2(tmp_path, sim_log, held, what):
    """Through the command line: one line, exit 2, the other writer's sibling kept."""
    for cmd in (["run", sim_log], ["batch", sim_log, "--assoc", "icnn", "--jobs", "1"]):
        out = tmp_path / cmd[0]
        theirs = held(left(out, what, os.getpid()))
        res = invoke(*cmd, "--out", out, "-q")
        assert res.exit_code == 2, res.output
        assert res.stderr.strip().splitlines()[-1] == (
            f"error: another cornerslam process (pid {os.getpid()} in another container) is writing '{out}' "
            "(wait for it to finish, or give another output directory)"
        )
        assert theirs.exists() and not (out / "summary.json").exists() and not (out / "batch.csv").exists()


# ---------------------------------------------------------------------------- the pid rule, kept
@pytest.mark.parametrize("what", ["partial", "running"])
def test_an_older_versions_sibling_keeps_the_pid_rule(tmp_path, what):
    """A name without the tag (an older cornerslam's, which holds no flock): a live pid's is refused and
    kept, a dead pid's cleared (a guard of the unchanged rule: it passed before the flocks too)."""
    out = tmp_path / "out"
    live = make(left(out, what, os.getppid(), tag=False))
    with pytest.raises(OutputError, match=rf"another cornerslam process \(pid {os.getppid()}\) is writing"):
        writes(out, what)
    assert live.exists()
    live.rename(left(out, what, dead_pid(), tag=False))
    writes(out, what)
    assert siblings(tmp_path) == []


@pytest.mark.parametrize("code", [errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS])
def test_without_flock_siblings_go_by_their_pid(tmp_path, monkeypatch, code):
    """A file system without flock (fcntl.flock fails): a writer's staging and mark are named without
    the tag, and every sibling is judged by its pid — a tagged one of a live pid refused and kept (it
    cannot be told from a live writer), of a dead pid cleared."""

    def no_flock(fd, op):
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr(fcntl, "flock", no_flock)
    out = tmp_path / "out"
    live = make(left(out, "partial", os.getppid()))
    with pytest.raises(OutputError, match=rf"another cornerslam process \(pid {os.getppid()}\) is writing"):
        writes(out, "running")
    assert live.exists()
    live.rename(left(out, "partial", dead_pid()))
    with StagedDir(out) as st:
        assert st.path.name.startswith(f".out.partial-{HOST}-{os.getpid()}-") and TAG not in st.path.name
        assert st.held == [None]
        with pytest.raises(OutputError, match=f"has this process's pid {os.getpid()}"):
            StagedDir(out)  # (this process's staging, by pid: not told from a restarted container's)
        st.commit()
    with alone_in(out, out):
        assert siblings(tmp_path) == [f".out.running-{HOST}-{os.getpid()}"]
    assert siblings(tmp_path) == []


# ---------------------------------------------------------------------------- this process's flocks
def test_a_sibling_cleared_before_it_was_locked_is_made_again(tmp_path):
    """Another process clearing leftovers in the instant between the making of a sibling and its
    flock finds nobody holding it and removes it: the writer makes another, and holds it."""
    out = tmp_path / "out"
    made = []

    def make_then_cleared(start: str) -> Path:
        path = make(tmp_path / f"{start}-{len(made):08d}")
        made.append(path)
        if len(made) == 1:
            clear_stale(out)
        return path

    path, fd = make_held(out, "partial", make_then_cleared)
    try:
        assert path == made[1] and path.is_dir() and not made[0].exists()
        clear_stale(out)
        assert path.is_dir()
    finally:
        os.close(fd)


def _fds() -> dict[int, str]:
    """This process's open fds and what each is open on."""
    found = {}
    for n in os.listdir("/proc/self/fd"):
        try:
            found[int(n)] = os.readlink(f"/proc/self/fd/{n}")
        except FileNotFoundError:
            pass  # (listdir's own)
    return found


@pytest.mark.skipif(not os.path.isdir("/proc/self/fd"), reason="needs Linux's /proc")
def test_the_flocks_are_released_when_the_writing_ends(tmp_path, sim_log):
    """One close-on-exec fd per sibling while it is written, none after: committed, failed, interrupted;
    a batch holds only its mark's (its spawned workers each hold the run they stage)."""
    out = tmp_path / "out"

    def ours() -> dict[int, str]:  # (another test's fd, closed by the garbage collector meanwhile, is not)
        return {fd: what for fd, what in _fds().items() if str(tmp_path) in what}

    before = ours()
    with StagedDir(out) as st:
        mc = st.stage_file(tmp_path / "r.mcap")
        fds = [fd for fd, what in ours().items() if ".partial-" in what]
        assert len(fds) == 2 and not any(os.get_inheritable(fd) for fd in fds)
        mc.write_text("x")
        st.commit()
    assert ours() == before
    for stop in (RuntimeError, KeyboardInterrupt):
        with pytest.raises(stop), StagedDir(out) as st:
            st.stage_file(tmp_path / "r.mcap")
            raise stop
        assert ours() == before and siblings(tmp_path) == []
    with staged_write(tmp_path / "f.csv") as tmp:
        tmp.write_text("x\n")
    with pytest.raises(RuntimeError), staged_files([tmp_path / "g", tmp_path / "h"]):
        raise RuntimeError
    assert ours() == before
    assert invoke("run", sim_log, "--out", out, "--mcap-out", tmp_path / "s.mcap", "-q").exit_code == 0
    assert (
        invoke(
            "batch", sim_log, "--assoc", "icnn,pca", "--jobs", "1", "--out", tmp_path / "b", "-q"
        ).exit_code
        == 0
    )
    assert ours() == before and siblings(tmp_path) == []


def test_a_replaced_directory_is_held_while_it_is_aside(tmp_path, monkeypatch):
    """The ``.old`` directory a commit moves the previous output to carries the tag and is held until it
    is deleted: another writer's clearing, between the two renames, leaves it alone."""
    out = tmp_path / "out"
    writes(out, "partial")
    seen = []

    def cleared_first(path: Path) -> None:
        if ".old-" in path.name:
            assert f"-{os.getpid()}-{TAG}-" in path.name
            clear_stale(out)  # (as another process would: it is held)
            seen.append(path.is_dir())
        liveness.remove(path)

    monkeypatch.setattr("cornerslam_cli.report.outdir.remove", cleared_first)
    writes(out, "partial")
    assert seen == [True] and siblings(tmp_path) == []


def test_a_commit_does_not_wait_on_a_users_flock_of_the_output(tmp_path):
    """`flock OUT cornerslam run … --out OUT` (a job-serialising pattern): the commit waited for ever for
    a shared flock on the output it replaces, its SIGINT and SIGTERM deferred — only SIGKILL ended it (a
    review). Now it does not wait: the replaced directory goes aside untagged, judged by its pid."""
    out = tmp_path / "out"
    writes(out, "partial")
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLD_EX, str(out)], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL
    )
    try:
        assert holder.stdout.readline() == b"held\n"
        done = subprocess.run(
            [sys.executable, "-c", WRITE_AGAIN, str(out)], capture_output=True, text=True, timeout=60
        )
    finally:
        holder.kill()
        holder.communicate()
    assert done.returncode == 0, done.stderr
    assert (out / "a.csv").read_text() == "y\n" and siblings(tmp_path) == []


HOLD_EX = """
import fcntl, os, sys, time
fcntl.flock(os.open(sys.argv[1], os.O_RDONLY), fcntl.LOCK_EX)
print("held", flush=True)
time.sleep(120)
"""
WRITE_AGAIN = """
import sys
from pathlib import Path
from cornerslam_cli.report.outdir import StagedDir
with StagedDir(Path(sys.argv[1])) as st:
    (st.path / "a.csv").write_text("y\\n")
    st.commit()
"""
