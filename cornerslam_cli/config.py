"""Typed, validated configuration: one frozen dataclass per section.

``load_config(path, overrides)`` reads a YAML file (any subset of keys; the rest keep the defaults
below, which ``configs/default.yaml`` mirrors), applies ``--set key=value`` overrides and returns a
:class:`Config`. Unknown keys, wrong types and numbers outside their range (declared beside each key
with ``ranges.num``; NaN and inf are never allowed) raise :class:`ConfigError` naming the dotted key
and the closest valid one or the allowed range, and where the key was given: the ``--set`` that set it,
or the config file and line. Each pipeline stage receives only its own section.

A config file is UTF-8 YAML of at most 1 MiB, one document, no key given twice. Anchors and aliases
are allowed, but a document that expands to more than ``MAX_YAML_NODES`` nodes (an alias bomb:
aliases of lists of aliases) is refused before anything is built from it, and error messages quote
at most a short prefix of any value. A plain value YAML 1.1 reads as a base-60 number (``1:30`` is
90, ``1:30.5`` is 90.5: a time written as minutes:seconds) or as an octal one (an integer with a
leading zero: ``010`` is 8, ``0300`` is 192) is refused naming the key and the text, in a file and in
``--set``: no key takes such text, and 90 or 8 is rarely what was meant (``0x10`` is 16 and
``00.5`` is 0.5, as written).

Over 400 lines because the YAML reading (a safe loader refusing keys given twice, alias bombs and
base-60 and octal numbers, its errors naming file and line) sits beside the validation it feeds: both decide
what a user's config may say; the YAML half could move to a module of its own, as textfile.py did.
"""

from __future__ import annotations

import copy
import dataclasses
import datetime
import logging
import math
import re
import sys
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import yaml

from .association.params import AssociationConfig
from .errors import ConfigError, did_you_mean
from .features.params import CornersConfig, LinesConfig, SensorConfig
from .filter.params import EkfConfig
from .graph.params import GraphConfig, LoopConfig, SubmapConfig
from .logs.params import InputConfig, KeyframeConfig
from .motion.params import ScanMatchConfig
from .ranges import Range, RangeError, check_ranges, field_range, num, short_repr, short_text
from .textfile import read_text

log = logging.getLogger("cornerslam.config")

TWO_PI = 2.0 * math.pi
MAX_CONFIG_BYTES = 1 << 20  # configs/default.yaml, every key, is 2.5 KB
MAX_YAML_NODES = 10_000  # nodes of a config document with every alias expanded (default.yaml: ~250)
# (pip installs no configs/: the source tree's; `cornerslam config` writes one anywhere)
CONFIG_FILE = "a YAML config file, e.g. what `cornerslam config > my.yaml` writes; configs/ is the source's"
SUMMARY_MARK = "cornerslam_version"  # summary.json's first field (results.RunSummary): a run's summary


@dataclass(frozen=True)
class GridConfig:
    """The occupancy grid every run writes (map.pgm + map.yaml for ROS map_server / nav2, map_grid.png)."""

    resolution: float = num(0.05, ge=0.001, le=100.0)  # metres per cell
    # cells at most (~6 bytes each while it is built): a larger map is written coarser, warned
    max_cells: int = num(10_000_000, ge=100, le=200_000_000)

    def __post_init__(self) -> None:
        check_ranges(self)


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
    grid: GridConfig = field(default_factory=GridConfig)
    submaps: SubmapConfig = field(default_factory=SubmapConfig)
    loops: LoopConfig = field(default_factory=LoopConfig)
    graph: GraphConfig = field(default_factory=GraphConfig)

    def to_dict(self) -> dict:
        return _to_plain(dataclasses.asdict(self))


def _to_plain(v: Any) -> Any:
    if isinstance(v, dict):
        return {k: _to_plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_to_plain(x) for x in v]
    return v


def _closest(key: str, cls: type, prefix: str) -> str:
    """The hint for an unknown key ``key`` of the section ``cls`` (at ``prefix``): the keys further down
    whose last part is ``key`` (``refine`` → ``graph.refine``), else the closest of the section's own
    keys, else them all; a dotted key that is one (``scan_match.window: 5`` in a file), how to nest it."""
    valid = [f.name for f in dataclasses.fields(cls)]
    if "." in key and key in dotted_keys(cls):  # (--set takes the dotted form; a file nests it)
        *sections, leaf = key.split(".")
        under = " under ".join(f"'{s}:'" for s in reversed(sections))
        return f"in a file, nest it: '{leaf}:' indented under {under}"
    deeper = [k for k in dotted_keys(cls) if "." in k and k.rpartition(".")[2] == key]
    if deeper:
        named = " or ".join(f"'{prefix}{k}'" for k in deeper)
        return f"did you mean {named}?"
    close = did_you_mean(key, valid, cutoff=0.5, prefix=prefix)  # named in full: 'input.max_range'
    return close or f"valid keys: {', '.join(sorted(valid))}"


def dotted_keys(cls: type) -> list[str]:
    """Every key of the dataclass ``cls`` and of its sections, dotted (``graph``, ``graph.refine``, …)."""
    hints = typing.get_type_hints(cls)
    keys = []
    for f in dataclasses.fields(cls):
        keys.append(f.name)
        if dataclasses.is_dataclass(hints[f.name]):
            keys += [f"{f.name}.{k}" for k in dotted_keys(hints[f.name])]
    return keys


_YAML11_EXPONENT = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)[eE][+-]?\d+$")
_SIGNED_FRACTION = re.compile(r"^[+-]\.\d+$")
_NON_FINITE = re.compile(r"^[+-]?(nan|inf|infinity)$", re.IGNORECASE)
_ZERO_PADDED = re.compile(r"^[+-]?0[0-9_]*[0-9][0-9_]*$")  # 010, 08: an integer with a leading zero


def _number_text(value: str) -> bool:
    """Text that means a number where a number is expected: YAML 1.1 reads 1e-6 (no dot) and -.5 (a
    sign before the dot; .5 is a number) as strings, and ``--set k=nan`` / ``inf`` arrive as strings
    (they are then refused as not finite)."""
    v = value.strip()
    return bool(_YAML11_EXPONENT.match(v) or _SIGNED_FRACTION.match(v) or _NON_FINITE.match(v))


@dataclass(frozen=True, repr=False)
class LongInteger:
    """A YAML integer with more digits than Python converts to ``int`` (``sys.get_int_max_str_digits()``,
    4,300 by default; PyYAML raised ValueError on it): kept as its text, refused by every key."""

    text: str

    def __repr__(self) -> str:
        based = self.text.lstrip("+-")[1:2].lower() in ("x", "o", "b")  # the 0x / 0o / 0b is no digit
        return f"{self.text[:10]}... ({sum(c.isalnum() for c in self.text) - 2 * based:,} digits)"


def _unpadded(value: Any) -> str | None:
    """The hint for an integer with a leading zero that YAML 1.1 reads as text (08, 09: no octal
    digits; 010 is refused as octal before this), else None."""
    if not (isinstance(value, str) and _ZERO_PADDED.match(value)):
        return None
    sign = "-" if value.startswith("-") else ""
    return f"write it without leading zeros ({sign}{value.lstrip('+-').replace('_', '').lstrip('0') or '0'})"


def _integer_hint(value: Any) -> str | None:
    """The hint for a value an integer key refuses: a leading zero's (:func:`_unpadded`), or the whole
    number a float or an exponent means (``1e7``, which YAML 1.1 reads as text; ``300.0``), else None."""
    if hint := _unpadded(value):
        return hint
    if isinstance(value, bool) or (isinstance(value, str) and not _number_text(value)):
        return None
    try:
        number = float(value)
    except (TypeError, ValueError, OverflowError):
        return None
    return f"write it as a whole number: {int(number)}" if number.is_integer() else None


def _as_float(value: int | float) -> float:
    try:
        return float(value)
    except OverflowError:  # an integer of hundreds of digits
        return math.inf if value > 0 else -math.inf


def _coerce(value: Any, tp: Any, key: str, allowed: Range | None = None) -> Any:
    """Check ``value`` against the annotation ``tp`` (and a number against its range ``allowed``, where
    the range check cannot); return it converted (int → float, list → tuple)."""
    origin = typing.get_origin(tp)
    got = short_repr(value)
    if tp in (int, float) and isinstance(value, LongInteger):  # past every range; no int can hold it
        raise ConfigError(
            f"config key '{key}' = {got} is out of range", f"allowed: {allowed}" if allowed else None
        )
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise ConfigError(f"config key '{key}' must be a mapping, got {got}")
        return from_dict(tp, value, key + ".")
    if origin is Literal:
        choices = typing.get_args(tp)
        if not isinstance(value, str) or value not in choices:
            dym = did_you_mean(str(value)[:100], map(str, choices), cutoff=0.5, then=" ")
            raise ConfigError(
                f"config key '{key}' = {got} is not allowed",
                f"{dym}choices: {', '.join(map(str, choices))}",
            )
        return value
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        if len(args) == 2 and type(None) in args:  # X | None given a value: an X, with X's errors
            return _coerce(value, next(a for a in args if a is not type(None)), key, allowed)
        for a in args:
            if a is type(None):
                continue
            try:
                return _coerce(value, a, key)
            except ConfigError:
                pass
        raise ConfigError(f"config key '{key}' has the wrong type: {got}", f"expected {tp}")
    if origin is tuple:
        (elem, *_rest) = typing.get_args(tp)
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"config key '{key}' must be a list, got {got}")
        return tuple(_coerce(v, elem, f"{key}[{i}]") for i, v in enumerate(value))
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"config key '{key}' must be true or false, got {got}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"config key '{key}' must be an integer, got {got}", _integer_hint(value))
        return value
    if tp is float:
        if isinstance(value, str) and _number_text(value):
            value = float(value)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"config key '{key}' must be a number, got {got}", _unpadded(value))
        return _as_float(value)
    if tp is str:
        if isinstance(value, bool):  # YAML 1.1: yes/no/on/off are booleans
            raise ConfigError(  # (YAML 1.1 reads yes/no/on/off/true/false as booleans)
                f"config key '{key}' must be a string, got {got}",
                f"quote it: 'on' or 'no' in a file, --set \"{key}='on'\" on a command line",
            )
        if not isinstance(value, str):
            raise ConfigError(f"config key '{key}' must be a string, got {got}")
        return value
    raise TypeError(f"unsupported config annotation {tp!r} for {key}")  # a bug in a section class


def from_dict(cls: type, data: dict, prefix: str = "") -> Any:
    """Build the dataclass ``cls`` from a (partial) mapping, validating every key at every depth."""
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    names = list(fields)
    kwargs = {}
    retired = getattr(cls, "RETIRED", {})
    for key, value in data.items():
        if key in retired and key not in names:
            log.warning("config key '%s%s' is no longer used and was ignored: %s", prefix, key, retired[key])
            continue
        if key not in names:
            name = short_text(str(key)) if isinstance(key, (str, datetime.date)) else short_repr(key)
            raise ConfigError(f"unknown config key '{prefix}{name}'", _closest(str(key)[:100], cls, prefix))
        kwargs[key] = _coerce(value, hints[key], prefix + key, field_range(fields[key]))
    try:
        return cls(**kwargs)
    except RangeError as e:  # a number outside the range declared with ranges.num
        raise ConfigError(
            f"config key '{prefix}{e.key}' = {short_repr(e.value)} {e.problem}", f"allowed: {e.allowed}"
        ) from None
    except ValueError as e:  # a section's __post_init__ check across keys
        raise ConfigError(f"config section '{prefix.rstrip('.') or 'root'}': {e}") from None


# --------------------------------------------------------------------------- YAML
_NULL_TAG, _BOOL_TAG = "tag:yaml.org,2002:null", "tag:yaml.org,2002:bool"
_INT_TAG = "tag:yaml.org,2002:int"
_FLOAT_TAG = "tag:yaml.org,2002:float"
_MERGE_TAG = "tag:yaml.org,2002:merge"  # `<<: *base`: the keys of another mapping merged into this one
_TIMESTAMP_TAG = "tag:yaml.org,2002:timestamp"  # a date key: named as YAML prints it (2024-01-01)
_UNLIKE_TAG = "tag:cornerslam,2026:unlike-as-written"  # a number YAML 1.1 reads in base 60 or 8
_OCTAL = re.compile(r"^[-+]?0[0-7_]*[0-7][0-7_]*$")  # YAML 1.1's base 8 ('0' and '0_' are 0 either way)


@dataclass(frozen=True)
class UnlikeNumber:
    """A plain YAML scalar that YAML 1.1 reads as a number other than the decimal one it looks like: a
    base-60 number (``1:30`` → 90) or an octal one (``010`` → 8). ``text`` as written, ``value`` what
    YAML 1.1 makes of it, ``line`` (1-based) where it stands. Never a config value:
    :func:`_refuse_unlike_number` refuses it under the key it was given for."""

    text: str
    value: int | float | LongInteger
    line: int

    @property
    def octal(self) -> bool:
        return ":" not in self.text


class _DuplicateKey(yaml.constructor.ConstructorError):
    """A mapping gives one key twice (a YAML error, but not one that makes a --set value a string)."""


class _ConfigLoader(yaml.SafeLoader):
    """PyYAML's safe loader that refuses a key given twice in one mapping (PyYAML keeps the last) and
    keeps a base-60 number (``1:30``) or an octal one (``010``) as an :class:`UnlikeNumber`, to be
    refused; everything else is resolved and built as ``yaml.safe_load`` does."""

    def resolve(self, kind: type, value: str, implicit: tuple[bool, bool]) -> str:
        tag = super().resolve(kind, value, implicit)
        if tag in (_INT_TAG, _FLOAT_TAG) and ":" in value:  # only YAML 1.1's base-60 forms have a colon
            return _UNLIKE_TAG
        if tag == _INT_TAG and _OCTAL.match(value):  # (a float is decimal: 010.5 is 10.5)
            return _UNLIKE_TAG
        return tag

    def construct_unlike_number(self, node: yaml.ScalarNode) -> UnlikeNumber:
        as_float = "." in node.value
        value = self.construct_yaml_float(node) if as_float else self.construct_yaml_int(node)
        return UnlikeNumber(node.value, value, node.start_mark.line + 1)

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen: dict[tuple[str, str], yaml.Mark] = {}
        for key_node, _ in node.value:
            if not isinstance(key_node, yaml.ScalarNode) or key_node.tag == "tag:yaml.org,2002:merge":
                continue
            k = (key_node.tag, key_node.value)
            if k in seen:
                raise _DuplicateKey(
                    None,
                    None,
                    f"key '{short_text(key_node.value)}' is given twice (first at line {seen[k].line + 1})",
                    key_node.start_mark,
                )
            seen[k] = key_node.start_mark
        return super().construct_mapping(node, deep)

    def construct_yaml_int(self, node: yaml.ScalarNode) -> int | LongInteger:
        try:  # more digits than int() converts (ValueError), or a 0x… / 0b… no message could print
            value = super().construct_yaml_int(node)
        except ValueError:
            value = None
        bits = sys.get_int_max_str_digits() * math.log2(10) or math.inf  # (0: no limit)
        return value if value is not None and abs(value).bit_length() <= bits else LongInteger(node.value)


_ConfigLoader.add_constructor(_INT_TAG, _ConfigLoader.construct_yaml_int)
_ConfigLoader.add_constructor(_UNLIKE_TAG, _ConfigLoader.construct_unlike_number)


def _find_unlike_number(value: Any, key: str = "") -> tuple[str, UnlikeNumber] | None:
    """The first base-60 or octal number in ``value`` (parsed YAML) and the dotted key it is under."""
    if isinstance(value, UnlikeNumber):
        return key, value
    if isinstance(value, dict):
        items = value.items()
    elif isinstance(value, list):
        items = ((f"[{i}]", v) for i, v in enumerate(value))
    else:
        return None
    for k, v in items:
        name = k.text if isinstance(k, UnlikeNumber) else str(k)
        sub = f"{key}{name}" if name.startswith("[") else f"{key}.{name}" if key else name
        if isinstance(k, UnlikeNumber):
            return sub, k
        if found := _find_unlike_number(v, sub):
            return found
    return None


def _refuse_unlike_number(value: Any, key: str = "", where: str = "") -> None:
    """ConfigError if ``value`` (parsed YAML, under the dotted ``key``) holds a base-60 or octal
    number; ``where`` names the file it was read from."""
    found = _find_unlike_number(value, key)
    if found is None:
        return
    name, s = found
    at = f"{where} line {s.line}: " if where else ""
    text = short_text(s.text)
    if s.octal:  # 010: 8 or 10? (ambiguous: refused, not read either way)
        what, fix = "an octal number", f"{_unpadded(s.text)}, or quote it ('{text}')"
    else:
        what, fix = (
            "a base-60 number",
            f"write the number itself, in seconds for a time, or quote it ('{text}')",
        )
    raise ConfigError(
        f"{at}config key '{short_text(name)}' = {text} is {what} to YAML 1.1, read as {short_repr(s.value)}",
        f"{fix} if it is text",
    )


def _expanded_size(node: yaml.Node, sizes: dict[int, int | None], where: str) -> int:
    """Nodes in ``node`` with every alias expanded (memoised per node: linear in the document)."""
    key = id(node)
    if key in sizes:
        if sizes[key] is None:
            raise ConfigError(f"{where} has an alias inside its own anchor (a recursive structure)")
        return sizes[key]
    sizes[key] = None
    children: list = []
    if isinstance(node, yaml.SequenceNode):
        children = node.value
    elif isinstance(node, yaml.MappingNode):
        children = [n for pair in node.value for n in pair]
    n = 1
    for child in children:
        n += _expanded_size(child, sizes, where)
        if n > MAX_YAML_NODES:
            raise ConfigError(
                f"{where} expands to more than {MAX_YAML_NODES:,} YAML nodes (aliases of aliases?)",
                "a config needs a few hundred; write the values out instead of nesting aliases",
            )
    sizes[key] = n
    return n


def _key_lines(node: yaml.Node, prefix: str, lines: dict[str, int], loader: _ConfigLoader) -> None:
    """Fill ``lines`` with the 1-based line of each key of the mapping ``node`` and of its nested
    mappings, dotted (``ekf.alpha1``). An alias is walked once, where it is first defined (its keys'
    lines are the anchor's: what the user would edit)."""
    if not isinstance(node, yaml.MappingNode):
        return
    merged = [v for k, v in node.value if k.tag == _MERGE_TAG]  # their keys are this mapping's
    for key_node, value_node in node.value:
        if key_node.tag == _MERGE_TAG:
            continue
        if isinstance(key_node, yaml.ScalarNode):
            text = key_node.value  # as loaded where YAML reads it otherwise: `null:` is None, `true:` True
            if key_node.tag in (_NULL_TAG, _BOOL_TAG, _INT_TAG, _FLOAT_TAG, _TIMESTAMP_TAG):
                text = str(loader.construct_object(key_node))
            key = prefix + text
            lines.setdefault(key, key_node.start_mark.line + 1)
            _key_lines(value_node, key + ".", lines, loader)  # (bounded: _expanded_size ran first)
    for value_node in merged:  # after the mapping's own keys, which win over merged ones (as in YAML)
        for m in value_node.value if isinstance(value_node, yaml.SequenceNode) else [value_node]:
            _key_lines(m, prefix, lines, loader)


def _parse_yaml(text: str, where: str, lines: dict[str, int] | None = None) -> Any:
    """``text`` as Python values (safe loader, one document), refusing a key given twice and a document
    whose aliases expand past ``MAX_YAML_NODES`` (checked on the node graph, before anything is built).
    ``where`` names the source in errors; YAML syntax errors are raised as ``yaml.YAMLError``.
    ``lines``, when given, is filled with the line of every dotted key (:func:`_key_lines`)."""
    loader = _ConfigLoader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        _expanded_size(node, {}, where)
        if lines is not None:
            _key_lines(node, "", lines, loader)
        return loader.construct_document(node)
    except RecursionError:
        raise ConfigError(f"{where} is nested too deeply", "a config has two or three levels") from None
    finally:
        loader.dispose()


def _yaml_problem(e: yaml.YAMLError, text: str) -> str:
    """' at line N: what' from a PyYAML error (its mark, context and problem), '' when it has none."""
    if isinstance(e, yaml.reader.ReaderError):  # a control character: a position, no mark
        line = text.count("\n", 0, e.position) + 1
        return f" at line {line}: control character #x{e.character:02x} is not allowed"
    mark = getattr(e, "problem_mark", None)
    what = " ".join(t for t in (getattr(e, "context", None), getattr(e, "problem", None)) if t)
    return (f" at line {mark.line + 1}" if mark is not None else "") + (f": {what}" if what else "")


def _empty_null_sections(
    data: dict, cls: type, where: str, prefix: str = "", lines: dict[str, int] | None = None
) -> dict:
    """``data`` (a file's mapping for the dataclass ``cls``) with every null section — ``ekf:`` with
    all its keys commented out, which YAML reads as null — taken as an empty one (its defaults, or
    the laser preset's); a section given as a scalar or a list is refused naming the file and key.
    Other keys are left to :func:`from_dict`."""
    hints = typing.get_type_hints(cls)
    out = dict(data)
    for k, v in data.items():
        tp = hints.get(k) if isinstance(k, str) else None
        if tp is None or not dataclasses.is_dataclass(tp):
            continue
        if v is None:
            out[k] = {}
        elif isinstance(v, dict):
            out[k] = _empty_null_sections(v, tp, where, f"{prefix}{k}.", lines)
        else:
            at = f" line {lines[prefix + k]}" if lines and prefix + k in lines else ""
            raise ConfigError(
                f"{where}{at}: section '{prefix}{k}' must be a mapping of its keys, got {short_repr(v)}",
                f"indent its keys under '{k}:', e.g. configs/default.yaml",
            )
    return out


class ConfigFileData(dict):
    """A config file's mapping (:func:`read_config_file`) that remembers where it came from: ``where``
    (``config file 'PATH'``) and the line of each dotted key, so that an invalid value found later, in
    :func:`config_from`, is reported at its line."""

    def __init__(self, data: dict, where: str, lines: dict[str, int]):
        super().__init__(data)
        self.where, self.lines = where, lines


def read_config_file(path: str | Path) -> dict:
    """The mapping a YAML config file holds (``{}`` for an empty file; a null section is an empty
    one), not yet validated as a config."""
    p = Path(path)
    where = f"config file '{p}'"
    text = read_text(p, "config file", ConfigError, CONFIG_FILE, max_bytes=MAX_CONFIG_BYTES)
    lines: dict[str, int] = {}
    try:
        loaded = _parse_yaml(text, where, lines)
    except yaml.YAMLError as e:
        raise ConfigError(f"{where} is not valid YAML{_yaml_problem(e, text)}", "fix the syntax") from None
    if loaded is None:
        return {}
    if not isinstance(loaded, dict):
        raise ConfigError(
            f"{where} must contain a mapping of sections, not {type(loaded).__name__}",
            "write 'section:' lines with their keys indented below, as `cornerslam config` prints",
        )
    if SUMMARY_MARK in loaded and isinstance(loaded.get("config"), dict):  # a run's summary.json
        loaded = loaded["config"]  # the config that run used: run again with it
        lines = {k.removeprefix("config."): n for k, n in lines.items() if k.startswith("config.")}
        where = f"{where} (the config section of a run's summary.json)"
        log.info("%s: running with the config its run used", where)
    _refuse_unlike_number(loaded, where=where)
    return ConfigFileData(_empty_null_sections(loaded, Config, where, lines=lines), where, lines)


def parse_override(text: str) -> tuple[list[str], Any]:
    shown = short_text(text)
    if "=" not in text:
        raise ConfigError(f"--set '{shown}' is not key=value", "e.g. --set association.alpha=0.01")
    key, raw = text.split("=", 1)
    keys = [k.strip() for k in key.split(".")]
    if not all(keys):
        raise ConfigError(f"--set '{shown}' has an empty key", "e.g. --set association.alpha=0.01")
    if raw.lstrip().startswith("#"):  # YAML would read a comment: no value at all
        why = f"quote it if it is the value: --set \"{short_text(key)}='{short_text(raw.strip())}'\""
        raise ConfigError(f"--set '{shown}': '#' starts a YAML comment, so the value would be empty", why)
    try:
        value = _parse_yaml(raw, f"--set '{shown}'") if raw.strip() else ""
    except _DuplicateKey as e:  # a mapping, not a string: `--set 'grid={resolution: 1, resolution: 2}'`
        raise ConfigError(f"--set '{shown}': {e.problem}", "give each key once") from None
    except yaml.YAMLError:
        value = raw
    try:
        _refuse_unlike_number(value, ".".join(keys))  # as a value error of --set: naming the key
    except ConfigError as e:  # and the --set it came from, as every other value error of a --set does
        raise ConfigError(override_place(text) + e.msg, e.hint) from None
    return keys, value


def _deep_merge(under: dict, over: dict) -> dict:
    """A new mapping: ``over``'s keys win, nested mappings are merged key by key."""
    out = dict(under)
    for k, v in over.items():
        out[k] = _deep_merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def _merge(base: dict, path: list[str], value: Any) -> None:
    """Set ``path`` to ``value`` in ``base``; a mapping is merged into the mapping there, key by key, as
    a file is over the preset (``--set 'scan_match={enabled: false}'`` keeps the file's other keys)."""
    d = base
    for p in path[:-1]:
        nxt = d.get(p)
        if not isinstance(nxt, dict):
            nxt = {}
            d[p] = nxt
        d = nxt
    old = d.get(path[-1])
    d[path[-1]] = _deep_merge(old, value) if isinstance(value, dict) and isinstance(old, dict) else value


def override_leaves(keys: list[str], value: Any) -> list[tuple[str, Any]]:
    """(dotted key, value) of each key a ``--set`` (:func:`parse_override`'s ``keys``, ``value``) sets:
    a mapping's leaves (``--set 'input={scan_topic: /b}'``; an empty mapping sets none)."""
    key = ".".join(map(str, keys))  # a mapping's key YAML reads as a number, a date or null: as printed
    if isinstance(value, dict):
        return [leaf for k, v in value.items() for leaf in override_leaves([key, k], v)]
    return [(key, value)]


def set_keys(overrides: typing.Sequence[str]) -> set[str]:
    """The dotted keys the ``overrides`` set (:func:`set_leaves`)."""
    return {leaf for _, leaf, _ in set_leaves(overrides)}


def set_leaves(overrides: typing.Sequence[str]) -> typing.Iterator[tuple[str, str, Any]]:
    """(the --set's text, dotted key, value) of each key the ``overrides`` set (:func:`override_leaves`:
    a mapping's keys too); a --set that :func:`parse_override` refuses is left out (its own error comes
    from :func:`config_from`)."""
    for text in overrides:
        try:
            keys, parsed = parse_override(text)
        except ConfigError:
            continue
        for leaf, loaded in override_leaves(keys, parsed):
            yield text, leaf, loaded


def config_from(data: dict, overrides: typing.Sequence[str] = (), base: dict | None = None) -> Config:
    """The config of a file's mapping ``data`` over the partial config ``base`` (a laser preset), with
    ``key=value`` overrides applied: defaults < base < data < overrides. ``data`` is not modified."""
    merged = _deep_merge(copy.deepcopy(base or {}), copy.deepcopy(dict(data)))  # overrides write into it
    given = []  # (dotted key, the --set text), in order
    for text in overrides:
        keys, value = parse_override(text)
        _merge(merged, keys, value)
        given += [(leaf, text) for leaf, _ in override_leaves(keys, value)]
    try:
        return from_dict(Config, merged)
    except ConfigError as e:
        raise _located(e, data, given) from None


def located(e: ConfigError, data: dict, overrides: typing.Sequence[str]) -> ConfigError:
    """``e``, an invalid value found after :func:`config_from` (``data``, ``overrides`` its arguments;
    ``input.laser_preset``, checked by lasers.py), prefixed with where its key was given, as
    :func:`config_from` does."""
    given = []
    for text in overrides:
        keys, value = parse_override(text)
        given += [(leaf, text) for leaf, _ in override_leaves(keys, value)]
    return _located(e, data, given)


def warn_ignored(
    data: dict,
    overrides: typing.Sequence[str],
    ignored: typing.Mapping[str, tuple[str, typing.Collection[Any]]],
) -> None:
    """A warning (logged) for each dotted key of ``ignored`` (key → why the command leaves it unused,
    and the values it runs anyway) that the config file's ``data`` (:func:`read_config_file`) sets, to
    a value the command does not run, and no ``--set`` of ``overrides`` does: said, not refused, since
    one file may serve several commands (compare runs each associator of --assoc: a file's
    ``association.method: pca`` is no news when pca is one of them). A ``--set`` of such a key is the
    command's own to refuse (``options.check_method_not_set``)."""
    given = set_keys(overrides)
    lines = getattr(data, "lines", {})
    for key, (why, runs) in ignored.items():
        node: Any = data
        for part in key.split("."):
            node = node.get(part, ...) if isinstance(node, dict) else ...
        if node is ... or key in given or (isinstance(node, str) and node in runs):
            continue
        where = getattr(data, "where", "config file") + (f" line {lines[key]}" if key in lines else "")
        log.warning("%s: config key '%s' = %s is ignored: %s", where, key, short_repr(node), why)


def yaml_quoted(text: str) -> str:
    """``text`` as a YAML double-quoted scalar that reads back as ``text`` exactly, for an override
    built from an option (``input.scan_topic=...``): printable ASCII kept, every other character
    escaped as ``\\UXXXXXXXX`` (JSON's ``\\uXXXX`` would write a character past U+FFFF as a surrogate
    pair, which YAML reads as two characters)."""
    escaped = (c if " " <= c <= "~" and c not in '"\\' else f"\\U{ord(c):08x}" for c in text)
    return '"' + "".join(escaped) + '"'


def override_place(text: str) -> str:
    """The prefix of an error in the ``--set`` override ``text`` (:func:`config_from`)."""
    return f"--set '{short_text(text)}': "


def replaced_place(e: ConfigError, text: str, place: str = "") -> ConfigError:
    """``e`` with the ``--set`` place of the override ``text`` replaced by ``place``: an override the
    user gave as another option (``--sweep``, ``--preset``), not as the ``--set`` it became."""
    return ConfigError(place + e.msg.removeprefix(override_place(text)), e.hint)


# the key ends at the quote before a space, ':' or the end (a key may hold a quote: --set "ekf'x=1")
_KEY_IN_MESSAGE = re.compile(r"config (key|section) '(.*?)'(?=[ :]|$)")


def _located(e: ConfigError, data: dict, given: list[tuple[str, str]]) -> ConfigError:
    """``e`` (from validating the merged config) prefixed with where its key was given: the last
    ``--set`` that set it (or a section above it, or a key inside it), else the config file and line
    (``data`` from :func:`read_config_file`); unchanged when neither gave it (a laser preset's value, or
    a check across keys from several places)."""
    found = _KEY_IN_MESSAGE.search(e.msg)
    if found is None:
        return e
    key = re.sub(r"\[\d+\]", "", found.group(2))
    if found.group(1) == "section":  # a check across the section's keys: one place, or none
        return _section_located(e, key, data, given)
    for dotted, text in reversed(given):
        if key == dotted or key.startswith(dotted + ".") or dotted.startswith(key + "."):
            return ConfigError(f"{override_place(text)}{e.msg}", e.hint)
    lines = getattr(data, "lines", {})
    if key in lines:
        return ConfigError(f"{data.where} line {lines[key]}: {e.msg}", e.hint)
    return e


def _section_located(e: ConfigError, key: str, data: dict, given: list[tuple[str, str]]) -> ConfigError:
    """``e``, a check across the keys of the section ``key``, prefixed with the one place its keys were
    given: the last ``--set`` of the section (or above it) with no ``--set`` of a key inside it after,
    one ``--set`` of a key inside it (the file giving none), or the file (no ``--set`` inside it)."""
    replaced = max((i for i, (d, _) in enumerate(given) if key == d or key.startswith(d + ".")), default=-1)
    places = {d: t for d, t in given[replaced + 1 :] if d.startswith(key + ".")}  # the last of each key
    lines = getattr(data, "lines", {})
    in_file = replaced < 0 and any(k.startswith(key + ".") for k in lines)
    if replaced >= 0 and not places:
        return ConfigError(f"{override_place(given[replaced][1])}{e.msg}", e.hint)
    if len(set(places.values())) == 1 and replaced < 0 and not in_file:  # one --set (of a mapping: its keys)
        return ConfigError(f"{override_place(next(iter(places.values())))}{e.msg}", e.hint)
    if not places and in_file and key in lines:
        return ConfigError(f"{data.where} line {lines[key]}: {e.msg}", e.hint)
    return e


def load_config(
    path: str | Path | None = None, overrides: typing.Sequence[str] = (), base: dict | None = None
) -> Config:
    """Load ``path`` (YAML; None = defaults) over the partial config ``base`` (a laser preset) and
    apply ``key=value`` overrides: defaults < base < file < overrides."""
    return config_from(read_config_file(path) if path is not None else {}, overrides, base)


def dump_config(cfg: Config) -> str:
    """The config as YAML (what ``configs/default.yaml`` holds for the defaults)."""
    return yaml.safe_dump(cfg.to_dict(), sort_keys=False)
