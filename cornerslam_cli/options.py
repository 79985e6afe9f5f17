"""The command line's shared options, defined once, and the parsers of option values.

Decorators add an option group to a command (``config_options``: ``--config`` / ``--set``;
``topic_options``; ``reference_options``: ``--ground-truth`` / ``--relations`` / ``--time-offset``;
``verbosity_options``). ``parse_assocs`` reads every command's ``--assoc``, ``parse_sweeps`` batch's
``--sweep``; ``command_config`` resolves a command's config from the options as ``run`` does. A bad
value is a click usage error or a ConfigError, which ``cli.py``'s error boundary prints.

Over 400 lines because every command's options and their value types are here, once, so that a command
and its help cannot disagree with another's on what an option means.
"""

from __future__ import annotations

import logging
import math
import os
import shlex
import stat
import sys
import tempfile

import click

CONFIG_COPIES = "config_copies"  # ctx.meta: temporary copy of a piped --config -> the path as given


def verbosity_options(f=None, *, progress: bool = True, steps: bool = True):
    """``-v`` (repeatable) and ``-q``, their help saying only what the command has: a progress bar
    (``progress``), filter steps to log (``steps``). ``@verbosity_options(progress=False, ...)`` too."""
    if f is None:
        return lambda g: verbosity_options(g, progress=progress, steps=steps)
    more = "-v what is read and each stage's totals, -vv every filter step" if steps else "-v what is read"
    f = click.option("-v", "--verbose", count=True, help=f"More log output: {more}.")(f)
    quiet = "Only errors; no warnings" + (", no progress bar." if progress else ".")
    f = click.option("-q", "--quiet", is_flag=True, help=quiet)(f)
    return f


def config_options(f):
    """``--config FILE`` and ``--set KEY=VALUE`` (repeatable)."""
    f = click.option(
        "--set",
        "overrides",
        multiple=True,
        metavar="KEY=VALUE",
        help="Override a config key, e.g. --set submaps.enabled=false (repeatable).",
    )(f)
    f = click.option(
        "--config",
        "config_path",
        type=GivenPath(),
        callback=_config_read_once,
        help="YAML config (default: built-in; - reads standard input).",
    )(f)
    return f


def _config_read_once(ctx: click.Context, param, value: str | None) -> str | None:
    """A ``--config`` that is not a regular file — ``-`` (standard input), a pipe, ``<(...)``,
    ``/dev/null`` — is read once
    into a temporary copy (removed when the command ends): ``compare`` and ``batch`` load the config
    once per associator or combination, and a pipe gives its text only once. The copy is as large
    as the loader accepts plus a byte (it then says "too large"); errors name the path as given
    (see ``cli._Cli``)."""
    from .config import MAX_CONFIG_BYTES

    if value == "-":  # standard input, as the convention goes (a file named '-' is ./-)
        if sys.stdin is None:  # started with standard input closed (`<&-`)
            raise click.BadParameter("standard input is closed: give the config file's name", ctx, param)
        data = sys.stdin.buffer.read(MAX_CONFIG_BYTES + 1)
    else:
        try:
            mode = os.stat(value).st_mode if value else 0
        except OSError:
            return value  # missing: the config loader says so
        if not mode or stat.S_ISREG(mode) or stat.S_ISDIR(mode):
            return value
        with open(value, "rb") as f:
            data = f.read(MAX_CONFIG_BYTES + 1)
    fd, copy = tempfile.mkstemp(prefix="cornerslam-config-", suffix=".yaml")
    with os.fdopen(fd, "wb") as f:
        f.write(data)
    ctx.call_on_close(lambda: os.unlink(copy))
    ctx.meta.setdefault(CONFIG_COPIES, {})[copy] = value
    return copy


class _TopicName(click.ParamType):
    """``--scan-topic`` / ``--odom-topic``: a topic's name, not ``''`` (an unset shell variable,
    ``--scan-topic "$TOPIC"``), which was taken as not given: the topic found by message type was run
    without a word."""

    name = "TOPIC"

    def convert(self, value, param, ctx):
        if value == "":
            self.fail(
                "'' names no topic (an unset shell variable?): give one or leave the option out", param, ctx
            )
        return value


def topic_options(f):
    """``--scan-topic`` and ``--odom-topic``."""
    for name, text in (
        ("--odom-topic", "Odometry topic (default: by message type, else tf)."),
        ("--scan-topic", "LaserScan topic (default: the only one)."),
    ):
        f = click.option(name, type=_TopicName(), default=None, help=text)(f)
    return f


class _Finite(click.ParamType):
    """A float that must be finite (click's FLOAT takes 'nan' and 'inf')."""

    name = "float"

    def convert(self, value, param, ctx):
        v = click.FLOAT.convert(value, param, ctx)
        if not math.isfinite(v):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return v


FINITE = _Finite()


class Whole(click.IntRange):
    """A whole number within a range: click's own says "'abc' is not a valid integer range" (a probe)."""

    name = "integer"


class _ScanIndex(click.IntRange):
    """``extract --step``: a scan index ≥ 0, also written ``#N`` as ``run --start '#N'`` takes it."""

    name = "N"

    def __init__(self):
        super().__init__(min=0)

    def convert(self, value, param, ctx):
        if isinstance(value, str) and value.startswith("#"):
            value = value[1:]
        return super().convert(value, param, ctx)


SCAN_INDEX = _ScanIndex()


class GivenPath(click.Path):
    """A file or directory name that is not ``''`` (an unset shell variable, ``--config "$CFG"``): as a
    path ``''`` is ``.``, the working directory, which the error then named; as an option's value it
    was taken as not given, the option silently ignored (``--mcap-out ''`` wrote no MCAP). With
    ``log``, a log to read: one that is no file but a config key's ``KEY=VALUE`` is a second setting
    given one ``--set`` (``--set a.b=1 c.d=2``: the second was taken as the LOG, said not to exist)."""

    def __init__(self, *args, log: bool = False, **kwargs):
        super().__init__(*args, **kwargs)
        self.log = log

    def convert(self, value, param, ctx):
        if value == "":
            self.fail("'' names no file (an unset shell variable?)", param, ctx)
        if self.log and isinstance(value, str) and is_setting(value) and not os.path.lexists(value):
            options = "--set or --sweep" if ctx is not None and ctx.info_name == "batch" else "--set"
            self.fail(f"'{value}' is no file but a setting: give {options} before each KEY=VALUE", param, ctx)
        return super().convert(value, param, ctx)


def is_setting(text: str) -> bool:
    """Whether ``text`` is ``KEY=VALUE`` of a config key (``scan_match.window=5``), as a --set takes."""
    from .config import Config, dotted_keys

    key, eq, _ = text.partition("=")
    return bool(eq) and "." in key and key in dotted_keys(Config)


class _PresetName(click.ParamType):
    """``config --preset``: ``auto``, ``none`` or a laser preset's name. ``''`` (an unset shell variable,
    ``--preset "$P"``) is refused naming the choices: it was taken as not given, the automatic choice,
    without a word; another unknown name too, as --preset's (the config named its key
    input.laser_preset, which the user had not written: an evo-user probe)."""

    name = "NAME"

    def convert(self, value, param, ctx):
        from .errors import did_you_mean
        from .lasers import PRESET_CHOICES, preset_choices

        if value not in PRESET_CHOICES:
            what = "names no laser preset" if value == "" else "is not a laser preset"
            close = did_you_mean(value, PRESET_CHOICES, then=" ") if value else ""
            self.fail(f"'{value}' {what} ({close}{preset_choices()})", param, ctx)
        return value


PRESET = _PresetName()


class _FigurePath(click.ParamType):
    """``extract --plot``'s file, in a format whose file names its creator (ownership.figure_mark)."""

    name = "FILE.png"

    def convert(self, value, param, ctx):
        from .report.ownership import figure_mark
        from .report.plots import agg_backend

        agg_backend()  # (a bad MPLBACKEND would end the import)
        from matplotlib.backend_bases import FigureCanvasBase

        path = click.Path(dir_okay=False).convert(value, param, ctx)
        formats = sorted(f for f in FigureCanvasBase.get_supported_filetypes() if figure_mark(f))
        if os.path.splitext(path)[1][1:].lower() not in formats:
            shown = click.format_filename(path)
            self.fail(f"'{shown}' does not end in a figure format (.{', .'.join(formats)})", param, ctx)
        return path


FIGURE_PATH = _FigurePath()


def reference_options(f):
    """What a run is scored against: ``--ground-truth``, ``--relations``, ``--time-offset``."""
    f = click.option(
        "--time-offset",
        default=0.0,
        type=FINITE,
        show_default=True,
        help="With --relations: relation time − log time, s.",
    )(f)
    f = click.option(
        "--relations",
        type=GivenPath(dir_okay=False),
        help="Kümmerle et al. 2009 .relations file to score against.",
    )(f)
    f = click.option(
        "--no-ground-truth", is_flag=True, help="Score against no ground truth, not even LOG.gt.tum."
    )(f)
    f = click.option(
        "--ground-truth", type=GivenPath(dir_okay=False), help="TUM ground truth (default: LOG.gt.tum)."
    )(f)
    return f


def chosen_ground_truth(ground_truth, no_ground_truth: bool):
    """``--ground-truth`` as given, None (LOG.gt.tum if there is one) or, with ``--no-ground-truth``,
    False: none at all — a LOG.gt.tum a run refuses, in a folder the user cannot rename it in."""
    if ground_truth and no_ground_truth:
        raise click.UsageError("--ground-truth and --no-ground-truth contradict each other: give one")
    return False if no_ground_truth else ground_truth


class _SpanBound(click.ParamType):
    """``--start`` / ``--end``: seconds from the log's first scan, or ``#INDEX`` (span.py)."""

    name = "SECONDS|#INDEX"

    def convert(self, value, param, ctx):
        from .span import Bound, parse_bound

        if isinstance(value, Bound):
            return value
        try:
            return parse_bound(value)
        except ValueError as e:
            self.fail(str(e), param, ctx)


def span_options(f):
    """``--start``, ``--end`` and ``--max-scans``: process part of the log (read by :func:`parse_span`)."""
    f = click.option(
        "--max-scans",
        type=Whole(min=1),
        default=None,
        help="Process at most N scans from the start.",
    )(f)
    f = click.option(
        "--end",
        type=_SpanBound(),
        default=None,
        help="Stop before this point: seconds from the first scan or #INDEX.",
    )(f)
    f = click.option(
        "--start",
        type=_SpanBound(),
        default=None,
        help="Begin here: seconds from the log's first scan, or #INDEX (a scan index, 0 = first).",
    )(f)
    return f


def parse_span(start, end, max_scans):
    """The :class:`span.Span` of the options; ``--end`` not after ``--start`` is a usage error."""
    from .span import Span

    span = Span(start, end, max_scans)
    if problem := span.order_problem():
        raise click.BadParameter(problem, param_hint="--end")
    return span


def check_time_offset(relations, time_offset: float) -> None:
    """``--time-offset`` shifts the relations' times only: given without ``--relations`` it would be
    silently ignored (a ground truth's stamps are not shifted), so that is a usage error."""
    if time_offset and not relations:
        raise click.UsageError(
            "--time-offset shifts the times of --relations, which is not given (a --ground-truth must "
            "use the log's clock): give --relations FILE, or drop --time-offset"
        )


def setup_logging(verbose: int, quiet: bool) -> None:
    """Log to stderr: warnings by default, ``-v`` info, ``-vv`` debug, ``-q`` errors only (not both)."""
    if verbose and quiet:
        raise click.UsageError("-q (only errors) and -v (more log output) contradict each other: give one")
    from .report.progress import log_to_stderr

    log_to_stderr(logging.ERROR if quiet else (logging.WARNING, logging.INFO, logging.DEBUG)[min(verbose, 2)])


def command_config(
    config_path, overrides, assoc=None, scan_topic=None, odom_topic=None, log_path=None, ignored=None
):
    """The resolved config: user layers over the laser preset chosen for ``log_path``'s scans;
    ``ignored``: config keys the command leaves unused, each with why and the values it runs anyway (the
    file setting one to another value: warned)."""
    from .config import yaml_quoted
    from .lasers import resolve_config

    extra = list(overrides)
    check_option_agrees(
        overrides,
        {"association.method": assoc, "input.scan_topic": scan_topic, "input.odom_topic": odom_topic},
    )
    # as overrides, each value quoted (config.yaml_quoted): an option's text is the name itself, which YAML
    # would otherwise read as a number or a boolean (--scan-topic yes)
    for key, value in (
        ("association.method", assoc),
        ("input.scan_topic", scan_topic),
        ("input.odom_topic", odom_topic),
    ):
        if value:
            extra.append(f"{key}={yaml_quoted(value)}")
    return resolve_config(log_path, config_path, extra, ignored)  # (an unknown associator named where given)


def check_option_agrees(overrides, options: dict[str, str | None]) -> None:
    """A usage error when an option (``--assoc``, ``--scan-topic``, ``--odom-topic``, config's
    ``--preset``) and a ``--set`` of its config key name different values: which one the user meant
    cannot be told, and the option used to win without a word."""
    import yaml

    from .config import set_leaves
    from .errors import OPTION_OF

    for text, leaf, loaded in set_leaves(overrides):
        value = text.partition("=")[2]  # (parse_override refuses a --set without one)
        given = options.get(leaf)
        if not given:
            continue
        try:
            same = yaml.safe_load(given) == loaded
        except yaml.YAMLError:
            same = False
        if not same and given.strip() not in (str(loaded).strip(), value.strip().strip("'\"")):  # yes
            raise click.UsageError(f"{OPTION_OF[leaf]} {given} and --set '{text}' disagree: give one of them")


def check_method_not_set(overrides, assocs: str) -> None:
    """A usage error for ``compare`` given a ``--set`` of ``association.method``: compare runs each
    associator of ``--assoc`` (``assocs``, comma-joined), so the ``--set`` would be ignored without a word."""
    from .config import set_leaves

    for text, leaf, m in set_leaves(overrides):
        if leaf == "association.method":
            what = "drop the --set" if str(m) in assocs.split(",") else f"give --assoc {m} instead"
            raise click.UsageError(
                f"compare runs each associator of --assoc ({assocs}): --set '{text}' would be ignored; {what}"
            )


def check_sweep_not_set(overrides, sweeps) -> None:
    """A usage error for ``batch`` given a ``--set`` of a key it also sweeps (or of a key inside a
    swept section that a swept value sets): each combination sets the swept value after the ``--set``,
    so the ``--set`` would be ignored without a word. A swept mapping sets only the keys it names, as a
    ``--set`` of one does (``--sweep 'graph={refine: true},{refine: false}'`` keeps a ``--set
    graph.refine_radius=3``)."""
    from .config import set_leaves
    from .sweep import swept_leaves

    swept = {key: swept_leaves(key, values) for key, values in sweeps.items()}  # the keys each one sets
    for text, leaf, _ in set_leaves(overrides):
        for given, leaves in swept.items():
            if any(leaf == k or leaf.startswith(k + ".") for k in leaves):
                raise click.UsageError(
                    f"--sweep {given} and --set '{text}' set the same key: each combination would "
                    f"use the swept value and ignore the --set; give the values in --sweep {given}=... only"
                )


def parse_assocs(text: str | None, allow_many: bool, log_path: str | None = None) -> list[str]:
    """The associators an ``--assoc`` value names, each checked against ``association.ASSOCIATORS`` (an
    unknown one: ConfigError with the closest name). ``None`` (not given) is ``[]``: the config's; a value
    naming none (``''``, an unset shell variable) is a usage error (``run --assoc ''`` ran the config's
    associator without a word). A list is comma-separated, spaces around a name ignored, and must name
    distinct associators, none empty (``pca,,icnn``: a usage error, as a ``--sweep`` value); a single name
    is taken whole, spaces around it ignored, and a list given where one is taken (``run``) is a usage
    error pointing to ``compare`` (on ``log_path``, when given)."""
    from .association import ASSOCIATORS, associator_class
    from .errors import ConfigError

    if text is None:
        return []
    listed = [a.strip() for a in text.split(",") if a.strip()]
    if allow_many and listed and len(listed) < text.count(",") + 1:  # as --sweep: one lost in typing
        raise click.BadParameter(
            f"'{text}' has an empty name between its commas: give the associators without empty ones, "
            f"e.g. {','.join(listed)}",
            param_hint="--assoc",
        )
    if not allow_many and len(listed) > 1:
        from .errors import display_path

        log = shlex.quote(display_path(log_path)) if log_path else "LOG"
        raise click.BadParameter(
            f"'{text}' lists {len(listed)} associators, but run takes one; to run several side by side: "
            f"cornerslam compare {log} --assoc {','.join(listed)}",
            param_hint="--assoc",
        )
    names = listed if allow_many else [text.strip()] if text.strip() else []
    if not names:
        raise click.BadParameter(
            f"'{text}' names no associator: give e.g. {'icnn,jcbb,pca' if allow_many else 'pca'}",
            param_hint="--assoc",
        )
    if len(set(names)) != len(names):
        raise click.BadParameter(
            f"'{text}' must list distinct associators, e.g. icnn,jcbb,pca", param_hint="--assoc"
        )
    for name in names:
        words = name.split()  # 'icnn jcbb': a list with spaces ("did you mean 'jcbb'?" misled)
        bad = next((w for w in words if w not in ASSOCIATORS), None) if len(words) > 1 else name
        if bad is None:
            sep = ",".join(words)
            log = shlex.quote(log_path) if log_path else "LOG"
            hint = (
                f"separate them with commas: {sep}"
                if allow_many
                else f"run takes one; cornerslam compare {log} --assoc {sep} runs several"
            )
            raise ConfigError(f"--assoc: '{name}' is not an associator", hint)
        try:
            associator_class(bad)
        except ConfigError as e:  # (named where it was given; of a list with spaces, its unknown word)
            raise ConfigError(f"--assoc: {e.msg}", e.hint) from None
    return names


def parse_sweeps(texts) -> dict[str, list[str]]:
    """``--sweep KEY=V1,V2,...`` values as {key: [values]}; a malformed or repeated key is a usage error."""
    from .sweep import dotted_key, sweep_values

    sweeps: dict[str, list[str]] = {}
    for text in texts:
        key, sep, values = text.partition("=")
        key = dotted_key(key)
        if not sep or not key or not values.strip():
            raise click.BadParameter(f"'{text}' is not KEY=V1,V2,...", param_hint="--sweep")
        try:
            sweeps[key] = sweep_values(key, values, sweeps)
        except ValueError as e:
            raise click.BadParameter(f"'{text}' {e}", param_hint="--sweep") from None
    return sweeps
