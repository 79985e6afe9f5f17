"""Dense refinement of the keyframe graph (``graph.refine``, off by default): every keyframe node's scan
points registered against each of the nearest earlier nodes that lie within ``refine_radius`` m of it
but that the robot reached at least ``refine_min_path`` m of path before, and those registrations added
to the keyframe graph of graph/smooth.py as more factors — the scan-pair constraints of Lu & Milios
(1997, "Globally consistent range scan alignment for environment mapping"), here between the nodes the
submaps left, under the loop closures' robust kernel.

Why: the front end registers each keyframe against the few scans before it, so heading error walks
between revisits (edmonton: 2–4° over 100 m in a large hall whose far walls every scan sees), and loop
closing joins whole submaps only where corners or points verify. A node sees what a node 5–10 m back saw;
the chain never compares them.

As the run goes, bounded (:class:`Refinement`): a node is registered once its points are all in — when
its submap closes; a submap's last node, the next one's origin, when that one closes —, from the online
graph's estimate (its submap origins ∘ the nodes' poses in their submaps), after the closing submap's
loop closures; ICP (motion/icp.py) of the node's points against the earlier node's and its two chain
neighbours' (those still kept and as far back along the path). ICP's weak prior (``scan_match``'s
``prior_sigma_*``) is towards that online estimate, so along a featureless corridor the registration
says little more than it did, with that prior's large variance.
A registration that fits below ``refine_min_fitness`` is dropped then; the others are kept (a relative
pose and its covariance) until :meth:`Refinement.apply`, after the keyframe graph is solved: each becomes a
factor when it moves its pair at most ``refine_max_xy`` / ``refine_max_theta`` from the solved graph's
estimate (which is already right locally: a larger move is another basin), with ICP's covariance times
the front end's learnt scale of match covariances (motion/fusion.py), as for loop closures; then the
graph is solved again. Points are kept only for targets: at most ``KEEP`` nodes with points per ``CELL``
m square of the map (the first to reach it), so the points held are bounded by the area mapped, not the
log's length — on a robot's tenth lap its nodes register against the first laps' and are dropped; what
grows with the log is the registrations kept for the end (a relative pose and its covariance each, at most
``refine_neighbours`` per node), as the keyframe graph's own factors do.

What it does on the panel: docs/results/README.md, "Dense refinement".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry import compose, inverse, relative, transform_points, wrap_angle
from ..motion.icp import LocalMap, register, voxel_thin
from ..motion.params import ScanMatchConfig
from .params import GraphConfig
from .posegraph import PoseGraph
from .submap import OpenSubmap

MIN_POINTS = 20  # a node with fewer scan points is neither registered nor a target
TARGET_NEIGHBOURS = (-1, 0, 1)  # the earlier node's map: its points and its neighbours' (denser normals)
CELL = 1.0  # m: the squares of the map in which nodes' points are kept for later registrations…
KEEP = 4  # … at most this many nodes' per square (the first ones): memory bounded by the area mapped


@dataclass
class Node:
    """A keyframe node of the refinement: where it is (``pose`` in submap ``submap``'s frame, the online
    graph's variable ``submap``), metres of path to it, and its points (own frame) — a list of parts
    until complete, then one thinned array."""

    submap: int
    pose: np.ndarray
    path: float
    points: list[np.ndarray] | np.ndarray


@dataclass(frozen=True)
class Scanpair:
    """A registration of node ``i``'s points against node ``j``'s map that fit: i's pose in j's frame
    and its covariance (ICP's, unscaled)."""

    j: int
    i: int
    pose: np.ndarray
    cov: np.ndarray


class Refinement:
    """The nodes' points as submaps close (:meth:`add_submap`), registered once complete against the
    earlier nodes kept (:meth:`register`), and the registrations made factors of the solved keyframe
    graph (:meth:`apply`); ``tried`` pairs registered, ``found`` the ones that fit, ``added`` the factors."""

    def __init__(self, graph: GraphConfig, match: ScanMatchConfig):
        self.cfg, self.match = graph, match
        self.nodes: dict[int, Node] = {}  # node id → Node: those kept as targets and those not yet registered
        self.kept: list[int] = []  # the targets' ids, ascending
        self._row: dict[int, int] = {}  # a target's id → its index in kept
        self.waiting: list[int] = []  # complete, not yet registered (ascending)
        self.found: list[Scanpair] = []
        self.cells: dict[tuple[int, int], int] = {}  # nodes kept per CELL square
        self.tried = 0
        self.added = 0
        self.converged = True  # the solve with the factors added reached its optimum (or there was none)

    def add_submap(
        self, sub: OpenSubmap, node_poses: np.ndarray, step_nodes: np.ndarray, anchors: np.ndarray
    ) -> None:
        """Submap ``sub``, closing: its nodes at ``node_poses`` (its frame; the last, its last step, is the
        next submap's origin), its origin's node ``sub.node``; each step's points (``sub.step_points``,
        submap frame; None: no scan; the list None: not kept, graph.refine off), the node it hangs from
        (``step_nodes``: the last step's is the last node, so the ids are known) and that node's pose in
        the submap (``anchors``). Its origin and every node but the last are then
        complete, queued for :meth:`register` (the last: when the next submap closes, or :meth:`complete`)."""
        index, origin_node, points = sub.index, sub.node, sub.step_points
        if points is None:
            return
        first_node = int(step_nodes[-1]) - len(node_poses) + 1
        if origin_node not in self.nodes:  # node 0, the first submap's origin
            self.nodes[origin_node] = Node(index, np.zeros(3), 0.0, [])
        start = self.nodes[origin_node].path
        path = start + np.cumsum(np.hypot(*np.diff(np.vstack((np.zeros(3), node_poses))[:, :2], axis=0).T))
        for k, (pose, p) in enumerate(zip(node_poses, path, strict=True)):
            self.nodes[first_node + k] = Node(index, pose, float(p), [])
        for pts, node, anchor in zip(points, step_nodes, anchors, strict=True):
            if pts is not None and len(pts):
                placed = transform_points(pts, inverse(anchor))
                self.nodes[int(node)].points.append(placed[voxel_thin(placed, self.match.voxel)])
        self._complete([origin_node, *range(first_node, first_node + len(node_poses) - 1)])

    def _complete(self, ids: list[int]) -> None:
        for n in ids:
            parts = self.nodes[n].points
            p = np.concatenate(parts) if parts else np.zeros((0, 2))
            self.nodes[n].points = p[voxel_thin(p, self.match.voxel)]
        self.waiting.extend(ids)

    def finish(self, online: PoseGraph, g: PoseGraph, scale: float) -> int:
        """The run has ended: :meth:`complete` with the ``online`` graph's origins, then :meth:`apply` to
        the solved keyframe graph ``g``; returns the factors added."""
        self.complete(online.poses())
        return self.apply(g, scale)

    def complete(self, origins: np.ndarray) -> None:
        """Register the nodes still waiting for points (at the run's end, the last submap's last node)."""
        self._complete([n for n, v in self.nodes.items() if isinstance(v.points, list)])
        self.register(origins)

    def register(self, origins: np.ndarray) -> None:
        """Register each complete node against its :func:`nearest` earlier nodes kept, placed with
        ``origins`` (the online graph's submap origins, after the closing submap's loops); keep the
        registrations that fit, then the node's points where its square has room."""
        if not self.waiting:  # (graph.refine off, or nothing complete)
            return
        kept = [self.nodes[n] for n in self.kept]
        subs = np.array([v.submap for v in kept], dtype=np.int64)
        poses = compose(origins[subs], np.array([v.pose for v in kept]).reshape(-1, 3)).reshape(-1, 3)
        paths = np.array([v.path for v in kept])
        maps: dict[tuple[int, ...], LocalMap | None] = {}  # targets built in this call (same origins)
        for i in self.waiting:
            node = self.nodes[i]
            pose_i = compose(origins[node.submap], node.pose)
            if len(node.points) >= MIN_POINTS:
                for j in nearest(pose_i, node.path, poses, paths, self.cfg):
                    self._pair(self.kept[j], i, poses, pose_i, maps)
            cell = (int(np.floor(pose_i[0] / CELL)), int(np.floor(pose_i[1] / CELL)))
            if len(node.points) and self.cells.get(cell, 0) < KEEP:
                self.cells[cell] = self.cells.get(cell, 0) + 1
                self._row[i] = len(self.kept)
                self.kept.append(i)
                poses, paths = np.vstack((poses, pose_i)), np.append(paths, node.path)
            else:
                del self.nodes[i]  # no points, or the first KEEP nodes here stand for this square: it goes
        self.waiting = []

    def _pair(
        self,
        j: int,
        i: int,
        poses: np.ndarray,
        pose_i: np.ndarray,
        maps: dict[tuple[int, ...], LocalMap | None],
    ) -> None:
        """Register node i against node j's map (j and its kept chain neighbours far enough back), its
        nodes placed at ``poses`` (rows: :attr:`kept`'s)."""
        path_i, row = self.nodes[i].path, self._row
        near = tuple(
            n
            for n in (j + o for o in TARGET_NEIGHBOURS)
            if n in row and path_i - self.nodes[n].path >= self.cfg.refine_min_path
        )
        at = poses[row[j]]
        if (j, *near) not in maps:
            parts = [transform_points(self.nodes[n].points, relative(at, poses[row[n]])) for n in near]
            pts = np.concatenate(parts) if parts else np.zeros((0, 2))
            pts = pts[voxel_thin(pts, self.match.voxel)]
            maps[(j, *near)] = LocalMap.build(pts) if len(pts) >= MIN_POINTS else None
        if (target := maps[(j, *near)]) is None:
            return
        reg = register(self.nodes[i].points, target, relative(at, pose_i), self.match)
        self.tried += 1
        if reg.fit >= self.cfg.refine_min_fitness:
            self.found.append(Scanpair(j, i, reg.pose, reg.cov))

    def apply(self, g: PoseGraph, scale: float) -> int:
        """Add the registrations found to the solved keyframe graph ``g`` — those that move their pair at
        most ``refine_max_xy`` / ``refine_max_theta`` from its estimate —, their covariances times
        ``scale`` (the front end's learnt scale of match covariances), and solve it again when any was
        added. Returns the factors added."""
        poses = g.poses()
        for s in self.found:
            move = relative(relative(poses[s.j], poses[s.i]), s.pose)
            if (
                np.hypot(move[0], move[1]) <= self.cfg.refine_max_xy
                and abs(wrap_angle(move[2])) <= self.cfg.refine_max_theta
            ):
                g.add_loop(s.j, s.i, s.pose, s.cov * scale)
                self.added += 1
        if self.added:
            g.optimize()
            self.converged = g.converged
        return self.added

    def solver_warning(self) -> str | None:
        """The warning for summary.json when the solve with the scan pairs stopped at its step limit,
        else None."""
        if self.converged:
            return None
        return (
            f"the keyframe graph's solve with the dense refinement's {self.added} scan pairs stopped at its "
            "step limit before converging: the trajectory is its last step (no worse than the solve "
            "without them by the graph's cost, maybe short of the optimum); run without graph.refine "
            "to compare"
        )


def nearest(
    pose: np.ndarray, path: float, poses: np.ndarray, paths: np.ndarray, cfg: GraphConfig
) -> np.ndarray:
    """Indices into ``poses`` (earlier nodes, with their ``paths``: metres along the robot's path) of the
    ``refine_neighbours`` nearest to ``pose`` within ``refine_radius`` m whose path to it (``path``) is at
    least ``refine_min_path`` m, ascending (ties in distance: the earlier)."""
    d = np.hypot(poses[:, 0] - pose[0], poses[:, 1] - pose[1])
    near = np.flatnonzero((d <= cfg.refine_radius) & (path - paths >= cfg.refine_min_path))
    return np.sort(near[np.argsort(d[near], kind="stable")][: cfg.refine_neighbours])
