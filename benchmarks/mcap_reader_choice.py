"""Issue 17: keep our MCAP reader (cornerslam_cli/logs/mcap.py) or use the mcap package's readers?

    python benchmarks/mcap_reader_choice.py [--scans 20000] [--out docs/results/mcap_reader.md]

Reads the same files three ways and counts the messages each gets, the error that stopped it and the
time taken:

* ``ours``: :class:`~cornerslam_cli.logs.mcap.McapSource` ``raw_messages`` over every topic (what
  ``open_log`` uses; warnings counted, never raises on damage);
* ``make_reader``: ``mcap.reader.make_reader(f).iter_messages()`` (seeking reader: chunk index and
  log-time order when the summary is readable, else its non-seeking fallback);
* ``StreamReader``: ``mcap.stream_reader.StreamReader(f).records`` (file order, no index).

Files: the sample log (``sample_logs/sim_office.mcap``) and generated zstd / lz4 / uncompressed logs,
each whole, cut at several byte offsets (a recorder that died) and with 64 zeroed bytes inside a chunk
(a corrupt chunk). "complete chunks before the cut" is what a reader that keeps every whole chunk must
at least get. Then raw read speed (records + decompression, no LaserScan decoding) on a long generated
log and the real Mines MCAP logs (if ``../shared/data/real`` is present), best of 3 passes.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

import mcap  # noqa: E402
from _log_fixtures import make_odoms, make_scans  # noqa: E402
from bench_read import generate  # noqa: E402
from mcap.data_stream import ReadDataStream  # noqa: E402
from mcap.reader import make_reader  # noqa: E402
from mcap.records import Chunk  # noqa: E402
from mcap.records import Message as McapMessage  # noqa: E402
from mcap.stream_reader import StreamReader, breakup_chunk  # noqa: E402

from cornerslam_cli.logs.base import ReadStats  # noqa: E402
from cornerslam_cli.logs.mcap import McapSource  # noqa: E402
from cornerslam_cli.logs.writers import write_mcap  # noqa: E402

SAMPLE = ROOT / "sample_logs" / "sim_office.mcap"
REAL = ROOT.parent / "shared" / "data" / "real"
CUTS = (0.10, 0.25, 0.50, 0.75, 0.90, 0.99)


@dataclass
class Outcome:
    """What one reader got from one file."""

    messages: int
    stopped_by: str  # exception that ended the read ("" if none), or our reader's warning count
    seconds: float
    in_order: bool


def read_ours(path: Path) -> Outcome:
    """Every message through McapSource.raw_messages; warnings, not exceptions, report damage."""
    t = time.perf_counter()
    stats = ReadStats()
    src = McapSource(path, stats)
    topics = {c.topic for c in src.channels()}
    stamps = [ts for _, ts, _ in src.raw_messages(topics)]
    src.close()
    warned = f"{len(stats.warnings)} warning(s)" if stats.warnings else ""
    return Outcome(len(stamps), warned, time.perf_counter() - t, stamps == sorted(stamps))


def _count_until_error(messages) -> tuple[list[int], str]:
    """Log times of the messages an iterator yields before it raises, and what it raised."""
    stamps: list[int] = []
    try:
        for log_time in messages:
            stamps.append(log_time)
    except Exception as exc:  # noqa: BLE001 - recording what the package raises is the point
        name = type(exc).__name__
        return stamps, f"{type(exc).__module__}.{name}" if name == "error" else name
    return stamps, ""


def read_make_reader(path: Path, validate_crcs: bool = False) -> Outcome:
    t = time.perf_counter()
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=validate_crcs)
        stamps, err = _count_until_error(m.log_time for _, _, m in reader.iter_messages())
    return Outcome(len(stamps), err, time.perf_counter() - t, stamps == sorted(stamps))


def read_stream(path: Path) -> Outcome:
    t = time.perf_counter()
    with open(path, "rb") as f:
        records = StreamReader(f).records
        stamps, err = _count_until_error(r.log_time for r in records if isinstance(r, McapMessage))
    return Outcome(len(stamps), err, time.perf_counter() - t, stamps == sorted(stamps))


READERS = {
    "ours": read_ours,
    "make_reader": read_make_reader,
    "make_reader+CRC": lambda p: read_make_reader(p, validate_crcs=True),
    "StreamReader": read_stream,
}


def chunk_ends(path: Path) -> list[tuple[int, int]]:
    """(end offset, message count) of each chunk of a complete file, from its chunk index."""
    with open(path, "rb") as f:
        reader = make_reader(f)
        out = []
        for ci in reader.get_summary().chunk_indexes:
            f.seek(ci.chunk_start_offset + 9)
            chunk = Chunk.read(ReadDataStream(f))
            n = sum(isinstance(r, McapMessage) for r in breakup_chunk(chunk))
            out.append((ci.chunk_start_offset + ci.chunk_length, n))
    return out


def corrupt(src: Path, dst: Path, which: int = 3) -> Path:
    """64 zeroed bytes in the middle of chunk ``which`` (as tests/test_logs_mcap.py does)."""
    with open(src, "rb") as f:
        ci = make_reader(f).get_summary().chunk_indexes[which]
    data = bytearray(src.read_bytes())
    mid = ci.chunk_start_offset + ci.chunk_length // 2
    data[mid : mid + 64] = bytes(64)
    dst.write_bytes(bytes(data))
    return dst


def damage_rows(name: str, path: Path, tmp: Path) -> list[str]:
    """Table rows for one log: whole, cut at CUTS, cut in the footer, one corrupt chunk."""
    data = path.read_bytes()
    ends = chunk_ends(path)
    total = sum(n for _, n in ends)
    cases: list[tuple[str, Path, str]] = [("whole", path, f"{total:,}")]
    for frac in CUTS:
        size = int(len(data) * frac)
        p = tmp / f"{name}-cut{int(frac * 100)}.mcap"
        p.write_bytes(data[:size])
        bound = sum(n for end, n in ends if end <= size)
        cases.append((f"cut at {frac:.0%}", p, f"{bound:,}"))
    p = tmp / f"{name}-cutfooter.mcap"
    p.write_bytes(data[:-4])
    cases.append(("cut 4 bytes short (in footer magic)", p, f"{total:,}"))
    if len(ends) > 4:
        cases.append(
            ("64 bytes zeroed in chunk 3", corrupt(path, tmp / f"{name}-corrupt.mcap"), f"< {total:,}")
        )
    rows = []
    for case, p, bound in cases:
        got = {k: fn(p) for k, fn in READERS.items()}
        cells = [f"{o.messages:,}{'' if o.in_order else ' (not in order)'}" for o in got.values()]
        errs = "; ".join(f"{k}: {o.stopped_by}" for k, o in got.items() if o.stopped_by)
        rows.append(f"| {name} | {case} | {bound} | " + " | ".join(cells) + f" | {errs} |")
    return rows


def best_rate(fn, path: Path, repeat: int = 3) -> tuple[int, float]:
    """(messages, best messages/s) of ``repeat`` passes."""
    best, n = 0.0, 0
    for _ in range(repeat):
        o = fn(path)
        n, best = o.messages, max(best, o.messages / o.seconds)
    return n, best


def speed_rows(paths: list[tuple[str, Path]]) -> list[str]:
    rows = []
    for name, p in paths:
        rates = [best_rate(fn, p) for fn in READERS.values()]
        mib = p.stat().st_size / 2**20
        cells = " | ".join(f"{r:,.0f}" for _, r in rates)
        rows.append(f"| {name} | {mib:.1f} | {rates[0][0]:,} | {cells} |")
    return rows


def generated(tmp: Path) -> list[tuple[str, Path]]:
    """120-scan logs in ~10 chunks per compression (the fixtures of tests/test_logs_mcap.py)."""
    out = []
    for comp in ("zstd", "lz4", "none"):
        p = tmp / f"gen-{comp}.mcap"
        write_mcap(p, make_scans(120, beams=361), make_odoms(120), compression=comp, chunk_size=32_000)
        out.append((f"generated {comp}", p))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scans", type=int, default=20_000)
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "mcap_reader.md")
    ap.add_argument("--real", type=Path, default=REAL, help="directory of the real logs (*/*.mcap)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        logs = [("sample sim_office", SAMPLE), *generated(tmp)]
        damage = [row for name, p in logs for row in damage_rows(name, p, tmp)]
        long = generate(tmp / "long.mcap", args.scans)
        real = sorted(args.real.glob("*/*.mcap")) if args.real.is_dir() else []
        speed = speed_rows(
            [(f"generated, {args.scans:,} scans + odometry", long), ("sample sim_office", SAMPLE)]
            + [(f"real `{p.parent.name}/{p.name}`", p) for p in real]
        )
    load = os.getloadavg()[0]
    text = (
        f"""# MCAP reader: ours or the mcap package's (issue 17)

Produced by `python benchmarks/mcap_reader_choice.py` (Python {platform.python_version()},
mcap {mcap.__version__}, {time.strftime("%Y-%m-%d")}, 1-min load {load:.1f} on {os.cpu_count()} CPUs).

Readers: **ours** = `McapSource.raw_messages` (cornerslam_cli/logs/mcap.py, what `open_log` uses);
**make_reader** = `mcap.reader.make_reader(f).iter_messages()` (chunk index when the summary is
readable, else its non-seeking fallback); **make_reader+CRC** = the same with `validate_crcs=True`;
**StreamReader** = `mcap.stream_reader.StreamReader(f).records` (file order). Cells: messages yielded
before the read ended (all topics). "bound" = messages in the
chunks that end before the cut (what a reader keeping every whole chunk gets; ours can get more, from
the readable prefix of the cut chunk). Errors: what stopped the package's readers (ours never raises on
damage; it warns). The package's readers check no CRC by default, so on an uncompressed chunk with
zeroed bytes they yield the damaged messages as if they were good; ours skips that chunk.

## Damaged and whole files

| log | file | bound | ours | make_reader | make_reader+CRC | StreamReader | stopped by |
|---|---|---:|---:|---:|---:|---:|---|
"""
        + "\n".join(damage)
        + """

## Raw read speed (messages/s, records + decompression, no LaserScan decoding; best of 3)

| log | MiB | messages | ours | make_reader | make_reader+CRC | StreamReader |
|---|---:|---:|---:|---:|---:|---:|
"""
        + "\n".join(speed)
        + "\n"
    )
    args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
