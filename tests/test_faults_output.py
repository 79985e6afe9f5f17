"""Output faults: what cornerslam does when the place it writes to is not its own, read-only, full,
busy or in use by another run; and that a closed stdout is no internal error.

``OUTPUT_FAULTS`` is the table: one scenario per class, each with an ``Expected`` as in the input
fault corpus (tests/fault_corpus.py: the behaviour line for docs/results/reliability.md, the exit
code, fragments of the last stderr line) and a setup that builds the place in a temporary directory.
What a test running as root cannot produce for real — a read-only file system, permission denied, a
full disk, a busy mount point — is produced by making the os calls on that path fail with the errno
the kernel gives. A refusal must leave the temporary directory byte for byte as it was: the log
beside it, a previous output, and no hidden leftover. ``python tests/test_faults_output.py`` prints
the table. Signals, pipes and locks need real processes or threads: those tests follow the table.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import signal
import stat
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from click.testing import CliRunner
from fault_corpus import Expected, make_odoms, make_scans

from cornerslam_cli.cli import cli
from cornerslam_cli.errors import OutputError
from cornerslam_cli.logs.writers import write_mcap

# report.html binds plot_run / plot_compare when first imported: imported now, not first by a case that
# has patched them to `interrupt` — html would keep the patch for every later test in this process (a
# later report, test_results.py's, was then "interrupted")
from cornerslam_cli.report import html  # noqa: F401, I001
from cornerslam_cli.report.liveness import HOST
from cornerslam_cli.report.outdir import StagedDir, clear_stale, target_lock
from cornerslam_cli.report.ownership import MARKER, mark_output

CMD = [sys.executable, "-c", "from cornerslam_cli.cli import main; main()"]
KEPT = "no output written (an earlier output there, if any, is kept)"


@dataclass
class World:
    """A scenario's temporary world: everything it touches lives in ``tmp``; the corpus's valid log
    is ``tmp/logs/x.mcap``; ``mp`` makes os calls fail."""

    tmp: Path
    log: Path
    mp: pytest.MonkeyPatch
    cleanup: list[Callable[[], object]] = field(default_factory=list)  # run after the scenario


@dataclass
class Case:
    """A scenario's command line, the path its error must name, and checks of what it wrote (then
    also after an exit 2, instead of "nothing touched")."""

    args: list
    named: Path | str | None = None
    after: Callable[[], None] | None = None


OUTPUT_FAULTS: dict[str, tuple[Expected, Callable[[World], Case]]] = {}


def fault(exit_code: int, *message: str):
    """Register the decorated setup as a scenario of the table: its name is the scenario's, its
    docstring the behaviour line."""

    def register(setup: Callable[[World], Case]) -> Callable[[World], Case]:
        behaviour = " ".join((setup.__doc__ or "").split())
        OUTPUT_FAULTS[setup.__name__] = (Expected(behaviour, exit_code, message), setup)
        return setup

    return register


# ---------------------------------------------------------------------------- building places
def previous_output(d: Path, kind: str = "run") -> Path:
    """A complete earlier cornerslam output (a marked directory) at ``d``."""
    d.mkdir(parents=True)
    (d / "summary.json").write_text('{"previous": true}\n')
    mark_output(d, kind)
    return d


def previous_results_mcap(path: Path) -> Path:
    """A results MCAP of an earlier run at ``path`` (its Header names ownership.RESULTS_MCAP_LIBRARY)."""
    from mcap.writer import Writer

    from cornerslam_cli.report.ownership import RESULTS_MCAP_LIBRARY

    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="", library=RESULTS_MCAP_LIBRARY)
        w.finish()
    return path


def dead_pid() -> int:
    """The pid of a process that has just exited."""
    proc = subprocess.Popen(["true"])
    proc.wait()
    return proc.pid


def fail_writes_under(mp: pytest.MonkeyPatch, directory: Path, code: int) -> None:
    """Creating a directory or opening a file for writing under ``directory`` fails with ``code``,
    as the kernel does on a read-only file system (EROFS) or without write permission (EACCES)."""
    real_open, real_mkdir = os.open, os.mkdir
    root = directory.resolve()

    def under(path) -> bool:
        p = Path(os.fsdecode(path)).resolve()
        return p == root or root in p.parents

    def fake_open(path, flags, *args, **kwargs):
        if flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT) and under(path):
            raise OSError(code, os.strerror(code), os.fsdecode(path))
        return real_open(path, flags, *args, **kwargs)

    def fake_mkdir(path, *args, **kwargs):
        if under(path) and not os.path.lexists(path):  # an existing one: EEXIST, as the kernel says first
            raise OSError(code, os.strerror(code), os.fsdecode(path))
        return real_mkdir(path, *args, **kwargs)

    mp.setattr(os, "open", fake_open)
    mp.setattr(os, "mkdir", fake_mkdir)


def interrupt(*args, **kwargs):
    raise KeyboardInterrupt


def summary(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())


def complete(out: Path) -> None:
    """A complete run output: the tables, the summary of a real run, the marker."""
    assert "counts" in summary(out) and (out / "trajectory.csv").is_file()
    assert json.loads((out / MARKER).read_text())["kind"] == "run"


# ---------------------------------------------------------------------------- the table
# 1. only our own outputs are replaced
@fault(2, "is not empty and was not written by cornerslam", "give a new or empty directory")
def out_holds_the_log(w: World) -> Case:
    """`--out` a directory holding the log (`run logs/x.mcap --out logs`): refused, nothing touched"""
    return Case(["run", w.log, "--out", w.log.parent], w.log.parent)


@fault(2, "is not empty and was not written by cornerslam")
def out_is_a_foreign_directory(w: World) -> Case:
    """`--out .`, `--out ~`, any non-empty directory of other files: refused, nothing touched"""
    home = w.tmp / "home"
    home.mkdir()
    (home / ".bashrc").write_text("export PS1='$ '\n")
    (home / "thesis.tex").write_text("\\documentclass{article}\n")
    w.mp.chdir(home)
    return Case(["run", w.log, "--out", "."], "'.'")


@fault(2, "holds the working directory", "give another output directory")
def out_is_the_working_directory(w: World) -> Case:
    """`--out .` in an empty working directory: refused (it would be renamed away under the shell)"""
    cwd = w.tmp / "empty"
    cwd.mkdir()
    w.mp.chdir(cwd)
    return Case(["run", w.log, "--out", "."], "'.'")


@fault(2, "holds 'notes.txt', which cornerslam did not write", "move it out first")
def out_holds_user_files_beside_our_output(w: World) -> Case:
    """a cornerslam output holding files it did not write (notes added later): refused, naming one"""
    out = previous_output(w.tmp / "out")
    (out / "notes.txt").write_text("keep me\n")
    return Case(["run", w.log, "--out", out], out)


@fault(2, "holds 'sub/notes.txt', which cornerslam did not write")
def out_holds_user_files_in_a_subdirectory_of_our_output(w: World) -> Case:
    """a cornerslam output whose subdirectory (made by `--mcap-out OUT/sub/r.mcap`) holds a file it
    did not write: refused, naming it (the marker lists the entries of plain subdirectories too)"""
    out = w.tmp / "out"
    res = invoke("run", w.log, "--out", out, "--mcap-out", out / "sub" / "r.mcap", "-q")
    assert res.exit_code == 0, res.output
    (out / "sub" / "notes.txt").write_text("keep me\n")
    return Case(["run", w.log, "--out", out], out)


@fault(2, "holds the input")
def out_holds_the_log_inside_our_output(w: World) -> Case:
    """a cornerslam output that holds the run's own log: refused"""
    out = previous_output(w.tmp / "out")
    log = shutil.copy(w.log, out / "x.mcap")
    mark_output(out, "run")  # listed, so only the input rule refuses it
    return Case(["run", log, "--out", out], out)


@fault(2, "holds a cornerslam compare output, not a run output")
def out_is_another_kind_of_output(w: World) -> Case:
    """`run --out` a compare or batch directory (or the reverse): refused, the kinds named"""
    out = previous_output(w.tmp / "cmp", kind="compare")
    return Case(["run", w.log, "--out", out], out)


@fault(2, "cannot write", "a symlink loop", "check the path")
def out_is_a_symlink_loop(w: World) -> Case:
    """`--out` a symlink in a loop (a -> b -> a): exit 2 naming it (Python 3.11's resolve() raised
    RuntimeError, an internal error), nothing touched"""
    (w.tmp / "a").symlink_to(w.tmp / "b")
    (w.tmp / "b").symlink_to(w.tmp / "a")
    return Case(["run", w.log, "--out", w.tmp / "a"], w.tmp / "a")


@fault(2, "is a file, not a directory")
def out_is_a_file(w: World) -> Case:
    """`--out` an existing file: refused"""
    return Case(["run", w.log, "--out", w.log], w.log)


@fault(2, "a part of the path is a file, not a directory")
def out_parent_is_a_file(w: World) -> Case:
    """`--out FILE/sub` (a file where a directory should be): refused"""
    return Case(["run", w.log, "--out", w.log / "sub"], w.log / "sub")


@fault(0)
def out_is_an_empty_directory(w: World) -> Case:
    """`--out` an empty directory (made by hand, a fresh volume): used"""
    out = w.tmp / "empty"
    out.mkdir()
    return Case(["run", w.log, "--out", out], after=lambda: complete(out))


@fault(0)
def out_is_our_previous_output(w: World) -> Case:
    """`--out` a previous cornerslam output of the same kind: replaced whole, no flag needed"""
    out = previous_output(w.tmp / "out")
    return Case(["run", w.log, "--out", out], after=lambda: complete(out))


@fault(0)
def out_is_an_output_of_an_older_version(w: World) -> Case:
    """`--out` a run output written before the marker (its summary.json says cornerslam_version):
    replaced"""
    out = w.tmp / "old"
    out.mkdir()
    (out / "summary.json").write_text('{\n  "cornerslam_version": "0.0.9"\n}\n')
    (out / "map.csv").write_text("id\n")
    return Case(["run", w.log, "--out", out], after=lambda: complete(out))


@fault(2, "holds the output of", "not of", "the default output directory of both logs", "its own --out")
def default_out_of_another_log_with_the_same_name(w: World) -> Case:
    """two logs of one name (`a/x.mcap`, `logs/x.mcap`) run without `--out`: the second is refused,
    naming both, the first's output kept (`--out` replaces as usual; the same log again replaces its
    own output)"""
    first = w.tmp / "a" / "x.mcap"
    first.parent.mkdir()
    shutil.copy(w.log, first)
    w.mp.chdir(w.tmp)
    res = invoke("run", first, "-q")
    assert res.exit_code == 0, res.output
    return Case(["run", w.log], str(first.resolve()))


def older_version_output(d: Path, *extra: str) -> Path:
    """A run output written before the marker (0.1.0: summary.json says cornerslam_version), plus
    the ``extra`` files a user put there."""
    d.mkdir(parents=True)
    (d / "summary.json").write_text('{\n  "cornerslam_version": "0.1.0"\n}\n')
    for name in ("map.csv", "trajectory.tum", *extra):
        (d / name).write_text("x\n")
    return d


@fault(2, "holds 'thesis.tex'", "which cornerslam did not write")
def out_is_an_older_versions_output_holding_user_files(w: World) -> Case:
    """`--out` an unmarked output of an older version to which the user added a file: refused,
    nothing touched (only the files such a version wrote may be replaced)"""
    out = older_version_output(w.tmp / "old", "thesis.tex")
    return Case(["run", w.log, "--out", out], out)


@fault(2, "holds 'pca/notes.txt'", "which cornerslam did not write")
def compare_into_an_older_versions_compare_holding_user_files(w: World) -> Case:
    """`compare --out` an unmarked compare output of an older version with a user file in one of
    its run directories: refused, nothing touched"""
    out = w.tmp / "oldcmp"
    out.mkdir()
    (out / "comparison.csv").write_text("assoc,steps,landmarks,matched_total\n")
    older_version_output(out / "pca", "notes.txt")
    return Case(["compare", w.log, "--assoc", "pca", "--out", out], out)


@fault(2, "is not empty and was not written by cornerslam")
def compare_into_a_foreign_directory(w: World) -> Case:
    """`compare --out` a directory that is not a cornerslam compare output: refused before
    extraction"""
    return Case(["compare", w.log, "--assoc", "icnn", "--out", w.log.parent], w.log.parent)


@fault(2, "is not empty and was not written by cornerslam")
def batch_into_a_foreign_directory(w: World) -> Case:
    """`batch --out` a directory that is neither new, empty nor a batch directory: refused before
    any run"""
    return Case(["batch", w.log, "--out", w.log.parent], w.log.parent)


@fault(2, "holds a cornerslam run output, not a batch output")
def batch_into_a_run_output(w: World) -> Case:
    """`batch --out` a run output: refused"""
    out = previous_output(w.tmp / "out")
    return Case(["batch", w.log, "--out", out], out)


@fault(2, "error: 1 of 1 combinations failed: see ")
def batch_row_dir_not_ours(w: World) -> Case:
    """a batch combination whose directory holds files cornerslam did not write: that row fails, the
    files are kept, the batch goes on (and exits 2: a combination failed)"""
    out = w.tmp / "batch"
    row = out / "x__pca"
    row.mkdir(parents=True)
    (row / "mine.txt").write_text("keep me\n")
    mark_output(out, "batch")  # an earlier batch, resumed

    def after():
        (r,) = _read_batch(out)
        assert r["status"] == "failed" and "was not written by cornerslam" in r["error"], r
        assert (row / "mine.txt").read_text() == "keep me\n"
        assert sorted(p.name for p in row.iterdir()) == ["mine.txt"]

    return Case(["batch", w.log, "--assoc", "pca", "--out", out, "--jobs", "1"], after=after)


@fault(2, f"another cornerslam process (pid {os.getppid()}) is writing", "wait for it to finish")
def batch_into_a_batch_being_written(w: World) -> Case:
    """a batch into the directory another live batch is writing (its `.NAME.running-HOST-PID` mark):
    refused, naming its pid, nothing written (before: both ran, and the last to write batch.csv won —
    the other's failed row lost, or rows describing runs the other had replaced)"""
    out = w.tmp / "batch"
    out.mkdir()
    mark_output(out, "batch")  # an earlier batch's, being resumed by the live one
    (w.tmp / f".batch.running-{HOST}-{os.getppid()}").touch()  # (a live process: this one's parent)

    def after():
        assert not (out / "batch.csv").exists() and [p.name for p in out.iterdir()] == [MARKER]

    return Case(["batch", w.log, "--assoc", "pca", "--out", out, "--jobs", "1"], after=after)


@fault(2, f"another cornerslam process (pid {os.getppid()}) is writing", "wait for it to finish")
def run_into_a_place_a_batch_is_writing(w: World) -> Case:
    """a run into a place a live batch is writing (its mark): refused like a second staged run"""
    out = w.tmp / "out"
    (w.tmp / f".out.running-{HOST}-{os.getppid()}").touch()
    return Case(["run", w.log, "--out", out], out)


@fault(0)
def mark_of_a_killed_batch(w: World) -> Case:
    """the mark of a batch that was killed (its process gone): cleared, the batch runs and leaves no
    mark"""
    out = w.tmp / "batch"
    stale = w.tmp / f".batch.running-{HOST}-{dead_pid()}"
    stale.touch()

    def after():
        assert [r["status"] for r in _read_batch(out)] == ["ok"]
        assert not stale.exists() and not [p for p in w.tmp.iterdir() if ".running-" in p.name]

    return Case(["batch", w.log, "--assoc", "pca", "--out", out, "--jobs", "1"], after=after)


def _read_batch(out: Path) -> list[dict]:
    from cornerslam_cli.batch import read_batch

    return read_batch(out / "batch.csv")


# 2. everything is staged before the one commit
@fault(130, KEPT)
def interrupted_while_drawing_figures(w: World) -> Case:
    """Ctrl-C / SIGTERM while `--plot` draws figures or report.html: exit 130 / 143, the previous
    output kept whole (figures are drawn in the staging directory)"""
    out = previous_output(w.tmp / "out")
    w.mp.setattr("cornerslam_cli.report.plots.plot_run", interrupt)
    return Case(["run", w.log, "--out", out, "--plot"])


@fault(130, KEPT)
def interrupted_while_writing_mcap_out(w: World) -> Case:
    """interrupted while `--mcap-out` is written: the previous MCAP and output directory kept, no
    temporary file left"""
    out = previous_output(w.tmp / "out")
    mc = previous_results_mcap(w.tmp / "res.mcap")
    w.mp.setattr("cornerslam_cli.report.mcap_out.write_results_mcap", interrupt)
    return Case(["run", w.log, "--out", out, "--mcap-out", mc])


@fault(130, KEPT)
def compare_interrupted_while_drawing(w: World) -> Case:
    """`compare` interrupted while drawing its figures or report: the previous compare directory
    kept"""
    out = previous_output(w.tmp / "cmp", kind="compare")
    w.mp.setattr("cornerslam_cli.report.plots.plot_compare", interrupt)
    return Case(["compare", w.log, "--assoc", "icnn", "--out", out])


@fault(130, KEPT)
def simulate_interrupted_while_writing(w: World) -> Case:
    """`simulate` interrupted while it writes its files: the earlier log, ground truth and corners kept
    whole, no partial or hidden file left (the MCAP was written in place: a truncated log stayed)"""
    from cornerslam_cli.simulate import simulate_log

    simulate_log(w.tmp / "s.mcap", beams=11, rate=1.0, seed=1)
    w.mp.setattr("cornerslam_cli.simulate.write_tum", interrupt)  # after the MCAP is written
    return Case(["simulate", w.tmp / "s.mcap", "--beams", "11", "--rate", "1"])


# 3. leftovers, concurrent runs, permissions
@fault(0)
def staging_left_by_a_killed_run(w: World) -> Case:
    """a hidden `.NAME.partial-HOST-PID-*` left by a SIGKILLed run (its process dead): removed by
    the next run into the same place"""
    out = w.tmp / "out"
    stale = w.tmp / f".out.partial-{HOST}-{dead_pid()}-abcd1234"
    stale.mkdir()
    (stale / "trajectory.csv").write_text("step\n0\n")

    def after():
        complete(out)
        assert not stale.exists()

    return Case(["run", w.log, "--out", out], after=after)


@fault(2, f"another cornerslam process (pid {os.getppid()}) is writing", "wait for it to finish")
def staging_of_a_live_run(w: World) -> Case:
    """another run is writing the same `--out` (its staging directory's process is alive): refused,
    naming its pid"""
    out = w.tmp / "out"
    (w.tmp / f".out.partial-{HOST}-{os.getppid()}-abcd1234").mkdir()  # (a live process: this one's parent)
    return Case(["run", w.log, "--out", out], out)


@fault(0)
def staging_of_another_host(w: World) -> Case:
    """staging leftovers of another host (a shared file system): left alone, the run goes on"""
    out = w.tmp / "out"
    other = w.tmp / ".out.partial-deadbeef-1-abcd1234"
    other.mkdir()

    def after():
        complete(out)
        assert other.is_dir()

    return Case(["run", w.log, "--out", out], after=after)


@fault(0)
def umask(w: World) -> Case:
    """output directories and files (and `--mcap-out`) get the permissions the umask gives (umask
    027: directories 750, files 640)"""
    out, mc = w.tmp / "out", w.tmp / "res.mcap"
    old = os.umask(0o027)
    w.cleanup.append(lambda: os.umask(old))

    def after():
        assert (out.stat().st_mode & 0o777, (out / "summary.json").stat().st_mode & 0o777) == (0o750, 0o640)
        assert mc.stat().st_mode & 0o777 == 0o640

    return Case(["run", w.log, "--out", out, "--mcap-out", mc], after=after)


# 4. the environment
@fault(2, "cannot write", "read-only file system")
def read_only_file_system(w: World) -> Case:
    """`--out` on a read-only file system (EROFS): refused before any work, naming the path"""
    ro = w.tmp / "ro"
    ro.mkdir()
    fail_writes_under(w.mp, ro, errno.EROFS)
    return Case(["run", w.log, "--out", ro / "out"], ro / "out")


@fault(2, "cannot write", "permission denied")
def permission_denied(w: World) -> Case:
    """`--out` in a directory without write permission (EACCES): refused before any work"""
    locked = w.tmp / "locked"
    locked.mkdir()
    fail_writes_under(w.mp, locked, errno.EACCES)
    return Case(["compare", w.log, "--assoc", "icnn", "--out", locked / "cmp"], locked / "cmp")


@fault(2, "cannot write", "its directory accepts no new files, as in /proc", "on a disk")
def out_in_a_directory_that_accepts_no_files(w: World) -> Case:
    """`--out /proc/foo` (a directory whose file system creates no files: ENOENT although it exists):
    refused before any work, naming the path (before: FileNotFoundError on the lock file, exit 1)"""
    proc = w.tmp / "proc"
    proc.mkdir()
    fail_writes_under(w.mp, proc, errno.ENOENT)
    return Case(["run", w.log, "--out", proc / "foo"], proc / "foo")


@fault(2, "cannot write", "its directory accepts no new files")
def mcap_out_in_a_directory_that_accepts_no_files(w: World) -> Case:
    """`--mcap-out /proc/r.mcap`, `compare` / `batch --out /proc/foo`, `simulate /proc/s.mcap`: refused
    the same way"""
    proc = w.tmp / "proc"
    proc.mkdir()
    fail_writes_under(w.mp, proc, errno.ENOENT)
    return Case(["run", w.log, "--out", w.tmp / "out", "--mcap-out", proc / "r.mcap"], proc / "r.mcap")


@fault(2, "cannot write", "no space left on device", "free some space")
def disk_full(w: World) -> Case:
    """disk full (ENOSPC) or over quota (EDQUOT) while a run writes: exit 2 naming the output, the
    staged directory removed, the previous output kept"""
    from cornerslam_cli.report.tables import CsvTable

    out = previous_output(w.tmp / "out")
    real_row, rows = CsvTable.row, []

    def row(self, *values):
        rows.append(1)
        if len(rows) > 30:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        real_row(self, *values)

    w.mp.setattr(CsvTable, "row", row)
    return Case(["run", w.log, "--out", out], out)


@fault(2, "is a mount point", "give a new directory inside it")
def out_is_a_mount_point(w: World) -> Case:
    """`--out` a mount point (a container volume): refused before any work, asking for a directory
    inside it"""
    vol = w.tmp / "vol"
    vol.mkdir()
    real = os.path.ismount
    w.mp.setattr(os.path, "ismount", lambda p: Path(p).resolve() == vol.resolve() or real(p))
    return Case(["run", w.log, "--out", vol], vol)


@fault(2, "cannot write", "busy (a mount point?)")
def rename_busy(w: World) -> Case:
    """the commit's rename fails with EBUSY (a bind mount `ismount` does not see): exit 2, the
    previous output kept, nothing staged left"""
    out = previous_output(w.tmp / "out")
    real = os.rename

    def rename(src, dst, *args, **kwargs):
        if out.resolve() in (Path(src).resolve(), Path(dst).resolve()):
            raise OSError(errno.EBUSY, os.strerror(errno.EBUSY), os.fsdecode(src))
        return real(src, dst, *args, **kwargs)

    w.mp.setattr(os, "rename", rename)
    return Case(["run", w.log, "--out", out], out)


@fault(0)
def name_of_240_bytes(w: World) -> Case:
    """a legal 240-byte `--out` name (its staging name would pass 255 bytes): written, the staging
    name shortened"""
    out = w.tmp / ("r" * 240)
    return Case(["run", w.log, "--out", out], after=lambda: complete(out))


@fault(2, "name too long")
def name_over_255_bytes(w: World) -> Case:
    """an `--out` name over 255 bytes: refused before any work"""
    out = w.tmp / ("r" * 256)
    return Case(["run", w.log, "--out", out], out)


@fault(2, "cannot write", "permission denied")
def mcap_out_unwritable(w: World) -> Case:
    """`--mcap-out` in an unwritable directory: refused before any work, naming it"""
    locked = w.tmp / "locked"
    locked.mkdir()
    fail_writes_under(w.mp, locked, errno.EACCES)
    return Case(["run", w.log, "--out", w.tmp / "out", "--mcap-out", locked / "r.mcap"], locked / "r.mcap")


@fault(2, "exists and is not a results file cornerslam wrote")
def mcap_out_is_a_users_file(w: World) -> Case:
    """`--mcap-out` an existing file cornerslam did not write (a user's text, a log `simulate` wrote):
    refused before any work, the file kept (before, it was replaced)"""
    mc = w.tmp / "thesis.txt"
    mc.write_text("a user's file\n")
    return Case(["run", w.log, "--out", w.tmp / "out", "--mcap-out", mc], mc)


@fault(2, "exists and is not a results file cornerslam wrote")
def mcap_out_is_a_simulated_log(w: World) -> Case:
    """`--mcap-out` an MCAP log cornerslam's `simulate` wrote (not results): refused, the log kept"""
    mc = w.tmp / "other.mcap"
    shutil.copyfile(w.log, mc)
    return Case(["run", w.log, "--out", w.tmp / "out", "--mcap-out", mc], mc)


@fault(0)
def mcap_out_replaces_earlier_results(w: World) -> Case:
    """`--mcap-out` an earlier run's results MCAP: replaced with this run's"""
    mc = previous_results_mcap(w.tmp / "res.mcap")
    before = mc.read_bytes()

    def after():
        assert mc.read_bytes() != before and mc.read_bytes()[:8] == b"\x89MCAP0\r\n"

    return Case(["run", w.log, "--out", w.tmp / "out", "--mcap-out", mc], after=after)


@fault(2, "is an input of this run")
def mcap_out_is_the_log(w: World) -> Case:
    """`--mcap-out` naming the input log: refused"""
    return Case(["run", w.log, "--out", w.tmp / "out", "--mcap-out", w.log], w.log)


@fault(2, "is a directory")
def mcap_out_is_a_directory(w: World) -> Case:
    """`--mcap-out` an existing directory: refused"""
    return Case(["run", w.log, "--out", w.tmp / "out", "--mcap-out", w.log.parent], w.log.parent)


@fault(2, "names a directory", "give a file name")
def mcap_out_ends_in_a_slash(w: World) -> Case:
    """`--mcap-out res/` (a directory that does not exist yet): refused before any work (before, a file
    named `res` was written)"""
    mc = f"{w.tmp / 'res'}/"
    return Case(["run", w.log, "--out", w.tmp / "out", "--mcap-out", mc], mc)


@fault(0)
def mcap_out_inside_out(w: World) -> Case:
    """`--mcap-out` inside `--out`: written in the staging directory, committed with it"""
    out = w.tmp / "out"

    def after():
        complete(out)
        assert (out / "sub" / "r.mcap").read_bytes()[:8] == b"\x89MCAP0\r\n"

    return Case(["run", w.log, "--out", out, "--mcap-out", out / "sub" / "r.mcap"], after=after)


@fault(2, "is a file of the run itself")
def mcap_out_is_a_file_of_the_run(w: World) -> Case:
    """`--mcap-out OUT/trajectory.tum` (a file the run writes itself): refused, nothing written (a .json
    name is refused before that: written as MCAP, it would not be JSON)"""
    mc = w.tmp / "out" / "trajectory.tum"
    return Case(["run", w.log, "--out", w.tmp / "out", "--mcap-out", mc], mc)


@fault(2, "is an input of this run")
def mcap_out_is_the_default_ground_truth(w: World) -> Case:
    """`--mcap-out LOG.gt.tum`, the ground truth a run finds beside its log without `--ground-truth`:
    refused (it is an input), the file kept"""
    gt = w.log.with_suffix(".gt.tum")
    gt.write_text("0 0 0 0 0 0 0 1\n")
    return Case(["run", w.log, "--out", w.tmp / "out", "--mcap-out", gt], gt)


@fault(2, "is an input of this run")
def mcap_out_is_the_config(w: World) -> Case:
    """`--mcap-out` naming the `--config` file: refused, the file kept"""
    cfg = w.tmp / "c.yaml"
    cfg.write_text("ekf: {}\n")
    return Case(["run", w.log, "--config", cfg, "--out", w.tmp / "out", "--mcap-out", cfg], cfg)


@fault(2, "is not a regular file", "give the name of a file to write")
def mcap_out_is_a_pipe_or_device(w: World) -> Case:
    """`--mcap-out` an existing FIFO or device (`/dev/null`): refused (renaming a file onto it would
    replace the node), before any work"""
    fifo = w.tmp / "fifo.mcap"
    os.mkfifo(fifo)
    return Case(["run", w.log, "--out", w.tmp / "out", "--mcap-out", fifo], fifo)


@fault(2, "is inside the compare output", "give a directory outside it")
def run_into_a_compare_outputs_run(w: World) -> Case:
    """`run --out CMP/pca`, one associator's run of a comparison (or a new directory inside it): refused,
    the comparison kept (before, the run replaced that directory and comparison.csv no longer described it)"""
    cmp = w.tmp / "cmp"
    previous_output(cmp / "pca")
    mark_output(cmp, "compare")
    return Case(["run", w.log, "--out", cmp / "pca"], cmp / "pca")


@fault(2, "is inside the compare output", "give a directory outside it")
def run_into_an_unmarked_compare_outputs_run(w: World) -> Case:
    """the same inside a compare output of a version before the ownership marker (known by its
    comparison.csv): refused"""
    cmp = w.tmp / "cmp"
    (cmp / "pca").mkdir(parents=True)
    (cmp / "comparison.csv").write_text("assoc,steps,landmarks,ate\npca,3,4,0.1\n")
    (cmp / "pca" / "summary.json").write_text('{\n  "cornerslam_version": "0.1.0"\n}\n')
    return Case(["run", w.log, "--out", cmp / "pca"], cmp / "pca")


@fault(2, "is a name cornerslam uses for its own bookkeeping", "give another file name")
def mcap_out_is_the_marker(w: World) -> Case:
    """`--mcap-out OUT/.cornerslam-output`, the name of the output's ownership marker: refused (before,
    the marker overwrote the MCAP and the run printed success)"""
    mc = w.tmp / "out" / ".cornerslam-output"
    return Case(["run", w.log, "--out", w.tmp / "out", "--mcap-out", mc], mc)


@fault(2, "is a name cornerslam uses for its own bookkeeping")
def mcap_out_is_the_lock_file(w: World) -> Case:
    """`--mcap-out .OUT.lock`, the name of the output's lock file: refused (before, the MCAP was
    deleted with the lock and the run printed success)"""
    mc = w.tmp / ".out.lock"
    return Case(["run", w.log, "--out", w.tmp / "out", "--mcap-out", mc], mc)


@fault(2, "exists and is not a lock file cornerslam wrote", "move it away")
def a_users_file_named_like_the_lock(w: World) -> Case:
    """a file of the user's named `.OUT.lock` beside `--out OUT`: refused, the file kept (before, it
    was taken as the lock and deleted after the run)"""
    lock = w.tmp / ".out.lock"
    lock.write_text("precious\n")
    return Case(["run", w.log, "--out", w.tmp / "out"], lock)


@fault(2, "is in the way of cornerslam's lock file", "move it away")
def a_symlink_named_like_the_lock(w: World) -> Case:
    """a symlink (to a file of the user's) named `.OUT.lock` beside `--out OUT`: refused, both kept
    (before, the symlink was deleted)"""
    (w.tmp / "mine.txt").write_text("precious\n")
    (w.tmp / ".out.lock").symlink_to(w.tmp / "mine.txt")
    return Case(["run", w.log, "--out", w.tmp / "out"], w.tmp / ".out.lock")


@fault(2, "is in the way of cornerslam's lock file", "move it away")
def a_directory_named_like_the_lock(w: World) -> Case:
    """a directory named `.OUT.lock` beside `--out OUT`: refused, kept (before: "cannot write 'OUT': it
    is a directory")"""
    (w.tmp / ".out.lock").mkdir()
    return Case(["compare", w.log, "--assoc", "icnn", "--out", w.tmp / "out"], w.tmp / ".out.lock")


@fault(2, "is in the way of cornerslam's lock file", "move it away")
def a_socket_named_like_the_lock(w: World) -> Case:
    """a Unix socket named `.OUT.lock` beside `--out OUT` (opening one fails with ENXIO): refused, kept
    (before: exit 1, internal error)"""
    import socket

    with socket.socket(socket.AF_UNIX) as sock:
        sock.bind(str(w.tmp / ".out.lock"))
    return Case(["run", w.log, "--out", w.tmp / "out"], w.tmp / ".out.lock")


@fault(0)
def a_lock_file_left_by_a_killed_run(w: World) -> Case:
    """an empty `.OUT.lock` (a run killed while creating it, or written by a version before the lock
    files were marked): used as the lock, removed after"""
    (w.tmp / ".out.lock").touch()
    return Case(["run", w.log, "--out", w.tmp / "out"], after=lambda: complete(w.tmp / "out"))


@fault(2, "is not a regular file")
def simulate_into_a_pipe(w: World) -> Case:
    """`simulate OUT.mcap` where OUT.mcap (or OUT.gt.tum, OUT.corners.csv) is a FIFO or a device:
    refused (writing a FIFO nobody reads hangs)"""
    fifo = w.tmp / "s.gt.tum"
    os.mkfifo(fifo)
    return Case(["simulate", w.tmp / "s.mcap", "--beams", "11", "--rate", "1"], fifo)


@fault(2, "exists and is not part of a log cornerslam simulate wrote")
def simulate_over_a_users_file(w: World) -> Case:
    """`simulate OUT.mcap` where OUT.mcap or OUT.gt.tum / OUT.corners.csv exists and OUT.mcap is not a
    log cornerslam wrote: refused before any work, the files kept (before, they were replaced); over
    its own earlier log it writes the set again"""
    (w.tmp / "s.gt.tum").write_text("a user's trajectory\n")
    return Case(["simulate", w.tmp / "s.mcap", "--beams", "11", "--rate", "1"], w.tmp / "s.gt.tum")


# 7. numbers on the command line; 13. --config that is not a regular file
@fault(2, "--seed must be >= 0")
def simulate_seed_negative(w: World) -> Case:
    """`simulate --seed -1`: usage error"""
    return Case(["simulate", w.tmp / "s.mcap", "--seed", "-1"])


@fault(2, "--rate must be in [0.1, 1000.0], got nan")
def simulate_out_of_range(w: World) -> Case:
    """`simulate` --laps < 1, --rate / --speed ≤ 0 or NaN, --beams < 2, or a log too large to build:
    usage error naming the option"""
    return Case(["simulate", w.tmp / "s.mcap", "--rate", "nan"])


@fault(2, "is not a finite number")
def time_offset_not_finite(w: World) -> Case:
    """`--time-offset nan` / `inf` (run, compare, evaluate): usage error"""
    return Case(["run", w.log, "--out", w.tmp / "out", "--time-offset", "nan"])


@fault(2, "--step", "x>=0")
def extract_step_negative(w: World) -> Case:
    """`extract --step -1`: usage error"""
    return Case(["extract", w.log, "--step", "-1"])


@fault(2, "invalid value for '--plot'", "does not end in a figure format (", ".pdf, ", ".png, ")
def extract_plot_not_a_figure(w: World) -> Case:
    """`extract --plot scan.txt`: usage error naming the file and the formats, before any work (it was
    an internal error after the work)"""
    return Case(["extract", w.log, "--plot", w.tmp / "scan.txt"], w.tmp / "scan.txt")


@fault(2, "does not end in a figure format")
def extract_plot_without_an_extension(w: World) -> Case:
    """`extract --plot scan`: usage error (matplotlib wrote scan.png, and `wrote scan` was printed)"""
    return Case(["extract", w.log, "--plot", w.tmp / "scan"], w.tmp / "scan")


@fault(0)
def extract_plot_into_a_new_directory(w: World) -> Case:
    """`extract --plot new/scan.png`: the directory made, as `--out` and `--mcap-out` make theirs (it
    was an internal error)"""
    figure = w.tmp / "new" / "sub" / "scan.PNG"

    def after():
        assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    return Case(["extract", w.log, "--plot", figure], after=after)


@fault(0)
def extract_plot_through_a_dangling_symlink(w: World) -> Case:
    """`extract --plot link.png`, link.png a symlink to a file in a directory not yet made: the figure
    written at the link's target, its directory made, as `--mcap-out` does (it was an internal error:
    the directory made was the link's own, and writing through the link found no directory)"""
    link, figure = w.tmp / "link.png", w.tmp / "gone" / "scan.png"
    link.symlink_to(figure)

    def after():
        assert link.is_symlink() and figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    return Case(["extract", w.log, "--plot", link], after=after)


@fault(2, "exists and is not a figure cornerslam extract wrote", "give a new file name")
def extract_plot_over_a_users_file(w: World) -> Case:
    """`extract --plot photo.png` where photo.png is a file extract did not write (its metadata does not
    name cornerslam extract): refused before any work, the file kept (before, it was overwritten);
    a figure an earlier `extract --plot` wrote is replaced"""
    photo = w.tmp / "photo.png"
    photo.write_bytes(b"\x89PNG\r\n\x1a\n a user's picture")
    return Case(["extract", w.log, "--plot", photo], photo)


@fault(2, "not a figure cornerslam extract wrote")
def extract_plot_through_a_symlink_to_a_users_file(w: World) -> Case:
    """`extract --plot link.png`, link.png a symlink to a user's existing `data`: refused, `data` kept
    (the figure was written at data.png beside it, the target's suffix choosing the name)"""
    link, data = w.tmp / "link.png", w.tmp / "data"
    data.write_text("OLD")
    link.symlink_to(data)

    def after():
        assert link.is_symlink() and data.read_text() == "OLD" and not (w.tmp / "data.png").exists()

    return Case(["extract", w.log, "--plot", link], link, after=after)


@fault(0)
def extract_plot_through_a_symlink_to_a_txt(w: World) -> Case:
    """`extract --plot link.png` → fig.txt, twice: a PNG written at fig.txt, and replaced the second time
    (it was an internal error: matplotlib took the format from the target's suffix)"""
    link, figure = w.tmp / "link.png", w.tmp / "fig.txt"
    link.symlink_to(figure)
    first = CliRunner().invoke(cli, ["extract", str(w.log), "--plot", str(link), "-q"])
    assert first.exit_code == 0, first.output

    def after():
        assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    return Case(["extract", w.log, "--plot", link], after=after)


@fault(0)
def simulate_into_a_new_directory(w: World) -> Case:
    """`simulate new/s.mcap`: the directory made (it was an internal error)"""
    out = w.tmp / "new" / "sub" / "s.mcap"

    def after():
        assert sorted(p.name for p in out.parent.iterdir()) == ["s.corners.csv", "s.gt.tum", "s.mcap"]

    return Case(["simulate", out, "--beams", "11", "--rate", "1"], after=after)


@fault(0)
def config_dev_null(w: World) -> Case:
    """`--config /dev/null` (or an empty file): no overrides; a pipe `--config <(...)` is read once"""
    from cornerslam_cli.lasers import resolve_config

    out = w.tmp / "out"
    expect = resolve_config(w.log, None, []).to_dict()

    def after():
        assert summary(out)["config"] == expect

    return Case(["run", w.log, "--out", out, "--config", os.devnull], after=after)


# ---------------------------------------------------------------------------- the table's test
@pytest.fixture(scope="module")
def valid_log(tmp_path_factory) -> Path:
    """The fault corpus's valid log: 40 scans of a robot circling a box (a run takes ~0.4 s)."""
    return write_mcap(tmp_path_factory.mktemp("valid") / "x.mcap", make_scans(), make_odoms())


def snapshot(d: Path) -> dict[str, bytes | None]:
    """Every entry under ``d`` (hidden ones too) with its bytes; None for a directory, the mode for
    a FIFO or device (reading one would block)."""
    return {
        str(p.relative_to(d)): None if p.is_dir() else p.read_bytes() if p.is_file() else p.lstat().st_mode
        for p in sorted(d.rglob("*"))
    }


def leftovers(d: Path) -> list[str]:
    """Staging directories, replaced directories and lock files of this host under ``d``."""
    return [
        p.name
        for p in d.rglob(".*")
        if p.name.endswith(".lock") or any(f".{what}-{HOST}-" in p.name for what in ("partial", "old"))
    ]


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


@pytest.mark.parametrize("name", list(OUTPUT_FAULTS))
def test_output_fault(name, tmp_path, monkeypatch, valid_log):
    exp, setup = OUTPUT_FAULTS[name]
    (tmp_path / "logs").mkdir()
    world = World(tmp_path, Path(shutil.copy(valid_log, tmp_path / "logs" / "x.mcap")), monkeypatch)
    try:
        case = setup(world)
        before = snapshot(tmp_path)
        res = invoke(*case.args, "-q")
    finally:
        monkeypatch.undo()
        for undo in world.cleanup:
            undo()
    assert "Traceback" not in res.output and "internal error" not in res.output, res.output
    assert res.exit_code == exp.exit_code, res.output
    if exp.exit_code != 0:
        last = res.stderr.strip().splitlines()[-1]
        if exp.exit_code == 2:
            assert last.startswith(("error:", "Error:")), res.stderr  # ours, or click's usage error
        for fragment in (*exp.message, *([str(case.named)] if case.named else [])):
            assert fragment in last, (fragment, last)
    if case.after is not None:  # it wrote what it should (a batch whose failed rows exit 2)
        case.after()
        assert leftovers(tmp_path) == []
    elif exp.exit_code == 0:
        assert leftovers(tmp_path) == []
    else:
        assert snapshot(tmp_path) == before  # nothing touched, nothing left behind


def test_a_kill_between_the_two_renames_puts_the_previous_output_back(tmp_path):
    """A commit killed after moving the previous output aside (``.NAME.old-…``) and before renaming
    the new one into place: the next run's clean-up renames it back, so it is never lost."""
    aside = previous_output(tmp_path / f".out.old-{HOST}-{dead_pid()}-abcd1234")
    before = snapshot(aside)
    clear_stale(tmp_path / "out")
    assert snapshot(tmp_path / "out") == before and not aside.exists()


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs Linux's /proc")
@pytest.mark.parametrize(
    "args, named",
    [
        (["run", "{log}", "--out", "/proc/cornerslam-out"], "/proc/cornerslam-out"),
        (["run", "{log}", "--out", "/proc/cornerslam-out/sub"], "/proc/cornerslam-out/sub"),
        (["run", "{log}", "--out", "{tmp}/out", "--mcap-out", "/proc/r.mcap"], "/proc/r.mcap"),
        (["compare", "{log}", "--assoc", "icnn", "--out", "/proc/cornerslam-cmp"], "/proc/cornerslam-cmp"),
        (["batch", "{log}", "--out", "/proc/cornerslam-batch"], "/proc/cornerslam-batch"),
        (["simulate", "/proc/s.mcap"], "/proc/s.mcap"),
    ],
)
def test_outputs_in_the_real_proc_are_refused_naming_them(args, named, valid_log, tmp_path):
    """The real /proc (ENOENT on every new name): exit 2 naming the path, nothing written anywhere."""
    res = invoke(*[a.format(log=valid_log, tmp=tmp_path) for a in args], "-q")
    assert res.exit_code == 2, res.output
    last = res.stderr.strip().splitlines()[-1]
    assert last == f"error: cannot write '{named}': its directory accepts no new files, as in /proc " + (
        "(write to a directory on a disk)"
    )
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------- real processes
def staging(out: Path) -> list[Path]:
    return [p for p in out.parent.iterdir() if p.name.startswith(f".{out.name}.partial-")]


def wait_for(condition: Callable[[], bool], proc: subprocess.Popen, what: str, timeout: float = 30) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert proc.poll() is None, f"the process ended before {what}: {proc.communicate()}"
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.005)


def test_a_second_run_into_the_same_out_is_refused_and_a_killed_runs_staging_is_cleared(
    sim_log, valid_log, tmp_path
):
    """Run A (a real process) is writing ``out``: run B into the same ``out`` is refused at once
    naming A's pid. A is SIGKILLed: its staging directory stays (nothing can run on SIGKILL); the next
    run into ``out`` removes it and commits."""
    out = tmp_path / "out"
    a = subprocess.Popen([*CMD, "run", str(sim_log), "--out", str(out), "-q"], stderr=subprocess.PIPE)
    try:
        wait_for(lambda: bool(staging(out)), a, "run A's staging directory")
        res = invoke("run", valid_log, "--out", out)
        assert res.exit_code == 2 and f"another cornerslam process (pid {a.pid}) is writing" in res.stderr
        assert a.poll() is None, "run A finished too soon: the check raced nothing"
    finally:
        a.kill()
        a.communicate()
    assert len(staging(out)) == 1 and not out.exists()
    assert invoke("run", valid_log, "--out", out, "-q").exit_code == 0
    complete(out)
    assert staging(out) == [] and leftovers(tmp_path) == []


def test_the_commit_waits_for_the_lock_of_its_target(tmp_path):
    """A commit holds the target's lock across its renames: one that finds it held waits (here in a
    thread, against a lock held by the test), then commits; a second StagedDir for a target being
    staged in a live process is refused."""
    target = tmp_path / "out"
    with StagedDir(target) as st:
        (st.path / "a.csv").write_text("x\n")
        with pytest.raises(OutputError, match=f"pid {os.getpid()}"):
            StagedDir(target)
        with target_lock(target):
            t = threading.Thread(target=st.commit)
            t.start()
            t.join(0.3)
            assert t.is_alive() and not target.exists()  # waiting for the lock
        t.join(10)
    assert sorted(p.name for p in target.iterdir()) == [MARKER, "a.csv"]
    assert leftovers(tmp_path) == []


def test_a_closed_stdout_is_no_internal_error(valid_log, tmp_path):
    """`cornerslam info LOG | head -1`, `cornerslam run LOG | true`: stdout closed before the first
    line. Exit 141 (as a Unix tool killed by SIGPIPE), nothing on stderr about it, and the run's
    output directory is committed (the summary is printed after the commit)."""
    out = tmp_path / "out"
    procs = [
        subprocess.Popen([*CMD, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        for args in (["info", str(valid_log)], ["run", str(valid_log), "--out", str(out)])
    ]
    for p in procs:
        p.stdout.close()  # the reader is gone before the process writes anything
    for p in procs:
        err = p.stderr.read()
        assert p.wait(timeout=60) == 141, err
        assert "Traceback" not in err and "internal error" not in err and "Exception ignored" not in err, err
    complete(out)


def test_a_closed_stderr_is_no_internal_error(valid_log, tmp_path):
    """`cornerslam run LOG 2>&-` (stderr closed, as some daemons start a job): the run completes
    (exit 0, output committed), and a bad input is still exit 2 (it crashed on the progress line)."""
    out = tmp_path / "out"
    for args, code in ((["run", valid_log, "--out", out], 0), (["run", tmp_path / "none.mcap"], 2)):
        line = " ".join(f"'{a}'" for a in [*CMD, *map(str, args)]) + " 2>&-"
        assert subprocess.run(["sh", "-c", line], timeout=60).returncode == code, line
    complete(out)


def test_an_unwritable_home_is_no_noise_under_quiet(valid_log, tmp_path):
    """HOME not a writable directory (a service user's, a read-only container): matplotlib could not
    make ~/.config/matplotlib and said so on two lines, with -q too, before drawing as asked."""
    home = tmp_path / "home"
    home.write_text("a file, not a directory\n")
    env = {
        k: v for k, v in os.environ.items() if k not in ("MPLCONFIGDIR", "XDG_CONFIG_HOME", "XDG_CACHE_HOME")
    }
    figure = tmp_path / "scan.png"
    args = [*CMD, "extract", str(valid_log), "--step", "1", "--plot", str(figure), "-q"]
    res = subprocess.run(args, env={**env, "HOME": str(home)}, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0 and res.stderr == "", res.stderr
    assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
def test_stdout_on_a_full_disk_is_exit_2(valid_log, tmp_path):
    """`cornerslam info LOG > /dev/full`: writing stdout fails with ENOSPC. Exit 2 with one line
    saying so, no internal error; a run's output directory is still committed."""
    out = tmp_path / "out"
    for args in (["info", str(valid_log)], ["run", str(valid_log), "--out", str(out)]):
        with open("/dev/full", "w") as full:
            res = subprocess.run([*CMD, *args], stdout=full, stderr=subprocess.PIPE, text=True, timeout=60)
        assert res.returncode == 2, res.stderr
        lines = res.stderr.strip().splitlines()
        assert lines[-1].startswith("error: cannot write to standard output: No space left"), res.stderr
        assert "Traceback" not in res.stderr and "Exception ignored" not in res.stderr, res.stderr
    complete(out)


def test_stdout_closed_is_exit_2(valid_log, tmp_path):
    """`cornerslam info LOG >&-` (stdout closed: Python's sys.stdout is None, and click's echo wrote
    nothing): exit 2 saying stdout cannot be written, as `ls >&-` does (before: exit 0, the report
    lost); with -q nothing goes to stdout, so a run succeeds."""
    out = tmp_path / "out"
    for args in (["info", str(valid_log)], ["config"], ["run", str(valid_log), "--out", str(out), "-q"]):
        res = subprocess.run(
            [*CMD, *args], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, timeout=60,
            preexec_fn=lambda: os.close(1),
        )  # fmt: skip
        if args[-1] == "-q":
            assert res.returncode == 0, res.stderr
            continue
        assert res.returncode == 2, res.stderr
        assert res.stderr.strip().splitlines()[-1] == (
            "error: cannot write to standard output: Bad file descriptor (redirect it elsewhere)"
        ), res.stderr
        assert "Traceback" not in res.stderr and "Exception ignored" not in res.stderr, res.stderr
    complete(out)


def _children(pid: int) -> list[int]:
    """Pids of the live (not zombie) child processes of ``pid``, from /proc."""
    out = []
    for stat_file in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat_file.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid and fields[0] != "Z":
            out.append(int(stat_file.parent.name))
    return out


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc")
@pytest.mark.parametrize("command", ["batch", "compare"])
def test_workers_end_with_a_killed_parent(tmp_path, command):
    """SIGKILL of `batch --jobs 2` / `compare --jobs 2` while its workers run: the workers exit
    within seconds (they used to finish, commit a row of a dead batch and then wait forever)."""
    log = write_mcap(tmp_path / "long.mcap", make_scans(600), make_odoms(601))
    out = tmp_path / "out"
    args = [command, str(log), "--assoc", "icnn,pca", "--jobs", "2", "--out", str(out), "-q"]
    proc = subprocess.Popen([*CMD, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    workers: list[int] = []
    try:
        wait_for(lambda: len(_children(proc.pid)) >= 2 and staging_anywhere(tmp_path), proc, "the workers")
        workers = _children(proc.pid)
        proc.kill()
        proc.wait(timeout=10)
        deadline = time.monotonic() + 15
        while any(_alive(w) for w in workers) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not [w for w in workers if _alive(w)], "workers outlived the killed parent"
    finally:
        proc.kill()
        for w in workers:
            if _alive(w):
                os.kill(w, signal.SIGKILL)


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc")
@pytest.mark.parametrize(
    "sig, to_group, code, word",
    [(signal.SIGINT, True, 130, "interrupted"), (signal.SIGTERM, False, 143, "terminated")],
)
def test_an_interrupted_batch_ends_its_workers(tmp_path, sig, to_group, code, word):
    """Ctrl-C (the terminal sends it to the whole process group) or SIGTERM (to the batch alone, as
    `timeout` sends it) while `batch --jobs 1` runs: the batch ends its workers, exits with the signal's
    status, and batch.csv tells the truth — a combination's directory exists iff its row is 'ok'. It
    used to wait while a worker ran the combination queued to it (Ctrl-C) or the one under way
    (SIGTERM) to its end, committing a directory its row called 'pending'; SIGTERM exited 130."""
    log = write_mcap(tmp_path / "long.mcap", make_scans(600), make_odoms(601))
    out = tmp_path / "out"
    args = ["batch", str(log), "--assoc", "icnn,jcbb,pca", "--jobs", "1", "--out", str(out), "-q"]
    proc = subprocess.Popen(
        [*CMD, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True
    )
    workers: list[int] = []
    try:
        wait_for(lambda: staging_anywhere(out), proc, "the first combination")
        workers = _children(proc.pid)
        os.killpg(proc.pid, sig) if to_group else proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
        assert proc.returncode == code, err
        assert err.strip().splitlines()[-1].startswith(f"{word}: "), err
        assert "Traceback" not in err, err
        time.sleep(0.5)
        assert not [w for w in workers if _alive(w)], "workers outlived the interrupted batch"
        rows = _read_batch(out)
        assert "pending" in {r["status"] for r in rows}
        for r in rows:
            assert (out / f"long__{r['assoc']}").exists() == (r["status"] == "ok"), rows
        assert not staging_anywhere(out)
    finally:
        proc.kill()
        for w in workers:
            if _alive(w):
                os.kill(w, signal.SIGKILL)


def staging_anywhere(d: Path) -> bool:
    """Some run's staging directory exists under ``d`` (a worker is writing)."""
    return any(".partial-" in p.name for p in d.rglob("*") if p.is_dir())


def test_sigterm_while_drawing_figures_keeps_the_previous_output(valid_log, tmp_path):
    """The reported failure: SIGTERM after the tables, while ``--plot`` draws. The figures are
    drawn in the staging directory, so the previous output is still complete and untouched."""
    out = previous_output(tmp_path / "out")
    before = snapshot(out)
    proc = subprocess.Popen(
        [*CMD, "run", str(valid_log), "--out", str(out), "--plot", "-q"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    wait_for(lambda: any((s / "map.png").exists() for s in staging(out)), proc, "the first figure")
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 143, err
    assert err.strip().splitlines()[-1] == f"terminated: {KEPT}"
    assert snapshot(out) == before and staging(out) == []


def test_config_from_a_pipe_is_read_once(valid_log, tmp_path):
    """`--config <(...)` is a pipe: it gives its text once, and ``batch`` loads the config once for
    the command and again for each combination. The CLI reads it once into a copy, so the override
    reaches the combination's run."""
    r, w = os.pipe()
    os.write(w, b"keyframes:\n  linear_update: 0.25\n")
    os.close(w)
    out = tmp_path / "batch"
    try:
        res = invoke("batch", valid_log, "--out", out, "-q", "--jobs", "1", "--config", f"/dev/fd/{r}")
    finally:
        os.close(r)
    assert res.exit_code == 0, res.output
    assert summary(out / "x__pca")["config"]["keyframes"]["linear_update"] == 0.25


def main() -> None:
    """The table for docs/results/reliability.md."""
    for name, (exp, _) in OUTPUT_FAULTS.items():
        print(f"| {name} | {exp.behaviour} | exit {exp.exit_code} |")


if __name__ == "__main__":
    main()


def test_simulate_writes_over_its_own_earlier_log(tmp_path):
    """`simulate` into the place of a log it wrote before replaces the set (a re-run is the usual case)."""
    out = tmp_path / "s.mcap"
    for seed in ("1", "2"):
        res = CliRunner().invoke(cli, ["simulate", str(out), "--beams", "11", "--rate", "1", "--seed", seed])
        assert res.exit_code == 0, res.output
    assert out.with_suffix(".gt.tum").exists() and out.with_suffix(".corners.csv").exists()


def test_simulate_keeps_a_users_file_beside_its_own_log(tmp_path, monkeypatch):
    """Over its own earlier log, simulate replaced NAME.gt.tum and NAME.corners.csv whatever they held: a
    user's own reference saved there was lost (a hostile-user probe). The log now records the sha256 of
    the two it wrote (an MCAP metadata record); one that differs is refused, exit 2, and kept."""
    from cornerslam_cli import simulate as sim

    out = tmp_path / "d.mcap"
    args = ["simulate", str(out), "--beams", "11", "--rate", "1"]
    assert CliRunner().invoke(cli, args).exit_code == 0
    assert set(sim.companion_hashes(out)) == {".tum", ".csv"}
    assert CliRunner().invoke(cli, [*args, "--seed", "2"]).exit_code == 0  # its own set: replaced
    for name in ("d.gt.tum", "d.corners.csv"):
        mine = tmp_path / name
        kept = mine.read_bytes()
        mine.write_text("mine\n")
        res = CliRunner().invoke(cli, args)
        assert res.exit_code == 2, res.output
        assert f"'{mine}' exists and is not part of a log cornerslam simulate wrote" in res.stderr
        assert mine.read_text() == "mine\n"
        mine.write_bytes(kept)
    # a log of a simulate before the record (the shipped sample until 2026-12-05): taken as written
    (tmp_path / "d.gt.tum").write_text("an older simulate's\n")
    monkeypatch.setattr(sim, "companion_hashes", lambda log: {})  # a whole log without the record
    sim.simulate_log(out, seed=1, rate=1.0, beams=11)
    assert (tmp_path / "d.gt.tum").read_text() != "an older simulate's\n"
    monkeypatch.undo()
    # its own log damaged since (cut short: its record unreadable): a user's edit is not taken for its
    mine = tmp_path / "d.gt.tum"
    mine.write_text("mine\n")
    out.write_bytes(out.read_bytes()[:-10])
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 2 and "cannot be read (the log is damaged)" in res.stderr, res.output
    assert mine.read_text() == "mine\n"
    # a companion that is a directory is named as one (the log's name was given instead)
    mine.unlink()
    (tmp_path / "d.corners.csv").unlink()
    (tmp_path / "d.corners.csv").mkdir()
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 2 and f"'{tmp_path / 'd.corners.csv'}' is a directory" in res.stderr, res.output


def test_simulate_into_an_unwritable_place_fails_before_the_work(tmp_path, monkeypatch):
    """A read-only directory: simulate ray-cast the whole log (its progress bar to the end), then failed;
    run, compare, batch and --mcap-out refuse before any work (a hostile-user probe). Its files are now
    staged first."""
    import errno

    from cornerslam_cli import simulate as sim

    place = tmp_path / "ro"
    place.mkdir()
    cast = []
    monkeypatch.setattr(sim, "raycast", lambda *a, **k: cast.append(1))
    fail_writes_under(monkeypatch, place, errno.EROFS)
    res = CliRunner().invoke(cli, ["simulate", str(place / "s.mcap"), "--beams", "11", "--rate", "1"])
    assert res.exit_code == 2 and "read-only file system" in res.stderr.lower(), res.output
    assert cast == [] and list(place.iterdir()) == []


def test_simulate_renames_its_three_files_as_one(tmp_path, monkeypatch):
    """Ctrl-C between `simulate`'s renames left the new log beside the old ground truth (a later `run`
    scored it against the wrong poses): SIGINT raised after the first rename now arrives only after the
    third, so the set is all new."""
    import signal

    from cornerslam_cli import simulate as sim

    out = tmp_path / "s.mcap"
    sim.simulate_log(out, seed=1, rate=1.0, beams=11)
    old = {p: p.read_bytes() for p in (out, out.with_suffix(".gt.tum"))}  # (the corners: the world's)
    replace, done = sim.os.replace, []

    def replace_then_interrupt(src, dst):
        replace(src, dst)
        done.append(dst)
        if len(done) == 1:
            signal.raise_signal(signal.SIGINT)

    monkeypatch.setattr(sim.os, "replace", replace_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        sim.simulate_log(out, seed=2, rate=2.0, beams=11)  # (the ground truth: at other stamps)
    assert len(done) == 3
    assert all(p.read_bytes() != b for p, b in old.items())  # the log and its ground truth both new


def test_simulate_reports_its_progress(tmp_path):
    """`simulate` said nothing until it was done (72 s on a long log), `-v` gave no stage totals: its
    ray-casting reports (done, total) up to the whole, and -v logs each stage."""
    from cornerslam_cli.simulate import simulate_log

    calls = []
    res = simulate_log(tmp_path / "s.mcap", rate=1.0, beams=11, progress=lambda d, n: calls.append((d, n)))
    assert calls[0] == (0, res["scans"]) and calls[-1] == (res["scans"], res["scans"])
    assert [d for d, _ in calls] == sorted(d for d, _ in calls)
    said = CliRunner().invoke(
        cli, ["simulate", str(tmp_path / "v.mcap"), "--beams", "11", "--rate", "1", "-v"]
    )
    assert said.exit_code == 0 and "ray-cast" in said.output and "wrote the log" in said.output, said.output


@pytest.mark.parametrize("name", ["s.png", "s.pdf", "s.svg", "s.jpg", "s.TIFF", "s.ps", "s.eps"])
def test_extract_plot_writes_over_its_own_earlier_figure(name, tmp_path, valid_log):
    """`extract --plot` again to the same name replaces the figure it wrote (a re-run is the usual case),
    in each format whose file can name its creator, keeping the file's permissions (it is written beside
    and renamed onto it)."""
    figure = tmp_path / name
    for step in ("1", "2"):
        res = CliRunner().invoke(cli, ["extract", str(valid_log), "--step", step, "--plot", str(figure)])
        assert res.exit_code == 0, res.output
        figure.chmod(0o640)
    assert figure.stat().st_size > 1000 and stat.S_IMODE(figure.stat().st_mode) == 0o640


def test_enoent_is_a_user_error_only_where_the_directory_creates_no_files(tmp_path, monkeypatch):
    """ENOENT while writing is '/proc'-like (exit 2) only when a fresh file cannot be created beside the
    name either; a file that should be there and is not (a read of a staged file a writer forgot), or
    a vanished directory, stays a bug (None: exit 1 with the traceback saved)."""
    from cornerslam_cli.report.oserrors import output_error

    with pytest.raises(OSError) as missing:
        open(tmp_path / "forgotten.csv")  # noqa: SIM115
    assert output_error(missing.value, tmp_path / "out") is None
    gone = OSError(errno.ENOENT, "No such file or directory", str(tmp_path / "gone" / "x.csv"))
    assert output_error(gone, tmp_path / "out") is None
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".cornerslam-probe")]  # probe removed
    proc = tmp_path / "proc"
    proc.mkdir()
    fail_writes_under(monkeypatch, proc, errno.ENOENT)
    refused = OSError(errno.ENOENT, "No such file or directory", str(proc / "foo"))
    assert "its directory accepts no new files" in str(output_error(refused, proc / "foo"))


def test_a_second_batch_into_a_running_batchs_directory_is_refused_however_it_is_named(tmp_path):
    """Batch A runs with `--out .` (from inside its directory); batch B names the same directory by its
    absolute path: refused, naming A's pid (the mark is beside the resolved directory, not inside it as
    `..running-…` where no other spelling finds it). A leftover mark carrying this process's own pid (a
    killed process's, its pid reused: pid 1 in a container) refuses nothing."""
    log = write_mcap(tmp_path / "long.mcap", make_scans(600), make_odoms(601))
    out = tmp_path / "out"
    out.mkdir()
    a = subprocess.Popen([*CMD, "batch", str(log), "--assoc", "icnn", "--jobs", "1", "--out", ".", "-q"],
                         cwd=out, stderr=subprocess.PIPE)  # fmt: skip
    try:
        wait_for(lambda: any(".running-" in p.name for p in tmp_path.iterdir()), a, "batch A's mark")
        assert not [p for p in out.iterdir() if ".running-" in p.name]
        res = invoke("batch", log, "--assoc", "pca", "--jobs", "1", "--out", out)
        assert res.exit_code == 2 and f"another cornerslam process (pid {a.pid}) is writing" in res.stderr
        assert a.poll() is None, "batch A finished too soon: the check raced nothing"
    finally:
        a.kill()
        a.communicate()
    from cornerslam_cli.report.outdir import alone_in

    with alone_in(out, "out"):  # (A's mark, SIGKILLed, is cleared as its process is gone)
        pass
    assert not [p for p in tmp_path.iterdir() if ".running-" in p.name]


@pytest.mark.parametrize("what", ["partial", "running"])
def test_a_leftover_of_this_processs_own_pid_is_refused_naming_it(tmp_path, sim_log, what):
    """A staging directory or a batch's mark carrying this process's own pid, named as a cornerslam before
    the flocks names them (no ``-flock``: tests/test_liveness.py for this version's), is not this
    process's (it stages nothing before its check): a container's before a restart (pid 1 again, the same
    host name) — or another container's, live, sharing the host name, whose staging a run must not delete
    (a review showed a start-time rule deleting it). Refused, saying so and naming the path to remove if
    nothing else writes there (session 40 let a batch ignore such a mark: two containers' batches would
    both write)."""
    out = tmp_path / "out"
    left = tmp_path / (f".out.{what}-{HOST}-{os.getpid()}" + ("-abcd1234" if what == "partial" else ""))
    left.mkdir() if what == "partial" else left.touch()
    for cmd in (["run", sim_log], ["batch", sim_log, "--assoc", "icnn", "--jobs", "1"]):
        res = invoke(*cmd, "--out", out, "-q")
        assert res.exit_code == 2, res.output
        assert f"another writer of '{out}' has this process's pid {os.getpid()} ('{left.name}'" in res.stderr
        assert f"if no other cornerslam writes '{out}', remove '{left}'" in res.stderr
        assert left.exists() and not (out / "summary.json").exists()


@pytest.mark.parametrize("err", [errno.EROFS, errno.ENOSPC])
def test_a_batch_resumed_on_a_read_only_or_full_disk_is_a_one_line_error(tmp_path, sim_log, monkeypatch, err):
    """Resuming a batch whose directory's file system became read-only (or full): its lock file could not
    be made and the batch ended in "internal error: OSError: [Errno 30] Read-only file system:
    '.b.lock'", exit 1 (a probe), where run and compare say "cannot write …", exit 2."""
    out = tmp_path / "b"
    assert invoke("batch", sim_log, "--assoc", "icnn", "--jobs", "1", "--out", out, "-q").exit_code == 0
    from cornerslam_cli.report import outdir

    def refused(path):
        raise OSError(err, os.strerror(err), str(path))

    monkeypatch.setattr(outdir, "_open_lock", refused)
    res = invoke("batch", sim_log, "--assoc", "icnn", "--jobs", "1", "--out", out, "-q")
    assert res.exit_code == 2 and "internal error" not in res.stderr, res.output
    assert res.stderr.startswith(f"error: cannot write '{out}'"), res.stderr
