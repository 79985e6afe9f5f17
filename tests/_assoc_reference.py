"""The Python searches of JCBB and PCA before they were compiled (association/search_kernels.py):
jcbb.py's ``jcbb_search``, pca.py's loop of it over the groups and its ``combine_groups``; recursive, one
:class:`JointCompatibility` try / commit per node. The reference the compiled searches are compared with
(tests/test_search_kernels.py: pairs, joint D², nodes and budget stop, exactly). Kept only for the tests.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

from cornerslam_cli.association.gating import Gated, JointCompatibility
from cornerslam_cli.association.jcbb import Best, Budget


class BudgetExhausted(Exception):
    """Raised inside a search when its node or time budget runs out."""


def tick(budget: Budget) -> None:
    """Count one node; BudgetExhausted (and ``budget.hit``) once it runs out."""
    if budget.max_nodes and budget.nodes >= budget.max_nodes:
        budget.hit = True
        raise BudgetExhausted
    budget.nodes += 1
    if budget.nodes & 255 == 0 and time.perf_counter() > budget.deadline:
        budget.hit = True
        raise BudgetExhausted


def can_improve(best: Best, count: int, remaining: int, d2: float) -> bool:
    """Could a hypothesis with ``count`` pairings and D² ``d2`` still beat the best?"""
    reach = count + remaining
    return reach > best.count or (best.explore_ties and reach == best.count and d2 < best.d2)


def jcbb_search(
    g: Gated,
    corners: Sequence[int],
    jc: JointCompatibility,
    budget: Budget,
    exact: bool = False,
    explore_ties: bool = True,
) -> Best:
    """jcbb.jcbb_search as it was in Python (see its docstring)."""
    order = [i for i in corners if len(g.candidates[i])]
    cands = [g.candidates[i].tolist() for i in order]
    remaining = list(range(len(order), -1, -1))  # remaining[t]: corners with candidates from t on
    used = {k for _, k in jc.pairs()}
    best = Best(explore_ties)
    base = jc.size
    gate = jc.gate

    def visit(t: int) -> None:
        tick(budget)
        i, h = (order[t], jc.size) if t < len(order) else (-1, jc.size)
        if t == len(order):
            if not exact or jc.d2[h] < gate[h]:
                best.offer(jc)
            return
        rest = remaining[t + 1]
        gate_next = gate[h + 1 + rest] if exact else gate[h + 1]
        for k in cands[t]:
            if k in used:
                continue
            d2 = jc.try_add(i, k)
            if d2 < gate_next and can_improve(best, h + 1, rest, d2):
                jc.commit()
                used.add(k)
                try:
                    visit(t + 1)
                finally:
                    used.discard(k)
                    jc.pop()
        d2 = jc.d2[h]
        if can_improve(best, h, rest, d2) and (not exact or d2 < gate[h + rest]):  # corner i unmatched
            visit(t + 1)

    try:
        visit(0)
    except BudgetExhausted:
        pass
    assert jc.size == base
    return best


def group_searches(
    g: Gated,
    groups: list[list[int]],
    jc: JointCompatibility,
    budget: Budget,
    exact: bool = False,
    explore_ties: bool = True,
) -> list[list[tuple[int, int]]]:
    """pca.Pca's loop of Algorithm 3 as it was: the Python JCBB of each group in turn."""
    return [jcbb_search(g, grp, jc, budget, exact, explore_ties).pairs for grp in groups]


def combine_groups(
    g: Gated,
    group_best: list[list[tuple[int, int]]],
    unit_pairs: list[list[tuple[int, int]]],
    jc: JointCompatibility,
    budget: Budget,
    explore_ties: bool = True,
) -> Best:
    """pca.combine_groups (PCBB + NUBB) as it was in Python (see pca.py's docstring)."""
    G = len(group_best)
    rem_after = [0] * (G + 1)  # corners with candidates in groups after t
    for t in range(G - 1, -1, -1):
        rem_after[t] = rem_after[t + 1] + len(unit_pairs[t])
    same = [set(group_best[t]) == set(unit_pairs[t]) for t in range(G)]
    used: set[int] = set()
    best = Best(explore_ties)

    def pcbb(t: int) -> None:
        tick(budget)
        if t == G:
            best.offer(jc)
            return
        Hg, h = group_best[t], jc.size
        if Hg and not any(k in used for _, k in Hg):  # Alg 4 lines 14–17: take H_g whole
            gate_all = jc.gate[h + len(Hg)]
            added = 0
            for i, k in Hg:
                d2 = jc.try_add(i, k)
                if not d2 < gate_all:  # D² only grows: already beyond the final gate
                    break
                jc.commit()
                added += 1
            if added == len(Hg) and can_improve(best, jc.size, rem_after[t + 1], jc.joint_d2):
                used.update(k for _, k in Hg)
                try:
                    pcbb(t + 1)
                finally:
                    used.difference_update(k for _, k in Hg)
            jc.pop(added)
        nubb(t, 0, 0)  # Alg 4 line 19

    def nubb(t: int, s: int, taken: int) -> None:
        tick(budget)
        U = unit_pairs[t]
        if s == len(U):
            if not (same[t] and taken == len(U) and U):  # that leaf repeats the H_g branch
                pcbb(t + 1)
            return
        i, k = U[s]
        h, rest = jc.size, len(U) - s - 1 + rem_after[t + 1]
        if k not in used:  # Alg 5 lines 1–9: append the unit pair
            d2 = jc.try_add(i, k)
            if d2 < jc.gate[h + 1] and can_improve(best, h + 1, rest, d2):
                jc.commit()
                used.add(k)
                try:
                    nubb(t, s + 1, taken + 1)
                finally:
                    used.discard(k)
                    jc.pop()
        if can_improve(best, h, rest, jc.d2[h]):  # Alg 5 lines 10–16: skip it
            nubb(t, s + 1, taken)

    try:
        pcbb(0)
    except BudgetExhausted:
        pass
    return best
