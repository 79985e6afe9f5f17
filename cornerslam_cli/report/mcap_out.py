"""A run's results as an MCAP file, to open beside the input log: in Foxglove (profile ``foxglove``, the
default: Foxglove's schemas in JSON, report/mcap_foxglove.py) or played with ``ros2 bag play`` to RViz
(``ros2``: ROS 2 messages in CDR, report/mcap_ros2.py). This module gathers what the
file says (:func:`_items`, the same for every profile) and writes it; the encodings say it.

Topics (frame ``map`` is the SLAM map frame, the first corrected pose; log times are the scan stamps
from trajectory.csv, so everything lines up with the input log), with the Foxglove profile's schemas
(the ROS 2 types: report/mcap_ros2.py):

=====================================  =========================  ========================================
topic                                  schema                     messages
=====================================  =========================  ========================================
``/cornerslam/pose``                   foxglove.PoseInFrame       one per step: corrected robot pose
``/cornerslam/odom_pose``              foxglove.PoseInFrame       one per step: odometry, anchored on the
                                                                  first corrected pose
``/cornerslam/path``                   foxglove.PosesInFrame      one, at the first stamp: whole corrected
                                                                  trajectory
``/cornerslam/odom_path``              foxglove.PosesInFrame      one: whole odometry trajectory
``/cornerslam/ground_truth_path``      foxglove.PosesInFrame      one, only with ground truth (SE(2)-
                                                                  aligned like the ATE)
``/cornerslam/tf``                     foxglove.FrameTransform    one per step: ``map`` → odom frame
                                                                  (corrected ∘ the odometry as logged⁻¹;
                                                                  the log's tf odom → base when it has
                                                                  one beside the Odometry topic read)
``/cornerslam/odom_tf``                foxglove.FrameTransform    one per step, only when the log has no
                                                                  tf odom → base: odom → base frame
                                                                  from the log's odometry
``/cornerslam/scan``                   foxglove.PointCloud        one per step (when the run passes its
                                                                  scans): the scan's end points in
                                                                  ``map`` at the corrected pose
``/cornerslam/landmarks``              foxglove.SceneUpdate       one per landmark, at the stamp of the
                                                                  step that created it: sphere, 3σ
                                                                  ellipse (line loop), corner direction
``/cornerslam/segments``               foxglove.SceneUpdate       one per step: that step's segments
                                                                  (line list, kept, so the map builds up)
``/cornerslam/grid``                   foxglove.Grid              one, at the last stamp, when the run wrote
                                                                  map.pgm: the occupancy grid, int8 cells
                                                                  ``occupancy`` 100 / 0 / −1 (occupied /
                                                                  free / unknown, nav_msgs' values)
=====================================  =========================  ========================================

The transform is ``map`` → odom (REP 105: corrected pose ∘ odometry⁻¹), not ``map`` → base: the input
log usually already carries odom → base_link, and a second parent for base_link would make Foxglove's
transform tree flip between the two. With both files open, base_link sits at the corrected pose. A log
without odom → base_link on tf (``input.odom_on_tf`` false in summary.json: odometry from
nav_msgs/Odometry only, CARMEN) gets it here, from the odometry the run used, so the results MCAP
alone places the robot; with the scans in ``map`` it shows the robot moving through its map. The
poses are in the log's odometry frame, so ``map`` and odom coincide at the first scan.
Landmarks are the final estimates (map.csv holds only the final map), shown from their creation on.
"""

from __future__ import annotations

import contextlib
import csv
import logging
from collections.abc import Callable, Iterator, Sequence
from decimal import Decimal
from pathlib import Path

import numpy as np

from ..errors import OutputError, display_path
from ..geometry import compose, compose_inverse, interpolate, inverse
from .mcap_items import MAP_FRAME, PROFILES, TOPICS, LandmarkItem
from .occupancy import ScanStore, read_grid
from .ownership import RESULTS_MCAP_LIBRARY
from .run_dir import ellipse_polygons, load_run

log = logging.getLogger("cornerslam.run")


def stamp_to_ns(text: str) -> int:
    """Decimal seconds as written in trajectory.csv → integer nanoseconds, without float rounding."""
    return int((Decimal(text) * 1_000_000_000).to_integral_value())


def _stamp_texts(path: Path) -> list[str]:
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        return [row["stamp"] for row in reader]


def write_results_mcap(
    out_dir: Path,
    path: Path,
    results: Path | None = None,
    ground_truth: str | Path | None = None,
    scans: ScanStore | None = None,
    anchors: Sequence[tuple[float, tuple[float, float, float]]] = (),
    clock_offset: int = 0,
    tf_odometry: tuple[np.ndarray, np.ndarray] | None = None,
    warn: Callable[..., None] | None = None,
    profile: str = "foxglove",
) -> Path:
    """Write a run directory's trajectory, landmarks and segment map to ``path`` (MCAP in ``profile``'s
    encoding, one of PROFILES); returns ``path``. See the module docstring for the topics. ``results`` is
    the name of the run directory recorded in the metadata (default ``out_dir``; a staging directory's
    target); ``ground_truth`` the TUM file the run was scored against (default: the one its summary
    names); ``scans`` the run's scans, one per step (occupancy.ScanStore), published on
    ``/cornerslam/scan``; ``anchors`` the run's re-anchorings of its odometry (logs/sync.py SyncStats),
    taken back out of it; ``clock_offset`` [ns] added to every log and publish time (the log's recorder
    clock, ahead of the stamps: pipeline.recorder_clock), not to the messages' own timestamps.
    ``tf_odometry``: the log's tf odom → base (stamps, poses) where the run read another odometry: map →
    odom is built on it at the steps inside its span, so that the log's own tf places the robot at its
    corrected pose."""
    from mcap.writer import Writer

    encoding = _encoding(profile)
    out_dir, path = Path(out_dir), Path(path)
    run = load_run(out_dir, ground_truth)
    items = _items(out_dir, run, scans, anchors, tf_odometry, warn)
    if items:
        check_stamps(items[0][0], items[-1][0], clock_offset, profile)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile=encoding.profile, library=RESULTS_MCAP_LIBRARY)
        schema_ids: dict[str, int] = {}
        channel_ids: dict[str, int] = {}  # by topic: two keys may share one (ROS 2's /tf)
        channels = {key: encoding.channel(key) for key in {key for _, key, _ in items}}
        # a topic with nothing to say is not declared, nor an item the encoding does not write (None)
        used = {key: c for key, c in channels.items() if c is not None}
        for c in (used[k] for k in [*TOPICS, *sorted(set(used) - set(TOPICS))] if k in used):
            if c.schema not in schema_ids:
                schema_ids[c.schema] = w.register_schema(c.schema, c.schema_encoding, c.schema_data)
            if c.topic not in channel_ids:
                channel_ids[c.topic] = w.register_channel(
                    c.topic, c.message_encoding, schema_ids[c.schema], c.metadata
                )
        seq: dict[str, int] = dict.fromkeys(channel_ids, 0)
        for ns, key, item in items:
            if key not in used:
                continue
            topic = used[key].topic
            data = encoding.encode(ns, key, item)
            w.add_message(channel_ids[topic], ns + clock_offset, data, ns + clock_offset, seq[topic])
            seq[topic] += 1
        for name, data in encoding.metadata.items():
            w.add_metadata(name, data)
        w.add_metadata(
            "cornerslam",
            {
                "log": run.summary.input.log,
                "assoc": run.assoc,
                "version": run.summary.cornerslam_version,
                "results": display_path(out_dir if results is None else results),  # MCAP strings are UTF-8
            },
        )
        w.finish()
    return path


class StampRangeError(ValueError):
    """The log's stamps do not fit the results MCAP's times (:func:`stamps_refused` names the file)."""

    def __init__(self, msg: str, hint: str):
        super().__init__(msg)
        self.hint = hint


@contextlib.contextmanager
def stamps_refused(name: str | Path) -> Iterator[None]:
    """A StampRangeError raised inside as the OutputError of the ``--mcap-out`` file ``name``: exit 2, the
    run's output not written (a results MCAP asked for and missing would look complete)."""
    try:
        yield
    except StampRangeError as e:
        raise OutputError(f"--mcap-out '{display_path(name)}' cannot be written: {e}", e.hint) from None


ROS2_LAST_SECOND = 2**31 - 1  # builtin_interfaces/Time.sec is an int32: 2038-01-19


def check_stamps(first_ns: int, last_ns: int, clock_offset: int, profile: str) -> None:
    """StampRangeError unless the stamps from ``first_ns`` to ``last_ns`` (and the log times, ``clock_offset``
    ns ahead) fit: MCAP's times and Foxglove's are unsigned, ROS 2's seconds an int32."""
    first_s = min(first_ns, first_ns + clock_offset) / 1e9
    if first_s < 0:
        raise StampRangeError(
            f"the log's stamps begin before 1970 ({first_s:.3f} s): MCAP's times are unsigned",
            "run it without --mcap-out",
        )
    if profile == "ros2" and last_ns // 1_000_000_000 > ROS2_LAST_SECOND:
        raise StampRangeError(
            f"the log's stamps reach {last_ns / 1e9:.3f} s, past ROS 2's int32 seconds (2038-01-19)",
            "write it with --mcap-profile foxglove",
        )


def _encoding(profile: str):
    """The encoder of ``profile`` (PROFILES): channel(key) → Channel, encode(ns, key, item) → bytes."""
    if profile == "foxglove":
        from .mcap_foxglove import FoxgloveEncoding

        return FoxgloveEncoding()
    if profile == "ros2":
        from .mcap_ros2 import Ros2Encoding

        return Ros2Encoding()
    raise ValueError(f"unknown results MCAP profile {profile!r}: one of {', '.join(PROFILES)}")


def _items(
    out_dir: Path,
    run,
    scans: ScanStore | None,
    anchors: Sequence,
    tf_odometry: tuple[np.ndarray, np.ndarray] | None,
    warn: Callable[..., None] | None,
) -> list[tuple[int, str, object]]:
    """What the results MCAP says, before any encoding, in log-time order: (stamp ns, topic key, item) —
    a pose (3,) for ``pose``/``odom_pose``; (parent, child, pose) for ``tf``/``odom_tf``; (points (k, 2),
    their origin (2,)) for ``scan``, and that origin once for ``scan_origin`` (for an encoding whose
    clouds hold no pose); (poses (n, 3), stamps ns or None) for the paths; a LandmarkItem; (step,
    segments (k, 4) x1 y1 x2 y2) for ``segments``; an occupancy.Grid for ``grid``."""
    stamp_texts = _stamp_texts(out_dir / "trajectory.csv")
    stamps_ns = [stamp_to_ns(t) for t in stamp_texts]
    ns_of_step = dict(zip(run.steps.astype(int).tolist(), stamps_ns, strict=True))
    # odom-frame poses as logged, for the map → odom transform
    stamps = np.array([float(t) for t in stamp_texts])
    odom_raw = as_logged(read_odom(out_dir), stamps, anchors)
    if tf_odometry is not None:  # (on the scans alone the log's tf and the run's odometry always differ)
        alone = run.summary.scan_odometry is not None
        odom_raw = on_logged_tf(odom_raw, stamps, *tf_odometry, (lambda *_: None) if alone else warn)
    inp = run.summary.config.get("input", {})  # the run's config
    # the frame the odometry gave the poses in (a nav_msgs/Odometry's frame_id), else the config's
    odom_frame = run.summary.input.odom_frame or str(inp.get("odom_frame") or "odom")
    # the frame the odometry gave the pose of (a nav_msgs/Odometry's child_frame_id), else the config's
    base_frame = run.summary.input.base_frame or str(inp.get("base_frame") or "base_link")
    odom_tf = not run.summary.input.odom_on_tf  # the log lacks odom → base on tf (or did not say)

    items: list[tuple[int, str, object]] = []
    for ns, c, o, m in zip(stamps_ns, run.corrected, run.odometry, compose_inverse(run.corrected, odom_raw),
                           strict=True):  # fmt: skip
        items += [(ns, "pose", c), (ns, "odom_pose", o), (ns, "tf", (MAP_FRAME, odom_frame, m))]
    if odom_tf:
        frames = (odom_frame, base_frame)
        items += [(ns, "odom_tf", (*frames, o)) for ns, o in zip(stamps_ns, odom_raw, strict=True)]
    if scans is not None:
        items += [(ns, "scan", (xy, scans.anchor)) for ns, xy in zip(stamps_ns, scans.points, strict=True)]
        if stamps_ns:
            items.append((stamps_ns[0], "scan_origin", scans.anchor))
    if stamps_ns:
        t0 = stamps_ns[0]
        items.append((t0, "path", (run.corrected, stamps_ns)))
        items.append((t0, "odom_path", (run.odometry, stamps_ns)))
        if run.ground_truth is not None:  # (at the steps' stamps where it has one pose a step)
            gt_ns = stamps_ns if len(run.ground_truth) == len(stamps_ns) else None
            items.append((t0, "ground_truth_path", (run.ground_truth, gt_ns)))
    items += _landmark_items(run.landmarks, ns_of_step, stamps_ns[0] if stamps_ns else 0)
    items += _segment_items(run.lines, run.steps.astype(int), stamps_ns)
    if stamps_ns and (grid := read_grid(out_dir)) is not None:  # (written before the results MCAP)
        items.append((stamps_ns[-1], "grid", grid))
    items.sort(key=lambda m: m[0])  # stable: per-stamp order as appended
    return items


def as_logged(odom: np.ndarray, stamps: Sequence[float], anchors: Sequence) -> np.ndarray:
    """The odometry poses ``odom`` (n, 3) at ``stamps`` as the log gave them: each re-anchoring's F (from
    its stamp on, corrected = F ∘ raw; ``anchors`` in stamp order) taken back out, raw = F⁻¹ ∘ corrected —
    so that map → odom ∘ the log's own odom → base_link is the corrected pose after an odometry jump too."""
    if not len(anchors) or not len(odom):
        return odom
    at = np.array([a[0] for a in anchors])
    k = np.searchsorted(at, np.asarray(stamps, dtype=float), side="right") - 1  # the anchor in effect
    fix = np.vstack((np.zeros(3), np.array([a[1] for a in anchors])))[k + 1]
    return compose(inverse(fix), odom)


TF_DIFFERS = 0.05  # m: the log's tf odometry this far from the run's is another estimate, warned of


def on_logged_tf(
    odom: np.ndarray,
    stamps: np.ndarray,
    tf_stamps: np.ndarray,
    tf_poses: np.ndarray,
    warn: Callable[..., None] | None = None,
) -> np.ndarray:
    """The odometry poses ``odom`` at ``stamps`` replaced, inside the tf's span, by the log's tf odom → base
    (``tf_stamps``, ``tf_poses``) interpolated there; warned when the two differ by over TF_DIFFERS (the
    tf another estimate of the robot's motion: an EKF's beside the wheels' /odom)."""
    inside = (stamps >= tf_stamps[0]) & (stamps <= tf_stamps[-1])
    if not inside.any():
        return odom
    out = odom.copy()
    out[inside] = interpolate(tf_stamps, tf_poses, stamps[inside])
    off = float(np.max(np.hypot(*(out[inside, :2] - odom[inside, :2]).T)))
    if off > TF_DIFFERS:
        (warn or log.warning)(
            "the log's tf odom → base differs from the odometry the run used by up to %.2f m: the results "
            "MCAP's map → odom is built on the tf's, so the log's own tf places the robot at its corrected "
            "pose", off,
        )  # fmt: skip
    return out


def read_odom(out_dir: Path) -> np.ndarray:
    """Odometry poses (n, 3) in the odom frame (trajectory.csv odom_* columns: re-anchored across any
    odometry jump, :func:`as_logged` gives them as logged)."""
    from .tables import read_csv

    t = read_csv(Path(out_dir) / "trajectory.csv")
    return np.column_stack((t["odom_x"], t["odom_y"], t["odom_theta"]))


def _landmark_items(lm: dict[str, np.ndarray], ns_of_step: dict[int, int], t0: int) -> list:
    """One item per landmark, at the stamp of the step that created it."""
    n = len(lm.get("id", ()))
    if n == 0:
        return []
    xy = np.column_stack((lm["x"], lm["y"]))
    cov = np.empty((n, 2, 2))
    cov[:, 0, 0], cov[:, 1, 1] = lm["var_x"], lm["var_y"]
    cov[:, 0, 1] = cov[:, 1, 0] = lm["cov_xy"]
    ellipses = ellipse_polygons(xy, np.nan_to_num(cov), k=24)
    out = []
    for i in range(n):
        item = LandmarkItem(
            int(lm["id"][i]), float(lm["x"][i]), float(lm["y"][i]), float(lm["phi"][i]), ellipses[i],
            int(lm["n_obs"][i]), int(lm["first_step"][i]), int(lm["last_step"][i]),
        )  # fmt: skip
        out.append((ns_of_step.get(item.first_step, t0), "landmarks", item))
    return out


def _segment_items(lines: dict[str, np.ndarray], steps: np.ndarray, stamps_ns: list[int]) -> list:
    """One item per step: its segments (k, 4) x1 y1 x2 y2 (lines.csv), none on a step without."""
    seg_steps = lines.get("step", np.empty(0)).astype(int)
    order = np.argsort(seg_steps, kind="stable")
    seg_steps = seg_steps[order]
    ends = [np.asarray(lines.get(k, np.empty(0)), dtype=float) for k in ("x1", "y1", "x2", "y2")]
    segs = np.column_stack(ends)[order] if len(seg_steps) else np.empty((0, 4))
    out = []
    for step, ns in zip(steps.tolist(), stamps_ns, strict=True):
        lo, hi = np.searchsorted(seg_steps, [step, step + 1])
        out.append((ns, "segments", (step, segs[lo:hi])))
    return out
