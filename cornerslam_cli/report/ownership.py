"""Which output places cornerslam may replace: the ownership marker of its output directories.

Every output directory cornerslam writes carries a marker file, ``.cornerslam-output``: JSON with
the version, the kind (``run``, ``compare``, ``batch``), the log it was made from (resolved path)
and, for runs and comparisons, the names of the entries written. An existing directory is replaced
only when it is empty, or when it is a cornerslam output of the same kind that holds nothing its
marker does not list (subdirectories with their own marker are checked against theirs); never when
it holds an input of the run or the working directory, and never at a mount point. Outputs of
versions before the marker count by their own files: a ``summary.json`` beginning with
``cornerslam_version`` (run), ``comparison.csv`` or ``batch.csv`` with our header. Anything else is
refused with an :class:`OutputError` (exit 2) before any work, as is an output inside another
(:func:`_refuse_nested`). Replacing one's own output needs no flag: rerunning into the same ``--out`` is
the usual case. Over 400 lines because the rules above, each with the checks of its place, are one
reading of what may be replaced. The default place
(``cornerslam_out/<stem>_<assoc>``) is named after the log's stem, which two logs can share
(``a/aces.log``, ``b/aces.log``): there, an output of another log is refused too, naming both
(:func:`check_same_log`), rather than silently replaced. Staging and committing an
output: report/outdir.py.
"""

from __future__ import annotations

import csv
import json
import logging
import os
import stat
from collections.abc import Iterator, Sequence
from pathlib import Path

from .. import __version__
from ..errors import OutputError
from ..logs.mcap import RESULTS_MCAP_LIBRARY, header_library
from .oserrors import output_errors, resolved

MARKER = ".cornerslam-output"
_MARKER_PARTIAL = MARKER + ".partial"  # the marker being written (renamed onto MARKER: never half written)
_GROUPS = {"compare": "comparison", "batch": "batch"}  # outputs made of runs
KINDS = ("run", "compare", "batch")
_LEGACY = (  # outputs written before the marker: (file, how it begins, kind)
    ("summary.json", b'{\n  "cornerslam_version"', "run"),
    ("comparison.csv", b"assoc,steps,landmarks,", "compare"),
    ("batch.csv", b"log,assoc,", "batch"),
)


def read_marker(path: Path) -> dict | None:
    """The marker of the directory ``path``, or None when it has none (or not ours)."""
    try:
        with open(path / MARKER, "rb") as f:
            marker = json.loads(f.read(1 << 20))
    except (OSError, ValueError):
        return None
    ok = isinstance(marker, dict) and "cornerslam" in marker and marker.get("kind") in KINDS
    return marker if ok else None


def output_kind(path: Path) -> str | None:
    """The kind of cornerslam output the directory ``path`` holds, or None (not ours)."""
    marker = read_marker(path)
    if marker is not None:
        return marker["kind"]
    for name, head, kind in _LEGACY:
        try:
            with open(path / name, "rb") as f:
                if f.read(len(head)) == head:
                    return kind
        except OSError:
            continue
    return None


def mark_output(path: Path, kind: str, log: Path | None = None) -> None:
    """Mark the directory ``path`` as a cornerslam output of ``kind`` made from ``log`` (recorded
    resolved); a run or comparison lists the entries it holds now (its complete contents) and, appended,
    the size of each of its regular files (``sizes``: batch's resume tells a file cut short since)."""
    marker: dict = {"cornerslam": __version__, "kind": kind}
    if log is not None:
        marker["log"] = os.fsdecode(log.resolve())
    if kind != "batch":  # a batch directory grows as it runs: its own rows are checked one by one
        entries = list(_entries(path))
        marker["files"] = [rel for rel, _ in entries]
        marker["sizes"] = {rel: e.stat().st_size for rel, e in entries if e.is_file() and not e.is_symlink()}
    partial = path / _MARKER_PARTIAL
    try:  # (a disk full mid-write left a 0-byte marker, "not written by cornerslam" to the next command)
        partial.write_text(json.dumps(marker, indent=1) + "\n")
        os.replace(partial, path / MARKER)
    finally:
        partial.unlink(missing_ok=True)


def files_intact(run_dir: Path) -> bool:
    """Whether the run directory's marker is there, every file it lists is still there and, where it
    recorded their sizes, of the same size: a file deleted or cut short since (a copy interrupted, a disk
    full; the marker itself, or a copy without it) is run again. An edit that keeps a file's size is not
    seen."""
    marker = read_marker(run_dir)
    if marker is None or marker.get("kind") != "run" or "files" not in marker:
        return False
    files, sizes = marker["files"], marker.get("sizes", {})
    if (
        not isinstance(files, list)
        or not all(isinstance(f, str) for f in files)
        or not isinstance(sizes, dict)
    ):
        return False  # (a marker edited by hand)
    if any(not os.path.lexists(run_dir / f) for f in files) or not set(sizes) <= set(files):
        return False
    return all(type(n) is int and n >= 0 and file_size(run_dir / f) == n for f, n in sizes.items())


def file_size(path: Path) -> int:
    """The size of the regular file ``path`` in bytes, −1 when it is not one (or cannot be read)."""
    try:
        st = os.stat(path, follow_symlinks=False)
    except (OSError, ValueError):
        return -1
    return st.st_size if stat.S_ISREG(st.st_mode) else -1


def _entries(path: Path, prefix: str = "") -> Iterator[tuple[str, Path]]:
    """(relative path, path) of every entry under ``path`` but the marker, sorted; a subdirectory
    is entered unless it is a symlink or carries its own marker (a compare's run directories)."""
    for entry in sorted(path.iterdir()):
        if entry.name == MARKER:
            continue
        rel = prefix + entry.name
        yield rel, entry
        if entry.is_dir() and not entry.is_symlink() and read_marker(entry) is None:
            yield from _entries(entry, rel + "/")


# what a run or compare directory held before the marker existed (version 0.1.0 and earlier)
_LEGACY_RUN_FILES = frozenset(
    "trajectory.tum trajectory.csv map.csv lines.csv timing.csv summary.json report.html "
    "map.png segments.png timing.png corners.png".split()
)
_LEGACY_COMPARE_FILES = frozenset(
    "comparison.csv report.html compare_matching.png compare_maps.png compare_timing.png".split()
)


def foreign_entries(path: Path) -> list[str]:
    """Entries of an output directory that cornerslam did not write, as relative paths: those its
    marker does not list (also inside its plain subdirectories, e.g. one made by ``--mcap-out
    OUT/sub/r.mcap``, and inside subdirectories that carry their own marker); for an output of a
    version before the marker, every entry but the files such a version wrote. The contents of a
    foreign directory are not listed."""
    marker = read_marker(path)
    if marker is None:
        return _foreign_legacy(path, output_kind(path))
    if "files" not in marker:
        return []
    listed = marker["files"]  # (a marker edited by hand into something else lists nothing)
    listed = {f for f in listed if isinstance(f, str)} if isinstance(listed, list) else set()
    out: list[str] = []
    for rel, entry in _entries(path):
        if any(rel.startswith(f + "/") for f in out):
            continue  # inside a foreign directory: that one is named
        if rel not in listed:
            out.append(rel)
        elif entry.is_dir() and not entry.is_symlink() and read_marker(entry) is not None:
            out += [f"{rel}/{sub}" for sub in foreign_entries(entry)]
    return out


def _foreign_legacy(path: Path, kind: str | None) -> list[str]:
    """Entries of an unmarked run or compare directory that such a version did not write (a
    compare's run directories are checked as runs); a batch directory is checked row by row."""
    if kind not in ("run", "compare"):
        return []
    own = _LEGACY_RUN_FILES if kind == "run" else _LEGACY_COMPARE_FILES
    out: list[str] = []
    for entry in sorted(path.iterdir()):
        if entry.name in own and entry.is_file() and not entry.is_symlink():
            continue
        run_dir = kind == "compare" and entry.is_dir() and not entry.is_symlink()
        if run_dir and output_kind(entry) == "run":
            out += [f"{entry.name}/{sub}" for sub in foreign_entries(entry)]
        else:
            out.append(entry.name)
    return out


def is_within(path: Path, directory: Path) -> bool:
    """``path``, resolved, is the (resolved) ``directory`` or inside it."""
    p = path.resolve()
    return p == directory or directory in p.parents


def _refuse_foreign(target: Path, kind: str, shown: Path) -> None:
    """Refuse an existing ``target`` that is a file, or a non-empty directory other than a
    cornerslam output of ``kind``."""
    if not os.path.lexists(target):
        return
    if not target.is_dir():
        raise OutputError(f"'{shown}' is a file, not a directory", "give a new directory")
    if _unused(target):
        return  # an empty directory may be used
    owner = output_kind(target)
    if owner is None:
        raise OutputError(
            f"'{shown}' is not empty and was not written by cornerslam",
            "cornerslam replaces only its own outputs: give a new or empty directory",
        )
    if owner != kind:
        raise OutputError(
            f"'{shown}' holds a cornerslam {owner} output, not a {kind} output",
            "give another directory, or remove it yourself",
        )


def _unused(target: Path) -> bool:
    """Whether the directory ``target`` holds nothing but, at most, a marker never written whole (a
    disk full as a command claimed it: a partial one, or an older version's 0-byte one): as empty.
    Such a file is a regular one holding nothing or the start of a marker; anything else is not ours."""
    entries = list(target.iterdir())
    if not {e.name for e in entries} <= {MARKER, _MARKER_PARTIAL} or read_marker(target) is not None:
        return False
    return all(_marker_cut_short(e) for e in entries)


_MARKER_START = b'{\n "cornerslam": '  # how mark_output's JSON begins


def _marker_cut_short(path: Path) -> bool:
    """Whether ``path`` is a regular file holding nothing or a cut-short start of a marker."""
    try:
        st = os.lstat(path)
        if not stat.S_ISREG(st.st_mode) or st.st_size > 1 << 16:
            return False
        with open(path, "rb") as f:
            head = f.read(len(_MARKER_START))
    except OSError:
        return False
    return _MARKER_START.startswith(head)


def _batch_runs(out: Path) -> set[str]:
    """The run directories a batch's ``batch.csv`` in ``out`` lists (its ``out_dir`` column)."""
    try:
        with open(out / "batch.csv", newline="", encoding="utf-8") as f:
            return {row.get("out_dir") or "" for row in csv.DictReader(f)} - {""}
    except (OSError, ValueError, csv.Error):
        return set()


def _refuse_nested(target: Path, shown: Path, inside: str | None = None) -> None:
    """Refuse (OutputError) an output ``target`` (resolved) inside another cornerslam output: a run's
    directory is replaced whole when the run is repeated (a directory inside it would stop that, as one
    cornerslam did not write), a comparison's and a batch's runs belong to it — except a run of the kind
    ``inside`` in its own place (a batch's run in the batch's directory)."""
    child = target
    for outer in target.parents:  # by their markers: a summary.json copied somewhere makes no output
        kind = (read_marker(outer) or {}).get("kind")
        if kind is None and outer == target.parent and output_kind(outer) in _GROUPS:
            kind = output_kind(outer)  # a comparison or batch of a version before the marker, as before
        ours = kind in ("run", "compare") or (kind == "batch" and child.name in _batch_runs(outer))
        if ours and not (kind == inside and child == target):
            whose = _GROUPS.get(kind, "run")
            why = (
                "a run's directory is replaced whole when it is run again"
                if kind == "run"
                else (f"its runs belong to that {whose}")
            )
            raise OutputError(
                f"'{shown}' is inside the {kind} output '{outer}': {why}",
                f"give a directory outside it; rerunning the {whose} replaces "
                + ("it" if kind == "run" else "them"),
            )
        child = outer


def check_replaceable(
    target: Path, kind: str, inputs: Sequence[Path] = (), shown: Path | None = None, inside: str | None = None
) -> None:
    """Refuse (OutputError) to replace ``target`` (resolved) by a ``kind`` output unless the module
    doc's rules allow it. ``inputs`` are the run's input files; ``shown`` names the target in errors;
    ``inside``: the kind of output whose part this one is (``batch``: a batch's run), else an output
    anywhere inside a run's or a comparison's directory, or in the place of a run its batch.csv lists in
    a batch's, is refused (:func:`_refuse_nested`; another directory beside a batch's runs is not one of
    them: ``cornerslam_out`` may hold a batch and the default places of runs)."""
    shown = target if shown is None else shown
    _refuse_nested(target, shown, inside)
    _refuse_foreign(target, kind, shown)
    if not target.is_dir():
        return
    if os.path.ismount(target):
        raise OutputError(
            f"'{shown}' is a mount point: an output directory is renamed into place, which a mount "
            "point cannot be",
            f"give a new directory inside it, e.g. {shown / 'run1'}",
        )
    try:
        held = [(Path.cwd(), "the working directory")]
    except OSError:
        held = []
    held += [(Path(p), f"the input '{p}'") for p in inputs]
    for path, what in held:
        if is_within(path, target):
            raise OutputError(f"'{shown}' holds {what}", "give another output directory")
    extra = foreign_entries(target)
    if extra:
        more = f" (and {len(extra) - 1} more)" if len(extra) > 1 else ""
        # (an output that lost its marker — copied without dotfiles — reads as one of a version before it)
        state = "damaged" if os.path.lexists(target / MARKER) else "missing"
        lost = (
            f" (its {MARKER} marker, which lists what it wrote, is {state})"
            if read_marker(target) is None
            else ""
        )
        raise OutputError(
            f"'{shown}' holds '{extra[0]}'{more}, which cornerslam did not write{lost}",
            "move it out first, or give another output directory",
        )


def recorded_log(path: Path) -> Path | None:
    """The log the output directory ``path`` was made from: its marker's, else (an output of a
    version before it was recorded) the one its run's summary.json names, resolved from the working
    directory; None when neither says."""
    marker = read_marker(path) or {}
    if isinstance(marker.get("log"), str):
        return Path(marker["log"])
    summaries = [path / "summary.json", *sorted(path.glob("*/summary.json"))]  # a run; a compare's runs
    for summary in summaries:
        log = _summary_field(summary, "input", "log")
        if log is not None:
            return Path(log).resolve() if isinstance(log, str) else None
    return None


def _summary_field(summary: Path, section: str, key: str):
    """``summary[section][key]`` of a summary.json (its first 16 MiB), None when it has none."""
    try:
        return json.loads(summary.read_bytes()[: 1 << 24])[section][key]
    except (OSError, ValueError, KeyError, TypeError):
        return None


def check_same_log(target: Path, log: Path, shown: Path, kind: str = "run", refuse: bool = True) -> bool:
    """Refuse (OutputError) to replace at ``target`` an output made from another log than ``log``:
    for the default place, named after the log's stem, which two logs may share; at a place the user
    gave (not ``refuse``), say it is replaced, before any work (a Ctrl-C keeps it). Whether it was said."""
    if not (e := other_log_error(target, log, shown)):
        return False
    if refuse:
        raise e
    logging.getLogger("cornerslam.output").warning(
        "'%s' holds the output of '%s': it is replaced by this %s's of '%s' (give another --out to keep it)",
        shown, recorded_log(target), kind, log,
    )  # fmt: skip
    return True


def other_log_error(
    target: Path, log: Path, shown: Path | str, log_hash: str | None = None, command: str = "run"
) -> OutputError | None:
    """The error :func:`check_same_log` raises, None when ``target`` holds no output of another log.
    ``command`` "batch": a batch's combination, named after the log's file name, which two files
    elsewhere may share; with ``log_hash`` (report/summary.py input_hash) an output of the same bytes at
    another path (the logs moved) is the same log's."""
    other = recorded_log(target) if target.is_dir() else None
    same = other is not None and str(other) == os.path.realpath(log)  # (realpath: no error on a loop)
    if other is None or same or (log_hash and _input_hash(target) == log_hash):
        return None
    where = "batched into one OUT" if command == "batch" else "the default output directory of both logs"
    return OutputError(
        f"'{shown}' holds the output of '{other}', not of '{log}': {where}",
        f"give this {command} its own --out, or remove the other output first",
    )


def _input_hash(run_dir: Path) -> str | None:
    """The log hash a run output's summary.json records, None when it has none."""
    return _summary_field(run_dir / "summary.json", "hashes", "input")


def refuse_special_file(path: Path, shown: str | Path) -> None:
    """Refuse (OutputError) to write the file ``path`` over a device, a pipe or a socket: writing one
    hangs or goes nowhere, and renaming a file onto it would replace the node (``/dev/null``)."""
    if os.path.exists(path) and not (path.is_file() or path.is_dir()):
        raise OutputError(
            f"'{shown}' is not a regular file (a device, pipe or socket)",
            "give the name of a file to write",
        )


def check_claimable(path: str | Path, kind: str) -> Path:
    """Refuse (OutputError) a ``path`` that :func:`claim_dir` would refuse, creating nothing;
    returns it resolved."""
    shown = Path(path)
    with output_errors(shown):
        target = resolved(shown)
        _refuse_nested(target, shown)
        _refuse_foreign(target, kind, shown)
    return target


def claim_dir(path: str | Path, kind: str) -> Path:
    """Create or reuse the directory ``path`` for a ``kind`` output written in place (a batch: it
    is resumed, never replaced): refuse a file or a non-empty directory that is not ours, mark it."""
    target = check_claimable(path, kind)
    with output_errors(path):
        target.mkdir(parents=True, exist_ok=True)
        if read_marker(target) is None:
            mark_output(target, kind)
    return target


FIGURE_CREATOR = "cornerslam extract"  # extract --plot's figures name it in their metadata


def figure_mark(fmt: str) -> dict:
    """``savefig``'s arguments that name ``FIGURE_CREATOR`` in a figure of format ``fmt`` where its file
    holds the text as is (png, pdf, svg, ps, eps, jpg, tif; none for the others: avif, gif, webp, …)."""
    if fmt in ("png",):
        return {"metadata": {"Software": FIGURE_CREATOR}}
    if fmt in ("pdf", "svg", "ps", "eps"):
        return {"metadata": {"Creator": FIGURE_CREATOR}}
    if fmt in ("jpg", "jpeg"):
        return {"pil_kwargs": {"comment": FIGURE_CREATOR.encode()}}
    if fmt in ("tif", "tiff"):
        return {"pil_kwargs": {"description": FIGURE_CREATOR}}
    return {}


def is_extract_figure(path: Path, suffix: str | None = None) -> bool:
    """Whether ``path`` is a figure ``extract --plot`` wrote (its metadata names ``FIGURE_CREATOR``):
    what a later ``extract --plot`` may replace. ``suffix``: of the name it was written by, which chose
    its format (a symlink's, when ``path`` is its target); by default its own. A format without that
    metadata (gif, webp, …) never is."""
    if not figure_mark((path.suffix if suffix is None else suffix)[1:].lower()):
        return False
    try:
        with open(path, "rb") as f:  # a figure of one scan: a few hundred KiB (read at most 16 MiB)
            return FIGURE_CREATOR.encode() in f.read(16 << 20)
    except OSError:
        return False


def is_results_mcap(path: Path) -> bool:
    """Whether ``path`` is a results MCAP cornerslam wrote (its Header names ``RESULTS_MCAP_LIBRARY``):
    what ``--mcap-out`` may replace."""
    return header_library(path) == RESULTS_MCAP_LIBRARY
