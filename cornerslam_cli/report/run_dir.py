"""A run output directory read back for drawing (report/plots.py) and for the results MCAP
(report/mcap_out.py): its tables and summary, the trajectories in the map frame, landmark ellipses.
:func:`check_one_run` refuses a compare or batch directory where one run's is expected (``evaluate``).

Frames: the corrected trajectory and the map are in the map frame (the first corrected pose). The
odometry is drawn in the map frame by anchoring its first pose on the first corrected pose, and the
ground truth by the SE(2) alignment the ATE uses (``evaluate.align_se2``), so the three overlay.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import LogError, ResultsError, display_path
from ..evaluate import align_se2, apply_se2, interpolate_inside, read_relations
from ..results import RunSummary
from .ownership import file_size, output_kind, read_marker
from .tables import read_csv, read_tum

log = logging.getLogger(__name__)

ELLIPSE_SIGMA = 3.0  # ellipses are drawn at ±3σ along each principal axis


@dataclass(frozen=True)
class RunData:
    """One run directory's tables, with the trajectories expressed in the map frame.

    corrected, odometry : (n, 3) x, y [m], θ [rad] per step, map frame.
    scan_odometry : (n, 3) the scan-matched odometry (map frame), or None when scan matching was off.
    ground_truth : (g, 3) SE(2)-aligned onto ``corrected``, or None.
    landmarks : map.csv columns; lines : lines.csv columns; timing : timing.csv columns.
    submap : (n,) int the submap of each step (all 0 for a single map), or None in a run written
    before submaps; loops : loops.csv columns, or None when the run had no submaps.
    """

    out_dir: Path
    summary: RunSummary
    log_name: str
    assoc: str
    steps: np.ndarray
    corrected: np.ndarray
    odometry: np.ndarray
    scan_odometry: np.ndarray | None
    ground_truth: np.ndarray | None
    landmarks: dict[str, np.ndarray]
    lines: dict[str, np.ndarray]
    timing: dict[str, np.ndarray]
    submap: np.ndarray | None = None
    loops: dict[str, np.ndarray] | None = None

    @property
    def title(self) -> str:
        return f"{self.log_name} — {self.assoc}"

    def map_landmarks(self) -> np.ndarray:
        """(n,) the landmarks in the whole map after each step: timing.csv's ``n_landmarks`` counts the
        open submap's, so each closed submap's count at its last step is added to the steps after it (at
        the end map.csv's rows, but for landmarks still tentative, ``ekf.tentative_sightings`` > 1, which
        the count holds and map.csv does not)."""
        n = self.timing["n_landmarks"].astype(np.int64)
        if self.submap is None or len(self.submap) != len(n) or len(n) == 0:
            return n
        s = self.submap
        last = np.flatnonzero(np.r_[s[1:] != s[:-1], False])  # each submap's last step, but the open one's
        closed = np.zeros(len(n), dtype=np.int64)
        closed[last + 1] = n[last]
        return n + np.cumsum(closed)

    def loop_closures(self) -> np.ndarray:
        """(k, 2, 2) the accepted loop closures as segments from submap a's origin to submap b's
        (map frame, on the corrected trajectory: :func:`submap_origins`); (0, 2, 2) without any."""
        if self.loops is None or self.submap is None or len(self.corrected) == 0:
            return np.zeros((0, 2, 2))
        origins = submap_origins(self.submap, self.corrected)
        accepted = self.loops["accepted"] == 1
        # (a directory written before 2026-12-03 names them submap_from, submap_to)
        a, b = ("other_submap", "submap") if "submap" in self.loops else ("submap_from", "submap_to")
        ab = np.column_stack((self.loops[a], self.loops[b]))[accepted]
        known = np.all((ab >= 0) & (ab < len(origins)), axis=1)
        if not known.all():  # an edited or mismatched directory: draw what can be placed
            log.warning(
                "%s: %d accepted loop closure(s) name a submap that trajectory.csv does not have "
                "(%d submaps): not drawn", self.out_dir / "loops.csv", int((~known).sum()), len(origins)
            )  # fmt: skip
        return origins[ab[known].astype(np.int64)]


def check_one_run(path: str | Path) -> None:
    """Refuse ``path`` when it is a compare or batch output directory: it holds one run directory
    per associator or combination, not a trajectory. The ``LogError`` names them, so that the user
    can pick one (it used to say that ``path/trajectory.tum`` does not exist)."""
    p = Path(path)
    kind = output_kind(p) if p.is_dir() else None
    if kind not in ("compare", "batch"):
        return
    runs = sorted(d for d in p.iterdir() if d.is_dir() and output_kind(d) == "run")
    each = "associator" if kind == "compare" else "combination"
    names = ", ".join(d.name for d in runs[:6]) + (f", … ({len(runs)} in all)" if len(runs) > 6 else "")
    holds = f"one run directory per {each} ({names})" if runs else f"no run directory (one per {each})"
    example = f"e.g. cornerslam evaluate {display_path(runs[0])}" if runs else "give a run's directory"
    raise LogError(
        f"'{display_path(p)}' is a cornerslam {kind} output: it holds {holds}",
        f"evaluate one of them with the same options: {example}",
    )


@dataclass(frozen=True)
class Recorded:
    """What a run directory's summary.json says it was scored against, as far as the files here still
    hold it (:func:`recorded_reference`): the ground truth, the relations and their time offset; for each
    that is not used, why not (empty: nothing recorded)."""

    ground_truth: str | None = None
    relations: str | None = None
    time_offset: float = 0.0
    why_not: tuple[str, ...] = ()


def recorded_reference(path: str | Path) -> Recorded:
    """The ground truth and relations a run directory ``path`` was scored against (its summary.json's
    ``accuracy.ground_truth`` / ``relations_file``, as the run named them: relative to where it ran, the
    relations with their ``relations_time_offset``), each when a file there from here holds the same poses
    or relations (sha256 against ``hashes.ground_truth`` / ``hashes.relations``); else not, and why. A
    file of that name with other contents is not used: another file, or this one changed."""
    p = Path(path)
    if p.is_dir() and not (p / "summary.json").is_file():
        return Recorded(why_not=(f"'{p}' has no summary.json to name what the run was scored against",))
    try:
        s = RunSummary.read(p) if (p / "summary.json").is_file() else None
    except ResultsError as e:  # damaged, cut short: what it names cannot be read from it
        return Recorded(why_not=(e.msg,))  # ("cannot read the run summary '…/summary.json': why")
    acc = s.accuracy if s is not None else None
    if acc is None:
        return Recorded()
    why: list[str] = []
    gt = _same_file(acc.ground_truth, "poses", s.hashes.ground_truth, _gt_hash, why)
    rel = _same_file(acc.relations_file, "relations", s.hashes.relations, _relations_hash, why)
    offset = acc.relations_time_offset
    if rel and offset is None:  # (a hash without an offset: not written so; refused all the same)
        rel = None
        why.append(f"the run was scored against the relations '{acc.relations_file}' at a --time-offset "
                   "its summary.json does not keep (an older version's run)")  # fmt: skip
    return Recorded(gt, rel, (offset or 0.0) if rel else 0.0, tuple(why))  # (no relations: no offset)


def recorded_offset(path: str | Path, relations: str | Path) -> float | None:
    """The --time-offset the run directory ``path`` scored the relations of the file ``relations`` at (by
    their sha256, whatever the file's name now), None when it did not score these, scored none of them
    there (an offset that fails too), kept no offset, or ``relations`` is no regular file (a pipe is read
    once: opened again it would wait for a writer)."""
    p = Path(path)
    try:
        s = RunSummary.read(p) if (p / "summary.json").is_file() else None
        acc = s.accuracy if s is not None else None
        if acc is None or acc.relations_time_offset is None or s.hashes.relations is None:
            return None
        if acc.relations is None or acc.relations.n == 0 or not Path(relations).is_file():
            return None
        return acc.relations_time_offset if _relations_hash(str(relations)) == s.hashes.relations else None
    except (ResultsError, OSError, LogError):  # (what evaluate refused already: nothing to add)
        return None


def _gt_hash(name: str) -> str:
    from .summary import reference_hash

    return reference_hash(*read_tum(name, "ground truth", lambda _: None))


def _relations_hash(name: str) -> str:
    from .summary import reference_hash

    return reference_hash(read_relations(name, lambda *_: None))  # (quietly, as _gt_hash reads)


def _same_file(name: str | None, what: str, recorded: str | None, hash_of, why: list[str]) -> str | None:
    """``name`` when the file of that name here holds the ``what`` whose sha256 the run recorded; else
    None, with why not appended to ``why`` (nothing: no such file recorded)."""
    if not name:
        return None
    if not Path(name).is_file():
        if "\ufffd" in name:  # a name that is not UTF-8: summary.json (JSON) kept it with its bytes replaced
            why.append(f"the run was scored against '{name}', a name that is not UTF-8, not kept as it is")
        else:
            why.append(f"the run was scored against '{name}', not found from here")
        return None
    if recorded is None:  # an older version's run: which file it was cannot be told
        why.append(f"the run names '{name}' but kept no sha256 of its {what} (an older version's run)")
        return None
    try:  # (quietly: reading it to score says what is odd about it)
        same = hash_of(name) == recorded
    except (OSError, LogError):
        same = False
    if not same:
        why.append(f"'{name}' here does not hold the {what} the run was scored against")
        return None
    return name


def check_unchanged(path: str | Path, name: str = "trajectory.tum") -> None:
    """Refuse the run directory ``path`` when its file ``name`` is not the size its run wrote (its
    marker's ``sizes``): cut short (a copy interrupted, a disk full) or changed since, its score would
    be a part's, as if the whole. A link in its place is followed (what is read is checked). An output
    without recorded sizes (an older version's, or one copied without its marker) is checked by its poses
    against the steps its summary.json counts, when it has one; a file given by its own path is scored as
    it is."""
    p = Path(path)
    sizes = (read_marker(p) or {}).get("sizes") if p.is_dir() else None
    wrote = sizes.get(name) if isinstance(sizes, dict) else None
    has = file_size((p / name).resolve()) if p.is_dir() else -1
    if has < 0 or has == wrote:
        return  # (missing, which reading it says)
    if type(wrote) is not int or wrote < 0:
        _check_poses(p, name)
        return
    raise LogError(
        f"'{display_path(p / name)}' holds {has:,} bytes, but its run wrote {wrote:,}: it was cut short or "
        "changed since",
        f"run the log again, or score the file as it is: cornerslam evaluate {display_path(p / name)} …",
    )


def _check_poses(p: Path, name: str) -> None:
    """:func:`check_unchanged` without recorded sizes: the poses of ``name`` against the steps of the run's
    summary.json (one pose a step), when it can be read."""
    try:
        steps = RunSummary.read(p).counts.steps
        with open(p / name, "rb") as f:
            poses = sum(1 for line in f if line.strip() and not line.lstrip().startswith(b"#"))
    except (OSError, ResultsError):
        return
    if poses != steps:
        raise LogError(
            f"'{display_path(p / name)}' holds {poses:,} poses, but its run's summary.json counts {steps:,} "
            "steps: it was cut short or changed since",
            f"run the log again, or score the file as it is: cornerslam evaluate {display_path(p / name)} …",
        )


def load_run(out_dir: str | Path, ground_truth: str | Path | None = None) -> RunData:
    """Read a run output directory for plotting. ``ground_truth``: the TUM file the run was scored
    against (default: the one its summary names, which shows a name that is not UTF-8 with U+FFFD
    and so cannot be opened by it)."""
    out_dir = Path(out_dir)
    summary = RunSummary.read(out_dir)
    traj = read_csv(out_dir / "trajectory.csv")
    corrected = np.column_stack((traj["x"], traj["y"], traj["theta"]))
    odom = np.column_stack((traj["odom_x"], traj["odom_y"], traj["odom_theta"]))
    scan_odom = None
    if "scan_odom_x" in traj and summary.scan_matching:
        scan_odom = np.column_stack((traj["scan_odom_x"], traj["scan_odom_y"], traj["scan_odom_theta"]))
    return RunData(
        out_dir=out_dir,
        summary=summary,
        log_name=Path(summary.input.log).name,
        assoc=summary.assoc,
        steps=traj["step"],
        corrected=corrected,
        odometry=odom_in_map(odom, corrected),
        scan_odometry=None if scan_odom is None else odom_in_map(scan_odom, corrected),
        ground_truth=_aligned_ground_truth(summary, traj["stamp"], corrected, ground_truth),
        landmarks=read_csv(out_dir / "map.csv"),
        lines=read_csv(out_dir / "lines.csv"),
        timing=read_csv(out_dir / "timing.csv"),
        submap=traj["submap"].astype(np.int64) if "submap" in traj else None,
        loops=read_csv(out_dir / "loops.csv") if (out_dir / "loops.csv").is_file() else None,
    )


def submap_origins(submap: np.ndarray, corrected: np.ndarray) -> np.ndarray:
    """(s, 2) the position of each submap's origin on the trajectory, from each step's ``submap``
    (non-decreasing from 0): the pose at the last step of submap s − 1 (whose end pose the next
    submap starts from, hierarchy.py), step 0's for submap 0."""
    n_sub = int(submap.max()) + 1 if len(submap) else 0
    if n_sub == 0:
        return np.zeros((0, 2))
    last = np.searchsorted(submap, np.arange(n_sub - 1), side="right") - 1  # of submaps 0 … s − 2
    return corrected[np.concatenate(([0], np.maximum(last, 0))), :2]


def odom_in_map(odom: np.ndarray, corrected: np.ndarray) -> np.ndarray:
    """Odometry poses (odom frame) re-expressed in the map frame: map←odom puts odom[0] on corrected[0]."""
    if len(odom) == 0:
        return odom
    ang = float(corrected[0, 2] - odom[0, 2])
    c, s = np.cos(ang), np.sin(ang)
    t = corrected[0, :2] - np.array([[c, -s], [s, c]]) @ odom[0, :2]
    return apply_se2(ang, t, odom)


def _aligned_ground_truth(
    summary: RunSummary, stamps: np.ndarray, corrected: np.ndarray, path: str | Path | None = None
) -> np.ndarray | None:
    named = summary.accuracy.ground_truth if summary.accuracy else None
    path = path if path is not None and named is not None else named
    if not path or len(corrected) < 2:
        return None
    try:
        gt_t, gt = read_tum(path)
    except Exception as e:  # a moved or deleted file must not stop the plots
        log.warning("ground truth '%s' not drawn: %s", path, e)
        return None
    inside, g = interpolate_inside(gt_t, gt, stamps)
    if inside.sum() < 2:
        return None
    ang, t = align_se2(g[:, :2], corrected[inside, :2])
    return apply_se2(ang, t, gt[(gt_t >= stamps[inside][0]) & (gt_t <= stamps[inside][-1])])


def ellipse_polygons(
    xy: np.ndarray, cov: np.ndarray, n_sigma: float = ELLIPSE_SIGMA, k: int = 32
) -> np.ndarray:
    """Polygons (n, k, 2) of the n_sigma ellipses of (n, 2, 2) position covariances centred at xy."""
    lam, vec = np.linalg.eigh(cov)
    axes = vec * np.sqrt(np.clip(lam, 0.0, None))[:, None, :]  # columns: principal semi-axes at 1σ
    a = np.linspace(0, 2 * np.pi, k, endpoint=False)
    circle = np.column_stack((np.cos(a), np.sin(a)))  # (k, 2)
    return xy[:, None, :] + n_sigma * np.einsum("kj,nij->nki", circle, axes)
