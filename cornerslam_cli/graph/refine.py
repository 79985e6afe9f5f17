"""Dense refinement of the keyframe graph (``graph.refine``, off by default): after the graph of
graph/smooth.py is solved, every keyframe node's scan points are registered against each of the nearest
earlier nodes that lie within ``refine_radius`` m of it but that the robot reached at least
``refine_min_path`` m of path before, and the graph is solved again with those registrations as more
factors — the scan-pair constraints of Lu & Milios (1997, "Globally consistent range scan alignment for
environment mapping"), here between the nodes the submaps left, under the loop closures' robust kernel.

Why: the front end registers each keyframe against the few scans before it, so heading error walks
between revisits (edmonton: 2–4° over 100 m in a large hall whose far walls every scan sees), and loop
closing joins whole submaps only where corners or points verify. A node sees what a node 5–10 m back saw;
the chain never compares them. The registrations are ICP (motion/icp.py) of the node's points against
the earlier node's and its two neighbours', from the solved graph's relative pose; a pair is kept when
its fit reaches ``refine_min_fitness`` and ICP moved it at most ``refine_max_xy`` / ``refine_max_theta``
(the solved graph is already right locally: a larger move is another basin). Its covariance is ICP's
times the front end's learnt scale of match covariances (motion/fusion.py), as for loop closures.

What it does on the panel (README "Dense refinement"): most maps agree better with themselves at their
revisits (every noisy radish log's, orebro's within its spread), and the ATE against the published
references moves both ways.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..geometry import inverse, relative, transform_points, wrap_angle
from ..motion.icp import LocalMap, register, voxel_thin
from ..motion.params import ScanMatchConfig
from .params import GraphConfig
from .posegraph import PoseGraph

if TYPE_CHECKING:
    from ..config import Config

MIN_POINTS = 20  # a node with fewer scan points is neither registered nor a target
TARGET_NEIGHBOURS = (-1, 0, 1)  # the earlier node's map: its points and its neighbours' (denser normals)


class Refinement:
    """The keyframe nodes' scan points in their own frames, thinned — the points of the steps that hang
    from each (graph/submap.py ``step_nodes``), gathered as submaps close — and, once :meth:`run` has
    used them, how many pairs it registered and how many became factors."""

    def __init__(self, voxel: float):
        self.voxel = voxel
        self._parts: dict[int, list[np.ndarray]] = {}
        self.tried = 0  # node pairs registered
        self.added = 0  # factors added (fit and move within their limits)

    def add_submap(self, points: list | None, step_nodes: np.ndarray, anchors: np.ndarray) -> None:
        """A closed submap's steps: their ``points`` (submap frame; None: no scan; the list None: not
        kept, graph.refine off), the node each hangs from and that node's pose in the submap (``anchors``)."""
        if points is None:
            return
        for pts, node, anchor in zip(points, step_nodes, anchors, strict=True):
            if pts is not None and len(pts):
                placed = transform_points(pts, inverse(anchor))
                self._parts.setdefault(int(node), []).append(placed[voxel_thin(placed, self.voxel)])

    def clouds(self) -> dict[int, np.ndarray]:
        out = {}
        for node, parts in self._parts.items():
            p = np.concatenate(parts)
            out[node] = p[voxel_thin(p, self.voxel)]
        return out

    def run(self, g: PoseGraph, cfg: Config, scale: float) -> int:
        """:func:`refine` the solved graph ``g`` with the points gathered (then let go of them), by the
        run's ``graph`` and ``scan_match`` settings; returns the factors added (0: ``g`` not solved again)."""
        clouds, self._parts = self.clouds(), {}
        self.tried, self.added = refine(g, clouds, cfg.graph, cfg.scan_match, scale)
        return self.added


def path_lengths(poses: np.ndarray) -> np.ndarray:
    """(n,) metres of path from node 0 to each node along the chain of ``poses``."""
    return np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(poses[:, :2], axis=0).T))))


def pairs(poses: np.ndarray, cfg: GraphConfig) -> list[tuple[int, int]]:
    """(j, i), j < i: for each node i the ``refine_neighbours`` nearest earlier nodes within
    ``refine_radius`` m whose path to i is at least ``refine_min_path`` m (ties: the earlier)."""
    path = path_lengths(poses)
    out = []
    for i in range(1, len(poses)):
        d = np.hypot(poses[:i, 0] - poses[i, 0], poses[:i, 1] - poses[i, 1])
        near = np.flatnonzero((d <= cfg.refine_radius) & (path[i] - path[:i] >= cfg.refine_min_path))
        near = near[np.argsort(d[near], kind="stable")][: cfg.refine_neighbours]
        out.extend((int(j), i) for j in sorted(near))
    return out


def refine(
    g: PoseGraph, clouds: dict[int, np.ndarray], cfg: GraphConfig, match: ScanMatchConfig, scale: float
) -> tuple[int, int]:
    """Add the registrations of :func:`pairs` to the solved graph ``g`` and solve it again; ``clouds``
    per node (:class:`Refinement`), ``match`` the ICP settings, ``scale`` the front end's learnt scale of
    match covariances. Returns (pairs registered, factors added)."""
    poses = g.poses()
    path = path_lengths(poses)
    maps: dict[tuple[int, tuple[int, ...]], LocalMap | None] = {}

    def target(j: int, i: int) -> LocalMap | None:
        """Node j's map: its points and its chain neighbours', placed with the solved graph — those
        before i by at least ``refine_min_path`` m of path (j + 1 may be i itself, or just behind it)."""
        near = tuple(
            k
            for k in (j + o for o in TARGET_NEIGHBOURS)
            if k in clouds and k < i and path[i] - path[k] >= cfg.refine_min_path
        )
        if (j, near) not in maps:
            parts = [transform_points(clouds[k], relative(poses[j], poses[k])) for k in near]
            pts = np.concatenate(parts) if parts else np.zeros((0, 2))
            pts = pts[voxel_thin(pts, match.voxel)]
            maps[(j, near)] = LocalMap.build(pts) if len(pts) >= MIN_POINTS else None
        return maps[(j, near)]

    tried = added = 0
    for j, i in pairs(poses, cfg):
        points = clouds.get(i)
        if points is None or len(points) < MIN_POINTS or (m := target(j, i)) is None:
            continue
        guess = relative(poses[j], poses[i])
        reg = register(points, m, guess, match)
        tried += 1
        move = relative(guess, reg.pose)
        if (
            reg.fit < cfg.refine_min_fitness
            or np.hypot(move[0], move[1]) > cfg.refine_max_xy
            or abs(wrap_angle(move[2])) > cfg.refine_max_theta
        ):
            continue
        g.add_loop(j, i, reg.pose, reg.cov * scale)
        added += 1
    if added:
        g.optimize()
    return tried, added
