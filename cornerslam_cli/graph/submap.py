"""What the two levels exchange: a closed submap (the local EKF's result in its own frame) and the
result of matching two submaps for a loop closure.

Frames: a submap's frame (its origin) is the robot's pose where the submap before it ended — its last
step, which the filter's new map starts from with zero uncertainty (the first submap's: the first step);
so a later submap's first pose is one step's motion from its origin, not zero (the first submap's first
pose is its origin). A relative pose ``a→b`` is
b's origin expressed in a's frame (x, y, θ); its covariance is of those three numbers, in a's frame —
the convention of the EKF's robot block Σ_rr when a's origin is fixed (graph/posegraph.py turns it into
GTSAM's tangent space).
"""

from __future__ import annotations

import functools
import math
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from ..geometry import (
    compose,
    inverse,
    relative,
    rotate_pose_covariance,
    transform_points,
    wrap_angle,
)
from ..motion.icp import LocalMap, voxel_thin


@dataclass(frozen=True)
class Submap:
    """A closed local map, in its own frame."""

    index: int
    first_step: int
    last_step: int
    landmarks: np.ndarray  # (n, 3) corners x, y, φ
    landmark_P: np.ndarray  # (3n, 3n) their joint covariance
    landmark_ids: np.ndarray  # (n,) ids in map.csv
    points: np.ndarray  # (k, 2) scan end points of its keyframes, voxel-thinned (SubmapConfig.voxel)
    end_pose: np.ndarray  # (3,) the robot at the last step: the next submap's origin
    end_cov: np.ndarray  # (3, 3) its covariance: the sequential factor of the graph
    poses: np.ndarray  # (s, 3) the robot at each of its steps (filtered, causal)
    node: int = 0  # its origin's node in the pose graph
    step_nodes: np.ndarray | None = None  # (s,) the graph node each step hangs from (its anchor) …
    anchor_poses: np.ndarray | None = None  # (s, 3) … and that node's pose in this submap's frame
    pose_covs: np.ndarray | None = None  # (s, 3, 3) the filter's covariance of each of ``poses`` (Σ_rr)

    # What loop closing reads of a submap's corners for every candidate pair it is in, computed at the
    # first (a closed submap does not change; read-only, so no caller can change them either).

    @functools.cached_property
    def landmark_blocks(self) -> np.ndarray:
        """(n, 3, 3) each landmark's own covariance: the diagonal blocks of ``landmark_P``."""
        return _read_only(diagonal_blocks(self.landmark_P))

    @functools.cached_property
    def corner_pairs(self) -> CornerPairs:
        """Every pair of its corners (graph/loops.py's hypotheses)."""
        return CornerPairs.of(self.landmarks)


def diagonal_blocks(P: np.ndarray, which: np.ndarray | None = None) -> np.ndarray:
    """(n, 3, 3) diagonal blocks of a (3n, 3n) joint covariance (``which``: only those landmarks')."""
    rows = np.arange(len(P) // 3) if which is None else which
    idx = 3 * rows[:, None] + np.arange(3)
    return P[idx[:, :, None], idx[:, None, :]]


KEPT_PAIRS = 64  # corner counts whose index pairs are kept (8·n² bytes each)


@functools.lru_cache(maxsize=KEPT_PAIRS)
def _upper_pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.triu_indices(n, 1)``, read-only and kept: on infinite-corridor's revisits (submaps of 1–26
    corners) each call cost far more than its use."""
    i, j = np.triu_indices(n, 1)
    return _read_only(i), _read_only(j)


@dataclass(frozen=True)
class CornerPairs:
    """All pairs i < j of a submap's corners (``np.triu_indices`` order) and their lengths, and the same
    sorted by length (stable).

    i, j : (p,) int64;  length : (p,) m;  sorted_i, sorted_j, sorted_length : (p,) by increasing length
    """

    i: np.ndarray
    j: np.ndarray
    length: np.ndarray
    sorted_i: np.ndarray
    sorted_j: np.ndarray
    sorted_length: np.ndarray

    @staticmethod
    def of(landmarks: np.ndarray) -> CornerPairs:
        """The pairs of corners (n, 3)."""
        lm = np.asarray(landmarks, dtype=float).reshape(-1, 3)
        n = len(lm)
        i, j = _upper_pairs(n) if n <= KEPT_PAIRS else np.triu_indices(n, 1)
        length = np.hypot(lm[j, 0] - lm[i, 0], lm[j, 1] - lm[i, 1])
        order = np.argsort(length, kind="stable")
        parts = (i, j, length, i[order], j[order], length[order])
        return CornerPairs(*(_read_only(x) for x in parts))


def _read_only(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


def local_map(submap: Submap) -> LocalMap:
    """Submap's points as ICP's map (normals, nearest-point grid)."""
    return LocalMap.build(submap.points)


class LocalMaps:
    """:func:`local_map` of the ``size`` submaps most recently asked for: loop closing verifies a new
    submap against the same few neighbours close after close (a revisited corridor); memory stays
    bounded by ``size``. The maps are the ones :func:`local_map` builds (immutable); a submap that is not
    the one a map was built for (the same index) gets its own."""

    def __init__(self, size: int):
        self.size = max(1, size)
        self._maps: OrderedDict[int, tuple[Submap, LocalMap]] = OrderedDict()

    def __call__(self, submap: Submap) -> LocalMap:
        kept = self._maps.pop(submap.index, None)
        built = kept[1] if kept is not None and kept[0] is submap else local_map(submap)
        self._maps[submap.index] = (submap, built)
        if len(self._maps) > self.size:
            self._maps.popitem(last=False)
        return built


@dataclass(frozen=True)
class LoopMatch:
    """Submap b matched against an earlier submap a (graph/loops.py)."""

    pose: np.ndarray  # (3,) b's origin in a's frame
    cov: np.ndarray  # (3, 3) covariance of ``pose`` in a's frame
    n_corners: int  # corners in the jointly compatible set
    fitness: float  # share of b's points overlapping a that lie within inlier_distance of a's points
    accepted: bool
    reason: str = ""  # why not accepted ("" when accepted)
    pairs: np.ndarray | None = None  # (k, 2) matched corners: rows of b.landmarks, rows of a.landmarks


class OpenSubmap:
    """The submap being built: its steps' local poses, its scans' points, how far the robot went."""

    def __init__(self, index: int, first_step: int, node: int, keep_steps: bool = False):
        self.index = index
        self.first_step = first_step
        self.node = node  # its origin's node in the keyframe graph (graph/smooth.py)
        self.poses: list[np.ndarray] = []
        self.covs: list[np.ndarray] = []  # each step's motion noise (Slam.step_noise)
        self.pose_covs: list[np.ndarray] = []  # each step's pose covariance in the submap's frame (Σ_rr)
        self.points: list[np.ndarray] = []
        # each step's points too, for graph.refine (graph/refine.py Refinement; None: not kept): raw
        # until the submap closes, so bounded by submaps.max_steps
        self.step_points: list[np.ndarray | None] | None = [] if keep_steps else None
        self.n_points = 0
        self.travelled = 0.0

    def add(
        self, pose: np.ndarray, cov: np.ndarray, pose_cov: np.ndarray, points: np.ndarray | None, voxel: float
    ) -> None:
        """One step: its local pose, motion noise, the pose's covariance (Σ_rr) and scan points (global
        frame). ``travelled`` sums the moves between the submap's steps, not the one from its origin
        (SubmapConfig.max_distance)."""
        if self.poses:
            self.travelled += math.hypot(*(pose[:2] - self.poses[-1][:2]))
        self.poses.append(pose)
        self.covs.append(cov)
        self.pose_covs.append(pose_cov)
        if self.step_points is not None:
            self.step_points.append(points)
        if points is not None and len(points):
            self.points.append(points)
            self.n_points += len(points)
            if self.n_points > 200_000:  # thin as it grows: bounded memory on a long submap
                self.points = [self.thinned(voxel)]
                self.n_points = len(self.points[0])

    def thinned(self, voxel: float) -> np.ndarray:
        if not self.points:
            return np.zeros((0, 2))
        p = np.concatenate(self.points)
        return p[voxel_thin(p, voxel)]


def overlap_steps(a: Submap, b: Submap, pose: np.ndarray) -> tuple[int, int]:
    """Where two submaps overlap under ``pose`` (b's origin in a's frame): the indices into ``a.poses``
    and ``b.poses`` of their closest pair of robot positions."""
    pb = transform_points(b.poses[:, :2], pose)
    d2 = ((a.poses[:, None, :2] - pb[None, :, :]) ** 2).sum(axis=-1)
    i, j = np.unravel_index(int(np.argmin(d2)), d2.shape)
    return int(i), int(j)


def overlap_covariances(a: Submap, b: Submap, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """What a loop match a→b (``pose``, b's origin in a's frame) holds besides its fit's covariance as a
    relation of the two submaps' *origins*: a's share and b's (3, 3), in a's frame. The points where the
    submaps overlap were placed in each submap's frame by the filter's poses there, uncertain relative to
    its origin (their Σ_rr, ``pose_covs``) — first order, at the closest pair of robot positions
    (:func:`overlap_steps`); the two submaps' filters are independent, so the shares add (two closures of b
    compared with each other share b's, which cancels: a's alone there). A pose of a off by δ (additive,
    a's frame) moves a's points and so the match by the same rigid motion (δθ about that pose); one of
    b's moves it by the inverse of that motion carried into a's frame. Zero when a submap kept no pose
    covariances."""
    if a.pose_covs is None or b.pose_covs is None:
        return np.zeros((3, 3)), np.zeros((3, 3))
    i, j = overlap_steps(a, b, pose)
    t = np.asarray(pose, dtype=float)
    pa = a.poses[i, :2]
    q = transform_points(b.poses[j : j + 1, :2], t)[0]  # b's overlap pose in a's frame
    c, s = math.cos(t[2]), math.sin(t[2])
    ja = np.array([[1.0, 0.0, -(t[1] - pa[1])], [0.0, 1.0, t[0] - pa[0]], [0.0, 0.0, 1.0]])
    jb = np.array([[-c, s, t[1] - q[1]], [-s, -c, -(t[0] - q[0])], [0.0, 0.0, -1.0]])
    return ja @ a.pose_covs[i] @ ja.T, jb @ b.pose_covs[j] @ jb.T


def keyframe_nodes(poses: np.ndarray, spacing: float, angle: float) -> np.ndarray:
    """The steps of a closed submap (its local ``poses``) that become pose-graph nodes: one once the
    robot has moved ``spacing`` m or turned ``angle`` rad since the last node (the origin first), and
    always the last step (the next submap's origin). Indices into ``poses``."""
    nodes, ref = [], np.zeros(3)
    for k, p in enumerate(poses[:-1]):
        if math.hypot(p[0] - ref[0], p[1] - ref[1]) >= spacing or abs(wrap_angle(p[2] - ref[2])) >= angle:
            nodes.append(k)
            ref = p
    nodes.append(len(poses) - 1)
    return np.array(nodes)


def hanging(poses: np.ndarray, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per step of a closed submap (its local ``poses``), the index into ``nodes`` of the last node at or
    before it (−1: none, it hangs from the submap's origin) and that node's pose (the origin's: 0)."""
    before = np.searchsorted(nodes, np.arange(len(poses)), side="right") - 1
    return before, np.where((before >= 0)[:, None], poses[nodes[before.clip(0)]], 0.0)


def keyframe_factors(
    poses: np.ndarray, covs: np.ndarray, end_cov: np.ndarray, nodes: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A closed submap as a chain of pose-graph factors between its ``nodes`` (keyframe_nodes): each
    node's pose relative to the one before (the first's to the origin), with the steps' motion noise
    ``covs`` (s, 3, 3) propagated between them — all scaled so the chain is as sure of the last pose as
    the filter was (``end_cov``: its corners narrowed what the motion noise alone would say; the volumes,
    det^(1/3), matched). Returns (rel (m, 3), cov (m, 3, 3))."""
    prev = np.vstack((np.zeros(3), poses[:-1]))
    anchors = np.vstack((np.zeros(3), poses[nodes[:-1]]))
    # each step's poses before and after it in the frame of the node its link leaves from, and its noise
    # turned into that frame and into the submap's: :func:`propagate`'s terms, all steps at once (its
    # arithmetic row by row; only the two chains' recursions stay a loop)
    ref = anchors[np.searchsorted(nodes, np.arange(len(poses)))]
    rel0, rel1 = relative(ref, prev), relative(ref, poses)
    noise_total, noise_part = (
        _rotated_pose_covariances(covs, prev[:, 2]),
        _rotated_pose_covariances(covs, rel0[:, 2]),
    )
    total, part, parts = np.zeros((3, 3)), np.zeros((3, 3)), []
    is_node = np.zeros(len(poses), dtype=bool)
    is_node[nodes] = True
    for k in range(len(poses)):
        total = _moved(total, prev[k], poses[k]) + noise_total[k]
        part = _moved(part, rel0[k], rel1[k]) + noise_part[k]
        if is_node[k]:
            parts.append(part)
            part = np.zeros((3, 3))
    scale = 1.0
    if det3(total) > 0 and det3(end_cov) > 0:
        scale = float(np.cbrt(det3(end_cov) / det3(total)))
    return relative(anchors, poses[nodes]), np.array(parts) * scale


def _rotated_pose_covariances(covs: np.ndarray, yaws: np.ndarray) -> np.ndarray:
    """(n, 3, 3) :func:`~cornerslam_cli.geometry.rotate_pose_covariance` of each of ``covs`` by the same
    row of ``yaws``: J Σ Jᵀ, the same two products per row."""
    th = np.ascontiguousarray(yaws)
    c, s = np.cos(th), np.sin(th)
    J = np.zeros((len(th), 3, 3))
    J[:, 0, 0], J[:, 0, 1], J[:, 1, 0], J[:, 1, 1], J[:, 2, 2] = c, -s, s, c, 1.0
    return J @ np.asarray(covs, dtype=float) @ J.transpose(0, 2, 1)


def _moved(acc: np.ndarray, p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
    """G acc Gᵀ, G = ∂(p0 ∘ δ)/∂p0: p0's covariance ``acc`` carried to p1 = p0 ∘ δ (:func:`propagate`)."""
    G = np.array([[1.0, 0.0, p0[1] - p1[1]], [0.0, 1.0, p1[0] - p0[0]], [0.0, 0.0, 1.0]])
    return G @ acc @ G.T


def det3(m: np.ndarray) -> float:
    """A 3 × 3 determinant by cofactors (not LAPACK's: the same bits under every BLAS kernel set)."""
    return float(
        m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1])
        - m[0, 1] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
        + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0])
    )


def propagate(acc: np.ndarray, p0: np.ndarray, p1: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Covariance of pose p1 = p0 ∘ δ (both in one frame) from p0's ``acc`` and δ's ``cov`` (p0's frame)."""
    return _moved(acc, p0, p1) + rotate_pose_covariance(cov, p0[2])


def landmark_frames(
    sub: Submap, nodes: np.ndarray, last_step: np.ndarray, offsets: np.ndarray | None = None
) -> np.ndarray:
    """(n, 3) where the solved keyframe graph puts ``sub``'s frame for each of its landmarks: as seen from
    the step which last observed it (``last_step``, log steps) — its smoothed pose (the node it hangs
    from ∘ its offset from it) ∘ its filtered pose⁻¹, which without ``offsets`` (s, 3: each step's from
    its node, graph.recalibrate's) is node ∘ its anchor pose⁻¹. The graph bends a submap along its nodes,
    so one rigid frame for all its landmarks (its origin's) would leave a landmark seen late in the submap
    where the early path puts it, off the smoothed trajectory by the submap's own drift; this way each
    keeps the pose relative to the robot that the filter gave it. ``nodes``: the graph's node poses."""
    k = np.asarray(last_step, dtype=np.int64) - sub.first_step
    if offsets is None:
        return compose(nodes[sub.step_nodes[k]], inverse(sub.anchor_poses[k]))
    return compose(compose(nodes[sub.step_nodes[k]], offsets[k]), inverse(sub.poses[k]))


def place_table(table: dict[str, np.ndarray], frames: np.ndarray, index: int) -> dict[str, np.ndarray]:
    """A submap's landmark columns moved into the global frame: each by its pose of the submap's frame,
    ``frames`` (n, 3), or all by one (3,) (its origin)."""
    n = len(table["id"])
    frames = np.broadcast_to(np.asarray(frames, dtype=float), (n, 3))
    c, s = np.cos(frames[:, 2]), np.sin(frames[:, 2])
    R = np.stack((np.stack((c, -s), axis=-1), np.stack((s, c), axis=-1)), axis=-2)  # (n, 2, 2)
    xy = np.einsum("nij,nj->ni", R, np.column_stack((table["x"], table["y"]))) + frames[:, :2]
    cov = np.stack((table["var_x"], table["cov_xy"], table["cov_xy"], table["var_y"]), axis=-1)
    cov = R @ cov.reshape(-1, 2, 2) @ R.transpose(0, 2, 1)
    return {
        **table,
        "x": xy[:, 0],
        "y": xy[:, 1],
        "var_x": cov[:, 0, 0],
        "var_y": cov[:, 1, 1],
        "cov_xy": cov[:, 0, 1],
        "submap": np.full(n, index, dtype=np.int64),
    }
