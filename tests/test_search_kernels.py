"""The compiled JCBB and PCA searches (association/search_kernels.py) against the Python searches they
replaced (tests/_assoc_reference.py): the same pairs, joint D² (==, not approximately), nodes, budget
stop and tie winner, on random problems generated here."""

from __future__ import annotations

import dataclasses

import _assoc_reference as ref
import numpy as np
import pytest
from _association_helpers import hard_step, random_problem

from cornerslam_cli.association import Jcbb, Pca, jcbb, load_kernels, pca, search_kernels
from cornerslam_cli.association.gating import JointCompatibility, gate, scan_order
from cornerslam_cli.association.jcbb import Budget
from cornerslam_cli.association.params import AssociationConfig, JcbbConfig, PcaConfig
from cornerslam_cli.types import Prediction


def random_case(rng: np.random.Generator, case: int):
    """A problem with 0–12 corners and 0–40 landmarks (every fifth the paper's hard step), and a config:
    both gate modes, both tie modes, both groupings, group sizes 1..m, with or without φ and the
    Euclidean gate, tiny node budgets (JCBB's or PCA's) on some."""
    m, n = int(rng.integers(0, 13)), int(rng.integers(0, 41))
    if case % 5 == 4:
        p = hard_step(rng)
    else:
        sigma = float(rng.choice([0.2, 0.5, 1.0]))
        p = random_problem(rng, m, max(n, 1), pose_sigma=(sigma, sigma, sigma / 5))
        if n == 0:  # no landmark at all
            none = Prediction(np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros((0, 3, 3)), p.pred.P[:3, :3])
            p = dataclasses.replace(p, pred=none)
    m = len(p.z)
    cfg = AssociationConfig(
        euclidean_gate=float(rng.choice([0.0, 0.5, 2.0])),
        use_phi=bool(rng.random() < 0.7),
        alpha=float(rng.choice([0.05, 0.2])),
        jcbb=JcbbConfig(
            joint_gate=str(rng.choice(["prefix", "exact"])),
            explore_ties=bool(rng.random() < 0.5),
            max_nodes=int(rng.integers(1, 60)) if rng.random() < 0.25 else 0,
        ),
        pca=PcaConfig(
            group_size=int(rng.integers(1, max(m, 1) + 1)),
            grouping=str(rng.choice(["scan", "spatial"])),
            max_nodes=int(rng.integers(1, 100)) if rng.random() < 0.25 else 0,
        ),
    )
    return p, cfg


def reference_result(monkeypatch, associator, p):
    """The associator's result with the Python searches in place of the compiled ones."""
    with monkeypatch.context() as mp:
        mp.setattr(jcbb, "jcbb_search", ref.jcbb_search)
        mp.setattr(pca, "group_searches", ref.group_searches)
        mp.setattr(pca, "combine_groups", ref.combine_groups)
        return associator(p.z, p.C, p.pred)


def assert_same_result(a, b):
    assert np.array_equal(a.pairs, b.pairs)
    assert np.array_equal(a.d2, b.d2, equal_nan=True)
    assert a.joint_d2 == b.joint_d2
    assert (a.nodes, a.budget_hit) == (b.nodes, b.budget_hit)
    for key in ("groups", "group_best", "unit_pairs", "group_nodes", "combine_nodes"):
        assert a.extra.get(key) == b.extra.get(key), key


@pytest.mark.parametrize("chunk", range(4))
def test_compiled_associators_equal_the_python_searches(monkeypatch, chunk):
    """PCA and JCBB on 400 random problems: the same result, bit for bit, as with the Python searches;
    the cases cover hypotheses of 0 to 12 pairings, searches of hundreds of nodes and budgets that hit."""
    rng = np.random.default_rng(1600 + chunk)
    counts, hits, most_nodes = set(), 0, 0
    for case in range(100):
        p, cfg = random_case(rng, case)
        for cls in (Pca, Jcbb):
            got, want = cls(cfg)(p.z, p.C, p.pred), reference_result(monkeypatch, cls(cfg), p)
            assert_same_result(got, want)
            counts.add(int((got.pairs >= 0).sum()))
            hits += got.budget_hit
            most_nodes = max(most_nodes, got.nodes)
    assert len(counts) >= 8 and hits >= 10 and most_nodes >= 200  # the cases are not all trivial


def committed(g, jc, rng, pairs_wanted):
    """Commit up to ``pairs_wanted`` random compatible pairings in jc (as a caller might before a search)."""
    used = set()
    for i in rng.permutation(g.m)[:pairs_wanted].tolist():
        free = [k for k in g.candidates[i].tolist() if k not in used]
        if free and jc.try_add(i, free[0]) < jc.gate[jc.size + 1]:
            jc.commit()
            used.add(free[0])
    return {i for i, _ in jc.pairs()}


def jc_state(jc):
    return jc.size, [a.copy() for a in jc.arrays()]


@pytest.mark.parametrize("exact", [False, True])
@pytest.mark.parametrize("explore_ties", [True, False])
def test_jcbb_search_from_committed_pairings_equals_the_python_one(exact, explore_ties):
    """jcbb_search from a hypothesis already holding pairings, over a random subset of corners in a
    random order, with a budget shared with earlier searches: the same best (count, D², pairs), the same
    nodes and stop, and the hypothesis's arrays left exactly as the Python search leaves them."""
    rng = np.random.default_rng(16 + 2 * exact + explore_ties)
    for case in range(60):
        p, cfg = random_case(rng, case)
        cfg = dataclasses.replace(cfg, euclidean_gate=0.0)
        g_fast, g_ref = gate(p.z, p.C, p.pred, cfg), gate(p.z, p.C, p.pred, cfg)
        capacity = max(g_fast.m, 1)
        jcs = JointCompatibility(g_fast, capacity), JointCompatibility(g_ref, capacity)
        base = int(rng.integers(0, 3))
        fixed = [
            committed(g, jc, np.random.default_rng(case), base)
            for g, jc in zip((g_fast, g_ref), jcs, strict=True)
        ]
        assert fixed[0] == fixed[1]
        corners = [i for i in scan_order(g_fast.z) if i not in fixed[0]]
        corners = [corners[j] for j in rng.permutation(len(corners))]
        max_nodes, spent = int(rng.choice([0, 5, 40])), int(rng.integers(0, 4))
        budgets = []
        for search, g, jc in ((jcbb.jcbb_search, g_fast, jcs[0]), (ref.jcbb_search, g_ref, jcs[1])):
            budget = Budget(max_nodes)
            budget.nodes = spent
            best = search(g, corners, jc, budget, exact, explore_ties)
            budgets.append((best.count, best.d2, best.pairs, budget.nodes, budget.hit))
        assert budgets[0] == budgets[1]
        (size_a, arrays_a), (size_b, arrays_b) = jc_state(jcs[0]), jc_state(jcs[1])
        assert size_a == size_b
        for a, b in zip(arrays_a, arrays_b, strict=True):
            assert np.array_equal(a, b)


def test_combine_groups_equals_the_python_one_on_reordered_and_shared_groups():
    """combine_groups on groups whose H_g is U_g in another order (the "same" leaf rule compares sets),
    whose unit pairs share landmarks (collisions), under node budgets that stop it part way: the same
    best and the same nodes as the Python PCBB + NUBB."""
    rng = np.random.default_rng(1616)
    tried = hit = 0
    for case in range(80):
        p, cfg = random_case(rng, case)
        g = gate(p.z, p.C, p.pred, cfg)
        nearest = g.nearest()
        order = [i for i in scan_order(g.z) if nearest[i] >= 0]
        size = int(rng.integers(1, 4))
        units = [[(i, int(nearest[i])) for i in order[s : s + size]] for s in range(0, len(order), size)]
        if rng.random() < 0.5 and len(order) > 1:  # two corners on one landmark
            i, j = order[:2]
            units[0] = [(i, int(nearest[j])), *units[0][1:]]
        group_best = [
            [U[j] for j in rng.permutation(len(U))][: int(rng.integers(0, len(U) + 1))] for U in units
        ]
        max_nodes = int(rng.choice([0, 3, 20]))
        found = []
        for search in (pca.combine_groups, ref.combine_groups):
            budget = Budget(max_nodes)
            jc = JointCompatibility(g, max(g.m, 1))
            best = search(g, group_best, units, jc, budget, cfg.jcbb.explore_ties)
            found.append((best.count, best.d2, best.pairs, budget.nodes, budget.hit))
        assert found[0] == found[1]
        tried += bool(units)
        hit += found[0][4]
    assert tried >= 40 and hit >= 5


def big_search(rng):
    """The paper's hard step with six candidates for each of ten corners: thousands of JCBB nodes."""
    p = hard_step(rng, counts=(6,) * 10, n_background=5)
    return p, AssociationConfig(euclidean_gate=0.0, jcbb=JcbbConfig(joint_gate="exact"))


def test_time_budget_stops_at_a_multiple_of_256_nodes():
    """max_seconds is checked when the node count reaches a multiple of 256 (through object mode in the
    compiled searches): a deadline already past stops JCBB and PCA there, with budget_hit, and the
    Python search stops at the same node."""
    p, cfg = big_search(np.random.default_rng(7))
    assert Jcbb(cfg)(p.z, p.C, p.pred).nodes > 1000
    timed = dataclasses.replace(
        cfg,
        jcbb=dataclasses.replace(cfg.jcbb, max_seconds=1e-9),
        pca=PcaConfig(group_size=10, max_seconds=1e-9),
    )
    for cls in (Jcbb, Pca):
        got = cls(timed)(p.z, p.C, p.pred)
        assert got.budget_hit and got.nodes == 256
    g = gate(p.z, p.C, p.pred, cfg)
    budget = Budget(0, 1e-9)
    ref.jcbb_search(g, scan_order(g.z), JointCompatibility(g, 10), budget, True)
    assert budget.hit and budget.nodes == 256


def test_load_kernels_compiles_every_search_a_run_uses():
    """After association.load_kernels, associating a real-sized problem with either method, gate or tie
    mode compiles nothing more: the searches' argument types are the warm-up's."""
    load_kernels()
    kernels = (search_kernels.jcbb_kernel, search_kernels.groups_kernel, search_kernels.combine_kernel)
    loaded = [len(k.signatures) for k in kernels]
    assert all(loaded)
    rng = np.random.default_rng(3)
    for case in range(10):
        p, cfg = random_case(rng, case)
        Pca(cfg)(p.z, p.C, p.pred)
        Jcbb(cfg)(p.z, p.C, p.pred)
    assert [len(k.signatures) for k in kernels] == loaded


def test_a_search_beyond_the_hypothesis_capacity_is_refused():
    """The compiled searches write without bounds checks: JCBB over more corners than the hypothesis can
    hold, or PCA's groups larger than it, is a ValueError before any search."""
    p = random_problem(np.random.default_rng(5), 6, 10)
    g = gate(p.z, p.C, p.pred, AssociationConfig())
    with pytest.raises(ValueError, match="capacity 3"):
        jcbb.jcbb_search(g, range(6), JointCompatibility(g, 3), Budget())
    with pytest.raises(ValueError, match="capacity 2"):
        pca.group_searches(g, [[0, 1], [2, 3, 4]], JointCompatibility(g, 2), Budget())
    assert jcbb.jcbb_search(g, range(3), JointCompatibility(g, 3), Budget()).count <= 3
