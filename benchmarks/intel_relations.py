"""Where the Intel relation error comes from: the Kümmerle relations by how far apart their two times are.

    python benchmarks/intel_relations.py [--data DIR] [--work DIR] [--out docs/results/intel_relations.md]

``cornerslam run intel-noisy-odom.log`` (default config, with ``--relations``), then the relation metric
(evaluate.relation_errors, linear interpolation between processed scans as the data README defines it)
of three trajectories over the same 910 scan stamps: our output, our scan-matched odometry (the front
end's chain) and gmapping's corrected poses (``intel.gfs.log``'s FLASER pose fields, rbpf_poses) — split
by the relation's time span. The relations were made on the full 13,631-scan recording; this log keeps
910 of its scans, so most relation times fall between two of them and are scored on an interpolated
pose. The table says how far they fall from a scan, and what that costs gmapping's poses too.
Deterministic: a re-run gives the same figures.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from radish_panel import run  # noqa: E402
from real_logs import INTEL, ROOT, TIME_OFFSET, default_data, load_run, rbpf_poses, relation_args  # noqa: E402

from cornerslam_cli.evaluate import read_relations, relation_errors  # noqa: E402

AT_SCAN = 0.01  # s: a relation time this close to a processed scan is scored on its pose
SPANS = ((0.0, 2.0), (2.0, 5.0), (5.0, 30.0), (30.0, 100.0), (100.0, np.inf))  # s between t1 and t2


def span_rows(stamps: np.ndarray, poses: dict[str, np.ndarray], rel: np.ndarray) -> list[str]:
    """Markdown rows: per span (and for relations whose two times are both at a processed scan, scored
    without interpolation), the relations in it and each trajectory's mean errors (m, deg)."""
    scored = {k: relation_errors(stamps, p, rel, TIME_OFFSET) for k, p in poses.items()}
    inside = next(iter(scored.values()))[0]
    dt = np.abs(rel[inside, 1] - rel[inside, 0])
    at_scan = (off_scan(stamps, rel[inside, 0]) <= AT_SCAN) & (off_scan(stamps, rel[inside, 1]) <= AT_SCAN)
    groups = [
        (f"{lo:g}–{hi:g} s" if hi < np.inf else f"≥ {lo:g} s", (dt >= lo) & (dt < hi)) for lo, hi in SPANS
    ]
    groups += [
        ("all", np.ones_like(dt, dtype=bool)),
        (f"all, both times within {AT_SCAN * 1e3:g} ms of a scan", at_scan),
    ]
    rows = []
    for label, sel in groups:
        cells = [f"{t[sel].mean():.3f} m, {r[sel].mean():.2f}°" for _, t, r in scored.values()]
        rows.append(f"| {label} | {int(sel.sum())} | " + " | ".join(cells) + " |")
    return rows


def off_scan(stamps: np.ndarray, t_rel: np.ndarray) -> np.ndarray:
    """How far (s) each relation time (relation clock) lies from the nearest processed scan."""
    t = t_rel - TIME_OFFSET
    i = np.searchsorted(stamps, t).clip(1, len(stamps) - 1)
    return np.minimum(np.abs(stamps[i] - t), np.abs(stamps[i - 1] - t))


def gap_line(stamps: np.ndarray, rel: np.ndarray) -> str:
    """How far relation times fall from the nearest processed scan, and how far apart the scans are."""
    t = np.concatenate((rel[:, 0], rel[:, 1]))
    t = t[(t - TIME_OFFSET >= stamps[0]) & (t - TIME_OFFSET <= stamps[-1])]
    off = off_scan(stamps, t)
    return (
        f"Processed scans are {np.median(np.diff(stamps)):.2f} s apart (median); a relation time lies "
        f"{np.median(off):.2f} s from the nearest one (median), within {AT_SCAN * 1e3:g} ms of one for "
        f"{100 * np.mean(off <= AT_SCAN):.1f} % of relation times."
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=default_data())
    ap.add_argument("--work", type=Path, default=ROOT / "cornerslam_out" / "intel_relations")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "intel_relations.md")
    args = ap.parse_args()
    summary = run(args.data / INTEL, args.work, relation_args(args.data))
    r = load_run(args.work)
    rel = read_relations(args.data / "intel" / "intel.relations")
    poses = {"our output": r["pose"], "our scan-matched odometry": r["scan_odom"]}
    poses["gmapping (intel.gfs.log)"] = rbpf_poses(r["stamp"], args.data)
    total = summary["accuracy"]["relations"]
    lines = [
        "# Intel: the relation error by relation span",
        "",
        f"`python benchmarks/intel_relations.py`: {__doc__.split(chr(10) + chr(10))[2].strip()}".replace(
            "\n", " "
        ),
        "",
        "| relation span | relations | " + " | ".join(poses) + " |",
        "|---|---:|" + "---|" * len(poses),
        *span_rows(r["stamp"], poses, rel),
        "",
        gap_line(r["stamp"], rel),
        f"summary.json of the run: {total['trans_mean']:.3f} ± {total['trans_std']:.3f} m, "
        f"{total['rot_mean_deg']:.2f} ± {total['rot_std_deg']:.2f}° over {total['n']} relations.",
        "",
    ]
    args.out.write_text("\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
