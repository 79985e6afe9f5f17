"""Joint compatibility branch and bound, JCBB (Neira & Tardós 2001; paper §"Existing data association").

Depth-first over the corners; corner i branches on each individually compatible landmark not yet used
(by increasing individual D²), keeping a hypothesis H while D²_H < χ²(d·|H|, 1 − α), then on "no match".
Best = most pairings, ties broken by smaller joint D².

Readings chosen (the textbook pseudo-code is ambiguous or inexact here):

* **Order.** Corners are visited in scan order (increasing bearing), the order PCA's groups use, so that
  PCA with p = m repeats this search exactly.
* **Joint gate** (``jcbb.joint_gate``). Joint compatibility is not hereditary: a hypothesis can pass
  χ²(d·|H|) while one of its prefixes fails χ²(d·|prefix|). ``prefix`` (default, Neira & Tardós, the
  paper) gates every partial hypothesis, so the answer is the best hypothesis *all of whose prefixes in
  visiting order* are jointly compatible. ``exact`` prunes a partial hypothesis only when no extension
  can pass (D²_H ≥ χ²(d·(|H| + remaining))) and gates the leaves: the best jointly compatible hypothesis
  of all, order independent, at the cost of more nodes.
* **Bound.** Neira & Tardós prune a branch when pairings(H) + remaining ≤ pairings(best). With the tie
  rule that would discard a branch that could still *tie* the best with a smaller D², so the result would
  depend on visiting order. We prune when pairings(H) + remaining < pairings(best), or when it is equal and
  D²_H ≥ D²_best: D² never decreases as pairings are added, so this is exact. Exploring those ties
  can cost many nodes when nearly every corner matches; ``jcbb.explore_ties = False`` restores the
  ≤ prune (still the most pairings; among equal counts, the first found in depth-first order wins
  unless a later leaf of equal count is reached with smaller D²).
* **remaining** counts only the corners still to visit that have at least one candidate (a corner with
  none can only take "no match"); such corners are not branched on at all.
* **nodes** = interpretation-tree nodes visited (leaves included).
* **Budget**: ``max_nodes`` / ``max_seconds`` stop the search; the better of the best hypothesis found
  so far and a greedy one (ICNN's pairs in scan order, each kept if collision-free and jointly
  compatible) is returned with ``budget_hit`` set.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np

from ..types import AssociationResult, Prediction
from .gating import PIVOT_RTOL, Gated, JointCompatibility, build_result, gate, scan_order
from .params import AssociationConfig
from .search_kernels import jcbb_kernel


class Budget:
    """Node / wall-time budget shared by the searches of one associator call (0 = unlimited).

    A search counts a node as it enters it; it stops when ``max_nodes`` have been counted, or when the
    count reaches a multiple of 256 past ``deadline``, and sets ``hit``.
    """

    def __init__(self, max_nodes: int = 0, max_seconds: float = 0.0):
        self.max_nodes = max_nodes
        self.deadline = time.perf_counter() + max_seconds if max_seconds > 0 else math.inf
        self.nodes = 0
        self.hit = False


class Best:
    """Best hypothesis so far: most pairings, then least joint D²."""

    def __init__(self, explore_ties: bool = True):
        self.explore_ties = explore_ties
        self.count = 0
        self.d2 = math.inf
        self.pairs: list[tuple[int, int]] = []

    def offer(self, jc: JointCompatibility) -> None:
        h, d2 = jc.size, jc.joint_d2
        if h > self.count or (h == self.count and d2 < self.d2):
            self.count, self.d2, self.pairs = h, d2, jc.pairs()


def check_capacity(jc: JointCompatibility, corners: int) -> None:
    """ValueError unless jc can hold a pairing of each of ``corners`` more corners (the compiled searches
    write without bounds checks)."""
    if jc.size + corners > jc.capacity:
        raise ValueError(
            f"{corners} corners on {jc.size} pairings exceed the hypothesis' capacity {jc.capacity}"
        )


def run_compiled(search, g: Gated, jc: JointCompatibility, budget: Budget, *args):
    """Run a compiled search of search_kernels.py (``args``: its own arguments) from jc's committed
    pairings, counting its nodes in ``budget``; what it returns. jc's arrays change as its try_add /
    commit would change them; its size does not."""
    counters = np.array([budget.max_nodes, budget.nodes, 0], dtype=np.int64)
    out = search(jc.arrays(), g.search_arrays(), jc.size, counters, budget.deadline, PIVOT_RTOL, *args)
    budget.nodes, budget.hit = int(counters[1]), budget.hit or bool(counters[2])
    return out


def run_search(search, g: Gated, jc: JointCompatibility, budget: Budget, explore_ties: bool, *args) -> Best:
    """:func:`run_compiled` of a search for one best hypothesis (``explore_ties`` and the best its last
    arguments)."""
    found = (np.zeros(1, np.int64), np.full(1, math.inf), np.empty((jc.capacity, 2), np.int64))
    run_compiled(search, g, jc, budget, *args, explore_ties, found)
    best = Best(explore_ties)
    best.count, best.d2 = int(found[0][0]), float(found[1][0])
    best.pairs = [(i, k) for i, k in found[2][: best.count].tolist()]
    return best


def jcbb_search(
    g: Gated,
    corners: Sequence[int],
    jc: JointCompatibility,
    budget: Budget,
    exact: bool = False,
    explore_ties: bool = True,
) -> Best:
    """Best jointly compatible hypothesis over ``corners`` (visited in the given order), from jc's state.

    exact False (Neira & Tardós): every partial hypothesis H must pass D²_H < χ²(d·|H|, 1 − α).
    exact True: H is pruned only when D²_H ≥ χ²(d·(|H| + remaining), 1 − α) — no extension can pass
    its gate then, because D² never decreases — and leaves are tested against χ²(d·|H|, 1 − α).
    Pairings already committed in ``jc`` (and their landmarks) stay in every hypothesis; the returned
    ``Best.pairs`` includes them. ``jc`` keeps its size, also when the budget runs out. Compiled
    (search_kernels.jcbb_kernel).
    """
    corners = np.asarray(corners, dtype=np.int64).reshape(-1)
    check_capacity(jc, len(corners))
    return run_search(jcbb_kernel, g, jc, budget, explore_ties, corners, bool(exact))


def greedy_fallback(g: Gated, corners: Sequence[int], best: Best) -> Best:
    """When a budget cut the search short: ICNN's pairs in visiting order, each kept if collision-free and
    jointly compatible with those kept so far (O(m) tries), if that beats what the search had found."""
    jc = JointCompatibility(g, max(len(corners), 1))
    used: set[int] = set()
    nearest = g.nearest()
    for i in corners:
        k = int(nearest[i])
        if k >= 0 and k not in used and jc.try_add(i, k) < jc.gate[jc.size + 1]:
            jc.commit()
            used.add(k)
    best.offer(jc)
    return best


class Jcbb:
    """JCBB associator: the exact best jointly compatible hypothesis (within the optional budget)."""

    def __init__(self, cfg: AssociationConfig | None = None):
        self.cfg = cfg or AssociationConfig(method="jcbb")

    def __call__(self, z: np.ndarray, C: np.ndarray, pred: Prediction) -> AssociationResult:
        t0 = time.perf_counter()
        g = gate(z, C, pred, self.cfg)
        budget = Budget(self.cfg.jcbb.max_nodes, self.cfg.jcbb.max_seconds)
        jc = JointCompatibility(g, max(g.m, 1))
        order = scan_order(g.z)
        jcfg = self.cfg.jcbb
        best = jcbb_search(g, order, jc, budget, jcfg.joint_gate == "exact", jcfg.explore_ties)
        if budget.hit:
            best = greedy_fallback(g, order, best)
        extra = {"seconds": time.perf_counter() - t0}
        return build_result(g, best.pairs, best.d2, budget.nodes, budget.hit, extra)
