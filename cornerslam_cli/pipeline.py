"""A cornerslam run: frontend → slam → run writer.

``run()`` reads as the table of contents of a run: the log's keyframes from the front end
(frontend.py: synchronised, features extracted, motion scan-matched), one step of the filter on each
(slam.py: predict, associate, update, augment), every step's rows and then the map and the summary
written by the run writer (report/run_writer.py) into a staged output directory (report/outdir.py).
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from .config import Config
from .errors import OutputError, display_path, printable
from .frontend import Frame, Input, check_processed, frames, open_input
from .hierarchy import HierarchicalSlam
from .lasers import warn_mount
from .logs.ros import CLOCK_APART
from .ranges import short_text
from .report.occupancy import ScanStore
from .report.oserrors import output_errors
from .report.outdir import StagedDir
from .report.ownership import is_results_mcap
from .report.run_writer import Reference, RunWriter, ground_truth_path, load_reference
from .report.tables import write_json
from .results import RunSummary
from .slam import Slam
from .span import Span

log = logging.getLogger("cornerslam.run")


def default_out_dir(log_path: Path, assoc: str) -> Path:
    name = Path(os.path.abspath(log_path)).name  # `run .` in a ROS 2 bag directory: the directory's name
    stem = display_path(name.split(".")[0]) or "log"  # a name that is not UTF-8: printable
    return Path("cornerslam_out") / f"{stem}_{assoc}"


def run(
    log_path: str | Path,
    cfg: Config,
    out: str | Path | None = None,
    ground_truth: str | Path | None | bool = None,
    progress: Callable[[int, int], None] | None = None,
    relations: str | Path | None = None,
    time_offset: float = 0.0,
    plot: bool = False,
    mcap_out: str | Path | None = None,
    mcap_profile: str = "foxglove",
    config_path: str | Path | None = None,
    span: Span | None = None,
    compiling: Callable[[], None] | None = None,
    inside: str | None = None,
    notes: Sequence[str] = (),
    finishing: Callable[[str], None] = lambda what: None,
) -> RunSummary:
    """Run corner EKF-SLAM on one log and write the output directory atomically: the tables, with
    ``plot`` the figures and report.html, and ``mcap_out`` beside it (in ``mcap_profile``'s encoding,
    report/mcap_out.py), all committed at once.

    The output places are checked before any work (report/ownership.py); the run's inputs — the log,
    the ground truth (also LOG.gt.tum found beside the log, unless ``ground_truth`` is False), the
    relations, the config file ``config_path`` — are never written over; ``span``: the part of the log
    to process (span.py); ``compiling``: frontend.open_input's; ``inside="batch"``: a batch's run,
    written inside its directory (any other output there is refused); ``notes``: warnings already said
    about the config (workers.warnings_copied), kept for summary.json's list; ``finishing(what)``: as
    each stage after the last step begins (the CLI's Progress.finishing).
    Returns the summary (also written to summary.json) with ``out_dir``, the committed directory.
    """
    wall0 = time.perf_counter()
    out_dir = Path(out) if out else default_out_dir(Path(log_path), cfg.association.method)
    gt = ground_truth_path(Path(log_path), ground_truth)
    inputs = [p for p in (log_path, gt, relations, config_path) if p]
    with StagedDir(out_dir, "run", inputs, log_path, own_log_only=not out, inside=inside) as stage:
        mcap_path = stage.stage_file(mcap_out, ours=is_results_mcap) if mcap_out else None
        ref = load_reference(Path(log_path), ground_truth, relations, time_offset)  # bad files fail first
        src = open_input(log_path, cfg, span, compiling)
        keep_notes(src, notes)
        scans = ScanStore() if mcap_path else None  # kept for the results MCAP's scans
        offset = 0  # ns: the results MCAP's log times ahead of the stamps (the log's recorder clock's)
        if mcap_path:
            warn_second_parent(src)
            offset = recorder_clock(src)
        summary = run_filter(
            frames(src, cfg, progress), src, cfg, stage.path, ref, wall0, scans, finishing=finishing
        )
        if plot or mcap_path:
            extras = (("the figures", plot), ("the results MCAP", mcap_path))
            finishing(" and ".join(what for what, made in extras if made))
        tf_odom = logged_tf_odometry(src) if mcap_path else None
        said = len(src.reader.stats.warnings)
        write_extras(stage, plot, mcap_out, mcap_path, ref.gt_path, scans, src.stats.anchors, offset, tf_odom,
                     src.reader.stats.warn, mcap_profile)  # fmt: skip
        if len(src.reader.stats.warnings) > said:  # the results MCAP's: kept in summary.json too
            summary = replace(summary, warnings=tuple(src.reader.stats.warnings))
            write_json(stage.path / "summary.json", summary.to_json())
        summary = summary.with_out_dir(stage.commit())
    return summary


def logged_tf_odometry(src: Input) -> tuple[np.ndarray, np.ndarray] | None:
    """The log's tf odom → base poses (stamps, poses) when the run read its odometry from another source
    (a nav_msgs/Odometry topic) though the tf carries odom → base too: the results MCAP's map → odom is
    built on them, as a viewer chains it with the log's tf (RosLogReader.tf_odometry_poses); else None."""
    if not src.odom_on_tf or src.info.odom_source.startswith("tf"):
        return None
    read = getattr(src.reader, "tf_odometry_poses", None)
    return read() if read is not None else None


def warn_second_parent(src: Input) -> None:
    """Warn when the log's tf already gives the odometry frame a parent (a localiser's map → odom): the
    results MCAP's own map → it would be a second transform into it when both files are open."""
    parent_on_tf = getattr(src.reader, "parent_on_tf", None)  # (a CARMEN log has no tf)
    odom = src.reader.odom_frame if parent_on_tf else ""
    if odom and (parent := parent_on_tf(odom)):
        src.reader.stats.warn(
            "log '%s': its tf already gives '%s' a parent (%s → %s), and the results MCAP gives it its own "
            "(map → %s): with both files open a viewer gets two transforms into it (show one file's tf)",
            src.path.name, short_text(odom), short_text(parent), short_text(odom), short_text(odom),
        )  # fmt: skip


def recorder_clock(src: Input) -> int:
    """How far ahead of the scans' header stamps the log's recorder clock is [ns], when more than
    :data:`CLOCK_APART` (a simulation recorded without use_sim_time: its stamps from 0, its log times
    the wall clock's), warned; else 0. The results MCAP's log times are then the recorder's, so that a
    viewer plays it beside the log (its messages keep the header stamps)."""
    record_offset = getattr(src.reader, "record_offset", None)  # (a CARMEN log has no recorder clock)
    offset = record_offset() if record_offset else None
    if offset is None or abs(offset) <= CLOCK_APART * 1e9:
        return 0
    src.reader.stats.warn(
        "log '%s': its recorder's clock is %.1f s %s its scans' header stamps (a simulation recorded without "
        "use_sim_time?): the results MCAP's log times follow the recorder's, so that it plays beside the log",
        src.path.name, abs(offset) * 1e-9, "ahead of" if offset > 0 else "behind",
    )  # fmt: skip
    return offset


def keep_notes(src: Input, notes: Sequence[str]) -> None:
    """Keep warnings said before the log was opened (the config's: workers.warnings_copied) in the
    input's list, summary.json's, by its reader's warn, marked said so that it does not say them again."""
    stats = src.reader.stats
    for text in notes:
        stats.said.add(printable(text))
        stats.warn("%s", text)


def write_extras(
    stage: StagedDir,
    plot: bool,
    mcap_out: str | Path | None,
    mcap_path: Path | None,
    ground_truth: Path | None = None,
    scans: ScanStore | None = None,
    anchors: Sequence[tuple[float, tuple[float, float, float]]] = (),
    clock_offset: int = 0,
    tf_odometry: tuple[np.ndarray, np.ndarray] | None = None,
    warn: Callable[..., None] = log.warning,
    profile: str = "foxglove",
) -> None:
    """What a run writes besides its tables, staged before the commit: with ``plot`` the figures and
    report.html; the results MCAP into ``mcap_path``, the staged place of ``mcap_out``, with the
    run's ``scans``, its odometry's re-anchorings (``anchors``: SyncStats's), its log times
    ``clock_offset`` ns ahead of the stamps (:func:`recorder_clock`) and the log's ``tf_odometry``
    (:func:`logged_tf_odometry`), in ``profile``'s encoding, saying what is odd with ``warn``. Both draw
    the ``ground_truth`` file the run was scored against."""
    if plot:
        from .report.html import write_report
        from .report.plots import plot_run

        plot_run(stage.path, ground_truth)
        write_report(stage.path)
    if mcap_path is not None:
        from .report.mcap_out import stamps_refused, write_results_mcap

        if mcap_path.is_relative_to(stage.path) and mcap_path.exists():
            raise OutputError(f"--mcap-out '{mcap_out}' is a file of the run itself", "give another name")
        with output_errors(mcap_out), stamps_refused(mcap_out):
            write_results_mcap(
                stage.path,
                mcap_path,
                stage.target,
                ground_truth,
                scans,
                anchors,
                clock_offset,
                tf_odometry,
                warn,
                profile,
            )


def run_filter(
    frame_iter: Iterable[Frame],
    src: Input,
    cfg: Config,
    dest: Path,
    ref: Reference,
    wall0: float,
    scans: ScanStore | None = None,
    stepped: Callable[[int], None] | None = None,
    finishing: Callable[[str], None] = lambda what: None,
) -> RunSummary:
    """The filter over the front end's frames, a run's files written into the (staging) directory
    ``dest`` (the scans kept in ``scans`` when given); ``stepped(n)`` after each of its n steps,
    ``finishing(what)`` as each stage after the last step begins (their work has no count to show);
    returns the summary."""
    slam = (
        HierarchicalSlam(cfg, src.laser2base)
        if cfg.submaps.enabled
        else Slam.from_config(cfg, src.laser2base)
    )
    graph = slam if isinstance(slam, HierarchicalSlam) else None
    if cfg.graph.refine and graph is None:
        src.reader.stats.warn(
            "graph.refine=true is ignored: it refines the two levels' keyframe graph, and "
            "submaps.enabled=false runs the single map"
        )
    if cfg.graph.recalibrate and (graph is None or src.matcher is None):
        why = (
            "submaps.enabled=false runs the single map"
            if graph is None
            else "input.odometry=scans fuses no scan matches with it"
            if src.scan_odometry is not None
            else "scan_match.enabled=false"
        )
        src.reader.stats.warn(
            f"graph.recalibrate=true is ignored: it carries the odometry bias the scan matcher learnt back "
            f"into the keyframe graph's steps, and {why}"
        )
    with RunWriter(dest, src.laser2base, cfg.grid, scans) as writer:
        for frame in frame_iter:
            record = slam.step(frame)
            writer.step(record, frame.points)
            log.debug(
                "step %d (%s): %d corners, %d matched, %d new, %d landmarks, match %.1f ms",
                record.step, cfg.association.method, record.n_corners, record.n_matched, record.n_new,
                record.n_landmarks, 1e3 * record.t_match,
            )  # fmt: skip
            if stepped is not None:
                stepped(slam.n_steps)
        writer.close_steps()
        check_processed(src, slam.n_steps, writer.totals.points)
        warn_mount(src, cfg)
        if graph is not None:
            finishing("the last loop closing and the smoothing")
            learnt = src.matcher is not None and cfg.graph.recalibrate
            graph.finish(src.matcher.fusion.carry_back if learnt else None)
            for warning in (graph.solver_warning(), graph.refinement.solver_warning()):
                if warning:
                    src.reader.stats.warn(warning)
        finishing("the map and the tables")
        summary = writer.finish(slam.landmark_table(), src, cfg, ref, wall0, graph)
    c = summary.counts
    log.info(
        "filter %s: %d steps, %d landmarks, %d matches, %.1f s",
        cfg.association.method, c.steps, c.landmarks, c.matched_total, time.perf_counter() - wall0,
    )  # fmt: skip
    return summary
