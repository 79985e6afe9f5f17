"""The smoothed trajectory's graph: after the run, every closed submap's keyframe chain and every
accepted loop closure, solved once in batch (hierarchy.py's ``finish``).

The online graph has one node per submap origin: small enough to solve after every submap, and its
marginals choose the loop candidates and gate them. But a closure between two origins also carries each
submap's drift from its origin to where the two overlap, and a rigid submap cannot give it back. Here a
node sits every ``graph.node_spacing`` m / ``node_angle`` rad along each submap (keyframe_nodes), the
chain between them carries the steps' motion noise (keyframe_factors), and each closure acts between
the nodes where its submaps overlap (reanchor), so the solve bends a submap by its own drift. The
online solution is the starting point; Levenberg–Marquardt, the same robust kernel.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..geometry import chain, compose, reanchor, relative
from .params import GraphConfig
from .posegraph import PoseGraph
from .submap import LoopMatch, Submap, hanging, overlap_steps


def smooth(
    cfg: GraphConfig,
    chains: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
    origins: np.ndarray,
    closures: list[tuple[Submap, Submap, LoopMatch]],
) -> PoseGraph:
    """The keyframe graph solved: ``chains`` per closed submap (rel (m, 3), cov (m, 3, 3), the nodes'
    poses in the submap's frame), ``origins`` (the online graph's origin per submap: the initial guess),
    ``closures`` in the order they entered the online graph (so loop k here is loop k there)."""
    g = PoseGraph(replace(cfg, solver="lm"), origins[0])
    for (rel, cov, local), origin in zip(chains, origins, strict=True):
        for r, c, guess in zip(rel, cov, compose(origin, local), strict=True):
            g.add_sequential(r, c, guess)
    for a, b, m in closures:
        g.add_loop(*keyframe_loop(a, b, m))
    g.optimize()
    return g


def keyframe_loop(a: Submap, b: Submap, m: LoopMatch) -> tuple[int, int, np.ndarray, np.ndarray]:
    """Closure a→b (``m``, between the origins) as a factor between the keyframe nodes where the two
    submaps overlap (their closest robot positions under it): (node i, node j, rel, cov)."""
    i, j = overlap_steps(a, b, m.pose)
    if a.step_nodes[i] == b.step_nodes[j]:  # b right after a, both hanging from a's last node
        return a.node, b.node, m.pose, m.cov
    rel, cov = reanchor(m.pose, m.cov, a.anchor_poses[i], b.anchor_poses[j])
    return int(a.step_nodes[i]), int(b.step_nodes[j]), rel, cov


def recalibrated(
    sub: Submap, shift: np.ndarray, nodes: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closed submap ``sub``'s keyframe chain with each step's increment moved by ``shift`` (s, 3): what
    carrying the odometry bias back changes of it (motion/fusion.py ``carry_back``). Returns
    the chain's rel (m, 3) between its ``nodes`` (keyframe_nodes), the nodes' poses in its frame and each
    step's pose relative to the node it hangs from (hierarchy.py ``final_poses``)."""
    prev = np.vstack((np.zeros(3), sub.poses[:-1]))
    poses = chain(relative(prev, sub.poses) + shift)
    anchors = np.vstack((np.zeros(3), poses[nodes[:-1]]))
    return relative(anchors, poses[nodes]), poses[nodes], relative(hanging(poses, nodes)[1], poses)
