"""``cornerslam batch``: many logs × associators × a grid of config values, locally or on Dask.

:func:`plan` expands the grid into :class:`Combo` s (validating every key and value before any work);
:func:`run_batch` runs each into ``OUT/<name>/`` — a complete ``run`` output directory — and writes
``OUT/batch.csv`` with one row per combination, in the plan's order.

Directory names: ``<log>__<assoc>[__<key>=<value>]...`` with the swept keys in the order given, the
values as written, and any character outside ``[A-Za-z0-9._=+-]`` replaced by ``_``, e.g.
``sim_office__pca__association.pca.group_size=5``. ``<log>`` is the file name up to its first dot;
logs sharing that stem use their whole file name, and logs sharing that too add a short hash of their
absolute path. Base ``--set`` overrides do not appear in names (they are in each summary.json).

Resume: a combination is skipped (status ``skipped``, its figures re-read) when ``OUT/<name>/summary.json``
is complete and its ``hashes`` (sha256 of the log's bytes, sha256 of the resolved config, version)
equal this run's, and ground truth is present now iff it was then. Anything else is run again; a
failed combination leaves no directory and is always retried.

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
already starts workers with OPENBLAS_NUM_THREADS=1.
"""

from __future__ import annotations

import csv
import hashlib
import itertools
import logging
import os
import re
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from . import __version__
from .blas import single_threaded_blas, single_threaded_blas_env
from .errors import ConfigError, CornerslamError, ResultsError, display_path
from .report.oserrors import output_errors
from .report.outdir import clear_stale, staged_file
from .report.ownership import claim_dir
from .results import Hashes, RunSummary

BATCH_CSV = "batch.csv"
FIGURES = [
    "steps",
    "landmarks",
    "matched_total",
    "t_match",
    "t_total",
    "wall_time",
    "ate_rmse",
    "odom_ate_rmse",
]
TIMING_FIGURES = ("t_match", "t_total", "wall_time")  # differ between runs of the same combination
STATUSES = ("ok", "failed", "skipped", "pending")
_UNSAFE = re.compile(r"[^A-Za-z0-9._=+-]")
_MAX_NAME = 180  # well under the 255-byte file name limit, leaving room for the staging prefix


@dataclass(frozen=True)
class Combo:
    """One point of the batch: a log, an associator and one value for each swept key.

    ``config`` is the fully resolved config as plain data (``Config.to_dict()``), laser preset included
    as ``run`` would choose it, so workers rebuild it without the config file; ``sweep`` holds (dotted
    key, value as written) in the order swept. ``error`` is set when the log could not be opened to
    choose its laser preset: the combination is reported failed without running.
    """

    log: str
    assoc: str
    sweep: tuple[tuple[str, str], ...]
    name: str
    config: dict = field(compare=False, repr=False)
    error: str = ""


def batch_columns(sweep_keys: Sequence[str]) -> list[str]:
    """The header of batch.csv for a batch sweeping ``sweep_keys``."""
    return ["log", "assoc", *sweep_keys, "status", "error", *FIGURES, "out_dir"]


def value_text(v: Any) -> str:
    """A sweep value as ``--set`` text (strings as written; true/false/null as YAML spells them)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if v is None:
        return "null"
    return str(v)


def plan(
    logs: Sequence[str | Path],
    assocs: Sequence[str],
    sweeps: Mapping[str, Sequence[Any]] | None = None,
    overrides: Sequence[str] = (),
    config_path: str | Path | None = None,
) -> list[Combo]:
    """Every log × associator × point of the sweep grid (the last swept key varies fastest).

    Each swept value is checked against the config schema first (ConfigError naming ``--sweep
    key=value``); unknown associators raise ConfigError with the closest name. Each combination's
    config is resolved as ``cornerslam run`` resolves it (:func:`lasers.resolve_config`: the laser
    preset matching the log's first scan under the user's layers); a log that cannot be opened is not
    an error here but failed rows in :func:`run_batch`. Logs listed twice are run once.
    """
    from .association import associator_class
    from .config import load_config
    from .errors import LogError
    from .lasers import resolve_config

    sweeps = {k: list(dict.fromkeys(value_text(v) for v in vs)) for k, vs in (sweeps or {}).items()}
    for key, values in sweeps.items():
        if key == "association.method":
            raise ConfigError("--sweep association.method is not allowed", "list associators with --assoc")
        if not values:
            raise ConfigError(f"--sweep {key} has no values", f"e.g. --sweep {key}=V1,V2")
        for v in values:
            try:
                load_config(config_path, [*overrides, f"{key}={v}"])
            except ConfigError as e:
                raise ConfigError(f"--sweep {key}={v}: {e.msg}", e.hint) from None
    if not assocs or len(set(assocs)) != len(assocs):
        raise ConfigError(f"associators {','.join(assocs)!r} must be distinct and non-empty")
    logs = list(dict.fromkeys(str(p) for p in logs))
    labels = _log_labels(logs)
    combos = []
    for log, assoc in itertools.product(logs, assocs):
        for values in itertools.product(*sweeps.values()):
            sweep = tuple(zip(sweeps, values, strict=True))
            sets = [*overrides, f"association.method={assoc}", *(f"{k}={v}" for k, v in sweep)]
            error = ""
            try:
                cfg = resolve_config(log, config_path, sets)
            except LogError as e:  # the log's rows fail; the batch goes on
                cfg, error = load_config(config_path, sets), _failed(e)["error"]
            associator_class(cfg.association.method)  # an unknown name: ConfigError with the closest one
            name = _dir_name(labels[log], assoc, sweep)
            combos.append(Combo(log, assoc, sweep, name, cfg.to_dict(), error))
    names = [c.name for c in combos]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise ConfigError(
            f"two combinations map to the directory name '{dup}'", "sweep values differing only in symbols"
        )
    return combos


def _safe(text: str) -> str:
    return _UNSAFE.sub("_", text)


def _short_hash(text: str) -> str:
    return hashlib.sha1(os.fsencode(text)).hexdigest()[:8]


def _log_labels(logs: Sequence[str]) -> dict[str, str]:
    """Log → its part of the directory name: stem, else file name, else file name + path hash."""
    out: dict[str, str] = {}
    tiers = [
        lambda p: _safe(Path(p).name.split(".")[0] or "log"),
        lambda p: _safe(Path(p).name or "log"),
        lambda p: _safe(Path(p).name or "log") + "-" + _short_hash(str(Path(p).resolve())),
    ]
    for log in logs:
        for tier in tiers:
            label = tier(log)
            if sum(tier(other) == label for other in logs) == 1 or tier is tiers[-1]:
                out[log] = label
                break
    return out


def _dir_name(log_label: str, assoc: str, sweep: tuple[tuple[str, str], ...]) -> str:
    name = "__".join([log_label, _safe(assoc), *(_safe(f"{k}={v}") for k, v in sweep)])
    if len(name) > _MAX_NAME:
        name = name[: _MAX_NAME - 9] + "-" + _short_hash(name)
    return name


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
) -> list[dict]:
    """Run every combination into ``out_dir/<name>/``; write ``out_dir/batch.csv``; return its rows.

    One failing combination (bad log, numerical failure, a bug) never stops the others: its row has
    status ``failed`` and the error line. ``jobs`` local worker processes (default ``os.cpu_count()``),
    or the Dask cluster at ``scheduler``. Rows come in the order of ``combos``.
    """
    from .config import Config, from_dict
    from .report.run_writer import config_hash, find_ground_truth, input_hash

    out = Path(out_dir)
    claim_dir(out, "batch")  # refuses a directory that is not a batch's, before any work
    clear_stale(out / BATCH_CSV)  # temporary files of a killed batch
    columns = batch_columns([k for k, _ in combos[0].sweep] if combos else [])
    rows = [_row(c, "pending") for c in combos]
    state = BatchState(len(combos))
    log_hashes: dict[str, str | None] = {}
    todo: list[int] = []
    for i, c in enumerate(combos):
        if c.error:
            rows[i] = _row(c, "failed", error=c.error)
            state.failed += 1
            continue
        if c.log not in log_hashes:  # once per log, not per combination
            try:
                log_hashes[c.log] = input_hash(Path(c.log))
            except (OSError, CornerslamError):
                log_hashes[c.log] = None  # the run reports the unreadable log (or pipe)
        figures = None
        if log_hashes[c.log] is not None:
            expect = Hashes(input=log_hashes[c.log], config=config_hash(from_dict(Config, c.config)),
                            version=__version__)  # fmt: skip
            figures = _resumable(out / c.name, expect, find_ground_truth(Path(c.log)) is not None)
        if figures is not None:
            rows[i] = _row(c, "skipped", figures=figures)
            state.skipped += 1
        else:
            todo.append(i)
    writer = _CsvWriter(out / BATCH_CSV, columns)
    writer.write(rows)
    if progress is not None:
        progress(state)

    def finished(i: int, result: dict) -> None:
        rows[i] = _row(combos[i], **result)
        setattr(state, result["status"], getattr(state, result["status"]) + 1)
        writer.write(rows, throttle=True)
        if progress is not None:
            progress(state)

    todo.sort(key=lambda i: -_size(combos[i].log))  # biggest logs first: a shorter tail on N workers
    tasks = [(i, combos[i].log, combos[i].config, str((out / combos[i].name).resolve())) for i in todo]
    try:
        if scheduler:
            _run_dask(tasks, scheduler, finished)
        elif tasks:
            _run_local(tasks, jobs or os.cpu_count() or 1, finished)
    finally:
        writer.write(rows)
    return rows


def _size(path: str) -> int:
    try:
        return os.path.getsize(path)
    except OSError:
        return 0


def _row(c: Combo, status: str, error: str = "", figures: dict | None = None) -> dict:
    row = {"log": display_path(c.log), "assoc": c.assoc, **dict(c.sweep), "status": status, "error": error}
    row.update({k: (figures or {}).get(k) for k in FIGURES})
    row["out_dir"] = c.name if status in ("ok", "skipped") else ""
    return row


def figures_from_summary(s: RunSummary) -> dict:
    """The batch.csv figures of one run's summary (returned by the run or read from summary.json)."""
    c, t, acc = s.counts, s.timing, s.accuracy
    nan = float("nan")
    return {
        "steps": c.steps,
        "landmarks": c.landmarks,
        "matched_total": c.matched_total,
        "t_match": float(t.t_match),
        "t_total": float(t.t_total),
        "wall_time": float(t.wall_time),
        "ate_rmse": acc.ate.rmse if acc and acc.ate else nan,
        "odom_ate_rmse": acc.odom_ate.rmse if acc and acc.odom_ate else nan,
    }


def _resumable(run_dir: Path, expect: Hashes, has_gt: bool) -> dict | None:
    """The figures of a complete earlier run of the same log, config and version, else None."""
    try:
        s = RunSummary.read(run_dir)
    except ResultsError:
        return None  # missing, unreadable or from an older layout: run it again
    if s.hashes != expect or (s.accuracy is not None) != has_gt:
        return None
    return figures_from_summary(s)


def run_one(log: str, config: dict, out_dir: str) -> dict:
    """Run one combination (in a worker): ``{"status": "ok", "figures": ...}`` or the failure line.

    Module-level and importing the package lazily, so spawn and Dask workers can unpickle it by name
    and set the BLAS thread count before numpy is first imported.
    """
    single_threaded_blas()
    try:
        from .config import Config, from_dict
        from .pipeline import run

        summary = run(log, from_dict(Config, config), out_dir)
        return {"status": "ok", "figures": figures_from_summary(summary)}
    except Exception as e:  # a bug in one combination must not stop the batch either
        return _failed(e)


def _failed(e: BaseException) -> dict:
    """The failure row's status and one-line error: a CornerslamError's message, a bug's type and message."""
    text = str(e) if isinstance(e, CornerslamError) else f"{type(e).__name__}: {e}"
    return {"status": "failed", "error": " ".join(text.split())}


def _run_local(tasks: list[tuple], jobs: int, finished: Callable[[int, dict], None]) -> None:
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    with single_threaded_blas_env():  # spawned workers inherit it before they import numpy
        pool = ProcessPoolExecutor(
            max_workers=min(jobs, len(tasks)),
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_init_worker,
            initargs=(logging.getLogger().getEffectiveLevel(),),
        )
        try:
            futures = {pool.submit(run_one, log, cfg, out): i for i, log, cfg, out in tasks}
            for fut in as_completed(futures):
                try:
                    result = fut.result()
                except Exception as e:  # the worker process died (killed, out of memory)
                    result = _failed(e)
                finished(futures[fut], result)
        finally:
            pool.shutdown(wait=True, cancel_futures=True)


def _init_worker(level: int) -> None:
    """A spawned worker logs at the parent's level (-q / -v), in the CLI's format, and ends with the
    batch (a killed ``cornerslam batch`` leaves no worker running)."""
    from .workers import exit_with_parent

    logging.basicConfig(level=level, format="%(levelname)s: %(message)s")
    exit_with_parent()


def _run_dask(tasks: list[tuple], scheduler: str, finished: Callable[[int, dict], None]) -> None:
    try:
        from dask.distributed import Client, as_completed
    except ImportError:
        raise CornerslamError(
            "--scheduler needs Dask distributed, which is not installed", "pip install cornerslam[dask]"
        ) from None
    try:
        client = Client(scheduler, timeout=10, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as e:
        raise CornerslamError(
            f"cannot connect to the Dask scheduler at '{scheduler}': {' '.join(str(e).split())}",
            "check the address (tcp://host:port) and that `dask scheduler` is running",
        ) from None
    with client:
        if not tasks:
            return
        idx, logs, cfgs, outs = (list(t) for t in zip(*tasks, strict=True))
        futures = client.map(run_one, logs, cfgs, outs, pure=False)
        index = {f.key: i for f, i in zip(futures, idx, strict=True)}
        for fut in as_completed(futures, loop=client.loop):
            try:
                result = fut.result()
            except Exception as e:  # the worker died (KilledWorker) or the task could not be sent
                result = _failed(e)
            finished(index[fut.key], result)


class _CsvWriter:
    """batch.csv, replaced atomically on each write (at most once a second when throttled)."""

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
        with output_errors(self.path):
            tmp = staged_file(self.path)
            try:
                with open(tmp, "w", newline="") as f:
                    w = csv.writer(f, lineterminator="\n")
                    w.writerow(self.columns)
                    for r in rows:
                        w.writerow(["" if r.get(k) is None else csv_value(r[k]) for k in self.columns])
                    f.flush()
                    os.fsync(f.fileno())
                os.replace(tmp, self.path)
            except BaseException:
                tmp.unlink(missing_ok=True)
                raise


def read_batch(path: str | Path) -> list[dict[str, str]]:
    """batch.csv as a list of rows of strings (the inverse of what :func:`run_batch` writes)."""
    with open(path, newline="") as f:
        return list(csv.DictReader(f))
