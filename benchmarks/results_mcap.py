"""Benchmark: writing the results MCAP (``run --mcap-out``) in each profile, on one run of a real log.

    .venv/bin/python benchmarks/results_mcap.py                    # infinite-corridor, best of 3
    .venv/bin/python benchmarks/results_mcap.py --log LOG --repeat 5 --out /tmp/rm.md

Results: docs/results/results_mcap.md.

The log is run once with ``--mcap-out``; when the run writes its results MCAP (its staged output and
its scans in hand), every profile's file is written ``--repeat`` times from the same inputs, in turn,
and the best wall time of each is kept, with the file's size and message count. What differs between
the profiles is the encoding alone: the content is gathered the same way (report/mcap_out.py).
"""

from __future__ import annotations

import argparse
import inspect
import platform
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cornerslam_cli import pipeline  # noqa: E402
from cornerslam_cli.config import load_config  # noqa: E402
from cornerslam_cli.report import mcap_out  # noqa: E402
from cornerslam_cli.report.mcap_items import PROFILES  # noqa: E402

DEFAULT_LOG = ROOT.parent / "shared" / "data" / "real" / "radish" / "infinite-corridor.log"


def measure(log: Path, repeat: int, work: Path) -> tuple[dict[str, dict], int]:
    """{profile: best seconds, bytes, messages} and the run's steps."""
    from mcap.reader import make_reader

    original = mcap_out.write_results_mcap
    found: dict[str, dict] = {}

    def timed(*args, **kw):
        call = inspect.signature(original).bind(*args, **kw)
        for profile in PROFILES:
            best = float("inf")
            target = work / f"results_{profile}.mcap"
            mine = {**call.arguments, "path": target, "profile": profile}
            for _ in range(repeat):
                t0 = time.perf_counter()
                original(**mine)
                best = min(best, time.perf_counter() - t0)
            with open(target, "rb") as f:
                stats = make_reader(f).get_summary().statistics
            found[profile] = {
                "seconds": best,
                "bytes": target.stat().st_size,
                "messages": stats.message_count,
            }
        return original(*args, **kw)

    mcap_out.write_results_mcap = timed
    try:
        summary = pipeline.run(log, load_config(), work / "run", mcap_out=work / "results.mcap")
    finally:
        mcap_out.write_results_mcap = original
    return found, summary.counts.steps


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--log", default=str(DEFAULT_LOG))
    ap.add_argument("--repeat", type=int, default=3, help="writes per profile; the best is kept")
    ap.add_argument("--out", default=str(ROOT / "docs" / "results" / "results_mcap.md"))
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        found, steps = measure(Path(args.log), args.repeat, Path(tmp))
    base = found["foxglove"]
    lines = [
        "# Writing the results MCAP, per profile",
        "",
        f"`python benchmarks/results_mcap.py --log {Path(args.log).name} --repeat {args.repeat}` "
        f"({platform.machine()}, Python {platform.python_version()}, {time.strftime('%Y-%m-%d')}): one "
        f"run of {Path(args.log).name} ({steps} steps), its results MCAP written {args.repeat}× per profile "
        "from the same staged output and scans, the best wall time kept.",
        "",
        "| profile | write (s) | ÷ foxglove | size (MB) | messages |",
        "|---|---:|---:|---:|---:|",
    ]
    for profile, f in found.items():
        lines.append(
            f"| {profile} | {f['seconds']:.2f} | {f['seconds'] / base['seconds']:.2f} | "
            f"{f['bytes'] / 1e6:.2f} | {f['messages']} |"
        )
    lines += [
        "",
        "The message counts differ by the profiles' layout, not their content: ROS 2 carries the scans' "
        "frame on /tf_static (one message), the Foxglove file each cloud's pose.",
    ]
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
