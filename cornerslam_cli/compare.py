"""``cornerslam compare``: every associator on the same extracted frames, side by side.

Frames are extracted once (extraction does not depend on the associator) and kept in memory, then
each associator runs the filter over them — in parallel worker processes with ``jobs`` > 1 (the
frames reach the workers by fork, not by pickling). Each associator's run is a complete ``run``
output directory under ``OUT/ASSOC``; progress is reported in scans while extracting, then in filter
steps of all the associators; ``comparison.csv`` has one row per associator; the figures and
report.html follow (report/comparison.py writes them). The whole of OUT is staged and committed once
(report/outdir.py).
"""

from __future__ import annotations

import dataclasses
import logging
import multiprocessing
import os
import signal
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from .config import Config
from .frontend import Frame, Input, frames, open_input
from .lasers import warn_mount
from .pipeline import keep_notes, run_filter
from .report.comparison import write_comparison
from .report.outdir import StagedDir
from .report.ownership import mark_output
from .report.run_writer import load_reference
from .results import RunSummary
from .span import Span
from .workers import end_children, exit_with_parent, signals_deferred

log = logging.getLogger("cornerslam.compare")
_SHARED: dict = {}  # what forked workers inherit: frames, input, reference


def with_assoc(cfg: Config, assoc: str) -> Config:
    return dataclasses.replace(cfg, association=dataclasses.replace(cfg.association, method=assoc))


def _run_one(
    assoc: str, out_dir: Path, stepped: Callable[[int], None] | None = None, in_worker: bool = False
) -> RunSummary:
    sh = _SHARED
    cfg = with_assoc(sh["cfg"], assoc)
    sh["src"].reader.stats.quiet = in_worker  # a worker keeps its warnings; the parent says each once
    # the runs share the input: the warnings a run adds to it (summary.json's) are taken back after it,
    # so the next run's summary has the extraction's and its own, as in a worker process of its own
    warnings = sh["src"].reader.stats.warnings
    extracted = list(warnings)
    try:
        return run_filter(
            sh["frames"], sh["src"], cfg, out_dir, sh["ref"], time.perf_counter(), stepped=stepped
        )
    finally:
        warnings[:] = extracted


def _worker_init() -> None:
    """A forked filter worker: ends when its parent has gone; ignores Ctrl-C (the terminal sends it to the
    whole process group: the parent decides, and ends its workers) and has SIGTERM's default action (not
    the parent's handler it was forked with), both unblocked (it was forked inside signals_deferred)."""
    exit_with_parent()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})


def _run_filters(
    assocs: Sequence[str], dirs: list[Path], jobs: int, progress: Callable[..., None] | None
) -> list[RunSummary]:
    """Each associator's filter over the shared frames, reporting ``progress`` in filter steps of all
    of them: after every step when they run one after another, as each finishes with ``jobs`` > 1
    (worker processes)."""
    n = len(_SHARED["frames"])
    total = n * len(assocs)

    def report(done: int, doing: str) -> None:
        if progress is not None:
            progress(done, total, "filter steps", doing)

    if jobs > 1 and len(assocs) > 1:
        ctx = multiprocessing.get_context("fork")
        workers = min(jobs, len(assocs))
        _SHARED["src"].filters_at_once = workers  # (the forked workers' summaries say so)
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_worker_init)
        try:
            with signals_deferred():  # (the workers fork here: a signal then lands after, in this process)
                futures = [pool.submit(_run_one, a, d, None, True) for a, d in zip(assocs, dirs, strict=True)]
            for k, _ in enumerate(as_completed(futures), 1):
                report(k * n, f"{workers} at a time")
            summaries = [f.result() for f in futures]
        except BaseException:  # interrupted (Ctrl-C, SIGTERM) or failed: its workers end with it, now
            end_children()
            raise
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
        for s in summaries:  # the runs' warnings, each said once (the extraction's were already)
            for text in s.warnings:
                _SHARED["src"].reader.stats.say(text)
        log.warning(
            "timings: %d filters ran at once (--jobs %d, %d cores usable): each one's times depend on what "
            "ran beside it (the CPU, its caches), and so on the order of --assoc; to compare them, run "
            "with --jobs 1",
            workers, jobs, len(os.sched_getaffinity(0)),
        )  # fmt: skip
        return summaries
    summaries = []
    for k, (a, d) in enumerate(zip(assocs, dirs, strict=True)):
        summaries.append(_run_one(a, d, lambda i, k=k, a=a: report(k * n + i, a)))
    return summaries


def compare(
    log_path: str | Path,
    cfg: Config,
    assocs: Sequence[str],
    out: Path,
    ground_truth: str | Path | None = None,
    jobs: int = 1,
    progress: Callable[..., None] | None = None,
    relations: str | Path | None = None,
    time_offset: float = 0.0,
    plots: bool = True,
    default_place: bool = False,
    span: Span | None = None,
    compiling: Callable[[], None] | None = None,
    notes: Sequence[str] = (),
    config_path: str | Path | None = None,
) -> list[RunSummary]:
    """Run each associator in ``assocs`` on ``log_path``; write OUT/ASSOC/, OUT/comparison.csv and
    (``plots``) the figures and OUT/report.html, committed together. The output place is checked
    before any work (``default_place``: OUT is named after the log: another log's output there is
    refused, not replaced); ``span``: the part of the log to process; ``compiling``: frontend.open_input's;
    ``notes``: warnings already said about the config, kept for each run's summary.json; ``config_path``:
    the config file (an input: never written over)."""
    inputs = [p for p in (log_path, ground_truth, relations, config_path) if p]
    with StagedDir(out, "compare", inputs, log_path, own_log_only=default_place) as stage:
        ref = load_reference(Path(log_path), ground_truth, relations, time_offset)
        t0 = time.perf_counter()
        src: Input = open_input(log_path, cfg, span, compiling)
        keep_notes(src, notes)
        frame_list: list[Frame] = list(frames(src, cfg, progress))
        # the input's: warned once here, not once per associator (its runs skip a repeat); as a run
        # warns it, only when the frames have valid beams (else their error comes alone: check_processed)
        if any(f.n_points for f in frame_list):
            warn_mount(src, cfg)
        dirs = [stage.path / a for a in assocs]
        for d in dirs:
            d.mkdir()
        log.info(
            "extracted %d keyframes of %s in %.1f s", len(frame_list), src.path.name, time.perf_counter() - t0
        )
        _SHARED.update(frames=frame_list, src=src, cfg=cfg, ref=ref)
        try:
            summaries = _run_filters(assocs, dirs, jobs, progress)
        finally:
            _SHARED.clear()
        write_comparison(stage.path, summaries, plots, ref.gt_path, progress)
        for d in dirs:
            mark_output(d, "run", Path(log_path))  # each is a complete run output
        final = stage.commit()
    return [s.with_out_dir(final / a) for s, a in zip(summaries, assocs, strict=True)]
