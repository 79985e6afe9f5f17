"""The plan of ``cornerslam batch``: many logs × associators × a grid of config values, each
combination a :class:`Combo` with its resolved config and the name of its output directory.

Directory names: ``<log>__<assoc>[__<key>=<value>]...`` with the swept keys in the order given, the
values as written, and any character outside ``[A-Za-z0-9._=+-]`` replaced by ``_``, e.g.
``sim_office__pca__association.pca.group_size=5``. ``<log>`` is the file name up to its first dot;
logs sharing that stem use their whole file name, and logs sharing that too add a short hash of their
absolute path. Base ``--set`` overrides do not appear in names (they are in each summary.json).
"""

from __future__ import annotations

import hashlib
import itertools
import os
import re
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .errors import ConfigError, one_line
from .workers import warnings_copied, warnings_once

_UNSAFE = re.compile(r"[^A-Za-z0-9._=+-]")
_MAX_NAME = 180  # well under the 255-byte file name limit, leaving room for the staging prefix


@dataclass(frozen=True)
class Combo:
    """One point of the batch: a log, an associator and one value for each swept key.

    ``config`` is the fully resolved config as plain data (``Config.to_dict()``), laser preset included
    as ``run`` would choose it, so workers rebuild it without the config file; ``sweep`` holds (dotted
    key, value as written) in the order swept. ``error`` is set when the log could not be opened to
    choose its laser preset: the combination is reported failed without running. ``notes``: the warnings
    resolving its config gave (a pinned preset not the log's laser), kept for its summary.json.
    """

    log: str
    assoc: str
    sweep: tuple[tuple[str, str], ...]
    name: str
    config: dict = field(compare=False, repr=False)
    error: str = ""
    notes: tuple[str, ...] = field(default=(), compare=False, repr=False)


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
    out: str | Path | None = None,
) -> list[Combo]:
    """Every log × associator × point of the sweep grid (the last swept key varies fastest).

    Each swept value is checked against the config schema first (ConfigError naming ``--sweep
    key=value``); unknown associators raise ConfigError with the closest name. Each combination's
    config is resolved as ``cornerslam run`` resolves it (:func:`lasers.resolve_config`: the laser
    preset matching the log's first scan under the user's layers); a log that cannot be opened is not
    an error here but failed rows in :func:`run_batch`. A log listed twice, however its path is spelled
    (``x.mcap``, ``./x.mcap``), is run once; so is a swept value however it is spelled (``0.1,0.10``,
    ``yes,true``: its first spelling names the directory). A warning loading the configs gives (a
    retired key) is said once, not once per value and combination.
    """
    with warnings_once():
        return _plan(logs, assocs, sweeps, overrides, config_path, out)


def _plan(
    logs: Sequence[str | Path],
    assocs: Sequence[str],
    sweeps: Mapping[str, Sequence[Any]] | None,
    overrides: Sequence[str],
    config_path: str | Path | None,
    out: str | Path | None = None,
) -> list[Combo]:
    from .config import load_config, override_place, parse_override, replaced_place
    from .errors import LogError
    from .lasers import resolve_config

    sweeps = {k: list(dict.fromkeys(value_text(v) for v in vs)) for k, vs in (sweeps or {}).items()}
    for key, values in sweeps.items():
        if key == "association.method":
            raise ConfigError("--sweep association.method is not allowed", "list associators with --assoc")
        if not values:
            raise ConfigError(f"--sweep {key} has no values", f"e.g. --sweep {key}=V1,V2")
        seen: dict[str, str] = {}  # the value the config reads → its first spelling
        for v in values:
            try:
                cfg = load_config(config_path, [*overrides, f"{key}={v}"])
            except ConfigError as e:
                raise replaced_place(e, f"{key}={v}", f"--sweep {key}={v}: ") from None
            seen.setdefault(repr(_lookup(cfg.to_dict(), parse_override(f"{key}={v}")[0])), v)
        sweeps[key] = list(seen.values())  # 0.1,0.10 or yes,true: one value, run once
    if not assocs or len(set(assocs)) != len(assocs):
        raise ConfigError(f"associators {','.join(assocs)!r} must be distinct and non-empty")
    first: dict[str, str] = {}  # a log listed twice, however spelled (x.mcap, ./x.mcap): its first spelling
    for p in map(str, logs):
        first.setdefault(os.path.realpath(p), p)
    logs = list(first.values())
    labels = _log_labels(logs, _labels_in(out) if out else {})
    combos = []
    for log, assoc in itertools.product(logs, assocs):
        for values in itertools.product(*sweeps.values()):
            sweep = tuple(zip(sweeps, values, strict=True))
            sets = [*overrides, f"association.method={assoc}", *(f"{k}={v}" for k, v in sweep)]
            error = ""
            with warnings_copied() as notes:
                try:
                    cfg = resolve_config(log, config_path, sets)
                except ConfigError as e:  # a swept laser preset that is none: the --sweep's, not a --set's
                    swept = [f"{k}={v}" for k, v in sweep if e.msg.startswith(override_place(f"{k}={v}"))]
                    if not swept:
                        raise
                    raise replaced_place(e, swept[0], f"--sweep {swept[0]}: ") from None
                except LogError as e:  # the log's rows fail; the batch goes on
                    cfg, error = load_config(config_path, sets), one_line(e)
            name = _dir_name(labels[log], assoc, sweep)
            combos.append(Combo(log, assoc, sweep, name, cfg.to_dict(), error, tuple(notes)))
    names = [c.name for c in combos]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise ConfigError(
            f"two combinations map to the directory name '{dup}' (sweep values differing only in symbols)",
            "make the values differ in letters or digits, or run them in two batches",
        )
    return combos


def _lookup(tree: dict, keys: list[str]) -> Any:
    """The value at ``keys`` (config.parse_override's: a dotted key's parts) of a nested config dict."""
    for part in keys:
        tree = tree[part]
    return tree


def _safe(text: str) -> str:
    return _UNSAFE.sub("_", text)


def _short_hash(text: str) -> str:
    return hashlib.sha1(os.fsencode(text)).hexdigest()[:8]


def _log_labels(logs: Sequence[str], known: Mapping[str, str] | None = None) -> dict[str, str]:
    """Log → its part of the directory name: the one an earlier batch into the same OUT gave it
    (``known``: resolved log path → label, :func:`_labels_in`) while no other log of this batch takes it;
    else its stem, else its file name, else file name + path hash — unique among this batch's logs.
    Without ``known`` a log's label depended on the batch's other logs (``x`` alone, ``x.clf`` beside an
    ``x.mcap``): a batch of other logs into the same OUT re-ran it under a new name and left the old."""
    out: dict[str, str] = {}
    taken: set[str] = set()
    for log in logs:  # labels an earlier batch gave, where they stay unique
        label = (known or {}).get(os.path.realpath(log))
        if label is not None and label not in taken:
            out[log] = label
            taken.add(label)
    rest = [log for log in logs if log not in out]
    for log in rest:
        for tier in _TIERS:
            label = tier(log)
            unique = sum(tier(other) == label for other in rest) == 1 and label not in taken
            if unique or tier is _TIERS[-1]:
                out[log] = label
                taken.add(label)
                break
    return out


_TIERS = [  # a log's label, from the shortest (stem) to one no other path shares (file name + path hash)
    lambda p: _safe(Path(p).name.split(".")[0] or "log"),
    lambda p: _safe(Path(p).name or "log"),
    lambda p: _safe(Path(p).name or "log") + "-" + _short_hash(str(Path(p).resolve())),
]


def _labels_in(out: str | Path) -> dict[str, str]:
    """The log labels the run directories of an earlier batch in ``out`` carry: resolved log path (their
    marker's) → the label. A directory's label is the one of its log's possible labels (:data:`_TIERS`)
    that its name starts with (a label may itself hold ``__``: ``run (1).mcap`` is ``run__1_``); a log
    with directories under several labels keeps the one with most; a label two logs' directories carry
    is no one's (a review: it had one log resume and the other fail as another's)."""
    from .report.ownership import read_marker

    per_log: dict[str, Counter[str]] = {}
    try:
        dirs = sorted(d for d in Path(out).iterdir() if d.is_dir() and "__" in d.name)
    except OSError:  # (none yet, or not readable: batch says why when it claims it)
        return {}
    for d in dirs:
        marker = read_marker(d)
        if marker is None or marker.get("kind") != "run" or not isinstance(marker.get("log"), str):
            continue
        log = marker["log"]
        fits = [t(log) for t in _TIERS if d.name.startswith(t(log) + "__")]
        if fits:
            per_log.setdefault(log, Counter())[max(fits, key=len)] += 1
    owners = Counter(label for labels in per_log.values() for label in labels)
    return {
        log: label
        for log, labels in per_log.items()
        if owners[label := max(labels, key=lambda k: (labels[k], -len(k)))] == 1
    }


def _dir_name(log_label: str, assoc: str, sweep: tuple[tuple[str, str], ...]) -> str:
    name = "__".join([log_label, _safe(assoc), *(_safe(f"{k}={v}") for k, v in sweep)])
    if len(name) > _MAX_NAME:
        name = name[: _MAX_NAME - 9] + "-" + _short_hash(name)
    return name


def sweep_values(key: str, text: str, swept: Mapping[str, list[str]] | None = None) -> list[str]:
    """The values of ``--sweep KEY=TEXT``: TEXT split at the commas outside braces, brackets and quotes
    (a YAML mapping or list keeps its own, ``graph={refine: true, refine_radius: 3},{refine: false}``, and
    a quoted value, ``input.scan_topic='/a,b','/c'``). A ValueError for an empty value ('3,,5', '3,5,':
    one lost in typing, not one to drop silently), for the key given again inside ('K={a: 1},K={a: 2}':
    its values follow one ``KEY=``), and for a key already in ``swept`` (the earlier --sweep options) or
    a section swept beside a key inside it (two labels for one setting)."""
    swept = swept or {}
    if key in swept:
        raise ValueError(f"sweeps '{key}' again; give all its values at once")
    values, depth, start, quote = [], 0, 0, ""
    for i, ch in enumerate(text):
        if quote:  # inside '…' or "…": commas and braces are the value's
            quote = "" if ch == quote else quote
            continue
        quote = ch if ch in "'\"" else ""
        depth += (ch in "{[") - (ch in "}]" and depth > 0)
        if ch == "," and depth == 0:
            values.append(text[start:i].strip())
            start = i + 1
    values.append(text[start:].strip())
    if "" in values:
        raise ValueError("has an empty value; list the values as KEY=V1,V2,... without empty ones")
    if any(dotted_key(v.split("=", 1)[0]) == key for v in values if "=" in v):
        raise ValueError(f"names {key} again in a value; give the key once, then its values: {key}=V1,V2")
    mine = swept_leaves(key, values)
    for other, theirs in ((k, swept_leaves(k, v)) for k, v in swept.items()):  # a section beside a key in it
        if any(a == b or a.startswith(f"{b}.") or b.startswith(f"{a}.") for a in mine for b in theirs):
            raise ValueError(f"sets a key --sweep {other} sets too (one setting, two labels); sweep it once")
    return values


def dotted_key(key: str) -> str:
    """A dotted key as --set reads it (config.parse_override): spaces around its parts dropped
    ('graph .refine')."""
    return ".".join(part.strip() for part in key.split("."))


def swept_leaves(key: str, values: list[str]) -> set[str]:
    """The dotted keys ``--sweep key=V`` sets for its values (a swept mapping: the keys it names; a
    value that does not parse: the key itself, its own error comes when the sweep is planned)."""
    from .config import ConfigError, override_leaves, parse_override

    leaves = set()
    for v in values:
        try:
            leaves.update(leaf for leaf, _ in override_leaves(*parse_override(f"{key}={v}")))
        except ConfigError:  # its own error comes when the sweep is planned
            leaves.add(dotted_key(key))
    return leaves
