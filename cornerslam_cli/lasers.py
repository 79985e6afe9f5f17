"""Laser presets: per-sensor noise models and extraction settings, chosen from the scan's geometry.

A preset is a partial config (sections ``sensor``, ``lines``, ``input``) layered *under* the user's
config file and ``--set`` overrides: defaults < preset < config file < ``--set``. With
``input.laser_preset: auto`` (the default) the preset whose beam count and angular step match the
log's first scan is used; ``none`` disables presets; a preset name forces one. The resolved name is
recorded in the saved config (``input.laser_preset``).

The same presets are written as YAML to ``configs/lasers/`` (``configs/regenerate_default.py``) so
they can be read, copied and edited; tests check the two agree.

Also the laser's mount on the robot (:func:`laser_mount`: the log's tf, else ``input.laser``) and the
warnings about it (:func:`warn_mount`).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
from collections.abc import Collection, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .config import (
    Config,
    config_from,
    dump_config,
    located,
    override_leaves,
    read_config_file,
    set_keys,
    warn_ignored,
)
from .errors import ConfigError, did_you_mean
from .geometry import wrap_angle
from .logs import open_configured
from .logs.params import MOUNT_SAME, LaserMountConfig
from .ranges import short_text
from .types import Scan

log = logging.getLogger("cornerslam.lasers")


@dataclass(frozen=True)
class LaserPreset:
    """A sensor's config layer and the scan geometry it is chosen for.

    beams : beam counts of the sensor's messages; increment_deg : angular step, degrees.
    """

    description: str
    beams: tuple[int, ...]
    increment_deg: float
    config: dict


PRESETS: dict[str, LaserPreset] = {
    # SICK LMS 200/291, 180° at 1°: σρ ≈ 1 cm systematic + 0.5 % (data sheet: ±15 mm typ.), σθ from the
    # 0.25° beam divergence; sparse beams: a segment needs fewer points, breakpoints must allow 1° gaps.
    "sick_lms_1deg": LaserPreset(
        "SICK LMS 180° at 1° (e.g. the Intel Research Lab log)",
        (180, 181),
        1.0,
        {
            "sensor": {"model": "linear", "a": 0.01, "b": 0.005, "sigma_theta": math.radians(0.25)},
            "lines": {"min_points": 5, "breakpoint_lambda": math.radians(12.0)},
        },
    ),
    "sick_lms_05deg": LaserPreset(
        "SICK LMS 180° at 0.5°",
        (360, 361),
        0.5,
        {"sensor": {"model": "linear", "a": 0.01, "b": 0.005, "sigma_theta": math.radians(0.25)}},
    ),
    # Hokuyo URG-04LX, 240° at 0.352°, 5.6 m: ±10 mm to 1 m, ±1 % beyond (data sheet). The sensor
    # only: a robot whose body the scan sees skips those beams in its own config (configs/mines.yaml).
    "hokuyo_urg04lx": LaserPreset(
        "Hokuyo URG-04LX 240° (e.g. the Mines ParisTech rover logs)",
        (681, 682, 683, 725, 726, 768, 769),
        360.0 / 1024.0,
        {
            "sensor": {"model": "piecewise", "sigma_r_near": 0.01, "near_range": 1.0, "sigma_r_rel": 0.01},
        },
    ),
    # Hokuyo UTM-30LX class, 270° at 0.25°: the paper's sensor model (eq 33-34).
    "hokuyo_270deg": LaserPreset(
        "Hokuyo 270° at 0.25° (UTM-30LX class; the paper's sensor; cornerslam simulate)",
        (1080, 1081),
        0.25,
        {"sensor": {"model": "piecewise", "sigma_r_near": 0.03, "near_range": 1.0, "sigma_r_rel": 0.03}},
    ),
}
PRESET_CHOICES = ("auto", "none", *PRESETS)  # what input.laser_preset may name


def _leaves(tree: Mapping) -> Iterator[tuple[str, Any]]:
    """(dotted key, value) of each leaf of a nested config mapping (:func:`config.override_leaves`)."""
    for k, v in tree.items():
        yield from override_leaves([k], v)


PRESET_KEYS = frozenset(k for p in PRESETS.values() for k, _ in _leaves(p.config))  # keys a preset may set
PRESET_NOTE = """\
# The keys commented out are set by the laser preset chosen for each log's scans (input.laser_preset:
# auto; configs/lasers/): their built-in defaults are shown. Set one and it replaces the preset's (a
# warning says so); `cornerslam config LOG` prints what a run of that log uses.
"""


def dump_for_any_laser(cfg: Config, given: Collection[str] = ()) -> str:
    """``dump_config(cfg)`` of a config resolved without a log (no preset chosen) and without a config
    file, the lines of the keys a laser preset sets commented out but for those ``given`` (--set): a
    file's keys are layered over the preset's, so that YAML as --config leaves each log its preset but
    for what the user set (configs/default.yaml, `cornerslam config` without LOG)."""
    quiet = PRESET_KEYS - set(given)
    out, section = [], ""
    for line in dump_config(cfg).splitlines():
        if not line.startswith(" "):
            section = line.split(":", 1)[0]
        elif not line.startswith("   ") and f"{section}.{line.strip().split(':', 1)[0]}" in quiet:
            line = f"  # {line.strip()}"
        out.append(line)
    return "\n".join(out) + "\n"


def file_keys(config_path: str | Path) -> set[str]:
    """The dotted keys a config file sets (read again: a pipe was copied once, options.py)."""
    return {k for k, _ in _leaves(read_config_file(config_path))}


def mount_source(cfg: Config) -> str:
    """Where the config's laser mount (``input.laser``) came from, for a log without one on tf:
    ``preset`` (the laser preset's), ``default`` (the built-in one: none of x, y, yaw set — a 0 set is
    the config's — and ``input.laser.from_tf`` not turned off, which says the config's mount is meant;
    ``upside_down`` alone does not: it says how the laser is turned, not where it is), else ``config``."""
    mount = cfg.input.laser
    preset = PRESETS.get(cfg.input.laser_preset)
    preset_mount = preset.config.get("input", {}).get("laser") if preset else None
    if preset_mount and all(getattr(mount, k) == v for k, v in preset_mount.items()):
        return "preset"
    return "default" if dataclasses.replace(mount, upside_down=False) == LaserMountConfig() else "config"


def detect_preset(n_beams: int, angle_increment: float) -> str | None:
    """Name of the preset matching a scan of ``n_beams`` beams ``angle_increment`` rad apart, or None."""
    for name, p in PRESETS.items():
        if n_beams in p.beams and spaced_as(p, angle_increment):
            return name
    return None


def spaced_as(p: LaserPreset, angle_increment: float) -> bool:
    """Whether beams ``angle_increment`` rad apart are the preset's (within 2 % of its step)."""
    return abs(math.degrees(abs(angle_increment)) - p.increment_deg) <= 0.02 * p.increment_deg


def preset_choices() -> str:
    """What ``input.laser_preset`` (and ``config --preset``) may name, as its refusals list it."""
    return f"choices: {', '.join(PRESET_CHOICES)}"


def first_scan(reader) -> Scan | None:
    """The first scan a log reader (logs/base.py) gives, None when it has none."""
    return next(iter(reader.scans()), None)


def invalid_beams(reader) -> tuple[str, str]:
    """Why every beam of a log read as invalid — said more closely when its first scan shows it (its
    ``range_max`` at or below its ``range_min``: a driver's parameter; input.max_range can only lower it)
    — and what to check. The reader's warnings are silenced (the run has said them)."""
    with _reader_quiet():
        scan = first_scan(reader)
    why = " (NaN, inf, zero or out of range)"
    if scan is not None and scan.range_max <= scan.range_min:
        return (
            f"{why}: its scans' range_max ({scan.range_max:.3f} m) is at or below their range_min "
            f"({scan.range_min:.3f} m), so every reading counts as no return",
            "set the laser driver's range_max to the laser's range; input.max_range can only lower it",
        )
    return why, "check the scan topic, range_min/range_max and input.max_range"


def first_scan_geometry(log_path: str | Path, cfg: Config) -> tuple[int, float] | None:
    """(beams, angle increment) of the log's first scan, None when it has none.

    The reader's warnings are silenced here: the run reads the log again and reports them once.
    """
    with _reader_quiet(), open_configured(Path(log_path), cfg.input) as reader:
        scan = first_scan(reader)
    return None if scan is None else (scan.n_beams, scan.angle_increment)


@contextmanager
def _reader_quiet() -> Iterator[None]:
    """The log readers' warnings silenced for a glance at a log the run reads (and warns of) again."""
    reader_log = logging.getLogger("cornerslam.logs")
    level = reader_log.level
    reader_log.setLevel(logging.ERROR)
    try:
        yield
    finally:
        reader_log.setLevel(level)


def _check_method(method: str, data: dict, overrides: Sequence[str]) -> None:
    """ConfigError for an ``association.method`` that names no associator, with the closest name and
    where it was given (the config file's line, the ``--set``), as a bad ``input.laser_preset`` is."""
    from .association import associator_class

    try:
        associator_class(method)
    except ConfigError as e:
        key = ConfigError(
            f"config key 'association.method' = '{short_text(method)}' is not an associator", e.hint
        )
        raise located(key, data, overrides) from None


def warn_mismatch(name: str, log_path: str | Path, cfg: Config) -> None:
    """A warning when the pinned preset ``name`` is not the laser of the log's scans (a config written
    by ``cornerslam config`` for another log names its preset): its sensor model and extraction settings
    are then another sensor's (:func:`mismatch_text`)."""
    geometry = first_scan_geometry(log_path, cfg)
    if geometry is not None and (text := mismatch_text(name, *geometry, log_path)):
        log.warning("%s", text)


def mismatch_text(name: str, beams: int, increment: float, log_path: str | Path) -> str:
    """Why the preset ``name`` is not the laser of scans of ``beams`` beams ``increment`` rad apart, and
    the preset that fits them; "" when it is. Only the beams' spacing is compared: fewer beams at the
    preset's spacing are its laser's scans cropped by the driver, which pinning the preset is how to model."""
    p = PRESETS[name]
    if spaced_as(p, increment):
        return ""
    fits = detect_preset(beams, increment)
    what = (
        f"'{fits}' fits them; set input.laser_preset to it or to auto" if fits else "set it to auto or none"
    )
    made_for = f"{'/'.join(map(str, p.beams))} beams {p.increment_deg:.3g}° apart"
    return (
        f"input.laser_preset '{name}' is for {made_for}, but the scans of "
        f"'{Path(os.path.abspath(log_path)).name}' have {beams} beams {math.degrees(abs(increment)):.3g}° "
        f"apart: its sensor model and extraction settings are another laser's ({what})"
    )


def resolve_config(
    log_path: str | Path | None,
    config_path: str | Path | None,
    overrides: Sequence[str] = (),
    ignored: Mapping[str, tuple[str, Collection[Any]]] | None = None,
) -> Config:
    """The run's config: the user's layers over the laser preset that ``input.laser_preset`` selects.

    The config file is read once (it may be a pipe) and layered twice: without, then with the preset.
    ``ignored``: dotted keys the command leaves unused, each with why and the values it runs anyway;
    the file setting one to another value is warned about (:func:`config.warn_ignored`)."""
    data = read_config_file(config_path) if config_path is not None else {}
    cfg = config_from(data, overrides)
    _check_method(cfg.association.method, data, overrides)
    if ignored and config_path is not None:
        warn_ignored(data, overrides, ignored)
    choice = cfg.input.laser_preset
    if choice == "none" or (choice == "auto" and log_path is None):
        return cfg
    if choice == "auto":
        geometry = first_scan_geometry(log_path, cfg)
        name = detect_preset(*geometry) if geometry else None
        if name is None:
            return cfg
    elif choice in PRESETS:
        name = choice
        if log_path is not None:
            warn_mismatch(name, log_path, cfg)
    else:
        hint = did_you_mean(choice[:100], PRESETS, then=" ")
        e = ConfigError(
            f"config key 'input.laser_preset' = '{short_text(choice)}' is not a laser preset",
            f"{hint}{preset_choices()}",
        )
        raise located(e, data, overrides)
    given = set_keys(overrides)  # (a --set's value wins over the file's)
    if over := [k for k in overruled_by_file(data, name) if k not in given]:
        lines = getattr(data, "lines", {})
        keys = ", ".join(f"{k} (line {lines[k]})" if k in lines else k for k in over)
        log.warning(
            "%s sets %s over the laser preset '%s'%s, and the file's %s used (leave %s out of the file for "
            "the preset's, or set input.laser_preset: none)",
            getattr(data, "where", "the config file"), keys, name,
            " chosen for this log's scans" if choice == "auto" else "", "value is" if len(over) == 1 else
            "values are", "it" if len(over) == 1 else "them",
        )  # fmt: skip
    cfg = config_from(data, overrides, base=PRESETS[name].config)
    return dataclasses.replace(cfg, input=dataclasses.replace(cfg.input, laser_preset=name))


def overruled_by_file(data: Mapping, name: str) -> list[str]:
    """The dotted keys of the preset ``name`` that a config file's mapping ``data`` sets to other values:
    the file is layered over the preset, so a full dump (configs/default.yaml before 2026-12-06, `cornerslam
    config` without a log) silently replaced a SICK log's sensor model with the built-in Hokuyo one."""
    own = dict(_leaves(PRESETS[name].config))
    given = dict(_leaves(data))

    def same(a, b) -> bool:
        numbers = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (a, b))
        return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12) if numbers else a == b

    return [k for k, v in own.items() if k in given and not same(given[k], v)]


def laser_mount(reader, cfg: Config) -> tuple[tuple[float, float, float], str, bool, str]:
    """The laser's pose on the robot and where it came from, whether it is upside down and where that
    came from: tf when the log has it, else the config's ``input.laser`` (:func:`lasers.mount_source`);
    upside down from the config (``config``) when the log's mount cannot say (a CARMEN ROBOTLASER1
    offset is planar), so the two sources can differ."""
    mount = cfg.input.laser
    if mount.from_tf:
        tf = reader.laser_to_base()
        if tf is not None:
            flip = reader.laser_upside_down()
            upside_down, flip_source = (mount.upside_down, "config") if flip is None else (flip, "tf")
            return (float(tf[0]), float(tf[1]), float(tf[2])), "tf", upside_down, flip_source
    x, y, yaw = (0.0 if v is None else v for v in (mount.x, mount.y, mount.yaw))  # None: not set
    return (x, y, yaw), mount_source(cfg), mount.upside_down, "config"


def warn_mount(src, cfg: Config) -> None:
    """Warn (into summary.json too) when the laser mount is the built-in default: the log has no tf
    for it and the config does not set it; when the config's ``input.laser.upside_down: true`` is
    overruled by a tf that mounts the laser upright (the key's default is false and no laser preset
    sets it, so true was the user's); and when the config's ``input.laser.x/y/yaw`` (default null: not
    set) are overruled by the tf's mount elsewhere. ``src``: the run's opened input (frontend.Input).
    Called once the run has its frames, so that a log that fails gives its one-line error alone."""
    if src.laser_source == "default":
        why = f"has no tf {_tf_text(src, cfg)}{getattr(src.reader, 'near_frames', '')}"
        keep = ", or input.laser.from_tf=false to keep it"
        topic = short_text(src.info.scan_topic)
        if getattr(src.reader, "laser_frame", None) == "":  # a scan read, its frame empty: no tf names it
            why = f"has scans on '{topic}' with an empty header frame_id, so no tf can place the laser"
        if src.info.format == "carmen":  # no tf to look in, nor a key to turn that off
            why = src.reader.mount_problem or f"gives no laser mount (its {topic} lines carry none)"
            keep = ""
        src.reader.stats.warn(
            "log '%s' %s: the laser is taken at the built-in default x=0 y=0 yaw=0 on the robot (set "
            "input.laser.x/y/yaw to its mount%s)",
            src.path.name, why, keep,
        )  # fmt: skip
    keys = overruled_mount(cfg, src.laser2base) if src.laser_source == "tf" else ""
    if keys:
        whose = (
            "ROBOTLASER1 lines place" if src.info.format == "carmen" else f"tf {_tf_text(src, cfg)} mounts"
        )
        src.reader.stats.warn(
            "log '%s': its %s the laser at x=%.3f y=%.3f yaw=%.3f, and that mount is used: %s ignored (set "
            "input.laser.from_tf=false to use the config's mount instead)",
            src.path.name, whose, *src.laser2base, keys,
        )  # fmt: skip
    if cfg.input.laser.upside_down and src.laser_upside_down_source == "tf" and not src.laser_upside_down:
        src.reader.stats.warn(
            "log '%s': its tf %s mounts the laser upright, and the tf's orientation is used: "
            "input.laser.upside_down=true is ignored (set input.laser.from_tf=false to use the config's "
            "mount instead, with input.laser.x/y/yaw)",
            src.path.name, _tf_text(src, cfg),
        )  # fmt: skip


def overruled_mount(cfg: Config, log_mount: tuple[float, float, float]) -> str:
    """The config's ``input.laser.x/y/yaw`` that the log's own mount ``log_mount`` overrules, where they
    differ from it (``"input.laser.x=0.2 is"``), or ``""``: what a run warns of and ``info`` notes."""
    mount = cfg.input.laser
    given = {k: v for k, v in (("x", mount.x), ("y", mount.y), ("yaw", mount.yaw)) if v is not None}
    logs = dict(zip(("x", "y", "yaw"), log_mount, strict=True))
    off = [abs(wrap_angle(v - logs[k]) if k == "yaw" else v - logs[k]) for k, v in given.items()]
    if max(off, default=0.0) <= MOUNT_SAME:
        return ""
    keys = " ".join(f"input.laser.{k}={v:g}" for k, v in given.items())
    return keys + (" is" if len(given) == 1 else " are")


def _tf_text(src, cfg: Config) -> str:
    """``base→laser`` as the log names them: the reader's base frame (``/`` stripped) and the frame
    of its scans (``laser`` when the reader has none: no scan read, an empty frame_id)."""
    base = getattr(src.reader, "base_frame", None) or cfg.input.base_frame
    return f"{short_text(base)}→{short_text(getattr(src.reader, 'laser_frame', None) or 'laser')}"
