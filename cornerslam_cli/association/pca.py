"""Partial compatibility algorithm, PCA (paper Algorithms 3–5, Fig 8).

Algorithm 3: split the m corners into groups of p; per group g find the local best hypothesis H_g by JCBB
and the ICNN unit pairs U_g (each corner's nearest individually compatible landmark). Algorithm 4 (PCBB)
then combines the groups depth-first: at group g it first tries to append H_g whole; then, through NUBB
(Algorithm 5), it walks the group's unit pairs one by one, each either appended or skipped. Every append
is checked for feature collision (no landmark twice) and joint compatibility with everything chosen so
far (D²_H < χ²(d·|H|, 1 − α)); the bound and the tie rule are JCBB's (:mod:`.jcbb`).

Readings chosen where the pseudo-code is garbled or ambiguous:

* **Groups** (GroupDivision): ``scan`` = corners sorted by bearing atan2(y, x) (the scan order of the
  extractor), cut into consecutive groups of p (the last may be smaller); ``spatial`` = repeatedly the
  remaining corner of least bearing plus its p − 1 nearest remaining corners (Euclidean, x–y). Corners
  with no candidate stay in their group; they can only be unmatched.
* **Alg 4 line 1** ``Best_Matching_Checking(U_group)``: U_g holds only individually compatible pairs
  already (ICNN output), so nothing further is removed.
* **Alg 4 lines 14–17**: the test is written on ``U_group[i].mbest`` but the append is ``V[t].H``; we read
  it as "if H_g is collision-free and jointly compatible with H_iter, append H_g whole and recurse into
  group t + 1". H_g's pairings are appended one by one through the incremental factor and the joint
  gate is applied once, to the whole of H_iter ∪ H_g.
* **Alg 4 line 19 / Alg 5**: NUBB is always tried after H_g (also when H_g was accepted): for each unit
  pair of the group in group order, branch "append it" (collision + joint test) then "skip it" (only if
  the bound allows); after the group's last unit pair, PCBB continues with the next group. The NUBB leaf
  that appends every unit pair is skipped when U_g equals H_g (it would repeat the H_g branch).
* **Bound / tie** (Alg 5 line 10, Alg 4 lines 7–11): a branch is pruned when pairings(H) + corners with
  candidates not yet visited < pairings(best), or equal with D²_H ≥ D²_best (exact, as in JCBB);
  ``jcbb.explore_ties = False`` prunes the equal case too (the paper's ≤), which is far cheaper when
  nearly all corners match. PCA reads its JCBB options (joint_gate, explore_ties) from ``jcbb``.
* **Special cases**: p = 1 makes H_g = U_g = {nearest pair}, so PCA returns the largest collision-free,
  jointly compatible subset of ICNN's pairs (ties: least joint D²). p ≥ m is one group: the H_g branch is
  JCBB's optimum and no NUBB subset can beat it, so PCA returns JCBB's answer.
* **Budget** (``pca.max_nodes`` / ``pca.max_seconds``) counts group JCBB and combination nodes together;
  when it runs out, the better of the best combination found so far and JCBB's greedy fallback
  (:func:`.jcbb.greedy_fallback`) is returned with ``budget_hit``.
"""

from __future__ import annotations

import itertools
import time

import numpy as np

from ..types import AssociationResult, Prediction
from . import gating
from .gating import Gated, JointCompatibility, build_result, csr, gate, scan_order
from .jcbb import Best, Budget, Jcbb, check_capacity, greedy_fallback, run_compiled, run_search
from .params import AssociationConfig
from .search_kernels import combine_kernel, groups_kernel


def make_groups(z: np.ndarray, p: int, grouping: str = "scan") -> list[list[int]]:
    """Split corner indices 0..m−1 into groups of at most p (see the module docstring)."""
    m, order = len(z), scan_order(z)
    if grouping == "scan":
        return [order[s : s + p] for s in range(0, m, p)]
    remaining = order  # spatial: seed of least bearing + its p − 1 nearest remaining corners
    groups = []
    while remaining:
        seed, rest = remaining[0], np.array(remaining[1:], dtype=np.int64)
        dist = np.hypot(*(z[rest, :2] - z[seed, :2]).T) if len(rest) else np.zeros(0)
        near = rest[np.argsort(dist, kind="stable")[: p - 1]].tolist()
        groups.append([seed, *near])
        taken = set(groups[-1])
        remaining = [i for i in remaining if i not in taken]
    return groups


def group_searches(
    g: Gated,
    groups: list[list[int]],
    jc: JointCompatibility,
    budget: Budget,
    exact: bool = False,
    explore_ties: bool = True,
) -> list[list[tuple[int, int]]]:
    """Algorithm 3's local best hypotheses H_g: :func:`.jcbb.jcbb_search` of each group in turn from jc's
    state, the budget shared. Compiled (search_kernels.groups_kernel)."""
    check_capacity(jc, max(map(len, groups), default=0))
    offsets, corners = csr(groups)
    out = np.empty((len(groups), jc.capacity, 2), dtype=np.int64)
    counts = run_compiled(groups_kernel, g, jc, budget, offsets, corners, bool(exact), explore_ties, out)
    return [[(i, k) for i, k in out[t, :c].tolist()] for t, c in enumerate(counts.tolist())]


def combine_groups(
    g: Gated,
    group_best: list[list[tuple[int, int]]],
    unit_pairs: list[list[tuple[int, int]]],
    jc: JointCompatibility,
    budget: Budget,
    explore_ties: bool = True,
) -> Best:
    """PCBB + NUBB (Algorithms 4–5): the best combination of each group's H_g or a subset of its U_g.
    Compiled (search_kernels.combine_kernel)."""
    after = [*itertools.accumulate(map(len, reversed(unit_pairs)), initial=0)]
    rem_after = np.array(after[::-1], dtype=np.int64)  # corners with candidates in groups from t on
    same = np.array([set(Hg) == set(U) for Hg, U in zip(group_best, unit_pairs, strict=True)], dtype=np.bool_)
    searched = (*csr(group_best, 2), *csr(unit_pairs, 2), same, rem_after)
    return run_search(combine_kernel, g, jc, budget, explore_ties, *searched)


class Pca:
    """PCA associator (the paper's): per-group JCBB + ICNN, combined by PCBB/NUBB."""

    def __init__(self, cfg: AssociationConfig | None = None):
        self.cfg = cfg or AssociationConfig(method="pca")

    def __call__(self, z: np.ndarray, C: np.ndarray, pred: Prediction) -> AssociationResult:
        t0 = time.perf_counter()
        pcfg = self.cfg.pca
        g = gate(z, C, pred, self.cfg)
        budget = Budget(pcfg.max_nodes, pcfg.max_seconds)
        groups = make_groups(g.z, pcfg.group_size, pcfg.grouping)
        local = JointCompatibility(g, max(pcfg.group_size, 1))
        nearest = g.nearest().tolist()
        exact, ties = self.cfg.jcbb.joint_gate == "exact", self.cfg.jcbb.explore_ties
        group_best = group_searches(g, groups, local, budget, exact, ties)  # Algorithm 3
        unit_pairs = [[(i, nearest[i]) for i in grp if nearest[i] >= 0] for grp in groups]
        group_nodes = budget.nodes
        jc = JointCompatibility(g, max(g.m, 1))
        best = combine_groups(g, group_best, unit_pairs, jc, budget, ties) if not budget.hit else Best()
        if budget.hit:
            best = greedy_fallback(g, [i for grp in groups for i in grp], best)
        extra = {
            "seconds": time.perf_counter() - t0,
            "groups": groups,
            "group_best": group_best,
            "unit_pairs": unit_pairs,
            "group_nodes": group_nodes,
            "combine_nodes": budget.nodes - group_nodes,
        }
        return build_result(g, best.pairs, best.d2, budget.nodes, budget.hit, extra)


def load_kernels() -> None:
    """Load (on a machine's first run: compile) the association's kernels now, so that the first timed
    association of a run does not pay it: gating.load_kernels (the gate, try and commit) and the compiled
    searches (search_kernels.py), by PCA and JCBB on each of its problems."""
    gating.load_kernels()
    for z, C, pred, cfg in gating.warm_up_problems():
        Pca(cfg)(z, C, pred)
        Jcbb(cfg)(z, C, pred)
