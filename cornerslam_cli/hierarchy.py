"""Two-level SLAM (Hierarchical SLAM, Estrada, Neira, Tardós, T-RO 2005): the paper's corner EKF
(slam.py) on bounded local submaps, joined by a pose graph over the submap origins (graph/posegraph.py,
GTSAM) with loop closures verified by the configured associator (graph/loops.py).

- **Local level.** The filter runs in the open submap's frame (its origin = the robot's pose at the
  previous submap's last step — the first submap's: the first step —, with zero relative uncertainty).
  A submap closes when it reaches ``submaps.max_steps`` steps, ``max_distance`` metres travelled or
  ``max_landmarks`` landmarks; its final pose and robot covariance become the sequential factor to the
  next origin, so per-step cost is bounded by the submap.
- **Global level.** After each closed submap: candidates are earlier submaps whose robot path came
  within ``loops.candidate_distance`` + ``candidate_sigmas`` σ of the closed submap's (its global
  marginal) under the graph's estimate (nearest first, at most ``max_candidates``); each is verified
  without a pose prior (graph/loops.py) — or, with too few corners in common or a corner pose the
  points refute, on its points around the graph's prediction (graph/points.py) —, its covariance scaled
  by the front end's learnt scale of ICP covariances and, as a relation of the two origins, the filter's
  covariances of the two submaps' overlap poses added (graph/submap.overlap_covariances; the keyframe graph
  takes the fit's own where the submaps overlap), then gated against the graph's prediction and its
  joint marginal (``loops.gate``, χ²₃); closures that disagree about where the submap is, beyond the
  graph's uncertainty between the submaps they come from, are all refused (perceptual aliasing).
  Accepted closures enter the graph under a robust kernel.
- **Outputs.** Each step's causal (online) estimate is its submap origin's pose in the graph *at that
  step* ∘ the filter's local pose. :meth:`finish` solves a keyframe graph (graph/smooth.py: closures
  act where the submaps overlap); :meth:`final_poses` hang from its nodes — the smoothed trajectory.
  Landmarks stay one per submap, linked across closures (map.csv ``linked_to``), not merged.

Over 400 lines because the two levels' bookkeeping (closing a submap, its loop decisions, the final
smoothing and the outputs read from it) shares one state; the verification itself is in graph/.
"""

from __future__ import annotations

import math
import time
from array import array
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from .geometry import compose, compose_inverse_cov, relative, transform_points
from .graph.loops import FEW_CORNERS, LOW_FITNESS, NO_HYPOTHESIS, agree, chi2, loop_associator, match_submaps
from .graph.paths import Paths
from .graph.points import POINTS, match_points, searchable
from .graph.posegraph import ONLINE_RELINEARIZE, PoseGraph
from .graph.refine import Refinement
from .graph.smooth import recalibrated, smooth
from .graph.submap import (
    LocalMaps,
    LoopMatch,
    OpenSubmap,
    Submap,
    hanging,
    keyframe_factors,
    keyframe_nodes,
    landmark_frames,
    overlap_covariances,
    place_table,
)
from .slam import Slam, StepRecord, globalise

if TYPE_CHECKING:
    from .config import Config
    from .frontend import Frame

NO_BIAS = (0.0,) * 12  # a step whose increment took no odometry bias (BiasTaken.row's length)
COV_FLOOR = np.diag([1e-8, 1e-8, 1e-10])  # added to a submap's end covariance: a still robot gives Σ = 0
# the corners gave no verdict (too few in common, no hypothesis) or a pose the points refute (low fitness:
# usually a corner constellation repeated elsewhere): the points decide, around the graph's prediction
TO_POINTS = (FEW_CORNERS, NO_HYPOTHESIS, LOW_FITNESS)


@dataclass(frozen=True)
class LoopRecord:
    """One verified candidate pair: a row of loops.csv."""

    step: int  # the step at which the submap closed
    submap_from: int  # the earlier submap a
    submap_to: int  # the closed submap b
    match: LoopMatch
    accepted: bool  # verified, inside the gate and consistent with the other closures of b
    reason: str
    chi2: float = float("nan")  # the match against the graph's prediction (Mahalanobis², 3 dof)
    factor: int = -1  # the graph's loop factor index when accepted
    on_points: bool = False  # searched on points around the graph's prediction (graph/points.py)
    origin_cov: np.ndarray | None = None  # the match's covariance as a relation of the origins (online graph)
    a_side_cov: np.ndarray | None = None  # ... without b's share: b's closures compared (it cancels there)

    def row(self, inlier: bool | None) -> dict:
        """loops.csv's row (report/tables.py ``LOOP_COLUMNS``)."""
        x, y, th = self.match.pose.tolist()
        return {
            "step": self.step,
            "submap": self.submap_to,
            "other_submap": self.submap_from,
            "dx": x,
            "dy": y,
            "dtheta": th,
            "n_corners": self.match.n_corners,
            "fitness": self.match.fitness,
            "accepted": self.accepted,
            "inlier": "" if inlier is None else inlier,
            "chi2": self.chi2,
            "reason": self.reason,
        }


class HierarchicalSlam:
    """Local EKF submaps (slam.py) joined by a pose graph with loop closures; :meth:`step` per frame
    like :class:`~cornerslam_cli.slam.Slam`, then :meth:`finish` closes the last submap."""

    def __init__(self, cfg: Config, laser2base: tuple[float, float, float]):
        self.cfg = cfg
        self.laser2base = laser2base
        self.slam = Slam.from_config(cfg, laser2base)
        self.graph = PoseGraph(cfg.graph, relinearize=ONLINE_RELINEARIZE)
        self.loop_associate = loop_associator(cfg.association, cfg.loops)
        self.local_maps = LocalMaps(2 * cfg.loops.max_candidates)  # ICP maps of recent candidates
        self.closed: list[Submap] = []
        self.paths = Paths()  # per closed submap: where the robot went (candidates)
        self.tables: list[dict[str, np.ndarray]] = []  # per closed submap: its landmarks (own frame)
        self.loops: list[LoopRecord] = []
        self.step_submap = array("l")
        self.local_poses = array("d")
        self.chains: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # per closed submap (smooth)
        self.taken = array("d") if cfg.graph.recalibrate else None  # per step: BiasTaken.row, or 0s
        self.offsets: list[np.ndarray] | None = None  # per closed submap, steps from their nodes (finish)
        self.n_nodes = 1  # keyframe nodes so far (node 0: the first origin)
        self.smoothed: PoseGraph | None = None  # the keyframe graph, solved by finish()
        self.refinement = Refinement(cfg.graph, cfg.scan_match)  # graph.refine (graph/refine.py)
        self._open = OpenSubmap(0, 0, 0, cfg.graph.refine)
        self._origin_cov = np.zeros((3, 3))  # the open submap origin's marginal in the graph
        self.t_loop = 0.0
        self.unconverged = 0  # graph solves (online and the final smoothing) stopped at their step limit
        self.n_ids = 0
        self._match_scale = 1.0  # the front end's learnt scale of fit covariances (Frame.match_scale)

    @property
    def n_steps(self) -> int:
        return self.slam.n_steps

    def step(self, frame: Frame) -> StepRecord:
        """One step of the local filter; closes the submap when it is full (loop closing and the
        graph's optimisation timed as the step's ``t_loop``). Returns the step in the global frame."""
        r = self.slam.step(frame)
        self._match_scale = frame.match_scale
        if self.taken is not None:
            self.taken.extend(NO_BIAS if frame.bias_taken is None else frame.bias_taken.row())
        sub = self._open
        sensor = compose(r.pose, self.laser2base)
        pts = None if frame.points is None else transform_points(frame.points.astype(float), sensor)
        sub.add(r.pose, self.slam.step_cov, self.slam.ekf.P[:3, :3].copy(), pts, self.cfg.submaps.voxel)
        self.step_submap.append(sub.index)
        self.local_poses.extend(r.pose)
        origin, origin_cov = self.graph.pose(sub.index), self._origin_cov
        t_loop = 0.0
        if self._full():
            t0 = time.perf_counter()
            self._close(r.step)
            t_loop = time.perf_counter() - t0
        return globalise(r, origin, origin_cov, sub.index, t_loop)

    def _full(self) -> bool:
        lim, sub = self.cfg.submaps, self._open
        return (
            len(sub.poses) >= lim.max_steps
            or sub.travelled >= lim.max_distance
            or self.slam.ekf.n_landmarks >= lim.max_landmarks
        )

    def finish(self, shift_of: Callable[[np.ndarray], np.ndarray] | None = None) -> None:
        """Close the last submap (its loops too) when it has steps; solve the keyframe graph — with
        ``shift_of`` (OdometryFusion.carry_back: the steps' BiasTaken rows → how far each step's
        increment moves), each step's increment moved so (graph.recalibrate)."""
        t0 = time.perf_counter()
        if self._open.poses:
            self._close(self.n_steps - 1, last=True)
        if self.closed:
            loops = [
                (self.closed[r.submap_from], self.closed[r.submap_to], r.match)
                for r in self.loops
                if r.factor >= 0
            ]
            chains = self.chains if shift_of is None or self.taken is None else self._recalibrated(shift_of)
            self.smoothed = smooth(self.cfg.graph, chains, self.graph.poses()[: len(self.closed)], loops)
            self.unconverged += not self.smoothed.converged
            if self.cfg.graph.refine:  # (its own solve's warning: Refinement.solver_warning)
                self.refinement.finish(self.graph, self.smoothed, self._match_scale)
        self.t_loop += time.perf_counter() - t0

    def _recalibrated(self, shift_of: Callable[[np.ndarray], np.ndarray]) -> list:
        """The closed submaps' chains with the increments moved by ``shift_of`` (:meth:`finish`; the
        steps' offsets kept for final_poses; closures as measured); bit for bit the same if none moves."""
        spacing = (self.cfg.graph.node_spacing, self.cfg.graph.node_angle)
        shift = shift_of(np.frombuffer(self.taken).reshape(-1, len(NO_BIAS)))
        if not shift.any():
            return self.chains
        out = [
            recalibrated(s, shift[s.first_step : s.last_step + 1], keyframe_nodes(s.poses, *spacing))
            for s in self.closed
        ]
        self.offsets = [o for *_, o in out]
        return [(rel, c[1], at) for (rel, at, _), c in zip(out, self.chains, strict=True)]

    def _optimize(self, graph: PoseGraph) -> None:
        """``graph.optimize()``, counting a solve that stopped at its step limit."""
        graph.optimize()
        self.unconverged += not graph.converged

    def solver_warning(self) -> str | None:
        """The warning for summary.json when a graph solve stopped at its step limit (its poses are the
        last step's, not the optimum), else None."""
        if not self.unconverged:
            return None
        return (
            f"{self.unconverged} pose-graph solve(s) stopped at their step limit before converging: the "
            "trajectory may be short of the optimum (a closure the robust kernel fights, or graph.kernel "
            "none with a false one); loops.csv lists the closures"
        )

    def _close(self, step: int, last: bool = False) -> None:
        """Close the open submap at ``step``: a node for the next origin, its loops, the graph optimised."""
        sub = self._close_submap()
        self.graph.add_sequential(sub.end_pose, sub.end_cov + COV_FLOOR)
        self._optimize(self.graph)
        if self.cfg.loops.enabled:
            self._close_loops(sub, step)
        self.refinement.register(self.graph.poses())  # (graph.refine off: nothing waits)
        if not last:
            self.slam.new_map()
            self._open = OpenSubmap(sub.index + 1, step + 1, self.n_nodes - 1, self.cfg.graph.refine)
            self._origin_cov = self.graph.marginal(sub.index + 1)

    def _close_submap(self) -> Submap:
        ekf, sub, g = self.slam.ekf, self._open, self.cfg.graph
        poses = np.array(sub.poses).reshape(-1, 3)
        nodes = keyframe_nodes(poses, g.node_spacing, g.node_angle)
        rel, cov = keyframe_factors(poses, np.array(sub.covs), ekf.P[:3, :3], nodes)
        self.chains.append((rel, cov + COV_FLOOR, poses[nodes]))
        before, anchor_poses = hanging(poses, nodes)
        step_nodes = np.where(before >= 0, self.n_nodes + before, sub.node)
        self.n_nodes += len(nodes)
        self.refinement.add_submap(sub, poses[nodes], step_nodes, anchor_poses)
        table = self.slam.landmark_table()
        n = len(table["id"])
        state = (3 + 3 * table["id"][:, None] + np.arange(3)).reshape(-1)
        ids = self.n_ids + np.arange(n)
        self.n_ids += n
        closed = Submap(
            index=sub.index,
            first_step=sub.first_step,
            last_step=sub.first_step + len(sub.poses) - 1,
            landmarks=np.column_stack((table["x"], table["y"], table["phi"])),
            landmark_P=ekf.P[np.ix_(state, state)].copy(),
            landmark_ids=ids,
            points=sub.thinned(self.cfg.submaps.voxel),
            end_pose=ekf.pose,
            end_cov=ekf.P[:3, :3].copy(),
            poses=poses,
            node=sub.node,
            step_nodes=step_nodes,
            anchor_poses=anchor_poses,
            pose_covs=np.array(sub.pose_covs).reshape(-1, 3, 3),
        )
        self.closed.append(closed)
        self.tables.append({**table, "id": ids})
        self.paths.add(closed.poses[:, :2])
        return closed

    def _close_loops(self, b: Submap, step: int) -> None:
        """Verify the candidates for submap ``b``, gate them, add the accepted ones to the graph."""
        cfg = self.cfg.loops
        found, searched = [], 0
        for a in self.candidates(b):
            m = match_submaps(a, b, cfg, self.loop_associate, self.cfg.scan_match, self.local_maps)
            on_points = cfg.point_search and searched < cfg.point_searches and m.reason in TO_POINTS
            on_points = on_points and searchable(a, b)  # (one that cannot run spends no search)
            searched += on_points
            pred = self.graph.relative(a.index, b.index) if on_points or m.accepted else None
            if on_points:
                kept = 0 if m.reason == LOW_FITNESS else m.n_corners  # (0: the points refuted their pose)
                found_on_points = match_points(a, b, *pred, cfg, self.cfg.scan_match, self.local_maps)
                m = replace(found_on_points, n_corners=kept)
            m = replace(m, cov=m.cov * self._match_scale)
            shares = overlap_covariances(a, b, m.pose) if m.accepted else None  # (as relations of origins)
            a_side = None if shares is None else m.cov + shares[0]
            cov = None if a_side is None else a_side + shares[1]
            d2 = chi2(*pred, m.pose, cov) if m.accepted else float("nan")
            reason = m.reason or ("" if d2 <= cfg.gate else f"disagrees with the graph (chi2 {d2:.1f})")
            ok = not reason
            if ok and on_points:
                reason = POINTS
            found.append(LoopRecord(step, a.index, b.index, m, ok, reason, d2, -1, on_points, cov, a_side))
            if sum(r.accepted for r in found) >= cfg.max_closures:
                break
        # (corner-verified ones only: a match found on points around the graph's own prediction is no
        # evidence against it)
        gated = [
            r
            for r in found
            if r.match.accepted and not r.accepted and r.chi2 <= cfg.group_gate and not r.on_points
        ]
        if len(gated) >= 2 and agree([self.placed(r) for r in gated]):
            # two or more closures from different parts of the map agree on where b is, against the
            # graph but not wildly (group_gate): the graph is what is wrong (an earlier false closure,
            # or drift beyond its covariance); they enter it, and its robust kernel weighs them against
            # what they contradict. Far beyond that it is a symmetric place seen from elsewhere.
            why = f"{len(gated)} closures agree against the graph"
            ids = {id(r) for r in gated}
            found = [replace(r, accepted=True, reason=why) if id(r) in ids else r for r in found]
        accepted = [r for r in found if r.accepted]
        if not self.consistent(accepted):
            why = "closures of this submap disagree on where it is (aliasing)"
            found = [replace(r, accepted=False, reason=why) if r.accepted else r for r in found]
        added = False
        for r in found:
            if r.accepted:
                try:
                    r = replace(
                        r, factor=self.graph.add_loop(r.submap_from, r.submap_to, r.match.pose, r.origin_cov)
                    )
                    added = True
                except ValueError:  # a degenerate ICP fit (a featureless corridor): no usable covariance
                    r = replace(r, accepted=False, reason="match covariance not positive definite")
            self.loops.append(r)
        if added:
            self._optimize(self.graph)

    def consistent(self, closures: list[LoopRecord]) -> bool:
        """Whether one submap's closures agree on where it is, two at a time: placed within AGREE_XY /
        AGREE_THETA of each other, or the pose a1→a2 they imply (m1 ∘ m2⁻¹) inside ``loops.pair_gate``
        of the graph's (on the sum of the covariances) — right closures from two parts of the map the
        graph has not yet joined place b apart by as much as the graph's own error between them."""
        for i, r1 in enumerate(closures):
            for r2 in closures[i + 1 :]:
                if agree([self.placed(r1), self.placed(r2)]):
                    continue
                pose, cov = compose_inverse_cov(r1.match.pose, r1.a_side_cov, r2.match.pose, r2.a_side_cov)
                pred, pred_cov = self.graph.relative(r1.submap_from, r2.submap_from)
                if chi2(pred, pred_cov, pose, cov) > self.cfg.loops.pair_gate:
                    return False
        return True

    def placed(self, r: LoopRecord) -> np.ndarray:
        """The global pose of submap b's origin that closure ``r`` implies (a's pose in the graph ∘ a→b)."""
        return compose(self.graph.pose(r.submap_from), r.match.pose)

    def candidates(self, b: Submap) -> list[Submap]:
        """Earlier submaps (at least ``loops.min_gap`` before ``b``) whose path came within
        ``candidate_distance`` of b's, plus ``candidate_sigmas`` σ of b's global marginal (its position,
        and its heading's lever arm over b's path), under the graph's estimate; nearest first, at most
        ``max_candidates``. Paths, not extents: two robots a few metres apart see the same walls, while
        a submap's points reach as far as its laser."""
        cfg = self.cfg.loops
        last = b.index - cfg.min_gap
        if last < 0:
            return []
        poses = self.graph.poses()
        Sb = self.graph.marginal(b.index)
        reach = self.paths.reach(b.index)
        sigma = (
            math.sqrt(max(np.linalg.eigvalsh(Sb[:2, :2]).max(), 0.0)) + math.sqrt(max(Sb[2, 2], 0.0)) * reach
        )
        radius = cfg.candidate_distance + cfg.candidate_sigmas * sigma
        closest = self.paths.closest(b.index, last, poses, radius)
        near = np.flatnonzero(closest <= radius)
        near = near[np.argsort(closest[near], kind="stable")][: cfg.max_candidates]
        return [self.closed[a] for a in near]

    def final_poses(self) -> np.ndarray:
        """(n, 3) every step's pose in the solved keyframe graph (the smoothed trajectory); before
        :meth:`finish`, with the online graph's submap origins."""
        if self.smoothed is None:
            local = np.frombuffer(self.local_poses).reshape(-1, 3)
            return compose(self.graph.poses()[np.frombuffer(self.step_submap, dtype=np.int64)], local)
        nodes = self.smoothed.poses()[np.concatenate([s.step_nodes for s in self.closed])]
        offsets = self.offsets or [relative(s.anchor_poses, s.poses) for s in self.closed]
        return compose(nodes, np.vstack(offsets))

    def landmark_table(self) -> dict[str, np.ndarray]:
        """map.csv's columns: every submap's landmarks in the global frame — once the keyframe graph is
        solved, each where the step that last observed it puts it, smoothed (graph/submap.py
        landmark_frames), before that at its submap's origin — their covariances turned with it (the
        graph's own uncertainty not added), with ``submap`` and ``linked_to`` (the id of the corner it
        was matched to across an accepted closure, or -1)."""
        if self.smoothed is None:
            poses = self.graph.poses()
            parts = [place_table(t, poses[i], i) for i, t in enumerate(self.tables)]
        else:
            nodes, offsets = self.smoothed.poses(), self.offsets or [None] * len(self.closed)
            parts = [
                place_table(t, landmark_frames(s, nodes, t["last_step"], o), s.index)
                for s, t, o in zip(self.closed, self.tables, offsets, strict=True)
            ]
        if not parts:  # none closed yet: the open submap 0's, whose frame is the global one
            return self.slam.landmark_table()
        table = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
        table["linked_to"] = self._links(len(table["id"]))
        return table

    def _links(self, n: int) -> np.ndarray:
        linked = np.full(n, -1, dtype=np.int64)
        for r in self.loops:
            if r.accepted and r.match.pairs is not None and len(r.match.pairs):
                a, b = self.closed[r.submap_from], self.closed[r.submap_to]
                linked[b.landmark_ids[r.match.pairs[:, 0]]] = a.landmark_ids[r.match.pairs[:, 1]]
        return linked

    def loop_rows(self) -> list[dict]:
        """loops.csv's rows; ``inlier``: whether the graph kept an accepted closure inside its kernel."""
        g = self.graph if self.smoothed is None else self.smoothed  # the keyframe graph once solved
        return [r.row(g.loop_inlier(r.factor) if r.factor >= 0 else None) for r in self.loops]
