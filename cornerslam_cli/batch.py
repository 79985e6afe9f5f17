"""``cornerslam batch``: many logs × associators × a grid of config values, locally or on Dask.

:func:`sweep.plan` expands the grid into combinations (validating every key and value before any
work; sweep.py also names their directories); :func:`run_batch` runs each into ``OUT/<name>/`` — a
complete ``run`` output directory — and writes ``OUT/batch.csv`` with one row per combination, in
the plan's order. A failed row's error is its one line: a bad input's message (a CornerslamError), or
``internal error: …`` naming the file its traceback was saved to (a bug); the rows returned carry
``internal`` (not a column) so that the CLI exits 1 for a bug and 2 for bad input.

Resume: a combination is skipped (status ``skipped``, its figures re-read) when ``OUT/<name>/summary.json``
is complete and its ``hashes`` (sha256 of the log's bytes, of the resolved config, of the package's code,
version, and of the ground truth's poses beside the log: none now as then, or the same) equal this run's,
and every file its marker lists is there
(a file's content is not checked). Anything else is run again; a failed combination leaves no
directory and is always retried.

batch.csv is rewritten atomically (temporary file + rename) as combinations finish (at most once a
second) and at the end; while the batch runs, or after it was interrupted, the combinations not yet
finished have status ``pending``. Paths in it are as given (``log``) or relative to OUT (``out_dir``).

OUT must be new, empty or a batch directory already (its ``.cornerslam-output`` marker, or the
batch.csv of an older version): any other directory is refused before any work (report/ownership.py).
A combination's directory is replaced only if it is a cornerslam run output; anything else there
fails that row.

Execution: a spawn-context process pool of ``jobs`` workers (workers import the package themselves;
OPENBLAS_NUM_THREADS etc. default to 1 in their environment), or with ``scheduler="tcp://host:port"``
a Dask distributed cluster (``pip install cornerslam[dask]``). Dask workers must have cornerslam
installed and see the logs and OUT at the same absolute paths (a shared filesystem); Dask's nanny
already starts workers with OPENBLAS_NUM_THREADS=1. A local worker that dies (killed, out of memory)
breaks its pool: the combinations it took down run again, and only the one whose worker died on it
again fails (:func:`_run_local`).

Over 400 lines because planning's resume check, the local pool with its recovery from a dead worker
and the Dask path share the batch's rows and state.
"""

from __future__ import annotations

import csv
import logging
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from . import __version__
from .blas import single_threaded_blas, single_threaded_blas_env
from .errors import CornerslamError, ResultsError, display_path, for_command, one_line, save_traceback
from .report.comparison import BATCH_FIGURES as FIGURES
from .report.comparison import BATCH_MORE_FIGURES as MORE_FIGURES
from .report.comparison import batch_figures
from .report.oserrors import output_errors
from .report.outdir import alone_in, clear_stale, staged_write
from .report.ownership import claim_dir, files_intact, other_log_error
from .results import Hashes, RunSummary
from .sweep import Combo
from .workers import end_children, warnings_kept, warnings_once

log = logging.getLogger("cornerslam.batch")

BATCH_CSV = "batch.csv"
TIMING_FIGURES = ("t_match", "t_total", "wall_time", "t_loop")  # differ between runs of the same combination
STATUSES = ("ok", "failed", "skipped", "pending")
BATCH_OPTIONS = ("--assoc",)  # of errors.OPTION_OF, the options cornerslam batch takes (the rest by --set)


def batch_columns(sweep_keys: Sequence[str]) -> list[str]:
    """The header of batch.csv for a batch sweeping ``sweep_keys``."""
    return ["log", "assoc", *sweep_keys, "status", "error", *FIGURES, "out_dir", *MORE_FIGURES]


@dataclass
class BatchState:
    """Counts passed to the progress callback after each change."""

    total: int
    ok: int = 0
    failed: int = 0
    skipped: int = 0

    @property
    def finished(self) -> int:
        return self.ok + self.failed + self.skipped

    @property
    def remaining(self) -> int:
        return self.total - self.finished


def run_batch(
    combos: Sequence[Combo],
    out_dir: str | Path,
    jobs: int | None = None,
    scheduler: str | None = None,
    progress: Callable[[BatchState], None] | None = None,
    config_path: str | None = None,
    ground_truth: bool = True,
) -> list[dict]:
    """Run every combination into ``out_dir/<name>/``; write ``out_dir/batch.csv``; return its rows.
    ``config_path``: the config file the combinations were planned from, an input of each run (a run
    whose directory holds it is refused, not written over). ``ground_truth``: whether each run scores
    against the LOG.gt.tum beside its log, as ``run`` does (False: --no-ground-truth).

    One failing combination (bad log, numerical failure, a bug) never stops the others: its row has
    status ``failed`` and the error line. ``jobs`` local worker processes (default ``os.cpu_count()``),
    or the Dask cluster at ``scheduler``. Rows come in the order of ``combos``. The workers' warnings
    are said as each combination finishes, each distinct text once.
    """
    with warnings_once():
        return _run_batch(combos, out_dir, jobs, scheduler, progress, config_path, ground_truth)


def _run_batch(
    combos: Sequence[Combo],
    out_dir: str | Path,
    jobs: int | None,
    scheduler: str | None,
    progress: Callable[[BatchState], None] | None,
    config_path: str | None = None,
    ground_truth: bool = True,
) -> list[dict]:
    client = _connect(scheduler) if scheduler else None  # before the output: a wrong address writes nothing
    try:
        if client is not None:  # (and workers of another build write nothing either)
            _check_workers(client)
        return _run_claimed(combos, Path(out_dir), jobs, client, progress, config_path, ground_truth)
    finally:
        if client is not None:
            client.close()


def _run_claimed(
    combos: Sequence[Combo],
    out: Path,
    jobs: int | None,
    client,  # dask.distributed.Client | None (Dask is optional)
    progress: Callable[[BatchState], None] | None,
    config_path: str | None = None,
    ground_truth: bool = True,
) -> list[dict]:
    """:func:`_run_batch` once the Dask ``client`` (None: local processes) is connected."""
    target = claim_dir(out, "batch")  # refuses a directory that is not a batch's, before any work
    with alone_in(target, display_path(out)):  # a second batch (or compare) into it is refused (resolved:
        # `--out .` marks it beside itself, and any spelling of it finds the mark)
        return _run_alone(combos, out, jobs, client, progress, config_path, ground_truth)


def _run_alone(
    combos: Sequence[Combo],
    out: Path,
    jobs: int | None,
    client,  # dask.distributed.Client | None
    progress: Callable[[BatchState], None] | None,
    config_path: str | None,
    ground_truth: bool,
) -> list[dict]:
    """:func:`_run_claimed` in the claimed directory ``out``, its only writer."""
    columns = batch_columns([k for k, _ in combos[0].sweep] if combos else [])
    rows = [_row(c, "pending") for c in combos]
    writer = _CsvWriter(out / BATCH_CSV, columns)
    # every combination pending, before the logs are hashed (seconds for large logs): a Ctrl-C from here
    # on leaves this batch's table, as the message says (an earlier batch's, or none, was left: a probe)
    writer.write(rows)
    try:
        return _fill_table(combos, out, jobs, client, progress, config_path, ground_truth, rows, writer)
    except KeyboardInterrupt as e:
        e.batch_table = str(out / BATCH_CSV)  # (cli's message names it only then)
        raise


def _fill_table(combos, out, jobs, client, progress, config_path, ground_truth, rows, writer) -> list[dict]:
    """:func:`_run_alone`'s table ``rows`` (all pending, written by ``writer``) filled in: each combination
    checked (its log hashed once, a complete earlier run skipped), the rest run."""
    from .config import Config, from_dict
    from .report.summary import code_hash, config_hash, input_hash

    state = BatchState(len(combos))
    log_hashes: dict[str, str | None] = {}
    gt_hashes: dict[str, str | None | bool] = {}  # False: a ground truth the run cannot read
    todo: list[int] = []
    for i, c in enumerate(combos):
        if not c.error and c.log not in log_hashes:  # once per log, not per combination
            try:
                log_hashes[c.log] = input_hash(Path(c.log))
            except (OSError, CornerslamError):
                log_hashes[c.log] = None  # the run reports the unreadable log (or pipe)
            gt_hashes[c.log] = _ground_truth_hash(c.log) if ground_truth else None
        error = c.error
        if not error and log_hashes[c.log] is not None:  # (an unreadable log's run says why)
            other = other_log_error(out / c.name, Path(c.log), c.name, log_hashes[c.log], "batch")
            error = one_line(other) if other else ""  # a file of the same name batched into OUT before
        if error:
            rows[i] = _row(c, "failed", error=error)
            state.failed += 1
            continue
        figures = None
        gt_hash = gt_hashes[c.log]
        if log_hashes[c.log] is not None and gt_hash is not False and code_hash() is not None:
            expect = Hashes(input=log_hashes[c.log], config=config_hash(from_dict(Config, c.config)),
                            version=__version__, ground_truth=gt_hash or None, code=code_hash())  # fmt: skip
            figures = _resumable(out / c.name, expect)
        if figures is not None:
            rows[i] = _row(c, "skipped", figures=figures)
            state.skipped += 1
        else:
            todo.append(i)
    writer.write(rows)

    def tick() -> None:  # the counts to the status line (between finished combinations: its clock, its ETA)
        if progress is not None:
            progress(state)

    tick()

    def finished(i: int, result: dict) -> None:
        name = display_path(combos[i].log)  # which log a warning is of (as batch.csv's log), unless it says
        for text in result.pop("warnings", ()):
            log.warning("%s", text if name in text else f"{name}: {text}")  # said once
        rows[i] = _row(combos[i], **result)
        setattr(state, result["status"], getattr(state, result["status"]) + 1)
        writer.write(rows, throttle=True)
        tick()

    todo.sort(key=lambda i: -_size(combos[i].log))  # biggest logs first: a shorter tail on N workers
    picked = [(i, combos[i]) for i in todo]
    # (on Dask the logs resolved too: a worker started in another directory reads them by absolute path)
    tasks = [
        (
            i,
            str(Path(c.log).resolve()) if client else c.log,
            c.config,
            str((out / c.name).resolve()),
            c.notes,
            config_path,
            ground_truth,
        )
        for i, c in picked
    ]
    try:
        if client is not None:
            _run_dask(tasks, client, finished, tick)
        elif tasks:
            _run_local(tasks, jobs or os.cpu_count() or 1, finished, tick=tick)
    except BaseException:  # interrupted: a worker killed after end_children's grace (a loaded machine)
        if client is None:  # left its staging directory; its process is gone now
            for task in tasks:
                clear_stale(Path(task[3]))
        raise
    finally:
        writer.write(rows)
    return rows


def _size(path: str) -> int:
    try:
        return os.path.getsize(path)
    except OSError:
        return 0


def _row(c: Combo, status: str, error: str = "", figures: dict | None = None, internal: bool = False) -> dict:
    """A row of batch.csv (its columns), and ``internal``: whether the failure was a bug."""
    # a hint naming --scan-topic: the --set batch takes, or the --sweep of the key when it is swept
    error = for_command(error, BATCH_OPTIONS, [key for key, _ in c.sweep])
    row = {"log": display_path(c.log), "assoc": c.assoc, **dict(c.sweep), "status": status, "error": error}
    row.update({k: (figures or {}).get(k) for k in FIGURES})
    row["out_dir"] = c.name if status in ("ok", "skipped") else ""
    row.update({k: (figures or {}).get(k) for k in MORE_FIGURES})
    row["internal"] = internal
    return row


def _ground_truth_hash(log: str) -> str | None | bool:
    """The :func:`~report.summary.reference_hash` of the ground truth ``run`` finds beside ``log``
    (LOG.gt.tum), None without one, False when it cannot be read (the run reports why)."""
    from .report.run_writer import find_ground_truth
    from .report.summary import reference_hash
    from .report.tables import read_tum

    gt = find_ground_truth(Path(log))
    if gt is None:
        return None
    try:
        return reference_hash(*read_tum(gt, "ground truth", lambda _: None))
    except (OSError, CornerslamError):
        return False


def _resumable(run_dir: Path, expect: Hashes) -> dict | None:
    """The figures of a complete earlier run of the same log, config, version, code and ground truth
    (its hash: none then as now, or the same poses; a run it scored nothing of, a ground truth that does
    not overlap the log, is resumed too), else None."""
    try:
        s = RunSummary.read(run_dir)
    except ResultsError:
        return None  # missing, unreadable or from an older layout: run it again
    if s.hashes != expect:
        return None
    return batch_figures(s) if files_intact(run_dir) else None


def run_one(
    log: str,
    config: dict,
    out_dir: str,
    notes: tuple[str, ...] = (),
    config_path: str | None = None,
    ground_truth: bool = True,
) -> dict:
    """Run one combination (in a worker): ``{"status": "ok", "figures": ...}`` or the failure line;
    ``notes``: its config's warnings, said when the batch planned it, kept for its summary.json;
    ``config_path``: the config file it was planned from (an input of the run: never written over);
    ``ground_truth``: False scores against none, not even LOG.gt.tum.

    Module-level and importing the package lazily, so spawn and Dask workers can unpickle it by name
    and set the BLAS thread count before numpy is first imported. The run's warnings are not printed
    but returned (``"warnings"``): the batch says each once, not once per combination.
    """
    single_threaded_blas()
    with warnings_kept() as warnings:
        try:
            from .config import Config, from_dict
            from .pipeline import run

            cfg = from_dict(Config, config)
            summary = run(
                log,
                cfg,
                out_dir,
                ground_truth=None if ground_truth else False,
                inside="batch",
                notes=notes,
                config_path=config_path,
            )
            result = {"status": "ok", "figures": batch_figures(summary)}
        except SystemExit:  # the batch was interrupted and ended us (workers.stopped_by_parent)
            os._exit(143)  # the staging is removed: end here, not in the combination queued to us next
        except Exception as e:  # a bug in one combination must not stop the batch either
            result = _failed(e)
    return {**result, "warnings": warnings}


def _failed(e: BaseException) -> dict:
    """The failure row's status and one-line error: bad input (a CornerslamError) as its message, a
    bug as ``internal error: …`` with its traceback saved to a file the line names (as ``cli.py``
    reports one)."""
    if isinstance(e, CornerslamError):
        return {"status": "failed", "error": one_line(e)}
    error = f"internal error: {one_line(e)} ({save_traceback(e)})"
    return {"status": "failed", "error": error, "internal": True}


def _run_local(
    tasks: list[tuple],
    jobs: int,
    finished: Callable[[int, dict], None],
    work: Callable = run_one,
    tick: Callable[[], None] = lambda: None,
) -> None:
    """The tasks (index, ``work``'s arguments…) on ``jobs`` local worker processes. A worker that dies
    (killed, out of memory) breaks its pool and every combination not yet finished with it: those run
    again, one at a time until the one running when a worker dies is found (failed: "its worker process
    died"), then in parallel again."""
    pending, alone = tasks, False
    while pending:
        broken = _run_pool(pending, 1 if alone else jobs, finished, work, tick)
        if broken and alone:  # one at a time, in order: the first not finished was running
            finished(broken[0][0], {"status": "failed", "error": WORKER_DIED})
            broken = broken[1:]
        pending, alone = broken, bool(broken) and not alone


WORKER_DIED = "its worker process died while running it (killed? out of memory?)"
TICK = 1.0  # s: the status line is redrawn this often between finished combinations (its clock, its ETA)
POLL = 0.1  # s between looks at a Dask batch's finished tasks


def _run_pool(
    tasks: list[tuple],
    jobs: int,
    finished: Callable[[int, dict], None],
    work: Callable,
    tick: Callable[[], None],
) -> list[tuple]:
    """Run ``tasks`` on a pool of ``jobs`` spawned workers, each result to ``finished`` (``tick`` every
    ``TICK`` s without one); the tasks a broken pool did not finish (a worker died), in the order given."""
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    broken = []
    with single_threaded_blas_env():  # spawned workers inherit it before they import numpy
        pool = ProcessPoolExecutor(
            max_workers=min(jobs, len(tasks)),
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_init_worker,
            initargs=(logging.getLogger().getEffectiveLevel(),),
        )
        try:
            futures = {pool.submit(work, *task[1:]): k for k, task in enumerate(tasks)}
            waiting = set(futures)
            while waiting:
                done, waiting = wait(waiting, timeout=TICK, return_when=FIRST_COMPLETED)
                if not done:
                    tick()
                for fut in sorted(done, key=futures.__getitem__):  # (in the tasks' order: deterministic)
                    try:
                        result = fut.result()
                    except BrokenProcessPool:  # a worker died: run again (_run_local)
                        broken.append(futures[fut])
                        continue
                    except Exception as e:  # the task could not be sent or its result not returned
                        result = _failed(e)
                    finished(tasks[futures[fut]][0], result)
        except BaseException:  # the batch ends (Ctrl-C, SIGTERM, batch.csv unwritable): so do its workers
            end_children()
            raise
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
    return [tasks[k] for k in sorted(broken)]


def _init_worker(level: int) -> None:
    """A spawned worker logs at the parent's level (-q / -v), in the CLI's format, and ends with the
    batch (a killed ``cornerslam batch`` leaves no worker running; an interrupted one ends its workers:
    none goes on to the combination queued to it)."""
    from .report.progress import StatusLine, log_to_stderr
    from .workers import exit_with_parent, stopped_by_parent

    log_to_stderr(level)
    # the parent's status line on this terminal has no newline: a worker's warning clears it first
    # (a line of its own, never drawn, puts that filter on the handlers; a forked worker inherits it)
    StatusLine(enabled=True)
    exit_with_parent()
    stopped_by_parent()


CONNECT_TIMEOUT = 10.0  # s: for the scheduler to answer, and to greet as a Dask scheduler does


def _connect(scheduler: str):
    """A Dask client of the scheduler at ``scheduler``; CornerslamError when Dask is not installed, the
    address names no transport Dask has (``http://…``: its client would hang 20 s on exit) or no port
    (``tcp://host``: likewise), nothing answers there within 10 s, or what answers is no Dask scheduler
    (:func:`_greets_as_dask`)."""
    try:
        from dask.distributed import Client
        from distributed.comm.addressing import parse_address, parse_host_port
        from distributed.comm.registry import get_backend
    except ImportError:
        raise CornerslamError(
            "--scheduler needs Dask distributed, which is not installed", 'pip install ".[dask]"'
        ) from None
    hint = "check the address (tcp://host:port) and that `dask scheduler` is running"
    try:
        scheme, where = parse_address(scheduler)
        get_backend(scheme)
        if scheme in ("tcp", "tls"):  # host:port checked here: a client that fails on it hangs 20 s too
            try:
                host, port = parse_host_port(where)
            except ValueError:
                raise ValueError(f"no port in '{where}' (tcp://host:port)") from None
            if scheme == "tcp":  # (TLS greets after its own handshake)
                _greets_as_dask(host, port, scheduler)
        return Client(scheduler, timeout=CONNECT_TIMEOUT, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as e:
        problem = f"cannot connect to the Dask scheduler at '{scheduler}': {' '.join(str(e).split())}"
        raise CornerslamError(problem, hint) from None


def _greets_as_dask(host: str, port: int, scheduler: str) -> None:
    """CornerslamError unless what listens at ``host:port`` speaks first, as a Dask scheduler does (its
    handshake, the moment a connection is made): a dashboard's port, an HTTP server, waits for a request,
    and distributed's client waited on it for ever, without a word (its timeout does not cover the
    handshake; a probe). OSError when nothing answers (:func:`_connect` says so)."""
    import socket

    with socket.create_connection((host, port), timeout=CONNECT_TIMEOUT) as s:
        s.settimeout(CONNECT_TIMEOUT)
        try:
            greeted = bool(s.recv(1))
        except TimeoutError:
            greeted = False
    if not greeted:
        raise CornerslamError(
            f"what answers at '{scheduler}' is not a Dask scheduler, or one too busy to answer (it said "
            f"nothing in {CONNECT_TIMEOUT:.0f} s, or hung up): the dashboard's port?",
            "give the scheduler's address: `dask scheduler` prints it as 'Scheduler at: tcp://…', "
            "port 8786 unless set",
        )


def _worker_build() -> str | None:
    """The code hash of the build a Dask worker runs (:func:`_check_workers`)."""
    from .report.summary import code_hash

    return code_hash()


def _check_workers(client) -> None:
    """CornerslamError when the cluster's workers cannot import cornerslam, or run another build of it
    than this one (workers started before the code changed keep the code they imported: their rows would
    mix two builds, and a resume would never take them for this build's). Workers that join later are not
    checked (an adaptive cluster may have none yet: that is said, while the batch waits for them)."""
    from .report.summary import code_hash

    here = code_hash()
    try:
        theirs = client.run(_worker_build)
    except Exception as e:  # noqa: BLE001 - a worker without cornerslam_cli (its deserialisation fails)
        raise CornerslamError(
            f"the Dask workers cannot run cornerslam: {one_line(e)}",
            "install this cornerslam where the workers run (pip install) and restart them",
        ) from None
    if not theirs:
        log.warning(
            "the Dask scheduler at %s has no workers yet: the batch waits for them (`dask worker %s`)",
            client.scheduler.address,
            client.scheduler.address,
        )
    other = sorted({h for h in theirs.values() if h != here} - {None})
    if here is not None and other:
        n = sum(h != here for h in theirs.values())
        raise CornerslamError(
            f"{n} of the {len(theirs)} Dask workers run another build of cornerslam (code {other[0][:8]}, "
            f"here {here[:8]}): their rows would mix two builds",
            "restart the workers (`dask worker …`) so they import this build",
        )


def _run_dask(
    tasks: list[tuple], client, finished: Callable[[int, dict], None], tick: Callable[[], None]
) -> None:
    """:func:`_run_pool` on a Dask cluster's workers (none dies for us: the cluster runs a task again)."""
    from dask.distributed import as_completed

    if tasks:
        idx, *columns = (list(t) for t in zip(*tasks, strict=True))
        futures = client.map(run_one, *columns, pure=False)
        index = {f.key: i for f, i in zip(futures, idx, strict=True)}
        done = as_completed(futures, loop=client.loop)
        while not done.is_empty():
            ready = done.next_batch(block=False)
            if not ready:
                tick()
                time.sleep(POLL)
            for fut in sorted(ready, key=lambda f: index[f.key]):
                try:
                    result = fut.result()
                except Exception as e:  # the worker died (KilledWorker) or the task could not be sent
                    result = _dask_failed(e)
                finished(index[fut.key], result)


SCHEDULER_LOST = "the connection to the Dask scheduler was lost (run the same command again to resume)"


def _dask_failed(e: Exception) -> dict:
    """A Dask task's failure row: a worker the cluster gave up on (killed, out of memory: Dask's
    KilledWorker) as the local pool's dead worker, the scheduler gone as that — neither a bug — else
    :func:`_failed`'s."""
    from concurrent.futures import CancelledError

    from distributed import KilledWorker

    if isinstance(e, KilledWorker):
        return {"status": "failed", "error": WORKER_DIED}
    if isinstance(e, CancelledError) and "connection-lost" in str(e):
        return {"status": "failed", "error": SCHEDULER_LOST}
    return _failed(e)


class _CsvWriter:
    """batch.csv, replaced atomically on each write (at most once a second when throttled; the first, before
    any run, also clears the temporary files of a killed batch: outdir.staged_write)."""

    def __init__(self, path: Path, columns: list[str]):
        self.path = path
        self.columns = columns
        self.last = 0.0

    def write(self, rows: list[dict], throttle: bool = False) -> None:
        from .report.tables import csv_value

        now = time.monotonic()
        if throttle and now - self.last < 1.0:
            return
        self.last = now
        with output_errors(self.path), staged_write(self.path) as tmp, open(tmp, "w", newline="") as f:
            w = csv.writer(f, lineterminator="\n")
            w.writerow(self.columns)
            for r in rows:
                w.writerow(["" if r.get(k) is None else csv_value(r[k]) for k in self.columns])
            f.flush()
            os.fsync(f.fileno())


def read_batch(path: str | Path) -> list[dict[str, str]]:
    """batch.csv as a list of rows of strings (the inverse of what :func:`run_batch` writes)."""
    with open(path, newline="") as f:
        return list(csv.DictReader(f))
