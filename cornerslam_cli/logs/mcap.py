"""MCAP files (ROS 2 CDR, ROS 1 or JSON messages): a streaming, damage-tolerant record reader.

Messages come out in log-time order, chunks decompressed one at a time, so memory stays flat in log
length. With a summary, chunks are read in the order of their start times from the chunk index (as
the mcap package's reader does), so a file whose chunks are not in time order is read in order too;
without one, in file order. Either way a heap merges the messages of chunks that overlap in time,
releasing those older than the next chunk's first message (the start time in the chunk's header is
not trusted: some writers leave it 0). Besides the chunk being read it holds at most
:data:`REORDER_BYTES` of messages; beyond that the oldest are released early, with a warning.

A file whose recorder died (no summary, cut mid-record) yields every message before the cut,
including the readable prefix of the cut chunk (zstd/lz4/uncompressed streams are decompressed
incrementally), and warns. A chunk that fails its CRC or does not decompress is skipped with a
warning; a record whose length runs past the end of the file ends the read with a warning.

Summary (statistics, channels, chunk indexes) is used when present for ``info()``; without it (or
without the channel records it counts) the data section is scanned once (no message decoding).
Record layouts: https://mcap.dev/spec.

Over 400 lines because it is one streaming reader (:class:`McapSource`) whose record parsing, chunk
index, reorder heap and damage handling share the position in the file.
"""

from __future__ import annotations

import heapq
import io
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path

from ..errors import LogError
from ..ranges import short_text
from .base import Channel, ReadStats
from .ros import RosLogReader, merged

MAGIC = b"\x89MCAP0\r\n"
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06
OP_MESSAGE_INDEX, OP_CHUNK_INDEX, OP_STATISTICS, OP_DATA_END = 0x07, 0x08, 0x0B, 0x0F
FOOTER_LEN = 1 + 8 + 20  # opcode, length, summary_start, summary_offset_start, summary_crc

_REC = struct.Struct("<BQ")
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_MSG = struct.Struct("<HIQQ")
_CHUNK = struct.Struct("<QQQI")
_STATS = struct.Struct("<QHIIIIQQ")
REORDER_BYTES = 64 << 20  # messages held back to restore log-time order across overlapping chunks


# the Header record's library of every results MCAP cornerslam writes (report/mcap_out.py; a log
# `simulate` writes says "cornerslam": before 2026-12-02 results did too, and are not recognised now)
RESULTS_MCAP_LIBRARY = "cornerslam results"


def header_library(path: str | Path) -> str | None:
    """The library an MCAP file's Header record names (what wrote it), or None for a file that is not an
    MCAP or cannot be read (:func:`header_fields`)."""
    fields = header_fields(path)
    return None if fields is None else fields[1]


def header_fields(path: str | Path) -> tuple[str, str] | None:
    """An MCAP file's Header record: (profile, library), or None for a file that is not an MCAP or cannot
    be read. Reads the magic and the Header record only: its opcode and u64 length, then the profile and
    the library as u32-length-prefixed strings."""
    try:
        with open(path, "rb") as f:
            head = f.read(len(MAGIC) + _REC.size + _U32.size + 4096)
    except OSError:
        return None
    pos = len(MAGIC) + _REC.size
    if not head.startswith(MAGIC) or len(head) < pos + _U32.size or head[len(MAGIC)] != OP_HEADER:
        return None
    size = _U32.unpack_from(head, pos)[0]
    profile = head[pos + _U32.size : pos + _U32.size + size].decode("utf-8", "replace")
    pos += _U32.size + size  # past the profile
    if len(head) < pos + _U32.size:
        return None
    size = _U32.unpack_from(head, pos)[0]
    return profile, head[pos + _U32.size : pos + _U32.size + size].decode("utf-8", "replace")


Message = tuple[int, int, memoryview]  # channel id, log time (ns), data


class McapFormatError(ValueError):
    """Bytes that are not a valid MCAP record."""


def _str(buf: memoryview, off: int) -> tuple[str, int]:
    (n,) = _U32.unpack_from(buf, off)
    off += 4
    if off + n > len(buf):
        raise McapFormatError("string overruns its record")
    return bytes(buf[off : off + n]).decode("utf-8", "replace"), off + n


def _schema(body: memoryview) -> tuple[int, str, str, str]:
    """(id, name, encoding, data) of a Schema record."""
    (sid,) = _U16.unpack_from(body, 0)
    name, off = _str(body, 2)
    enc, off = _str(body, off)
    data, _ = _str(body, off)
    return sid, name, enc, data


def _channel(body: memoryview) -> tuple[int, int, str, str]:
    """(id, schema_id, topic, message_encoding) of a Channel record."""
    cid, sid = struct.unpack_from("<HH", body, 0)
    topic, off = _str(body, 4)
    enc, _ = _str(body, off)
    return cid, sid, topic, enc


def _u16_u64_map(body: memoryview, off: int) -> tuple[dict[int, int], int]:
    (n,) = _U32.unpack_from(body, off)
    off += 4
    out = {}
    for pos in range(off, off + n, 10):
        k, v = struct.unpack_from("<HQ", body, pos)
        out[k] = v
    return out, off + n


@dataclass
class _Index:
    """What is known of a file's channels and counts (from the summary or a scan)."""

    schemas: dict[int, tuple[str, str, str]] = field(default_factory=dict)  # id -> name, encoding, data
    channels: dict[int, tuple[str, str, int]] = field(default_factory=dict)  # id -> topic, encoding, sid
    counts: dict[int, int] | None = None
    start: int | None = None
    end: int | None = None
    n_messages: int = 0
    # from the summary's chunk indexes: (message_start_time, offset, length, channel ids or empty)
    chunks: list[tuple[int, int, int, frozenset[int]]] = field(default_factory=list)
    # ... and (message_start_time, message_end_time, {channel id: its message index record's offset})
    message_indexes: list[tuple[int, int, dict[int, int]]] = field(default_factory=list)
    spans: dict[int, tuple[int, int]] = field(default_factory=dict)  # a scan's: channel id -> first, last


class McapSource:
    """A :class:`~cornerslam_cli.logs.ros.RawSource` over one MCAP file (only ``open()`` gets a name)."""

    format = "mcap"

    def __init__(self, path: Path, stats: ReadStats):
        self.path = Path(path)
        self.stats = stats
        self.name = self.path.name
        self.size = self.path.stat().st_size
        self._f = open(self.path, "rb")  # noqa: SIM115 - closed by close()
        head = self._f.read(8)
        if head != MAGIC:
            self._f.close()
            raise LogError(
                f"'{self.name}' is not an MCAP file (bad magic bytes)",
                "check the file; MCAP files start with \\x89MCAP0",
            )
        # written by `cornerslam run --mcap-out`: what to say when it is given as a log (logs/ros.py)
        self.results_of_run = header_library(self.path) == RESULTS_MCAP_LIBRARY
        self.summary_ok = False
        self.index = self._read_summary()
        if self.index is None:
            self._f.seek(-8, io.SEEK_END)
            if self._f.read(8) != MAGIC:
                self.stats.warn(
                    "%s has no end magic/footer (recording interrupted?): reading what is there", self.name
                )
            self.index = self._scan()

    # ---------------------------------------------------------------- low level
    def _records(self, start: int, end: int, warn: bool) -> Iterator[tuple[int, memoryview, int, bool]]:
        """(opcode, body, offset, complete) of the top-level records in [start, end)."""
        f = self._f
        f.seek(start)
        pos = start
        while pos < end:
            hdr = f.read(9)
            if len(hdr) < 9:
                if warn:
                    self._warn_cut(pos, "in a record header")
                return
            op, length = _REC.unpack(hdr)
            if op == 0:
                if warn:
                    self.stats.skip_damaged(
                        "%s: invalid record (opcode 0) at byte %d: stopped reading", self.name, pos
                    )
                return
            if length > end - pos - 9:
                if warn:
                    self._warn_cut(pos, f"in a record of {length} bytes (opcode 0x{op:02x})")
                if op == OP_CHUNK:
                    yield op, memoryview(f.read(max(0, min(end - pos - 9, 1 << 31)))), pos, False
                return
            body = memoryview(f.read(length))
            yield op, body, pos, True
            pos += 9 + length
            if op in (OP_FOOTER, OP_DATA_END):
                return
        if warn and end == self.size:
            self._warn_cut(pos, "before the footer")

    def _warn_cut(self, pos: int, what: str) -> None:
        self.stats.truncated = True
        self.stats.warn(
            "%s ends early at byte %d of %d (%s; recorder stopped?): messages after the cut are lost",
            self.name,
            pos,
            self.size,
            what,
        )

    def _chunk_records(self, body: memoryview, pos: int, complete: bool) -> memoryview | None:
        """Decompressed records of a Chunk record (a prefix if the chunk is cut), None if unusable."""
        try:
            t0, t1, usize, crc = _CHUNK.unpack_from(body, 0)
            comp, off = _str(body, _CHUNK.size)
            (rlen,) = _U64.unpack_from(body, off)
            off += 8
        except (struct.error, McapFormatError):
            self.stats.skip_damaged(
                "%s: chunk at byte %d is cut in its header: its messages are lost", self.name, pos
            )
            return None
        data = body[off : off + rlen]
        what = f"chunk at byte {pos} (log time {t0 * 1e-9:.3f}–{t1 * 1e-9:.3f} s)"
        try:
            if comp == "":
                out = data
            elif comp == "zstd":
                import zstandard

                if complete:
                    out = memoryview(zstandard.ZstdDecompressor().decompress(data, max_output_size=usize))
                else:
                    out = memoryview(zstandard.ZstdDecompressor().decompressobj().decompress(bytes(data)))
            elif comp == "lz4":
                import lz4.frame

                if complete:
                    out = memoryview(lz4.frame.decompress(data))
                else:
                    out = memoryview(lz4.frame.LZ4FrameDecompressor().decompress(bytes(data)))
            else:
                self.stats.skip_damaged(
                    "%s: %s uses unknown compression %r: skipped", self.name, what, comp, unsupported=True
                )
                return None
        except Exception as exc:  # noqa: BLE001 - corrupt compressed data
            self.stats.skip_damaged("%s: %s does not decompress (%s): skipped", self.name, what, exc)
            return None
        if complete and crc and zlib.crc32(out) != crc:
            self.stats.skip_damaged("%s: %s fails its CRC (corrupt bytes): skipped", self.name, what)
            return None
        if not complete:
            self.stats.warn("%s: %s is cut: keeping its first %d bytes of records", self.name, what, len(out))
        return out

    def _file_order(self, warn: bool) -> Iterator[list[Message]]:
        """The messages of each chunk (or lone message record) in file order; registers the schemas
        and channels met on the way."""
        for op, body, pos, complete in self._records(8, self._data_end(), warn):
            try:
                if op == OP_CHUNK:
                    recs = self._chunk_records(body, pos, complete)
                    if recs is not None:
                        yield self._inner(recs, pos, warn and complete)
                elif op == OP_MESSAGE:
                    cid, _, t, _ = _MSG.unpack_from(body, 0)
                    yield [(cid, t, body[_MSG.size :])]
                else:
                    self._note_definition(op, body)
            except (struct.error, McapFormatError) as exc:
                if warn:
                    self.stats.skip_damaged("%s: bad record at byte %d (%s): skipped", self.name, pos, exc)

    def _index_order(self, wanted: set[int]) -> Iterator[list[Message]]:
        """The messages of each chunk holding a ``wanted`` channel, chunks in the order of their start
        times in the chunk index (a file's chunks need not be in time order)."""
        f = self._f
        for _, pos, length, chans in sorted(self.index.chunks):
            if chans and not chans & wanted:
                continue
            f.seek(pos)
            hdr = f.read(9)
            op, n = _REC.unpack(hdr) if len(hdr) == 9 else (0, 0)
            body = memoryview(f.read(n)) if op == OP_CHUNK and 9 + n == length else memoryview(b"")
            if len(body) != length - 9:
                self.stats.skip_damaged(
                    "%s: the chunk index points at byte %d, where no chunk is: skipped", self.name, pos
                )
                continue
            recs = self._chunk_records(body, pos, True)
            if recs is not None:
                yield self._inner(recs, pos, True)

    def _inner(self, recs: memoryview, pos: int, warn: bool) -> list[Message]:
        """The messages in a chunk's records; registers its schemas and channels."""
        out = []
        off, n = 0, len(recs)
        try:
            while off + 9 <= n:
                op, length = _REC.unpack_from(recs, off)
                body_off = off + 9
                if body_off + length > n:
                    raise McapFormatError("a record overruns the chunk")
                body = recs[body_off : body_off + length]
                off = body_off + length
                if op == OP_MESSAGE:
                    if length < _MSG.size:
                        continue
                    cid, _, t, _ = _MSG.unpack_from(body, 0)
                    out.append((cid, t, body[_MSG.size :]))
                else:
                    self._note_definition(op, body)
        except (struct.error, McapFormatError) as exc:
            if warn:
                self.stats.skip_damaged(
                    "%s: chunk at byte %d has a bad record (%s): rest skipped", self.name, pos, exc
                )
        return out

    def _note_definition(self, op: int, body: memoryview) -> None:
        """Remember a schema or channel record met while streaming (the first definition wins)."""
        if op == OP_SCHEMA:
            sid, name, enc, data = _schema(body)
            self.index.schemas.setdefault(sid, (name, enc, data))
        elif op == OP_CHANNEL:
            cid, sid, topic, enc = _channel(body)
            self.index.channels.setdefault(cid, (topic, enc, sid))

    def _data_end(self) -> int:
        return self._summary_start if self.summary_ok else self.size

    # ---------------------------------------------------------------- summary / scan
    def _read_summary(self) -> _Index | None:
        if self.size < 8 + FOOTER_LEN + 8:
            return None
        f = self._f
        f.seek(self.size - FOOTER_LEN - 8)
        tail = f.read(FOOTER_LEN + 8)
        if tail[-8:] != MAGIC or tail[0] != OP_FOOTER:
            return None
        summary_start = _U64.unpack_from(tail, 9)[0]
        footer_pos = self.size - FOOTER_LEN - 8
        if not 8 <= summary_start <= footer_pos:
            return None
        idx = _Index()
        stats_seen = False
        n_chunks = n_schemas = n_channels = 0
        try:
            for op, body, _, _ in self._records(summary_start, footer_pos, warn=False):
                if op == OP_SCHEMA:
                    sid, name, enc, data = _schema(body)
                    idx.schemas[sid] = (name, enc, data)
                elif op == OP_CHANNEL:
                    cid, sid, topic, enc = _channel(body)
                    idx.channels[cid] = (topic, enc, sid)
                elif op == OP_STATISTICS:
                    n, n_schemas, n_channels, _, _, n_chunks, t0, t1 = _STATS.unpack_from(body, 0)
                    counts, _ = _u16_u64_map(body, _STATS.size)
                    idx.counts, idx.n_messages, stats_seen = counts, n, True
                    if n:
                        idx.start, idx.end = t0, t1
                elif op == OP_CHUNK_INDEX:
                    t0, t1, pos, length = struct.unpack_from("<QQQQ", body, 0)
                    offsets, _ = _u16_u64_map(body, 32)
                    idx.chunks.append((t0, pos, length, frozenset(offsets)))
                    idx.message_indexes.append((t0, t1, offsets))
        except (struct.error, McapFormatError):
            return None
        if not stats_seen:
            return None  # counts unknown: scan instead
        if len(idx.channels) < n_channels or len(idx.schemas) < n_schemas:
            return None  # channels not repeated in the summary (a writer's option): found by the scan
        if len(idx.chunks) != n_chunks or any(not 8 <= c[1] < summary_start for c in idx.chunks):
            idx.chunks, idx.message_indexes = [], []  # an index that does not cover the chunks: file order
        self._summary_start = summary_start
        # the data section ends at the DataEnd record, which precedes the summary
        self.summary_ok = True
        return idx

    def _scan(self) -> _Index:
        """Index of a file without a usable summary: one pass over the data section, no decoding."""
        self.index = idx = _Index(counts={})
        for batch in self._file_order(warn=True):
            for cid, t, _ in batch:
                idx.counts[cid] = idx.counts.get(cid, 0) + 1
                idx.n_messages += 1
                idx.start = t if idx.start is None else min(idx.start, t)
                idx.end = t if idx.end is None else max(idx.end, t)
                idx.spans[cid] = merged(idx.spans.get(cid), (t, t))
        return idx

    # ---------------------------------------------------------------- RawSource
    def channels(self) -> list[Channel]:
        """One per topic: the channels of a topic (a converted ROS 1 bag's connections, a channel
        registered again) are counted together, with the type and encoding of the first."""
        out: dict[str, Channel] = {}
        idx = self.index
        for cid, (topic, enc, sid) in sorted(idx.channels.items()):
            name, fmt, data = idx.schemas.get(sid, ("", "", ""))
            count = idx.counts.get(cid, 0) if idx.counts is not None else None
            prev = out.get(topic)
            if prev is not None:
                out[topic] = replace(prev, count=None if count is None else prev.count + count)
            else:
                out[topic] = Channel(topic, name, enc, count, data, fmt)
        return list(out.values())

    def time_range(self) -> tuple[int, int] | None:
        if self.index.start is None or self.index.end is None:
            return None
        return self.index.start, self.index.end

    def topic_spans(self) -> dict[str, tuple[int, int]]:
        """Each topic's first and last log time [ns], where the file tells them cheaply: from the scan of
        a file without a summary, else from the message indexes of the chunks that can hold its first
        and last message — every chunk's when the chunk index's times are not to be trusted (some writers
        leave them 0) — a topic whose chunks have none left out. (``cornerslam info``'s rates; it seeks the
        file, so not while a :meth:`raw_messages` read is under way.)"""
        spans = dict(self.index.spans)
        trusted = all(0 < t0 <= t1 for t0, t1, _ in self.index.message_indexes)
        for cid in self.index.channels if not spans else ():
            held = [
                (t0, t1, offsets[cid]) for t0, t1, offsets in self.index.message_indexes if cid in offsets
            ]
            span = None
            for t0, _, at in sorted(held):  # the chunks that may hold an earlier message than found
                if trusted and span is not None and t0 >= span[0]:
                    break
                if times := self._index_times(at, cid):
                    span = merged(span, (min(times), max(times)))
            for _, t1, at in sorted(held, key=lambda h: -h[1]) if trusted else ():  # ... a later one
                if span is not None and t1 <= span[1]:
                    break
                if times := self._index_times(at, cid):
                    span = merged(span, (min(times), max(times)))
            if span is not None:
                spans[cid] = span
        out: dict[str, tuple[int, int]] = {}
        for cid, span in spans.items():  # (a topic's channels together)
            topic = self.index.channels.get(cid, ("",))[0]
            out[topic] = merged(out.get(topic), span)
        return out

    def _index_times(self, at: int, cid: int) -> tuple[int, ...]:
        """The log times of a message index record (at byte ``at``) of channel ``cid``; none if it is not
        one (a damaged file)."""
        self._f.seek(at)
        hdr = self._f.read(9)
        if len(hdr) < 9 or hdr[0] != OP_MESSAGE_INDEX:
            return ()
        body = self._f.read(min(_REC.unpack(hdr)[1], self.size - at))
        if len(body) < 6 or _U16.unpack_from(body, 0)[0] != cid:
            return ()
        n = min(_U32.unpack_from(body, 2)[0], len(body) - 6) // 16
        return struct.unpack_from(f"<{2 * n}Q", body, 6)[::2]

    def raw_messages(self, topics: set[str]) -> Iterator[tuple[str, int, memoryview]]:
        """Messages of ``topics`` in log-time order (see :meth:`_merged`). Warns at the end if some
        still came after a later message of their topic: a file without a chunk index whose chunks
        (or lone messages) are not in time order, read in file order; the synchroniser then skips
        them as going backwards, and the warning says why."""
        last: dict[str, int] = {}
        late: dict[str, int] = {}
        for topic, t, data in self._merged(topics):
            if t < last.get(topic, -1):
                late[topic] = late.get(topic, 0) + 1
            else:
                last[topic] = t
            yield topic, t, data
        for topic, n in sorted(late.items()):
            self.stats.warn(
                "%s: %d messages of '%s' are stored after later ones and there is no chunk index to read "
                "them in log-time order (rewrite the file with an index, e.g. `mcap recover`)",
                self.name, n, short_text(topic),
            )  # fmt: skip

    def _merged(self, topics: set[str]) -> Iterator[tuple[str, int, memoryview]]:
        """Messages of ``topics`` in log-time order: a heap releases the messages not newer than the
        first message of the next chunk, so overlapping chunks are merged in bounded memory."""
        ids = {cid: topic for cid, (topic, _, _) in self.index.channels.items() if topic in topics}
        chunks = self._index_order(set(ids)) if self.index.chunks else self._file_order(warn=True)
        heap: list[tuple[int, int, str, memoryview]] = []
        seq = held = read = 0
        for batch in chunks:
            if not batch:
                continue
            horizon = min(t for _, t, _ in batch)  # not the chunk header's start time: may be 0
            while heap and (heap[0][0] <= horizon or held > REORDER_BYTES):
                if heap[0][0] > horizon and held > REORDER_BYTES:
                    self.stats.warn(
                        "%s: more than %d MiB of messages overlap in log time: some may come out of order",
                        self.name, REORDER_BYTES >> 20,
                    )  # fmt: skip
                t_, _, topic_, data_ = heapq.heappop(heap)
                held -= len(data_)
                yield topic_, t_, data_
            for cid, t, data in batch:
                topic = ids.get(cid)
                if topic is None:
                    chan = self.index.channels.get(cid)
                    if chan is None or chan[0] not in topics:
                        continue
                    ids[cid] = topic = chan[0]
                heapq.heappush(heap, (t, seq, topic, data))
                seq += 1
                read += 1
                held += len(data)
        while heap:
            t_, _, topic_, data_ = heapq.heappop(heap)
            yield topic_, t_, data_
        if self.summary_ok and self.index.counts is not None:
            expected = sum(self.index.counts.get(c, 0) for c in ids)
            if read < expected:
                self.stats.warn(
                    "%s: read %d of the %d messages the summary lists on %s",
                    self.name,
                    read,
                    expected,
                    ", ".join(sorted(topics)),
                )

    def close(self) -> None:
        self._f.close()


def mcap_source(path: Path, stats: ReadStats, what: str, hint: str = "check the file") -> McapSource:
    """A :class:`McapSource` over ``path``; LogError "cannot read ``what``: …" when it is not readable
    MCAP (an MCAP file given alone, or a ROS 2 bag's one storage file: logs/rosbag.py)."""
    try:
        return McapSource(path, stats)
    except (OSError, struct.error, McapFormatError, io.UnsupportedOperation) as exc:
        raise LogError(f"cannot read {what}: {exc}", hint) from exc


def open_mcap(path: Path, **kw) -> RosLogReader:
    stats = ReadStats()
    source = mcap_source(path, stats, f"MCAP file '{Path(path).name}'")
    return RosLogReader(source, path, stats=stats, **kw)
