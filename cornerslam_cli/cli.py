"""The ``cornerslam`` command line: the click group, one small function per command that calls the
library and echoes its text (report/text.py), and the one error boundary. Shared options: options.py.

Exit codes (INTERFACE.md): 0 success; 1 internal error (traceback saved to a file); 2 bad input or
usage, reported as one line naming the file, key or topic and what to do.

Over 400 lines because every command's click declaration lives here beside the one error boundary
(only cli.py turns errors into exit codes); each command body is a few lines calling the library.
"""

from __future__ import annotations

import errno
import io
import logging
import os
import re
import signal
import sys
import threading
from functools import partial
from pathlib import Path

from .blas import single_threaded_blas

single_threaded_blas()  # before numpy is first imported (blas.py says why)

import click  # noqa: E402
from click.core import ParameterSource  # noqa: E402

from . import __version__  # noqa: E402
from .errors import (  # noqa: E402
    CornerslamError,
    LogError,
    display_path,
    for_command,
    one_line,
    save_traceback,
    terminal_safe,
)
from .options import (  # noqa: E402
    CONFIG_COPIES,
    FIGURE_PATH,
    FINITE,
    PRESET,
    SCAN_INDEX,
    GivenPath,
    Whole,
    check_method_not_set,
    check_option_agrees,
    check_sweep_not_set,
    check_time_offset,
    chosen_ground_truth,
    command_config,
    config_options,
    is_setting,
    parse_assocs,
    parse_span,
    parse_sweeps,
    reference_options,
    setup_logging,
    span_options,
    topic_options,
    verbosity_options,
)
from .report.mcap_items import PROFILES  # noqa: E402
from .report.progress import BatchProgress, Progress  # noqa: E402
from .report.text import (  # noqa: E402
    batch_counts,
    batch_lines,
    comparison_lines,
    evaluation_lines,
    info_lines,
    scan_heading,
    summary_lines,
)

log = logging.getLogger("cornerslam")


# ---------------------------------------------------------------------------- the error boundary
class _Terminated(KeyboardInterrupt):
    """SIGTERM (kill) taken down the Ctrl-C path, so the staged output directory is removed too."""


def _on_sigterm(signum, frame):
    signal.signal(signal.SIGTERM, signal.SIG_IGN)  # a second kill must not interrupt the clean-up
    raise _Terminated


def _stdout_gone() -> None:
    """After EPIPE on stdout: point it at /dev/null, so the interpreter's last flush stays quiet."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, io.UnsupportedOperation):
        pass


class _ClosedStdout(io.TextIOBase):
    """Standard output when the process was started with it closed (Python's ``sys.stdout`` is then None
    and click's echo writes nothing): a write fails as on a closed descriptor, so the command exits 2
    saying so, as `ls >&-` does, instead of 0 with its report lost."""

    def writable(self) -> bool:
        return True

    def write(self, text: str) -> int:
        raise OSError(errno.EBADF, "standard output is closed")


def _stdout_write_failed(exc: BaseException) -> bool:
    """Whether ``exc`` (an OSError) was raised writing to standard output (click.echo without
    ``err``): stdout on a full disk (`> /dev/full`) or a failing device is the environment, not a bug."""
    tb = exc.__traceback__
    while tb is not None:
        frame = tb.tb_frame
        if frame.f_code.co_name == "echo" and frame.f_globals.get("__name__") == "click.utils":
            return not frame.f_locals.get("err", False)
        tb = tb.tb_next
    return False


class _Cli(click.Group):
    """The one error boundary: a CornerslamError becomes one line and exit 2; a bug exits 1 with its
    traceback saved to a file; Ctrl-C exits 130, SIGTERM 143 (the staged output directory is
    discarded); a closed stdout (`| head -1`) exits 141 quietly, as a Unix tool killed by SIGPIPE
    does (the output directory of a finished run is already committed)."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        """The group's own options (``cornerslam --bogus``): a usage error is one line too; no
        arguments at all still print the help."""
        given = bool(args)  # (the parser consumes the list)
        try:
            return super().parse_args(ctx, args)
        except click.exceptions.UsageError as e:
            if not given:
                raise
            _usage_exit(ctx, e)

    def invoke(self, ctx: click.Context):
        if sys.stderr is None:  # started with stderr closed (`2>&-`): messages go nowhere, not into a crash
            sys.stderr = open(os.devnull, "w")  # noqa: SIM115  # open until the process ends
        if sys.stdout is None:  # started with stdout closed (`>&-`): what it says must fail, not vanish
            sys.stdout = _ClosedStdout()
        main_thread = threading.current_thread() is threading.main_thread()
        previous = signal.signal(signal.SIGTERM, _on_sigterm) if main_thread else None
        try:
            return super().invoke(ctx)
        except CornerslamError as e:
            text = one_line(e)  # a message quoting a library's error may span lines (rosbags' YAML errors)
            for copy, given in ctx.meta.get(CONFIG_COPIES, {}).items():
                text = text.replace(copy, given)  # a --config pipe read into a temporary copy
            command = self.get_command(ctx, ctx.invoked_subcommand) if ctx.invoked_subcommand else None
            text = for_command(text, [o for p in (command.params if command else []) for o in p.opts])
            click.echo(f"error: {text}", err=True)
            ctx.exit(2)
        except click.exceptions.UsageError as e:  # a subcommand's arguments: one line, as our own errors
            _usage_exit(ctx, e)
        except (click.exceptions.ClickException, click.exceptions.Exit, click.exceptions.Abort):
            raise
        except KeyboardInterrupt as e:
            _interrupted(ctx, e)
        except BrokenPipeError:
            _stdout_gone()
            ctx.exit(141)
        except Exception as exc:
            if (signal_exc := _interrupt_in_chain(exc)) is not None:
                _interrupted(ctx, signal_exc)  # raised inside a compiled kernel, wrapped by numba
            if isinstance(exc, OSError) and _stdout_write_failed(exc):
                _stdout_gone()
                reason = os.strerror(exc.errno) if exc.errno else str(exc)
                click.echo(
                    f"error: cannot write to standard output: {reason} (redirect it elsewhere)", err=True
                )
                ctx.exit(2)
            click.echo(f"internal error: {one_line(exc)} ({save_traceback(exc)})", err=True)
            ctx.exit(1)
        finally:
            if main_thread and previous is not None:
                signal.signal(signal.SIGTERM, previous)


def _usage_exit(ctx: click.Context, e: click.exceptions.UsageError) -> None:
    click.echo(f"error: {usage_line(e)}", err=True)
    ctx.exit(e.exit_code)


def usage_line(e: click.exceptions.UsageError) -> str:
    """Click's usage error as one line: its message, lower-cased first letter and no final full stop (as
    our own errors read), and where the command's help is — instead of click's usage, hint and message
    on four lines."""
    msg = " ".join(e.format_message().split()).replace(". (Did you mean", " (did you mean")
    msg = (msg[:1].lower() + msg[1:]).removesuffix(".")
    extra = re.fullmatch(r"got unexpected extra arguments? \((.*)\)", msg)
    if extra and any(is_setting(a) for a in extra[1].split()):  # `--set a.b=1 c.d=2`
        msg += ": give --set before each KEY=VALUE"
    where = e.ctx.command_path if e.ctx is not None else "cornerslam"
    return f"{msg} (see '{where} --help')"


def _signal_word(e: KeyboardInterrupt) -> tuple[str, int]:
    """What stopped us and the exit status it gives: SIGTERM 143, Ctrl-C 130 (as a shell's 128 + N)."""
    return ("terminated", 143) if isinstance(e, _Terminated) else ("interrupted", 130)


WRITE_NOTHING = ("info", "config", "evaluate")  # commands that only print: an interrupt loses no file


def _interrupted(ctx: click.Context, e: KeyboardInterrupt) -> None:
    """Exit 130 (Ctrl-C) or 143 (SIGTERM) with one line saying whether the output was written (of a
    command that writes no file, only the word: "no output written" had them look for one)."""
    word, code = _signal_word(e)
    written = getattr(e, "output_written", None)  # the signal came after the commit
    if written is not None:
        text = f": after the output was complete ('{written}' is written)"
    elif ctx.invoked_subcommand in WRITE_NOTHING:
        text = ""
    else:
        text = ": no output written (an earlier output there, if any, is kept)"
    click.echo(f"{word}{text}", err=True)
    ctx.exit(code)


def _interrupt_in_chain(exc: BaseException) -> KeyboardInterrupt | None:
    """The Ctrl-C / SIGTERM behind ``exc``, if any: a signal handler's exception raised while a Numba
    kernel runs reaches us as a SystemError ("returned a result with an exception set") caused by it."""
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


# ---------------------------------------------------------------------------- commands
def _echo(lines: list[str]) -> None:
    """A command's report, a line at a time, each with its control characters escaped (a log's file
    name or topic may hold a newline or an escape sequence)."""
    for line in lines:
        click.echo(terminal_safe(line))


@click.group(cls=_Cli, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="cornerslam")
def cli() -> None:
    """Natural-corner EKF-SLAM (Yan et al. 2014) on recorded 2D laser logs.

    Exit codes: 0 success, 1 internal error (traceback saved), 2 bad input or usage, 130 Ctrl-C,
    143 SIGTERM, 141 output pipe closed.
    """


@cli.command()
@click.argument("log_path", metavar="LOG", type=GivenPath(log=True))
@config_options
@click.option("--assoc", default=None, help="Associator: icnn, jcbb or pca (default: config, pca).")
@click.option("--out", type=GivenPath(), help="Output directory (default ./cornerslam_out/LOG_ASSOC).")
@topic_options
@reference_options
@click.option("--plot", is_flag=True, help="Also draw the map, timing and corner plots and report.html.")
@click.option(
    "--mcap-out",
    type=GivenPath(),
    help="Also write the results as MCAP (Foxglove; --mcap-profile ros2: ROS 2).",
)
@click.option(
    "--mcap-profile",
    type=click.Choice(PROFILES),
    default="foxglove",
    show_default=True,
    help="The --mcap-out file's encoding: Foxglove's schemas, or ROS 2 messages for `ros2 bag play`.",
)
@span_options
@verbosity_options
def run(
    log_path,
    config_path,
    overrides,
    assoc,
    out,
    scan_topic,
    odom_topic,
    ground_truth,
    no_ground_truth,
    relations,
    time_offset,
    plot,
    mcap_out,
    mcap_profile,
    start,
    end,
    max_scans,
    verbose,
    quiet,
):
    """Run corner EKF-SLAM on LOG and write trajectory, map, lines, timing and summary.

    \b
    Example:
      cornerslam run sample_logs/sim_office.mcap --assoc jcbb --out out/
    """
    from .pipeline import run as run_pipeline
    from .workers import warnings_copied

    setup_logging(verbose, quiet)
    names = parse_assocs(assoc, allow_many=False, log_path=log_path)
    check_mcap_name(mcap_out, mcap_profile)
    check_time_offset(relations, time_offset)
    ground_truth = chosen_ground_truth(ground_truth, no_ground_truth)
    span = parse_span(start, end, max_scans)
    with warnings_copied() as notes:  # the config's (a preset not the log's laser): summary.json's too
        cfg = command_config(
            config_path, overrides, names[0] if names else None, scan_topic, odom_topic, log_path
        )
    progress = Progress(f"{display_path(Path(log_path).name)} ({cfg.association.method})", not quiet)
    compiled: list[bool] = []
    try:
        summary = run_pipeline(
            log_path,
            cfg,
            out,
            ground_truth,
            progress,
            relations=relations,
            time_offset=time_offset,
            plot=plot,
            mcap_out=mcap_out,
            mcap_profile=mcap_profile,
            config_path=config_path,
            span=span,
            compiling=lambda: compiled.append(_say_compiling(quiet)),
            notes=notes,
            finishing=progress.finishing,
        )
    finally:
        progress.close()
    out_dir = Path(summary.out_dir)
    if not quiet:
        _echo(summary_lines(summary))
        if any(compiled):  # the wall time holds a first run's minute (a new user read it as slow)
            click.echo(COMPILED_NOTE)
        if plot:
            click.echo(f"report: {out_dir / 'report.html'}")
        if mcap_out:
            click.echo(f"results MCAP: {mcap_out}")


@cli.command()
@click.argument("log_path", metavar="LOG", type=GivenPath(log=True))
@click.option(
    "--assoc", "assocs", default="icnn,jcbb,pca", show_default=True, help="Comma-separated associators."
)
@config_options
@click.option("--out", type=GivenPath(), help="Output directory (default ./cornerslam_out/LOG_compare).")
@topic_options
@reference_options
@click.option(
    "--jobs",
    default=1,
    show_default=True,
    type=Whole(1, 64),
    help="Parallel processes (the filters' times then include waiting for the CPU: compare times with 1).",
)
@span_options
@verbosity_options
def compare(
    log_path,
    assocs,
    config_path,
    overrides,
    out,
    scan_topic,
    odom_topic,
    ground_truth,
    no_ground_truth,
    relations,
    time_offset,
    jobs,
    start,
    end,
    max_scans,
    verbose,
    quiet,
):
    """Run several associators on LOG with the same extracted features and tabulate them.

    \b
    Example:
      cornerslam compare sample_logs/sim_office.mcap --assoc icnn,jcbb,pca --jobs 2
    """
    from .compare import compare as run_compare
    from .pipeline import default_out_dir
    from .workers import warnings_copied

    setup_logging(verbose, quiet)
    names = parse_assocs(assocs, allow_many=True)
    check_time_offset(relations, time_offset)
    ground_truth = chosen_ground_truth(ground_truth, no_ground_truth)
    span = parse_span(start, end, max_scans)
    ignored = {"association.method": (f"compare runs each associator of --assoc ({','.join(names)})", names)}
    with warnings_copied() as notes:  # the config's: each run's summary.json's too
        cfg = command_config(config_path, overrides, None, scan_topic, odom_topic, log_path, ignored)
    check_method_not_set(overrides, ",".join(names))  # (after the config: an unknown name is named as such)
    out_dir = Path(out) if out else default_out_dir(Path(log_path), "compare")
    progress = Progress(f"{display_path(Path(log_path).name)} (compare)", not quiet)
    try:
        summaries = run_compare(
            log_path, cfg, names, out_dir, ground_truth, jobs, progress, relations, time_offset,
            default_place=not out, span=span, compiling=partial(_say_compiling, quiet), notes=notes,
            config_path=config_path,
        )  # fmt: skip
    finally:
        progress.close()
    if not quiet:
        _echo(comparison_lines(summaries))
        done = out_dir.resolve()  # (as run says it: the whole path, to copy)
        click.echo(f"wrote {done} (report: {done / 'report.html'})")


COMPILED_NOTE = "(the wall time includes compiling the numerical kernels: once, later runs use the cache)"


def _say_compiling(quiet: bool) -> bool:
    """On stderr, unless ``quiet``: that the kernels are compiled first, when their caches are empty (a
    first run's minute would otherwise pass without a word, its progress line only after it). Whether
    they are."""
    from .compiled import compile_note

    note = compile_note()
    if not quiet and note:
        click.echo(note, err=True)
    return bool(note)


@cli.command()
@click.argument("log_path", metavar="LOG", type=GivenPath(log=True))
@config_options
@topic_options
@verbosity_options(progress=False, steps=False)
def info(log_path, config_path, overrides, scan_topic, odom_topic, verbose, quiet):
    """Show what is in LOG: format, topics, types, counts, rates, and what `run` would use — with
    --config/--set, what it would use under them (input.*: topics, frames, stamps, the laser's mount and
    preset).

    \b
    Example:
      cornerslam info robot.bag --set input.stamps=receive --set input.base_frame=base_footprint
    """
    from dataclasses import replace

    from .frontend import skipped_all
    from .lasers import first_scan, laser_mount, mismatch_text, overruled_mount
    from .logs import alone_info, open_configured, read_alone
    from .logs.mcap import header_fields
    from .logs.unreadable import no_scan_read
    from .report.ownership import is_results_mcap
    from .report.run_writer import find_ground_truth, load_reference

    setup_logging(verbose, quiet)
    cfg = _info_config(config_path, overrides, scan_topic, odom_topic)
    reader = open_configured(Path(log_path), cfg.input)
    log_info = reader.info()
    alone = read_alone(cfg.input)  # (input.odometry=scans: the odometry a run would use is the scans')
    if alone:
        log_info = alone_info(reader, log_info)
    topics = cfg.input.scan_topic or cfg.input.odom_topic  # (--scan-topic, or its --set)
    if is_results_mcap(Path(log_path)) and not topics:  # run --mcap-out's: described
        lines = info_lines(log_path, replace(log_info, problems=()), None)
        ros2 = (header_fields(log_path) or ("", ""))[0] == "ros2"
        _echo(
            [*lines[: lines.index("run would use:")], RESULTS_MCAP_ROS2_NOTE if ros2 else RESULTS_MCAP_NOTE]
        )
        return
    beams = {"deskew": cfg.input.deskew, "beam_time": cfg.input.beam_time}  # (as a run would use them)
    if log_info.problems:  # a log run refuses (no LaserScan, only odometry, …): its topics, then why
        scan = None
        if log_info.scan_topic:  # scans without odometry: their first is read all the same (scans())
            try:
                scan = first_scan(reader)
            except LogError:
                pass  # the error below says what run would refuse
        preset = _info_preset(cfg, scan)
        lines = info_lines(
            log_path, replace(log_info, problems=()), None, scan, preset, mount_read=False, **beams
        )
        _echo(_with_stamps(lines, reader))
        reader.check()  # the first problem as the error: exit 2, as run (on the scans alone: theirs)
    scan, unread, laser, mount_text, upside_down, flip_source = None, None, None, "", False, ""
    try:  # (a topic declared with no message: run refuses it here, info lists the counts first)
        laser, source, upside_down, flip_source = laser_mount(reader, cfg)  # the tf's, else the config's
        if source == "tf" and (keys := overruled_mount(cfg, laser)):  # (run warns of it)
            note = f"the log's mount is used: {keys} ignored (input.laser.from_tf=false uses the config's)"
            log_info = replace(log_info, notes=(*log_info.notes, note))
        if cfg.input.laser.upside_down and flip_source == "tf" and not upside_down:  # (run warns of it too)
            note = "the log's tf mounts the laser upright: input.laser.upside_down=true is ignored"
            log_info = replace(log_info, notes=(*log_info.notes, note))
        if source == "default" and (near := getattr(reader, "near_frames", "")):  # (run warns of it too)
            log_info = replace(log_info, notes=(*log_info.notes, near.strip()[1:-1]))
        laser, mount_text = _mount_shown(laser, source, cfg, log_info.format)
        scan = first_scan(reader) if log_info.scan_topic else None
    except LogError as e:  # info lists what it can: the topics, then why run would refuse the log
        unread = e
    if log_info.scan_topic and scan is None and unread is None:  # every chunk corrupt: no scan at all
        unread = no_scan_read(log_path, "run has none to process", topics_hint=False, stats=reader.stats)
    if scan is not None and unread is None:  # (a run refuses it at its first scan: a probe)
        unread = skipped_all(cfg.input, scan.n_beams, log_info.scan_topic)
    preset = _info_preset(cfg, scan)
    pinned = cfg.input.laser_preset not in ("auto", "none") and scan is not None  # (run warns of another's)
    if pinned and (text := mismatch_text(preset, scan.n_beams, scan.angle_increment, log_path)):
        log_info = replace(log_info, notes=(*log_info.notes, text))
    if getattr(reader, "mount_problem", ""):  # a CARMEN log's laser poses that are no fixed mount
        log_info = replace(log_info, notes=(*log_info.notes, f"the log {reader.mount_problem}"))
    if gt := find_ground_truth(Path(log_path)):  # (what run and compare will score against, unasked)
        found = f"ground truth {display_path(gt)} beside it: run and compare score against it"
        try:  # read as run reads it, a file it refuses said so (not one over INFO_GT_BYTES: seconds)
            if (size := gt.stat().st_size) > INFO_GT_BYTES:
                found += f" (its {size / 2**20:.0f} MiB not read here: run checks them)"
            else:
                load_reference(Path(log_path))
        except CornerslamError as e:
            found = f"run and compare exit 2 on the ground truth beside it: {e.msg} ({e.hint})"
        except OSError:
            pass  # (run says why it cannot read it)
        log_info = replace(log_info, notes=(*log_info.notes, found))
    frames = None  # the robot's frame (the odometry's child_frame_id, else input.base_frame), the laser's
    if laser is not None and not mount_text and getattr(reader, "laser_frame", None):
        frames = (reader.base_frame, reader.laser_frame)
    lines = info_lines(
        log_path, log_info, laser, scan, preset, upside_down, frames, mount_text=mount_text,
        flip_from_config=flip_source == "config", **beams,
    )  # fmt: skip
    _echo(_with_stamps(lines, reader))
    if unread is not None:  # exit 2, as run
        raise unread
    odom_tf = None if alone else getattr(reader, "odom_tf_problem", lambda: None)()  # ROS: tf odometry gone
    if odom_tf and odom_tf[1]:  # every tf message read: run would fail at the end of the log
        raise LogError(*odom_tf[0])
    if odom_tf:  # the first 2,000 messages after the first scan only: likely, not certain
        reader.stats.warn("%s in the first 2,000 messages after the first scan (%s)", *odom_tf[0])


INFO_GT_BYTES = 16 * 2**20  # info reads a ground truth beside the log up to this size (~400,000 poses, ~2 s)


def _info_config(config_path, overrides, scan_topic, odom_topic):
    """``info``'s config: the user's layers as a run resolves them, without the laser preset (no preset
    sets an ``input`` key, so the log is read alike; the preset info shows is chosen from the first scan
    it reads anyway, :func:`_info_preset` — resolving it here read the log a second time)."""
    return command_config(config_path, overrides, None, scan_topic, odom_topic)


def _with_stamps(lines: list[str], reader) -> list[str]:
    """``info``'s lines with, under ``input.stamps=receive``, what the scans and odometry are timed by
    (after the odometry line)."""
    if not reader.receive:
        return lines
    at = lines.index("run would use:") + 3
    return [*lines[:at], f"  stamps    {reader.stamps_name} (input.stamps=receive)", *lines[at:]]


def _info_preset(cfg, scan) -> str | None:
    """The laser preset a run takes for ``scan`` under ``cfg`` (``input.laser_preset``: auto by the scan's
    geometry — None when none matches —, "none" or a name), None without a scan."""
    from .lasers import detect_preset

    choice = cfg.input.laser_preset
    if scan is None:
        return None
    return detect_preset(scan.n_beams, scan.angle_increment) if choice == "auto" else choice


def _mount_shown(laser, source, cfg, fmt) -> tuple[tuple[float, float, float] | None, str]:
    """``info``'s laser mount from :func:`lasers.laser_mount`'s (``laser``, ``source``): the log's mount
    as it is (text ""), the built-in default as None (info_lines says so), else the config's mount with
    why it is used."""
    if source == "tf":
        return laser, ""
    if source == "default":
        return None, ""
    why = "not in its laser lines" if fmt == "carmen" else "not on tf"
    if not cfg.input.laser.from_tf:
        why = "input.laser.from_tf=false"
    return laser, f"the config's input.laser: {why}"  # (no laser preset sets a mount)


def _recorded_offset_hint(e: LogError, out_dir, relations, time_offset: float) -> LogError:
    """``e`` (evaluate's refusal), its hint naming the --time-offset the run scored these same relations
    at, when no relation fell inside at another (``--relations`` given again without ``--time-offset``:
    0, which puts the Intel relations 976,052,857 s away). An offset given is not second-guessed: the
    hint only."""
    from .report.run_dir import recorded_offset

    if not relations or not e.msg.startswith("no relation in "):
        return e
    offset = recorded_offset(out_dir, relations)  # (the same relations, by content: a file moved since)
    if offset is None or offset == time_offset:
        return e
    return LogError(e.msg, f"the run scored them at --time-offset {offset!r}: give it")


OTHER_FORMATS = {".bag": "a ROS 1 bag", ".db3": "a ROS 2 bag's storage", ".json": "JSON", ".csv": "CSV"}


def check_mcap_name(mcap_out: str | None, profile: str) -> None:
    """``--mcap-out`` writes MCAP: a name whose suffix says another format (``res.bag``) is refused — an
    MCAP behind a .bag name fails in every tool that opens it by its name (a ROS-user probe); a
    ``--mcap-profile`` given without ``--mcap-out`` would write nothing: refused too."""
    given = click.get_current_context().get_parameter_source("mcap_profile") != ParameterSource.DEFAULT
    if given and not mcap_out:
        raise click.UsageError(
            f"--mcap-profile {profile} is the encoding of the --mcap-out file: give --mcap-out FILE"
        )
    suffix = Path(mcap_out).suffix.lower() if mcap_out else ""
    if suffix in OTHER_FORMATS:
        raise click.UsageError(
            f"--mcap-out '{mcap_out}' names {OTHER_FORMATS[suffix]}, but it is written as MCAP: name it "
            f"{Path(mcap_out).stem}.mcap"
        )
    if mcap_out and suffix != ".mcap":  # (written all the same: a name is the user's to choose)
        log.warning(
            "--mcap-out '%s' does not end in .mcap: `ros2 bag play` and Foxglove choose their reader by "
            "it (name it %s.mcap to open it there)", mcap_out, Path(mcap_out).name
        )  # fmt: skip


RESULTS_MCAP_NOTE = (
    "results:  written by `cornerslam run --mcap-out` (Foxglove schemas: the trajectories, scans, segments, "
    "landmarks, occupancy grid); open it in Foxglove Studio. It is not a log to run"
)
RESULTS_MCAP_ROS2_NOTE = (
    "results:  written by `cornerslam run --mcap-out` (ROS 2 messages: the trajectories, scans, segments, "
    "landmarks, occupancy grid, its transforms on /tf); play it with `ros2 bag play`, beside the log in one "
    "player from Jazzy on (`ros2 bag play -i LOG -i FILE`), or open it in Foxglove Studio. It is not a log "
    "to run"
)


@cli.command()
@click.argument("out_path", metavar="OUT.mcap", type=GivenPath(dir_okay=False))
@click.option("--seed", default=0, show_default=True, help="Random seed (same seed, same log).")
@click.option("--laps", default=1, show_default=True, help="Laps of the loop trajectory, 1–100.")
@click.option("--rate", default=10.0, show_default=True, help="Scan rate, Hz, 0.1–1000.")
@click.option("--beams", default=1081, show_default=True, help="Beams per scan (over 270°), 2–100000.")
@click.option("--speed", default=0.5, show_default=True, help="Robot speed, m/s, 0.05–5.")
@verbosity_options(steps=False)
def simulate(out_path, seed, laps, rate, beams, speed, verbose, quiet):
    """Write a synthetic indoor log OUT.mcap with ground truth OUT.gt.tum and true corners.

    \b
    Example:
      cornerslam simulate sim.mcap --seed 3 && cornerslam run sim.mcap
    """
    from .report.oserrors import output_errors
    from .report.outdir import refuse_directory_name
    from .simulate import simulate_log

    setup_logging(verbose, quiet)
    refuse_directory_name(out_path, "give a file name ending in .mcap")
    progress = Progress("simulate", enabled=not quiet)
    try:
        with output_errors(out_path):
            res = simulate_log(
                Path(out_path), seed=seed, laps=laps, rate=rate, beams=beams, speed=speed, progress=progress
            )
    finally:
        progress.close()
    if not quiet:
        click.echo(
            f"wrote {res['log']} ({res['scans']} scans, {res['duration']:.1f} s), "
            f"{res['gt']}, {res['corners']}"
        )


@cli.command()
@click.argument("out_dir", metavar="OUTDIR", type=GivenPath())
@click.option("--ground-truth", type=GivenPath(dir_okay=False), help="TUM ground truth.")
@click.option("--relations", type=GivenPath(dir_okay=False), help="Kümmerle et al. 2009 .relations file.")
@click.option(
    "--time-offset", default=0.0, type=FINITE, show_default=True, help="Relation time − log time, seconds."
)
@click.option(
    "--correct-scale",
    is_flag=True,
    help="ATE after the best similarity (as evo's -s), and its scale: a check of the ranges' scale "
    "against the ground truth's, not the ATE of a 2-D laser (its scale comes from the ranges).",
)
@verbosity_options(progress=False, steps=False)
def evaluate(out_dir, ground_truth, relations, time_offset, correct_scale, verbose, quiet):
    """Accuracy of a run's trajectory.tum against ground truth or relations (without either: the ground
    truth and relations the run was scored against, the relations at their --time-offset, each when the
    file its summary.json names holds the same poses or relations here).

    \b
    Example:
      cornerslam evaluate cornerslam_out/intel-noisy-odom_pca \\
        --relations intel.relations --time-offset 976052857.334
    """
    from .evaluate import evaluate_files
    from .report.run_dir import check_one_run, check_unchanged, recorded_reference
    from .report.text import scored_line

    setup_logging(verbose, quiet)
    check_one_run(out_dir)  # a compare or batch directory: names its run directories
    if not ground_truth and not relations:  # what the run was scored against, where the files still hold it
        if not os.path.lexists(out_dir):  # (a mistyped run directory, said so: not a want of references)
            hint = "give a run's output directory or a trajectory file"
            raise LogError(f"'{out_dir}' does not exist", hint)
        rec = recorded_reference(out_dir)
        given = click.get_current_context().get_parameter_source("time_offset") != ParameterSource.DEFAULT
        ground_truth, relations = rec.ground_truth, rec.relations
        time_offset = time_offset if given else rec.time_offset  # (one given is used: a review)
        why = f" ({'; '.join(rec.why_not)})" if rec.why_not else ""
        if not ground_truth and not relations:
            raise click.UsageError(f"give --ground-truth FILE.tum or --relations FILE{why}")
        if ground_truth:
            log.info("ground truth: %s, as the run's summary.json names it", ground_truth)
        if relations:
            log.info("relations: %s at --time-offset %r, as %s", relations, time_offset,
                     "given" if given else "the run's summary.json names them")  # fmt: skip
            if given and time_offset != rec.time_offset:  # (a mistyped offset moves the figures far)
                log.warning("scored at --time-offset %r, not the run's %r", time_offset, rec.time_offset)
        if rec.why_not:  # the other one scored: a table of both would lose a row without a word
            log.warning("not scored against%s", why)
    if correct_scale and not ground_truth:
        raise click.UsageError("--correct-scale scales the ATE: give --ground-truth FILE.tum too")
    check_time_offset(relations, time_offset)
    check_unchanged(out_dir)  # its trajectory.tum cut short since: not scored as the whole run
    try:
        res = evaluate_files(out_dir, ground_truth, relations, time_offset, correct_scale)
    except LogError as e:  # no relation inside at the default offset: the run's own, when it had one
        raise _recorded_offset_hint(e, out_dir, relations, time_offset) from None
    _echo([*evaluation_lines(res), scored_line(out_dir, ground_truth, relations, correct_scale)])


@cli.command()
@click.argument("log_path", metavar="LOG", type=GivenPath(log=True))
@click.option(
    "--step",
    type=SCAN_INDEX,
    help="Index of the scan in the log, N or '#N' (0 = first, the default; a run's steps skip scans: "
    "see --at).",
)
@click.option("--at", type=FINITE, help="The scan of this stamp, s (a run's step: trajectory.csv's stamp).")
@click.option(
    "--plot", "plot_path", type=FIGURE_PATH, help="Draw the scan and features to a PNG (or .pdf, .svg)."
)
@config_options
@topic_options
@verbosity_options(progress=False, steps=False)
def extract(log_path, step, at, plot_path, config_path, overrides, scan_topic, odom_topic, verbose, quiet):
    """Print the segments and corners of one scan (and draw them with 3σ ellipses).

    \b
    Example:
      cornerslam extract sample_logs/sim_office.mcap --step 40 --plot scan40.png
    """
    from .extract import extract_step
    from .frontend import scans_prepared
    from .report.extract_plot import format_extraction, plot_extraction

    setup_logging(verbose, quiet)
    if step is not None and at is not None:
        raise click.UsageError(
            "--step (the log's scan index) and --at (a stamp) contradict each other: give one"
        )
    cfg = command_config(config_path, overrides, None, scan_topic, odom_topic, log_path)
    target = _figure_target(plot_path) if plot_path else None  # refused before any work
    # the beams a run keeps (input.skip_beams_*, input.max_range), in the sensor frame (not mirrored)
    step, scan, segments, corners = extract_step(
        log_path, 0 if step is None else step, cfg, lambda r: scans_prepared(r, cfg, msgs=r.scans()), at
    )
    click.echo(scan_heading(step, scan))
    click.echo(format_extraction(segments, corners))
    if target is not None:
        from .report.oserrors import output_errors
        from .report.outdir import staged_write

        with output_errors(plot_path):
            # the target's directory made; written beside the target and renamed onto it (a killed
            # extract leaves no cut figure, and an earlier one whole), in the format the path as given
            # names (the target's suffix may not: link.png -> fig.txt)
            target.parent.mkdir(parents=True, exist_ok=True)
            with staged_write(target) as tmp:
                plot_extraction(scan, segments, corners, tmp, fmt=Path(plot_path).suffix[1:].lower())
        click.echo(f"wrote {plot_path}")


def _figure_target(plot_path: str) -> Path:
    """Where ``extract --plot`` writes: a symlink's target (a dangling one's too), as --out and
    --mcap-out do. An existing file there is replaced only when an earlier ``extract --plot`` wrote
    it (a user's photo.png was overwritten without a word); a device or pipe is refused."""
    from .errors import OutputError
    from .report.oserrors import output_errors, resolved
    from .report.ownership import is_extract_figure, refuse_special_file

    with output_errors(plot_path):
        target = resolved(Path(plot_path))
        refuse_special_file(target, plot_path)
        if target.is_file() and not is_extract_figure(target, Path(plot_path).suffix):
            raise OutputError(
                f"'{display_path(plot_path)}' exists and is not a figure cornerslam extract wrote",
                "give a new file name, or move that file away",
            )
        place = next(p for p in target.parents if p.exists())  # (made when written: the nearest existing)
        # a read-only mount, no permission: refused before the scan's table is printed, not after it (a
        # probe); a file where a directory should be is said when written
        if place.is_dir() and not os.access(place, os.W_OK | os.X_OK):
            raise OutputError(
                f"cannot write --plot '{display_path(plot_path)}': '{display_path(place)}' is not writable",
                "give a place you can write to",
            )
    return target


@cli.command()
@click.argument("logs", metavar="LOGS...", nargs=-1, required=True, type=GivenPath(log=True))
@click.option(
    "--assoc", "assocs", default=None, help="Comma-separated associators (default: the config's, pca)."
)
@click.option(
    "--sweep",
    "sweeps",
    multiple=True,
    metavar="KEY=V1,V2,...",
    help="Run each value of a config key; repeat for a grid, e.g. --sweep submaps.max_distance=5,10.",
)
@config_options
@click.option("--out", required=True, type=GivenPath(), help="Batch directory (resumable).")
@click.option("--jobs", default=None, type=Whole(1, 256), help="Local worker processes [default: CPUs].")
@click.option(
    "--scheduler", default=None, metavar="tcp://HOST:PORT", help="Run on this Dask scheduler instead."
)
@click.option(
    "--no-ground-truth", is_flag=True, help="Score against no ground truth, not even each LOG.gt.tum."
)
@verbosity_options
def batch(
    logs, assocs, sweeps, config_path, overrides, out, jobs, scheduler, no_ground_truth, verbose, quiet
):
    """Run every LOG × associator × swept config value into OUT/<name>/ and tabulate in OUT/batch.csv.

    A bad log fails its rows without stopping the batch; rerunning the same command skips the
    combinations already complete with the same log, config and build. Exit 0 only if every
    combination ran or was skipped; otherwise 2 (bad input), or 1 if any failed by a bug.

    \b
    Example:
      cornerslam batch sample_logs/*.mcap --assoc icnn,pca --sweep submaps.max_distance=5,10 \\
          --out sweep/ --jobs 2
    """
    from .workers import warnings_once

    setup_logging(verbose, quiet)
    with warnings_once():  # a warning of every combination's config, or of every run: said once
        _batch(logs, assocs, sweeps, config_path, overrides, out, jobs, scheduler, not no_ground_truth, quiet)


def _batch(logs, assocs, sweeps, config_path, overrides, out, jobs, scheduler, ground_truth, quiet):
    from .batch import BATCH_CSV, SCHEDULER_LOST, WORKER_DIED, run_batch
    from .report.ownership import check_claimable
    from .sweep import plan

    if scheduler == "":  # an unset shell variable: it ran on this machine's cores without a word
        raise click.BadParameter("'' names no scheduler (an unset shell variable?)", param_hint="--scheduler")

    check_option_agrees(overrides, {"association.method": assocs})  # --assoc is set after each --set
    names = parse_assocs(assocs, allow_many=True)
    if names and config_path:  # the file's association.method, if another, is ignored: said, as compare does
        why = f"batch runs each associator of --assoc ({','.join(names)})"
        command_config(config_path, overrides, ignored={"association.method": (why, names)})
    names = names or [command_config(config_path, overrides).association.method]
    if scheduler and jobs:
        log.warning("--jobs is ignored with --scheduler (the cluster's workers run the batch)")
    check_claimable(out, "batch")  # a directory that is not a batch's: refused before any work
    swept = parse_sweeps(sweeps)
    check_sweep_not_set(overrides, swept)  # the sweep is set after each --set: one would be ignored
    combos = plan(logs, names, swept, overrides, config_path, out)
    progress = BatchProgress(not quiet)
    if not scheduler:  # (a cluster's workers compile where they run)
        _say_compiling(quiet)
    try:
        config_file = str(config_path) if config_path else None
        rows = run_batch(combos, out, jobs, scheduler, progress, config_file, ground_truth)
    except KeyboardInterrupt as e:
        progress.close()
        word, code = _signal_word(e)
        wait = "once the runs the cluster's workers had begun have ended (they go on) " if scheduler else ""
        table = getattr(e, "batch_table", None)  # written once the directory is claimed: else none yet
        done = f"{table} lists the finished combinations (the rest 'pending')" if table else "no run begun"
        click.echo(f"{word}: {done}; run the same command again {wait}to resume", err=True)
        raise click.exceptions.Exit(code) from None
    progress.close()
    if not quiet:
        _echo(batch_lines(rows, [k for k, _ in combos[0].sweep]))
        click.echo(f"wrote {Path(out).resolve() / BATCH_CSV}")  # (as run says it: the whole path)
    failed, _ = batch_counts(rows)
    if failed:  # as make: a batch with a failed combination is no success (1: a bug or a dead worker; else 2)
        bugs = sum(bool(r["internal"]) for r in rows)
        died = sum(r["error"] == WORKER_DIED for r in rows)  # killed, out of memory: no bad input either
        word = "internal error" if bugs else "error"
        which = [f"{bugs} by an internal error: a bug, traceback saved"] if bugs else []
        which += [f"{died} whose worker process died (killed? out of memory?)"] if died else []
        lost = sum(r["error"] == SCHEDULER_LOST for r in rows)  # the cluster, not the input
        which += [f"{lost} cut off from the Dask scheduler: run again to resume"] if lost else []
        which = f" ({'; '.join(which)})" if which else ""
        click.echo(
            f"{word}: {failed} of {len(rows)} combinations failed{which}: see {Path(out) / BATCH_CSV}",
            err=True,
        )
        raise click.exceptions.Exit(1 if bugs or died or lost else 2)


@cli.command("config")
@click.argument("log_path", metavar="[LOG]", required=False, type=GivenPath(log=True))
@config_options
@click.option(
    "--preset",
    default=None,
    type=PRESET,
    help="Laser preset under the config: auto (chosen from LOG's scans), none, or a preset's name.",
)
@verbosity_options(progress=False, steps=False)
def config_command(log_path, config_path, overrides, preset, verbose, quiet):
    """Print the fully resolved config as YAML: built-in defaults < laser preset < --config < --set.

    With LOG, the laser preset is chosen from its first scan, as `run` would; --preset picks it instead,
    as `--set input.laser_preset=NAME` would (over a --config file's choice). Without LOG or --preset (and
    no preset named in the --config file), the keys a laser preset sets are commented out but for those
    --set or the --config file gives: as --config the output leaves each log its preset. The output is a
    valid --config file.

    \b
    Example:
      cornerslam config sample_logs/intel_cut.clf --set association.method=jcbb > my.yaml
    """
    from .config import ConfigError, dump_config, override_place, replaced_place, yaml_quoted
    from .logs import read_alone

    setup_logging(verbose, quiet)
    check_option_agrees(overrides, {"input.laser_preset": preset})  # (it silently won)
    if log_path is not None:  # a LOG that is none (no preset to choose from it: never opened) is refused
        from .logs import detect_format

        detect_format(log_path)
    by_option = f"input.laser_preset={yaml_quoted(preset)}" if preset else None
    try:
        cfg = command_config(
            config_path, [*overrides, *([by_option] if by_option else [])], log_path=log_path
        )
    except ConfigError as e:  # a bad --preset is the option's, not a --set the user did not write
        if by_option is None or not e.msg.startswith(override_place(by_option)):
            raise
        raise replaced_place(e, by_option) from None
    read_alone(cfg.input)  # (--odom-topic beside input.odometry=scans: refused, as run refuses it)
    if log_path is None and cfg.input.laser_preset == "auto":  # each log's preset left to it, but for
        from .config import set_keys  # what --set and the --config file set (a file's: warned when run)
        from .lasers import PRESET_NOTE, dump_for_any_laser, file_keys

        given = set_keys(overrides) | (file_keys(config_path) if config_path is not None else set())
        click.echo(PRESET_NOTE + dump_for_any_laser(cfg, given), nl=False)
    else:
        click.echo(dump_config(cfg), nl=False)


main = cli  # the console-script entry point
