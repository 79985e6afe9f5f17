"""What the commands print on standard output, as lines of text (the CLI echoes them).

Each function takes a result — a run's ``RunSummary`` (summary.json), a comparison's summaries, a
batch's rows, a log's ``LogInfo``, ``evaluate_files``' ``Accuracy`` — and returns the lines, without a
trailing newline, so the wording and the column layout are tested without a terminal.

Over 400 lines because every command's printed text is here, one wording for all (a run's lines are
compare's and the report's too).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import display_path
from ..logs import SCANS_SOURCE
from ..ranges import short_text

if TYPE_CHECKING:
    from ..logs.base import LogInfo
    from ..results import Accuracy, MapConsistency, RelationError, RunInput, RunSummary
    from ..types import Scan


def mean_std(e: RelationError | None) -> str:
    """Translational relation error as 'mean ± std' (m); '-' without relations."""
    return f"{e.trans_mean:.3f} ± {e.trans_std:.3f}" if e is not None and e.n else "-"


def relation_text(e: RelationError) -> str:
    """A relation error (``evaluate.relation_error``) in words: translation, rotation, how many."""
    if e.n == 0:
        return "no relation falls inside the trajectory's time span (check --time-offset)"
    return (
        f"translation {mean_std(e)} m, rotation {e.rot_mean_deg:.2f} ± {e.rot_std_deg:.2f} deg "
        f"({e.n}/{e.n_total} relations)"
    )


def unusable_scans(c) -> str:
    """The run line's note of the scans the reader could not use (beam angles or count unusable:
    ``counts.scans_bad_geometry``), which the scans and skipped counts do not hold; "" when none."""
    n = c.scans_bad_geometry or 0
    return f"; {n} more scan{'s' if n != 1 else ''} unusable, not read: see the warnings" if n else ""


def span_text(i: RunInput) -> str:
    """The part of the log a run processed, when ``--start``/``--end``/``--max-scans`` chose it (all of
    it, perhaps: the text gives the scans), else "": a run's figures over a slice read like the whole
    log's otherwise."""
    if (p := i.span) is None:
        return ""
    return (
        f"{p.options}: scans #{p.first_index}–#{p.last_index} of the log, "
        f"{p.first_time:.3f}–{p.last_time:.3f} s from its first scan"
    )


def span_lines(i: RunInput) -> list[str]:
    """:func:`span_text` as a printed line, none for the whole log."""
    return [f"span: {text}"] if (text := span_text(i)) else []


def odometry_label(summary: RunSummary) -> str:
    """What the run's odometry is called: the scans' own on the scans alone (input.odometry: scans)."""
    return "odometry" if summary.scan_odometry is None else "scan odometry"


def summary_lines(s: RunSummary) -> list[str]:
    """``cornerslam run``: counts, stage times, accuracy when there is a reference, the output."""
    c, t = s.counts, s.timing
    alone = s.scan_odometry is not None  # (input.odometry: scans)
    odometry = odometry_label(s)
    lines = [
        f"{s.input.log}: {c.steps} steps ({c.scans_in} scans, {c.scans_skipped} skipped, "
        f"{c.keyframes_skipped} between keyframes{unusable_scans(c)}), {c.landmarks} landmarks, "
        f"{c.matched_total} matches with {s.assoc}",
        *span_lines(s.input),
        topics_line(s.input),
        mount_line(s.input),
        *preset_lines(s.config),
        *deskew_lines(s.input),
        f"time: extract {t.t_extract:.2f}s {'scan odometry' if alone else 'scan match'} "
        f"{t.t_scan_match or 0.0:.2f}s "
        f"predict {t.t_predict:.2f}s match {t.t_match:.2f}s "
        f"update {t.t_update:.2f}s ({t.scans_per_second:.0f} steps/s), wall {t.wall_time:.1f}s",
    ]
    if c.submaps is not None:
        lines.append(
            f"submaps: {c.submaps}, loop closures {c.loops_accepted} accepted, {c.loops_rejected} refused, "
            + (
                ""
                if c.refine_factors is None
                else f"refinement {c.refine_factors} scan pairs (of {c.refine_registered} registered, "
                f"{c.refine_fit} fit), "
            )
            + f"loop time {t.t_loop or 0.0:.2f}s"
        )
    acc = s.accuracy
    if acc is not None and acc.ate is not None:
        lines.append(
            f"ATE RMSE {acc.ate.rmse:.3f} m ({odometry} {acc.odom_ate.rmse:.3f} m"
            + (f", scan-matched {acc.scan_odom_ate.rmse:.3f} m" if acc.scan_odom_ate else "")
            + f") against {acc.ground_truth}"
            + (f", over {acc.ate.n} of the {s.counts.steps} poses" if acc.ate.n < s.counts.steps else "")
            + (f" ({acc.ate.in_holes} in its gaps not scored)" if acc.ate.in_holes else "")
        )
    if s.consistency is not None:
        lines.append(consistency_line(s.consistency, odometry))
    if acc is not None and acc.relations is not None:
        lines.append(f"relations: {relation_text(acc.relations)}")
        lines.append(f"  {odometry}: {relation_text(acc.odom_relations)}")
        if acc.scan_odom_relations is not None:
            lines.append(f"  scan-matched odometry: {relation_text(acc.scan_odom_relations)}")
    lines.append(f"wrote {s.out_dir}")
    return lines


MOUNT_SOURCES = {
    "tf": "from the log's tf",
    "config": "from the config's input.laser",
    "preset": "from the laser preset",
    "default": "the built-in default: not on the log's tf, not in the config",
}
# a CARMEN log's "tf" mount: a ROBOTLASER1 line's laser pose (logs/carmen.py laser_to_base)
ROBOTLASER_SOURCE = "from the log's ROBOTLASER1 laser pose"
CARMEN_DEFAULT_SOURCE = "the built-in default: not in the log's laser lines, not in the config"


UPSIDE_DOWN_SOURCES = {"tf": "from the log's tf", "config": "from the config's input.laser.upside_down"}


def consistency_line(c: MapConsistency, odometry: str = "odometry") -> str:
    """How well the map agrees with itself (summary.json ``consistency``): a figure without ground truth."""
    cells = f"map cells {c.cells_vs_odom:.2f}× the {odometry}'s"
    if not c.revisit_share:
        return f"map consistency: {cells}; the run never comes back to a place (no revisit misalignment)"
    revisit = f"revisit misalignment {100 * c.revisit_mean:.1f} cm on {100 * c.revisit_share:.0f} % of points"
    odom = (
        f"{odometry} {100 * c.odom_revisit_mean:.1f} cm on {100 * c.odom_revisit_share:.0f} %"
        if c.odom_revisit_share
        else f"{odometry} never back"
    )
    return f"map consistency: {revisit} ({odom}), {cells}"


def topics_line(inp: RunInput) -> str:
    """What the run read of the log: its scan topic and odometry (a CARMEN log's kinds of line)."""
    odom = short_text(inp.odom_topic or "-", 200)
    if inp.format == "carmen":
        return f"read: {short_text(inp.scan_topic, 200)} lines, odometry from {inp.odom_source or odom}"
    source = f" ({inp.odom_source})" if inp.odom_source else ""
    if inp.odom_source == SCANS_SOURCE:  # (input.odometry: scans)
        return f"topics: scans {short_text(inp.scan_topic, 200)}, odometry from {inp.odom_source}"
    return f"topics: scans {short_text(inp.scan_topic, 200)}, odometry {odom}{source}"


def mount_line(inp: RunInput) -> str:
    """Where the run's laser mount came from (summary.json's ``input``): its position, and whether it is
    upside down, each with its own source — one when they share it."""
    x, y, yaw = inp.laser_to_base
    source = MOUNT_SOURCES.get(inp.laser_to_base_source, inp.laser_to_base_source)
    if inp.laser_to_base_source == "tf" and inp.format == "carmen":
        source = ROBOTLASER_SOURCE
    elif inp.laser_to_base_source == "default" and inp.format == "carmen":  # CARMEN has no tf
        source = CARMEN_DEFAULT_SOURCE
    at = f"laser mount: x={x:.3f} m y={y:.3f} m yaw={yaw:.3f} rad"
    flip_source = inp.laser_upside_down_source
    if not inp.laser_upside_down:
        return f"{at} ({source})"
    if flip_source is None:  # a summary written before the flag's source was: not known
        return f"{at} ({source}), upside down"
    if flip_source == inp.laser_to_base_source:
        return f"{at}, upside down ({source})"
    return f"{at} ({source}), upside down ({UPSIDE_DOWN_SOURCES.get(flip_source, flip_source)})"


def preset_lines(config: dict) -> list[str]:
    """Which laser preset (lasers.py) the run's config was layered on — its sensor model and extraction
    settings, under the user's config; nothing when the config does not say (an older summary)."""
    name = config.get("input", {}).get("laser_preset")
    if name is None:
        return []
    if name == "auto":  # (resolved to a preset's name when one matched the scans)
        return ["laser preset: none matches the scans (the config's sensor model)"]
    if name == "none":
        return ["laser preset: none (input.laser_preset: none; the config's sensor model)"]
    return [f"laser preset: {name} (its sensor model and extraction settings, under the config)"]


def deskew_lines(inp: RunInput) -> list[str]:
    """A line saying the scans were deskewed and with what beam times; none when they were not."""
    if inp.beam_times not in ("log", "config"):
        return []
    where = "the log's time_increment" if inp.beam_times == "log" else "input.beam_time"
    return [f"deskewed: beams {1e6 * abs(inp.beam_time):.2f} µs apart ({where})"]


def comparison_lines(summaries: list[RunSummary]) -> list[str]:
    """``cornerslam compare``: one row per associator (accuracy columns when any run has a
    reference, loop-closing columns when any run had submaps), then the scan-matched odometry's
    accuracy, the same for every associator, the part of the log when not all of it, and, when the
    filters ran at once (--jobs), that their times do not compare (the warning said so before the
    figures, scrolled away by their progress)."""
    head = (
        f"{'assoc':<6} {'steps':>6} {'landmarks':>9} {'matched':>8} "
        f"{'t_match s':>10} {'max ms':>8} {'t_total s':>10}"
    )
    has_gt = any(s.accuracy is not None and s.accuracy.ate is not None for s in summaries)
    has_rel = any(s.accuracy is not None and s.accuracy.relations is not None for s in summaries)
    alone = bool(summaries) and summaries[0].scan_odometry is not None  # (one input for all associators)
    odom, w_ate, w_rel = ("scan odom", 15, 21) if alone else ("odom", 10, 18)
    if has_gt:
        head += f" {'ATE m':>8} {odom + ' ATE m':>{w_ate}}"
    if has_rel:
        head += f" {'relations m':>16} {odom + ' relations m':>{w_rel}}"
    has_loops = any(s.counts.submaps is not None for s in summaries)
    if has_loops:
        head += f" {'submaps':>7} {'loops ok':>8} {'refused':>7}" + (
            f" {'online ATE m':>12}" if has_gt else ""
        )
    lines = [head]
    for s in summaries:
        c, t = s.counts, s.timing
        line = (
            f"{s.assoc:<6} {c.steps:>6} {c.landmarks:>9} {c.matched_total:>8} "
            f"{t.t_match:>10.3f} {1000 * t.t_match_max:>8.1f} {t.t_total:>10.2f}"
        )
        a = s.accuracy  # (one run scored and another not: '-' cells, not a crash)
        if has_gt:
            ate, odom_ate = (f"{a.ate.rmse:.3f}", f"{a.odom_ate.rmse:.3f}") if a and a.ate else ("-", "-")
            line += f" {ate:>8} {odom_ate:>{w_ate}}"
        if has_rel:
            line += f" {mean_std(a and a.relations):>16} {mean_std(a and a.odom_relations):>{w_rel}}"
        if has_loops:
            line += _loop_columns(s, has_gt)
        lines.append(line)
    a = summaries[0].accuracy if summaries else None
    if a is not None and (a.scan_odom_ate or a.scan_odom_relations):  # the motion input: one for all
        parts = []
        if a.scan_odom_ate is not None:
            parts.append(f"ATE {a.scan_odom_ate.rmse:.3f} m")
        if a.scan_odom_relations is not None:
            parts.append(f"relations {mean_std(a.scan_odom_relations)} m")
        lines.append("scan-matched odometry (the filter's motion input): " + ", ".join(parts))
    lines += span_lines(summaries[0].input) if summaries else []  # (one span for all)
    if (at_once := max((s.timing.concurrent_filters or 1 for s in summaries), default=1)) > 1:  # --jobs
        lines.append(
            f"times: the filters ran {at_once} at a time: they compare with no other run's (--jobs 1)"
        )
    return lines


def _loop_columns(s: RunSummary, has_gt: bool) -> str:
    """A comparison row's loop-closing cells: submaps, closures accepted and refused, and with a
    reference the online (causal) estimate's ATE; '-' where the run had no submaps."""
    c, a = s.counts, s.accuracy
    online = "-" if a is None or a.online_ate is None else f"{a.online_ate.rmse:.3f}"
    if c.submaps is None:
        cells = f" {'-':>7} {'-':>8} {'-':>7}"
    else:
        cells = f" {c.submaps:>7} {c.loops_accepted:>8} {c.loops_rejected:>7}"
    return cells + (f" {online:>12}" if has_gt else "")


def batch_lines(rows: list[dict], keys: list[str]) -> list[str]:
    """``cornerslam batch``: a table of the combinations (a column per swept key, by its last dotted
    part, or whole when two keys share it), each distinct failure once with its count, and the totals."""

    def num(v, fmt):
        return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, fmt)  # nan: no ATE

    last = [k.rsplit(".", 1)[-1] for k in keys]  # (submaps.max_distance and scan_match.max_distance: whole)
    head = ["log", "assoc", *(s if last.count(s) == 1 else k for s, k in zip(last, keys, strict=True))]
    head += ["status", "steps", "landmarks", "ATE m"]
    logs_named: dict[str, set] = {}  # a log by its file name, unless two folders hold logs of that name
    for r in rows:
        logs_named.setdefault(Path(r["log"]).name, set()).add(r["log"])
    table = [
        [
            Path(r["log"]).name if len(logs_named[Path(r["log"]).name]) == 1 else r["log"],
            r["assoc"],
            *(str(r[k]) for k in keys),
            r["status"],
            num(r["steps"], "d"),
            num(r["landmarks"], "d"),
            num(r["ate_rmse"], ".3f"),
        ]
        for r in rows
    ]
    widths = [max(len(str(x)) for x in col) for col in zip(head, *table, strict=True)]
    lines = [
        "  ".join(str(x).ljust(w) for x, w in zip(line, widths, strict=True)).rstrip()
        for line in [head, *table]
    ]
    failures: dict[tuple[str, str], int] = {}
    for r in rows:
        if r["status"] == "failed":
            key = (r["log"], r["error"])
            failures[key] = failures.get(key, 0) + 1
    lines += [f"failed ({n}x): {log_path}: {error}" for (log_path, error), n in failures.items()]
    failed, skipped = batch_counts(rows)
    lines.append(
        f"{len(rows)} combination{'' if len(rows) == 1 else 's'}: {len(rows) - failed - skipped} ran, "
        f"{skipped} skipped (complete), {failed} failed"
    )
    return lines


def batch_counts(rows: list[dict]) -> tuple[int, int]:
    """(failed, skipped) combinations of a batch's rows."""
    return sum(r["status"] == "failed" for r in rows), sum(r["status"] == "skipped" for r in rows)


def info_lines(
    log_path: str | Path,
    i: LogInfo,
    laser: tuple[float, float, float] | None,
    scan: Scan | None = None,
    preset: str | None = None,
    upside_down: bool = False,
    tf_frames: tuple[str, str] | None = None,
    mount_read: bool = True,
    mount_text: str = "",
    flip_from_config: bool = False,
    deskew: bool = True,
    beam_time: float = 0.0,
) -> list[str]:
    """``cornerslam info``: the log's format, topics with counts and rates, what a run would use
    (``laser``: the laser's (x, y, yaw) in the base frame from tf — ``tf_frames`` names the two,
    e.g. (base_footprint, laser) — a CARMEN log's ROBOTLASER1 laser pose — or None, and
    ``upside_down`` there (``flip_from_config``: that from the config, the log's mount being planar);
    ``mount_text``: ``laser`` is instead the config's mount, from where it says;
    not ``mount_read``: not looked up, the log's problems coming first; ``scan``:
    the first scan, its geometry and beam times, with the laser ``preset`` it matches, and whether a run
    would deskew it: ``deskew`` and ``beam_time``, the config's), problems and notes."""
    n = "unknown" if i.n_messages is None else i.n_messages
    lines = [f"file:      {display_path(log_path)}", f"format:    {i.format}", f"messages:  {n}"]
    if i.start is not None:
        lines.append(f"start:     {i.start:.3f} s")
        lines.append(f"duration:  {i.duration:.2f} s")
    lines.append("topics:")
    # names and types as the log has them, control characters escaped (short_text); the columns as wide as
    # the longest (geometry_msgs/PoseWithCovarianceStamped) up to 60
    names = [(short_text(t.name, 200), short_text(t.msgtype, 200)) for t in i.topics]
    wide = [min(max([least, *(len(n[k]) for n in names)]), 60) for k, least in ((0, 28), (1, 30))]
    for t, (name, msgtype) in zip(i.topics, names, strict=True):
        count = "?" if t.count is None else str(t.count)
        rate = f"{t.rate_hz:8.2f} Hz" if t.rate_hz else ""
        note = f" [{t.encoding_note}]" if t.encoding_note else ""
        lines.append(f"  {name:<{wide[0]}} {msgtype:<{wide[1]}} {count:>8} msgs {rate}{note}")
    lines.append("run would use:")
    lines.append(f"  scans     {short_text(i.scan_topic, 200) or '-'}")
    if i.odom_source == SCANS_SOURCE:  # (input.odometry: scans)
        lines.append(f"  odometry  from {i.odom_source}")
    else:
        lines.append(
            f"  odometry  {short_text(i.odom_topic, 200) or '-'} ({i.odom_source or _no_odometry(i)})"
        )
    flip = ", upside down: scans mirrored" if upside_down else ""
    if upside_down and flip_from_config and laser is not None and not mount_text:  # (a planar log mount)
        flip = ", upside down (input.laser.upside_down): scans mirrored"
    if laser is not None:
        x, y, yaw = laser
        source = mount_text or (ROBOTLASER_SOURCE if i.format == "carmen" else "from tf")
        if tf_frames and i.format != "carmen" and not mount_text:
            source += f" {short_text(tf_frames[0])}→{short_text(tf_frames[1])}"
        lines.append(f"  laser     x={x:.3f} m y={y:.3f} m yaw={yaw:.3f} rad{flip} ({source})")
    elif not i.scan_topic and i.format != "carmen":  # tf gives the mount of the scan topic's frame: none yet
        lines.append("  laser     - (no scan topic chosen)")
    elif not mount_read:  # (the robot's frame, from its odometry, is where the mount is looked up from)
        lines.append("  laser     - (not looked up: the problem below comes first)")
    else:
        where = "not in its laser lines" if i.format == "carmen" else "not on tf"
        default = "from the config's input.laser (built-in default x=0 y=0 yaw=0)"
        lines.append(f"  laser     {where}: {default}{flip}")
    if scan is not None:
        lines += scan_lines(scan, preset, deskew, beam_time)
    lines += [f"problem:   {text}" for text in i.problems]
    lines += [f"note:      {text}" for text in i.notes]
    return lines


def _no_odometry(i: LogInfo) -> str:
    """Why ``info`` names no odometry topic: several Odometry topics (run takes one named /odom, or the
    one in the scans' namespace — with no scan topic chosen yet, --scan-topic may choose it —, else
    refuses to guess), or none."""
    n = sum(t.msgtype == "nav_msgs/Odometry" for t in i.topics)
    if n <= 1:
        return "none found"
    robot = "" if i.scan_topic else ", or --scan-topic: the one in the scans' namespace is taken"
    return f"{n} nav_msgs/Odometry topics: choose one with --odom-topic{robot}"


def scan_lines(scan: Scan, preset: str | None, deskew: bool = True, beam_time: float = 0.0) -> list[str]:
    """``info``'s lines on the first scan: its beams, the laser preset a run would take for them
    (lasers.py, ``input.laser_preset: auto``) and whether its beams' times are known and used as a run
    uses them (``deskew``, ``beam_time``: the config's ``input.deskew`` and ``input.beam_time``)."""
    inc = math.degrees(abs(scan.angle_increment))
    fov = inc * max(scan.n_beams - 1, 0)
    which = f"preset {preset}" if preset else "no laser preset matches (the config's sensor model)"
    if preset == "none":  # (input.laser_preset=none: none asked for)
        which = "no laser preset (input.laser_preset=none: the config's sensor model)"
    spread = f"over {fov:.1f}° ({inc:.3f}° apart)" if scan.n_beams > 1 else "(a single beam)"
    lines = [f"  beams     {scan.n_beams} {spread}, {scan.range_min:.3f}–{scan.range_max:.3f} m: {which}"]
    if scan.range_max <= scan.range_min:  # (a driver's parameter: a run refuses the log)
        lines[0] += " — range_max at or below range_min: every reading counts as no return"
    dt, where = (scan.time_increment, "the log's time_increment") if scan.time_increment else (beam_time, "")
    used = "deskewed" if deskew else "not deskewed (input.deskew=false)"
    if dt:  # (frontend._deskewed: the message's own time_increment, else input.beam_time)
        sweep = 1e3 * abs(dt) * max(scan.n_beams - 1, 0)
        where = where or "not in the log: input.beam_time"
        lines.append(f"  beam times {1e6 * abs(dt):.2f} µs apart ({where}, {sweep:.1f} ms a sweep): {used}")
    else:
        why = "input.beam_time to deskew" if deskew else "input.deskew=false"
        lines.append(f"  beam times not in the log: scans used as recorded ({why})")
    return lines


def evaluation_lines(res: Accuracy) -> list[str]:
    """``cornerslam evaluate``: ATE and RPE against ground truth, the relation error, as present in
    ``res`` (``evaluate.evaluate_files``)."""
    lines = []
    if res.ate is not None:
        a = res.ate
        per_m = "-" if math.isnan(res.rpe_per_m) else f"{res.rpe_per_m:.4f}"  # path shorter than 1 m
        scaled = "" if a.scale is None else f", scale corrected ×{a.scale:.5f}"
        holes = f"; {a.in_holes} in gaps of the ground truth not scored" if a.in_holes else ""
        lines.append(
            f"ATE  rmse {a.rmse:.4f} m  mean {a.mean:.4f} m  max {a.max:.4f} m  (n={a.n}{scaled}{holes})"
        )
        rescaled = "" if a.scale is None else f" (scale corrected ×{a.scale:.5f}, as evo_rpe -as)"
        lines.append(f"RPE  per step {res.rpe_step_rmse:.4f} m  per metre {per_m} m/m{rescaled}")
    if res.relations is not None:
        lines.append(f"relations: {relation_text(res.relations)}")
    return lines


def scored_line(out_dir, ground_truth, relations, correct_scale: bool) -> str:
    """``cornerslam evaluate``'s last line: what was scored against what, and how aligned (evo users
    compare with ``evo_ape``, whose default is no alignment)."""
    p = Path(out_dir)
    what = p / "trajectory.tum" if p.is_dir() else p
    against = []
    if ground_truth:
        how = "Sim(2)-aligned, as evo_ape -a -s" if correct_scale else "SE(2)-aligned, as evo_ape -a"
        against.append(f"ground truth {display_path(ground_truth)} ({how})")
    if relations:
        against.append(f"relations {display_path(relations)}")
    return f"scored: {display_path(what)} against {' and '.join(against)}"


def scan_heading(step: int, scan: Scan) -> str:
    """``cornerslam extract``: which scan, when, and how many of its beams are valid."""
    return f"scan {step} at {scan.stamp:.3f} s: {len(scan.ranges)} valid of {scan.n_beams} beams"
