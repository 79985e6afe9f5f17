"""Typed, validated configuration: one frozen dataclass per section.

``load_config(path, overrides)`` reads a YAML file (any subset of keys; the rest keep the defaults
below, which ``configs/default.yaml`` mirrors), applies ``--set key=value`` overrides and returns a
:class:`Config`. Unknown keys and wrong types raise :class:`ConfigError` naming the dotted key and
the closest valid one. Each pipeline stage receives only its own section.
"""

from __future__ import annotations

import copy
import dataclasses
import difflib
import math
import re
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import yaml

from .association.params import AssociationConfig
from .errors import ConfigError
from .features.params import CornersConfig, LinesConfig, SensorConfig
from .filter.params import EkfConfig
from .motion.params import ScanMatchConfig


@dataclass(frozen=True)
class LaserMountConfig:
    """Pose of the laser in the robot base frame (used when the log has no tf for it)."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0
    from_tf: bool = True  # prefer a static transform base→laser found in the log


@dataclass(frozen=True)
class OdomJumpConfig:
    """Odometry jumps and resets (``logs/sync.py reanchor_odometry``).

    Between two odometry samples dt seconds apart, a move farther than ``distance`` or a turn larger
    than ``angle`` per ``period`` seconds (scaled by dt / period when dt > period) is not motion the
    robot can make: it is a jump (a reset of the odometry to zero, a relocalisation). The jump is
    not applied as motion: the odometry after it is re-anchored to continue from the pose before it,
    and the step across it adds diag(sigma_xy², sigma_xy², sigma_theta²) to the robot covariance.
    """

    distance: float = 2.0  # metres per period; 0 = no jump detection
    angle: float = math.pi / 2  # radians per period
    period: float = 0.1  # seconds
    sigma_xy: float = 0.1  # metres, added robot uncertainty across a jump
    sigma_theta: float = 0.05  # radians

    def __post_init__(self) -> None:
        for name in ("distance", "angle", "period", "sigma_xy", "sigma_theta"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"odom_jump.{name} must be a finite number >= 0, got {v}")
        if self.period <= 0.0:
            raise ValueError(f"odom_jump.period must be > 0, got {self.period}")


@dataclass(frozen=True)
class InputConfig:
    """Which topics to read and how to treat beams."""

    scan_topic: str = ""  # "" = choose by message type
    odom_topic: str = ""  # "" = nav_msgs/Odometry topic, else tf odom→base
    odom_frame: str = "odom"
    base_frame: str = "base_link"
    max_range: float = 0.0  # 0 = use the scan's range_max; beams at or beyond are "no return"
    skip_beams_start: int = 0  # beams at the start of each scan to ignore (e.g. robot body)
    skip_beams_end: int = 0
    scan_time_offset: float = 0.0  # seconds added to every scan stamp before syncing with odometry
    laser_preset: str = "auto"  # auto (by the scan's geometry) | none | a name in lasers.PRESETS
    laser: LaserMountConfig = field(default_factory=LaserMountConfig)
    odom_jump: OdomJumpConfig = field(default_factory=OdomJumpConfig)


@dataclass(frozen=True)
class KeyframeConfig:
    """Process a scan only after the robot moved this much (gmapping linearUpdate/angularUpdate)."""

    linear_update: float = 0.0  # metres; 0 with angular_update 0 = every scan
    angular_update: float = 0.0  # radians
    max_interval: float = 0.0  # seconds; 0 = no time-based keyframes


@dataclass(frozen=True)
class Config:
    input: InputConfig = field(default_factory=InputConfig)
    keyframes: KeyframeConfig = field(default_factory=KeyframeConfig)
    scan_match: ScanMatchConfig = field(default_factory=ScanMatchConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    lines: LinesConfig = field(default_factory=LinesConfig)
    corners: CornersConfig = field(default_factory=CornersConfig)
    association: AssociationConfig = field(default_factory=AssociationConfig)
    ekf: EkfConfig = field(default_factory=EkfConfig)

    def to_dict(self) -> dict:
        return _to_plain(dataclasses.asdict(self))


def _to_plain(v: Any) -> Any:
    if isinstance(v, dict):
        return {k: _to_plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_to_plain(x) for x in v]
    return v


def _closest(key: str, valid: list[str]) -> str:
    match = difflib.get_close_matches(key, valid, n=1, cutoff=0.5)
    return f"did you mean '{match[0]}'?" if match else f"valid keys: {', '.join(sorted(valid))}"


_YAML11_EXPONENT = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)[eE][+-]?\d+$")


def _coerce(value: Any, tp: Any, key: str) -> Any:
    """Check ``value`` against the annotation ``tp``; return it converted (int → float, list → tuple)."""
    origin = typing.get_origin(tp)
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise ConfigError(f"config key '{key}' must be a mapping, got {value!r}")
        return from_dict(tp, value, key + ".")
    if origin is Literal:
        choices = typing.get_args(tp)
        if value not in choices:
            hint = difflib.get_close_matches(str(value), [str(c) for c in choices], n=1, cutoff=0.5)
            dym = f"did you mean '{hint[0]}'? " if hint else ""
            raise ConfigError(
                f"config key '{key}' = {value!r} is not allowed",
                f"{dym}choices: {', '.join(map(str, choices))}",
            )
        return value
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        for a in args:
            if a is type(None):
                continue
            try:
                return _coerce(value, a, key)
            except ConfigError:
                pass
        raise ConfigError(f"config key '{key}' has the wrong type: {value!r}", f"expected {tp}")
    if origin is tuple:
        (elem, *_rest) = typing.get_args(tp)
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"config key '{key}' must be a list, got {value!r}")
        return tuple(_coerce(v, elem, f"{key}[{i}]") for i, v in enumerate(value))
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"config key '{key}' must be true or false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"config key '{key}' must be an integer, got {value!r}")
        return value
    if tp is float:
        if isinstance(value, str) and _YAML11_EXPONENT.match(value.strip()):
            value = float(value)  # YAML 1.1 reads 1e-6 (no dot) as a string; it is a number
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"config key '{key}' must be a number, got {value!r}")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"config key '{key}' must be a string, got {value!r}")
        return value
    raise TypeError(f"unsupported config annotation {tp!r} for {key}")  # a bug in a section class


def from_dict(cls: type, data: dict, prefix: str = "") -> Any:
    """Build the dataclass ``cls`` from a (partial) mapping, validating every key at every depth."""
    hints = typing.get_type_hints(cls)
    names = [f.name for f in dataclasses.fields(cls)]
    kwargs = {}
    for key, value in data.items():
        if key not in names:
            raise ConfigError(f"unknown config key '{prefix}{key}'", _closest(str(key), names))
        kwargs[key] = _coerce(value, hints[key], prefix + key)
    try:
        return cls(**kwargs)
    except ValueError as e:  # a section's __post_init__ range check
        raise ConfigError(f"config section '{prefix.rstrip('.') or 'root'}': {e}") from None


def _parse_override(text: str) -> tuple[list[str], Any]:
    if "=" not in text:
        raise ConfigError(f"--set '{text}' is not key=value", "e.g. --set association.alpha=0.01")
    key, raw = text.split("=", 1)
    key = key.strip()
    if not key:
        raise ConfigError(f"--set '{text}' has an empty key")
    try:
        value = yaml.safe_load(raw) if raw.strip() else ""
    except yaml.YAMLError:
        value = raw
    return key.split("."), value


def _deep_merge(under: dict, over: dict) -> dict:
    """A new mapping: ``over``'s keys win, nested mappings are merged key by key."""
    out = dict(under)
    for k, v in over.items():
        out[k] = _deep_merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def _merge(base: dict, path: list[str], value: Any) -> None:
    d = base
    for p in path[:-1]:
        nxt = d.get(p)
        if not isinstance(nxt, dict):
            nxt = {}
            d[p] = nxt
        d = nxt
    d[path[-1]] = value


def load_config(
    path: str | Path | None = None, overrides: typing.Sequence[str] = (), base: dict | None = None
) -> Config:
    """Load ``path`` (YAML; None = defaults) over the partial config ``base`` (a laser preset) and
    apply ``key=value`` overrides: defaults < base < file < overrides."""
    data: dict = {}
    if path is not None:
        p = Path(path)
        if not p.is_file():
            raise ConfigError(
                f"config file '{p}' does not exist", "give a YAML file, e.g. configs/default.yaml"
            )
        try:
            loaded = yaml.safe_load(p.read_text())
        except yaml.YAMLError as e:
            mark = getattr(e, "problem_mark", None)
            where = f" at line {mark.line + 1}" if mark is not None else ""
            raise ConfigError(f"config file '{p}' is not valid YAML{where}", "fix the syntax") from None
        if loaded is None:
            loaded = {}
        if not isinstance(loaded, dict):
            raise ConfigError(f"config file '{p}' must contain a mapping of sections")
        data = loaded
    if base:
        data = _deep_merge(copy.deepcopy(base), data)  # overrides below write into data
    for text in overrides:
        keys, value = _parse_override(text)
        _merge(data, keys, value)
    return from_dict(Config, data)


def dump_config(cfg: Config) -> str:
    """The config as YAML (what ``configs/default.yaml`` holds for the defaults)."""
    return yaml.safe_dump(cfg.to_dict(), sort_keys=False)
