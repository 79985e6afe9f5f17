"""Log readers: ``open_log(path)`` picks a reader from :data:`READERS` by what the path is.

>>> with open_log("sample_logs/exp1.mcap") as log:          # doctest: +SKIP
...     print(log.info().scan_topic, log.laser_to_base())
...     for msg in log.messages():                           # Scan | OdomSample, log-time order
...         ...

Formats: ``mcap`` (ROS 2 CDR or ROS 1 messages), ``rosbag1`` (.bag), ``rosbag2`` (directory with
metadata.yaml, sqlite3 or mcap storage), ``carmen`` (.clf/.log, optionally gzip). Only
:func:`open_log` touches filenames; readers raise :class:`~cornerslam_cli.errors.LogError` for
every problem with the input.
"""

from __future__ import annotations

import codecs
import dataclasses
import gzip
import shlex
import stat
import zlib
from collections.abc import Callable
from pathlib import Path

from ..errors import ConfigError, LogError, display_path, symlink_loop
from ..ranges import short_text
from .base import LogInfo, LogReader, ReadStats, TopicInfo
from .carmen import GZIP_MAGIC, CarmenReader
from .mcap import MAGIC as MCAP_MAGIC
from .mcap import open_mcap
from .params import InputConfig
from .rosbag import STORAGE_SUFFIXES, message_compression_of, open_rosbag1, open_rosbag2, split_bag_of

__all__ = [
    "READERS",
    "LogInfo",
    "LogReader",
    "ReadStats",
    "TopicInfo",
    "check_regular",
    "detect_format",
    "open_configured",
    "open_log",
]

READERS: dict[str, Callable[..., LogReader]] = {
    "mcap": open_mcap,
    "rosbag1": open_rosbag1,
    "rosbag2": open_rosbag2,
    "carmen": CarmenReader,
}
EXTENSIONS = {
    ".mcap": "mcap",
    ".bag": "rosbag1",
    ".db3": "rosbag2",  # a ROS 2 bag's sqlite3 storage file alone
    ".clf": "carmen",
    ".log": "carmen",
    ".gz": "carmen",
}
ROSBAG1_MAGIC = b"#ROSBAG V2.0"
SQLITE_MAGIC = b"SQLite format 3\x00"
SUPPORTED = "a .mcap file, a ROS 1 .bag, a ROS 2 bag directory or a CARMEN log (.clf/.log/.gz)"


def detect_format(path: str | Path) -> str:
    """Key of :data:`READERS` for ``path`` (content sniffed first, then extension); LogError if none."""
    p = Path(path)
    try:
        exists = p.exists()
    except OSError as exc:  # EACCES (a directory on the way we may not search), ENAMETOOLONG, ...
        raise LogError(
            f"cannot read log '{p}': {exc.strerror or exc}",
            "check the path and the permissions of the directories on it",
        ) from exc
    if not exists:
        if symlink_loop(p):  # exists() is False on ELOOP too (a loop on the path, or the log itself)
            raise LogError(f"cannot read log '{p}': a symlink loop", "check the path")
        if str(path) == "-":  # the usual name of standard input: it is a pipe here too
            raise LogError("log '-' (standard input) cannot be read", _STREAM_HINT)
        raise LogError(f"log '{p}' does not exist", "check the path")
    check_regular(p)
    if p.is_dir():
        if (p / "metadata.yaml").is_file() or any(f.suffix in STORAGE_SUFFIXES for f in p.iterdir()):
            return "rosbag2"  # (without metadata.yaml: read from its one storage file, logs/rosbag.py)
        raise LogError(
            f"directory '{p}' is not a ROS 2 bag (no metadata.yaml, no .mcap or .db3 file)",
            f"give {SUPPORTED}",
        )
    if p.name == "metadata.yaml" and p.is_file():  # (its directory holds it: a bag's own)
        raise LogError(f"'{p}' is the metadata of a ROS 2 bag", f"give the bag's directory, '{p.parent}'")
    try:
        with open(p, "rb") as f:
            head = f.read(64)
    except OSError as exc:
        raise LogError(f"cannot read log '{p}': {exc.strerror or exc}", "check the file permissions") from exc
    if not head:
        raise LogError(f"log '{p}' is empty", "the recording holds no data; check the file")
    if head.startswith(MCAP_MAGIC):
        return "mcap"
    if head.startswith(ROSBAG1_MAGIC):
        return "rosbag1"
    _refuse_compressed(p, head)
    if head.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):  # a CARMEN log saved by a Windows editor
        shown = Path(display_path(p))
        utf8 = shlex.quote(str(shown.with_name(f"{shown.stem}-utf8{shown.suffix}")))
        raise LogError(
            f"log '{p.name}' is UTF-16 text",
            f"convert it to plain text first: iconv -f UTF-16 -t UTF-8 {shlex.quote(str(shown))} > {utf8}",
        )
    suffix = p.suffix.lower()
    if head.startswith(SQLITE_MAGIC) and suffix == ".db3":  # (another SQLite file: unsupported, below)
        return "rosbag2"
    fmt = EXTENSIONS.get(suffix)
    if fmt in ("mcap", "rosbag1", "rosbag2"):
        raise LogError(f"'{p.name}' is not a valid {suffix} file (bad magic bytes)", "check the file")
    if fmt is None:
        # no known extension: a CARMEN text log is recognized by its first tag
        text = head.removeprefix(codecs.BOM_UTF8)  # (the CARMEN reader drops a byte-order mark too)
        tag = text.split(None, 1)[0] if text.split() else b""
        if tag in (b"FLASER", b"RLASER", b"ROBOTLASER1", b"ODOM", b"PARAM", b"#") or text[:1] == b"#":
            return "carmen"
        raise LogError(f"unsupported log '{p.name}'", f"give {SUPPORTED}")
    return fmt


# magic -> (name, decompressor, the suffixes that name the compression: the first, as written, is the one
# every version of the tool names its output from; the others it may not know (an older zstd .zstd), nor
# the first in capitals (unzstd, unxz, bunzip2: X.ZST has "an unknown suffix")
_COMPRESSED = {
    b"BZh": ("bzip2", "bunzip2", (".bz2", ".bz")),
    b"\xfd7zXZ\x00": ("xz", "unxz", (".xz",)),
    b"\x28\xb5\x2f\xfd": ("zstd", "unzstd", (".zst", ".zstd")),
}


def _decompress_command(p: Path, tool: str, suffixes: tuple[str, ...]) -> str:
    """How to decompress ``p``: ``tool -k FILE`` when its name ends in ``suffixes[0]``; otherwise the
    tool may not name its output (gunzip -k x.mcap: "unknown suffix -- ignored"), so to stdout, to a file
    named without the compression's suffix (log.mcap.zstd: log.mcap), else with ``-decompressed``."""
    shown = display_path(p)
    if p.suffix == suffixes[0]:
        return f"{tool} -k {shlex.quote(shown)}"
    name = p.stem if p.suffix.lower() in suffixes else f"{p.stem}-decompressed{p.suffix}"
    return f"{tool} -c {shlex.quote(shown)} > {shlex.quote(str(Path(shown).with_name(name)))}"


def _refuse_compressed(p: Path, head: bytes) -> None:
    """LogError for a compressed log that cornerslam cannot read as it is: an MCAP or ROS 1 bag in
    gzip (``.gz`` is otherwise a gzipped CARMEN log, and the error said "not a CARMEN log"), and any
    log in bzip2, xz or zstd (only CARMEN logs are read gzipped)."""
    if head.startswith(GZIP_MAGIC):
        try:
            with gzip.open(p, "rb") as f:
                inner = f.read(len(ROSBAG1_MAGIC))
        except (OSError, EOFError, zlib.error):  # a damaged gzip: the CARMEN reader says so
            return
        for magic, what in ((MCAP_MAGIC, "MCAP"), (ROSBAG1_MAGIC, "ROS 1 bag")):
            if inner.startswith(magic):
                raise LogError(
                    f"'{p.name}' is a gzip-compressed {what}",
                    f"decompress it first: {_decompress_command(p, 'gunzip', ('.gz',))}",
                )
    for magic, (name, tool, suffixes) in _COMPRESSED.items():
        if head.startswith(magic):
            raise LogError(
                f"'{p.name}' is compressed with {name}",
                f"decompress it first: {_decompress_command(p, tool, suffixes)} "
                "(a CARMEN log may be given gzip-compressed)",
            )


_STREAM_HINT = "cornerslam reads a log several times: save it to a file first, e.g. `cat … > log.mcap`"
_NOT_FILES = {  # file type -> (what it is, what to do)
    stat.S_IFIFO: ("a pipe", _STREAM_HINT),
    stat.S_IFSOCK: ("a socket", _STREAM_HINT),
    stat.S_IFCHR: ("a character device", f"give {SUPPORTED}"),
    stat.S_IFBLK: ("a block device", f"give {SUPPORTED}"),
}


def check_regular(path: str | Path) -> None:
    """LogError for a log that is neither a file nor a directory. A pipe (``<(zcat x.mcap)``, a FIFO)
    can be read only once, but a log is read several times (laser preset, index, laser mount,
    messages, hash), and opening a FIFO that nobody writes to would hang."""
    p = Path(path)
    kind = _NOT_FILES.get(stat.S_IFMT(p.stat().st_mode))
    if kind is not None:
        raise LogError(f"log '{p}' is {kind[0]}, not a file", kind[1])


def open_log(
    path: str | Path,
    scan_topic: str = "",
    odom_topic: str = "",
    odom_frame: str = "odom",
    base_frame: str = "base_link",
    scan_frame: str = "",
    stamps: str = "header",
    scans_alone: bool = False,
) -> LogReader:
    """Open a log for reading; the format is chosen by :func:`detect_format`.

    ``stamps``: ``input.stamps`` — "header" (each message's header stamp) or "receive" (when the recorder
    got it: a ROS log's log time, a CARMEN line's logger timestamp). ``scans_alone``: a run reads its
    scans only (``input.odometry: scans``): a log without odometry passes ``check()``.
    Topic errors (no / several LaserScan, no odometry, missing requested topic) are raised by
    ``messages()``, ``laser_to_base()`` and ``check()``, not here, so ``info()`` can report them.
    """
    p = Path(path)
    fmt = detect_format(p)
    if fmt != "carmen" and (packed := message_compression_of(p)) is not None:
        raise LogError(
            f"'{display_path(p)}' is a storage file of the ROS 2 bag '{p.parent.name or '.'}', whose "
            f"messages are compressed one by one ({packed}): read alone, they cannot be decoded",
            f"give the bag's directory: {display_path(p.parent)}",
        )
    reader = READERS[fmt](
        p,
        scan_topic=scan_topic,
        odom_topic=odom_topic,
        odom_frame=odom_frame,
        base_frame=base_frame,
        scan_frame=scan_frame,
        stamps=stamps,
        scans_alone=scans_alone,
    )
    if fmt != "carmen" and (bag := split_bag_of(p)) is not None:
        reader.stats.warn(
            "%s is one of the %d storage files of the ROS 2 bag '%s': only its messages are read (give the "
            "bag's directory to read them all)", p.name, bag, p.parent.name or ".",
        )  # fmt: skip
    return reader


def open_configured(path: str | Path, inp: InputConfig) -> LogReader:
    """:func:`open_log` on the topics, frames and stamps of the config's ``input`` section, as a run
    reads the log (``run``, ``extract``, ``info`` and the laser preset's look at the first scan alike)."""
    return open_log(
        path,
        scan_topic=inp.scan_topic,
        odom_topic=inp.odom_topic,
        odom_frame=inp.odom_frame,
        base_frame=inp.base_frame,
        scan_frame=inp.scan_frame,
        stamps=inp.stamps,
        scans_alone=inp.odometry == "scans",
    )


SCANS_SOURCE = "the scans (input.odometry=scans)"  # summary.json's input.odom_source on the scans alone


def read_alone(inp: InputConfig) -> bool:
    """Whether a run reads the scans alone (``input.odometry: scans``, motion/scan_odometry.py); a
    ConfigError when an odometry topic is chosen beside it (the two contradict each other)."""
    if inp.odometry != "scans":
        return False
    if inp.odom_topic:
        raise ConfigError(
            f"input.odom_topic '{short_text(inp.odom_topic)}' is given, but input.odometry=scans reads no "
            "odometry",
            "give one of input.odom_topic (--odom-topic) and input.odometry=scans, not both",
        )
    return True


def alone_info(reader: LogReader, info: LogInfo) -> LogInfo:
    """``info`` as a run on the scans alone reads the log: its odometry is the scans' (SCANS_SOURCE), and
    only what stops it reading the scans is a problem (``cornerslam info``)."""
    try:
        reader.check(odometry=False)
        problems: tuple[str, ...] = ()
    except LogError as e:
        problems = (f"{e.msg} ({e.hint})" if e.hint else e.msg,)
    return dataclasses.replace(info, odom_topic="", odom_source=SCANS_SOURCE, problems=problems)
