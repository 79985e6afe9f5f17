"""Does a change move the real-log panel by more than the panel's own spread? Baseline and variant side by
side in one run, each log in K + 1 copies.

    python benchmarks/panel_variant.py --set scan_match.window=20 [--set ...] [--baseline REV] [--k 2]
        [--perturb odom|submaps|kernel] [--jobs 2] [--logs aces,csail-exact,...] [--out FILE]

The variant is this checkout with the ``--set`` overrides; the baseline is this checkout with the
defaults, or git revision ``--baseline`` (a code change) with its defaults. Some logs' figures are chaotic
(docs/results/panel_spread.md): a last-bit change moves infinite-corridor by ~0.1 m, and a change of the
algorithm changes which loop closures pass their gates — a single run per build tells a real gain from
luck on no log. So every log (the seven radish buildings with noisy and with exact odometry, and Intel)
runs as it is and in K copies with one ODOM line moved by 1 µm (as panel_spread.py does), in both builds.
Per log: the mean and range of the K + 1 figures (ATE RMSE; Intel: relation error, translation mean) and
of the scan-matched chain's; the verdict is **better** or **worse** only when the two ranges do not
overlap. The 1 µm copies sample only the input's chaos, not every decision a change of the algorithm moves
(a log stable under them may still move by centimetres under any change): read a verdict as "this change
moved this log", and judge a change by the whole table.

``--perturb submaps`` samples that larger spread instead: the K copies are the log itself run with
``submaps.max_distance`` moved by ±5 %, ±10 %, … of its default (K = 2: 9.5 and 10.5 m beside 10), in both
builds. Where a submap ends decides which closures pass and how the submaps' errors add up between them
(experiments.md: infinite-corridor 0.659 / 0.383 / 0.361 m at 9.5 / 10 / 10.5 with identical chains), so a
change's verdict on such a log under the 1 µm copies is mostly which side of that spread it lands on.
``--perturb kernel`` samples the front end's own chaos, which the others hardly reach (their chains move
on few logs): the K copies run with ``scan_match.robust_scale`` (ICP's Cauchy kernel, 0.05 m)
moved by ±0.2 %, ±0.4 %, … — far below anything a user would tune. On edmonton that moves the scan-matched
chain 0.307 → 0.135–0.307 m and the ATE 0.352 → 0.162–0.352 m (docs/results/panel_spread_kernel.md;
docs/results/experiments.md, "The front end's own chaos"):
ICP's along-track pose in a weakly constrained stretch moves by centimetres when its input moves by a
millimetre, and the bias and closures learnt downstream carry it. A variant that sets the perturbed key
itself (``--set scan_match.robust_scale=0.1 --perturb kernel``) has its copies moved by the same relative
steps around its own value.
Writes a markdown report (default docs/results/variant_<settings>.md, or variant_vs_<REV>.md; with
``--perturb submaps`` / ``kernel`` the name ends in ``_submaps`` / ``_kernel``) and every run's figures
beside it (the same name, .json); ``--from-json FILE --at REV`` writes the report again from such a file
(the runs made at REV, with the command's other options as they were then) without running anything —
after a change of the report's wording; the file is left as it is, and the report's statistics and
defaults are this checkout's. Besides the per-log verdicts the report gives, per group, the
change of the median of the per-log means with a bootstrap interval over each log's runs
(:func:`median_shift`).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import re
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _baseline import build_env, revision, source_tree  # noqa: E402
from panel_spread import GROUPS, MOVED, copies, group_means, in_group, moved_values, panel  # noqa: E402
from real_logs import ROOT, default_data  # noqa: E402

from cornerslam_cli.config import load_config, set_leaves  # noqa: E402
from cornerslam_cli.errors import ConfigError  # noqa: E402

MAX_K = 18  # copies of a --perturb by config: submaps.max_distance at most ±45 % (±50 %: 0, refused)


def run(log: Path, out: Path, extra: list[str], env: dict[str, str]) -> tuple[float, float, float]:
    """``cornerslam run LOG`` with the build of ``env``: (figure, the scan-matched chain's figure, the
    map's revisit misalignment in m — summary.json ``consistency``, nan when the run never revisits)."""
    cmd = [sys.executable, "-m", "cornerslam_cli", "run", str(log), "--out", str(out), "-q", *extra]
    res = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=out.parent)
    if res.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed: {res.stderr.strip()}")
    summary = json.loads((out / "summary.json").read_text())
    a, revisit = summary["accuracy"], (summary.get("consistency") or {}).get("revisit_mean")
    revisit = float("nan") if revisit is None else revisit
    if "relations" in a:
        return a["relations"]["trans_mean"], a["scan_odom_relations"]["trans_mean"], revisit
    return a["ate"]["rmse"], a["scan_odom_ate"]["rmse"], revisit


BUILDS = ("baseline", "variant")


def measure(logs, builds, k: int, jobs: int, tmp: Path, perturb: str = "odom") -> list[dict]:
    """Every log in K + 1 copies (:func:`copies`) through both builds (``builds``: name → (environment,
    extra options, the value the build's options set the perturbed key to, or None))."""
    with ThreadPoolExecutor(jobs) as pool:
        plan = []
        for name, log, score in logs:
            # each log's copies made once per value (odom: one set of files both builds read)
            made = {v: copies(name, log, k, perturb, tmp, v) for v in {v for *_, v in builds.values()}}
            runs = {
                b: [
                    pool.submit(run, p, tmp / f"out-{b}-{name}-{i}", [*score, *extra, *more], env)
                    for i, (p, more, _) in enumerate(made[value])
                ]
                for b, (env, extra, value) in builds.items()
            }
            plan.append((name, runs))
        return [{"log": n, **{b: [f.result() for f in fs] for b, fs in runs.items()}} for n, runs in plan]


def verdict(base: np.ndarray, var: np.ndarray) -> str:
    """better / worse when the ranges of the K + 1 figures do not overlap (lower is better)."""
    if var.max() < base.min():
        return "**better**"
    if var.min() > base.max():
        return "**worse**"
    return "within spread"


def span(x: np.ndarray) -> str:
    return f"{x.mean():.3f} ({x.min():.3f}–{x.max():.3f})"


def table(rows: list[dict]) -> list[str]:
    out = [
        "| log | baseline (m) | variant (m) | Δ mean (m) | verdict "
        "| chain: baseline | chain: variant | chain verdict |",
        "|---|---:|---:|---:|---|---:|---:|---|",
    ]
    for r in rows:
        b, v = np.array(r["baseline"]), np.array(r["variant"])
        fig, chain = (f"| {span(b[:, i])} | {span(v[:, i])} " for i in (0, 1))
        out.append(
            f"| {r['log']} {fig}| {v[:, 0].mean() - b[:, 0].mean():+.3f} | {verdict(b[:, 0], v[:, 0])} "
            f"{chain}| {verdict(b[:, 1], v[:, 1])} |"
        )
    return out


def revisit_table(rows: list[dict]) -> list[str]:
    """The maps' revisit misalignment (cm) per log: how well each map agrees with itself where the robot
    came back (report/consistency.py), a figure without the reference."""
    out = [
        "| log | baseline (cm) | variant (cm) | Δ mean (cm) | verdict |",
        "|---|---:|---:|---:|---|",
    ]
    for r in rows:
        b, v = 100 * np.array(r["baseline"])[:, 2], 100 * np.array(r["variant"])[:, 2]
        if np.isnan(b).any() or np.isnan(v).any():
            out.append(f"| {r['log']} | — | — | — | a run that never revisits |")
            continue
        out.append(
            f"| {r['log']} | {b.mean():.2f} ({b.min():.2f}–{b.max():.2f}) | {v.mean():.2f} ({v.min():.2f}–"
            f"{v.max():.2f}) | {v.mean() - b.mean():+.2f} | {verdict(b, v)} |"
        )
    return out


DRAWS = 2000  # bootstrap draws of median_shift


def resampled_mean(x: np.ndarray, rng: np.random.Generator) -> float:
    """The mean of ``x`` resampled with replacement, its deviation from ``x``'s mean scaled by
    √(n / (n − 1)): resampling n runs shrinks the spread of their mean by √((n − 1)/n), and at n = 3–5
    median_shift's 90 % interval would leave out 0 on simulated panels with no change clearly more often
    than 1 time in 10."""
    n = len(x)
    return float(x.mean() + (rng.choice(x, n).mean() - x.mean()) * np.sqrt(n / (n - 1)))


def median_shift(
    rows: list[dict], draws: int = DRAWS, seed: int = 0
) -> dict[str, tuple[float, float, float]]:
    """Per group of logs the rows have (panel_spread.GROUPS): the variant's median of the per-log means
    less the baseline's, and the 5th and 95th percentiles of that difference when each log's K + 1 figures are
    resampled with replacement in each build (a fixed seed: the report is reproducible). The verdicts
    judge one log at a time; this judges the median, which a change can move by less than any one log's
    spread and still move."""
    rng = np.random.default_rng(seed)
    figures = {b: {r["log"]: np.array([f for f, *_ in r[b]]) for r in rows} for b in ("baseline", "variant")}
    out = {}
    if min(len(f) for fig in figures.values() for f in fig.values()) < 2:
        return out  # (one run a log: no spread to resample)
    for group in GROUPS:
        if not (logs := [n for n in figures["baseline"] if in_group(n, group)]):
            continue
        observed = float(
            np.median([figures["variant"][n].mean() for n in logs])
            - np.median([figures["baseline"][n].mean() for n in logs])
        )
        shifts = np.empty(draws)
        for d in range(draws):
            med = {}
            for b, fig in figures.items():
                med[b] = np.median([resampled_mean(fig[n], rng) for n in logs])
            shifts[d] = med["variant"] - med["baseline"]
        lo, hi = np.percentile(shifts, [5, 95])
        out[group] = (observed, float(lo), float(hi))
    return out


def summary(rows: list[dict]) -> list[str]:
    """Per group of logs (noisy radish, exact radish): median and worst of the per-log means."""
    out = []
    means = {
        b: {r["log"]: float(np.mean([f for f, *_ in r[b]])) for r in rows} for b in ("baseline", "variant")
    }
    for groups in zip(*(group_means(m) for m in means.values()), strict=True):
        for b, (group, median, worst) in zip(means, groups, strict=True):
            out.append(
                f"- {group}, {b}: median of the means {median:.3f} m, worst {means[b][worst]:.3f} m ({worst})"
            )
    for group, (delta, lo, hi) in median_shift(rows).items():
        reading = (
            "clear of 0: the copies' spread alone gives such a change about 1 time in 10"
            if lo > 0 or hi < 0
            else "it spans 0: no change of the median shown"
        )
        out.append(
            f"- {group}: variant − baseline median of the means {delta:+.3f} m, 90 % bootstrap interval "
            f"{lo:+.3f} … {hi:+.3f} m (each log's runs resampled in both builds, {DRAWS} draws; {reading}; "
            "with K + 1 runs a log the interval is rough)"
        )
    verdicts = [verdict(np.array(r["baseline"])[:, 0], np.array(r["variant"])[:, 0]) for r in rows]
    out.append(
        f"- verdicts: {verdicts.count('**better**')} better, {verdicts.count('**worse**')} worse, "
        f"{verdicts.count('within spread')} within spread"
    )
    return out


def report(
    rows: list[dict],
    sets: list[str],
    base_rev: str,
    k: int,
    perturb: str = "odom",
    value: float | None = None,
    at: str | None = None,
) -> list[str]:
    """The report's lines; ``at``: the revision the runs were made at, when it is not this checkout (the
    report re-rendered from its saved runs, ``--from-json``)."""
    rev = at or revision()
    again = f" (this report written again from its runs, .json, at {revision()})" if at else ""
    cmd = " ".join(["python benchmarks/panel_variant.py", *(f"--set {s}" for s in sets), f"--k {k}"])
    if base_rev != "HEAD":
        cmd += f" --baseline {base_rev}"
    copies_are = f"in {k} copies with one ODOM line moved by 1 µm (panel_spread.py)"
    if perturb in MOVED:
        cmd += f" --perturb {perturb}"
        key, base, _ = MOVED[perturb]
        values = ", ".join(f"{v:g}" for v in moved_values(perturb, k))
        copies_are = (
            f"with `{key}` at {values} m beside this checkout's default "
            f"({base:g} m; the baseline's copies too)"
        )
        if value is not None:  # the variant sets the key itself: its copies move around its value
            own = ", ".join(f"{v:g}" for v in moved_values(perturb, k, value))
            copies_are = (
                f"with `{key}` moved by the same steps: the baseline's at {values} m beside this checkout's "
                f"default ({base:g} m), the variant's at {own} m beside its {value:g} m"
            )
    base = "the defaults" if base_rev == "HEAD" else f"revision {revision(base_rev)}, its defaults"
    variant = ", ".join(f"`{s}`" for s in sets) or "its defaults"
    title = ", ".join(f"`{s}`" for s in sets) or f"this build ({rev})"
    return [
        f"# Panel: {title} against {base}",
        "",
        f"`{cmd}` at {rev}{again}. Variant: this build with {variant}; baseline: {base}. Each log runs "
        f"as it is and {copies_are}{'' if value is not None else ', in both builds'}; "
        "cells give the mean of the figures and their range. Verdict **better** / **worse** only when the "
        "ranges do not overlap. Figures: ATE RMSE against the corrected poses beside each radish log; "
        "Intel: relation error, translation mean. Chain: the scan-matched odometry alone (the front end's "
        "output before the filter) scored the same way"
        + (
            " (it does not depend on where submaps end: its range is one value, and any difference is a "
            "chain verdict)."
            if perturb == "submaps"
            else "."
        ),
        "",
        *table(rows),
        "",
        *summary(rows),
        "",
        "Revisit misalignment (summary.json `consistency`): for each scan point placed with the trajectory, "
        "the distance to the nearest point of scans ≥ 100 scans away, capped at 0.3 m, averaged over the "
        "points that have one (revisit_floor.md) — the map's agreement with itself, not with the reference.",
        "",
        *revisit_table(rows),
        "",
    ]


def run_panel(logs, args, value: float | None) -> list[dict]:
    """Both builds' runs of every log (:func:`measure`), in a temporary directory."""
    sets = [x for s in args.sets for x in ("--set", s)]
    with tempfile.TemporaryDirectory(prefix="panel-variant-") as tmp, contextlib.ExitStack() as stack:
        src = ROOT if args.baseline == "HEAD" else stack.enter_context(source_tree(args.baseline))
        builds = {"baseline": (build_env(src), [], None), "variant": (build_env(ROOT), sets, value)}
        assert tuple(builds) == BUILDS
        return measure(logs, builds, args.k, args.jobs, Path(tmp), args.perturb)


def slug(sets: list[str], base_rev: str) -> str:
    """A file name for the comparison: the settings (``scan_match.window-20``), or the baseline revision."""
    text = "_".join(sets) if sets else f"vs_{base_rev}"
    return re.sub(r"[^A-Za-z0-9._-]+", "-", text)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--baseline", default="HEAD", help="git revision of the baseline (default: this build)")
    ap.add_argument("--data", type=Path, default=default_data(), help="folder of the real logs")
    ap.add_argument("--k", type=int, default=2, help="perturbed copies per log")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--logs", default="", help="comma-separated log names (default: the whole panel)")
    ap.add_argument(
        "--perturb",
        choices=("odom", *MOVED),
        default="odom",
        help="what the K copies move: an ODOM line by 1 µm, submaps.max_distance ±5 %%, ..., or "
        "scan_match.robust_scale ±0.2 %%, ...",
    )
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--from-json", type=Path, default=None, help="write the report from this file's runs")
    ap.add_argument("--at", default=None, help="with --from-json: the revision its runs were made at")
    args = ap.parse_args()
    if (args.from_json is None) != (args.at is None):
        ap.error("--from-json and --at go together: the saved runs and the revision they were made at")
    if not args.sets and args.baseline == "HEAD":
        ap.error("nothing to compare: give --set KEY=VALUE and/or --baseline REV")
    value = None
    if args.perturb in MOVED:
        moved = MOVED[args.perturb][0]
        if args.k > MAX_K:
            ap.error(f"--perturb {args.perturb}: --k at most {MAX_K} (submaps: ±5 % a copy, 0 is refused)")
        # a variant of the perturbed key itself: its copies move around the value it sets, by the same
        # relative steps as the baseline's around the default — each copy's config checked now, not after
        # the panel's quarter of an hour
        if any(leaf == moved for _, leaf, _ in set_leaves(args.sets)):
            try:
                value = float(functools.reduce(getattr, moved.split("."), load_config(None, args.sets)))
                for v in moved_values(args.perturb, args.k, value):
                    load_config(None, [*args.sets, f"{moved}={v:g}"])
            except ConfigError as e:
                ap.error(f"--perturb {args.perturb} with --set {moved}: {e}")
    logs = panel(args.data)
    if args.logs:
        wanted = args.logs.split(",")
        if unknown := sorted(set(wanted) - {n for n, _, _ in logs}):
            ap.error(f"unknown log(s) {', '.join(unknown)} (the panel's: {', '.join(n for n, _, _ in logs)})")
        logs = [x for x in logs if x[0] in wanted]
    if args.from_json is None and (missing := [str(p) for _, p, _ in logs if not p.exists()]):
        ap.error(f"{', '.join(missing)} not found (pass --data DIR)")
    suffix = f"_{args.perturb}" if args.perturb in MOVED else ""
    out = args.out or ROOT / "docs" / "results" / f"variant_{slug(args.sets, args.baseline)}{suffix}.md"
    if args.from_json is not None:
        saved = json.loads(args.from_json.read_text())
        rows = [{k: np.array(v, dtype=float) if k != "log" else v for k, v in r.items()} for r in saved]
        rows = [r for r in rows if r["log"] in {n for n, _, _ in logs}]
        if bad := [r["log"] for r in rows if any(len(r[b]) != args.k + 1 for b in BUILDS)]:
            ap.error(f"{args.from_json}: {', '.join(bad)} not run {args.k + 1} times a build (--k {args.k})")
    else:
        rows = run_panel(logs, args, value)
    text = "\n".join(report(rows, args.sets, args.baseline, args.k, args.perturb, value, args.at))
    out.write_text(text)
    if args.from_json is not None:  # its runs stay where they are (a --logs subset would drop the rest)
        print(text)
        return
    # every run's figures (figure, chain's figure, revisit), for reading the panel again another way
    clean = [
        {
            "log": r["log"],
            **{b: [[None if np.isnan(x) else float(x) for x in run] for run in r[b]] for b in BUILDS},
        }
        for r in rows
    ]
    out.with_name(out.name.removesuffix(".md") + ".json").write_text(json.dumps(clean, indent=1) + "\n")
    print(text)


if __name__ == "__main__":
    main()
