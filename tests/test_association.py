"""Data association (NOTES §4): ICNN, JCBB, PCA against independent references."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from _association_helpers import (
    PAPER_HARD_COUNTS,
    brute_force_best,
    hard_step,
    naive_d2,
    naive_icnn,
    pairs_of,
    random_problem,
    simulate_step,
    stacked_joint_d2,
)
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cornerslam_cli.association import ASSOCIATORS, Icnn, Jcbb, Pca, make_associator
from cornerslam_cli.association.gating import JointCompatibility, chi2_gate, gate, scan_order
from cornerslam_cli.association.params import AssociationConfig, JcbbConfig, PcaConfig
from cornerslam_cli.errors import ConfigError
from cornerslam_cli.types import AssociationResult, Prediction

ALPHA = 0.05


def cfg_for(method: str, **kw) -> AssociationConfig:
    return dataclasses.replace(AssociationConfig(method=method, euclidean_gate=0.0), **kw)


def chi2_of(dof):
    return float(chi2_gate(dof, ALPHA))


def empty_prediction() -> Prediction:
    return Prediction(np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros((0, 3, 3)), np.eye(3) * 0.01)


# ------------------------------------------------------------------ registry and config


def test_unknown_associator_names_the_closest():
    with pytest.raises(ConfigError) as e:
        make_associator(AssociationConfig(method="jbcc"))
    assert e.value.msg == "unknown associator 'jbcc'"
    assert e.value.hint == "did you mean 'jcbb'? Choices: icnn, jcbb, pca"


@pytest.mark.parametrize(
    "kw",
    [
        {"alpha": 0.0},
        {"alpha": 1.0},
        {"euclidean_gate": -1.0},
        {"pca": dataclasses.replace(PcaConfig(), group_size=1)},  # valid: control
    ],
)
def test_config_validation(kw):
    if kw.get("pca"):
        AssociationConfig(**kw)
        with pytest.raises(ValueError):
            PcaConfig(group_size=0)
        with pytest.raises(ValueError):
            JcbbConfig(joint_gate="greedy")
        return
    with pytest.raises(ValueError):
        AssociationConfig(**kw)


@pytest.mark.parametrize("name", list(ASSOCIATORS))
def test_registry_builds_the_named_class(name):
    assert isinstance(make_associator(cfg_for(name)), ASSOCIATORS[name])


@pytest.mark.parametrize("name", list(ASSOCIATORS))
@pytest.mark.parametrize("m,n", [(0, 0), (0, 5), (4, 0)])
def test_empty_inputs_give_unmatched_results(name, m, n):
    rng = np.random.default_rng(0)
    if n:
        p = random_problem(rng, 3, n)
        pred, z, C = p.pred, p.z[:m], p.C[:m]
    else:
        pred = empty_prediction()
        z, C = rng.normal(size=(m, 3)), np.tile(np.eye(3) * 0.01, (m, 1, 1))
    r = make_associator(cfg_for(name))(z, C, pred)
    assert isinstance(r, AssociationResult)
    assert r.pairs.shape == (m,) and np.all(r.pairs == -1)
    assert r.d2.shape == (m,) and np.all(np.isnan(r.d2))
    assert r.n_candidates.shape == (m,) and np.all(r.n_candidates == 0)
    assert r.joint_d2 == 0.0


@pytest.mark.parametrize("name", list(ASSOCIATORS))
@pytest.mark.parametrize("use_phi", [True, False])
def test_results_are_consistent_with_the_gate(name, use_phi):
    """Every associator: matched pairs are individually compatible, d2 and candidate counts are reported
    from the gate, the joint D² is that of the stacked hypothesis."""
    rng = np.random.default_rng(1)
    cfg = cfg_for(name, use_phi=use_phi)
    d = 3 if use_phi else 2
    for _ in range(10):
        p = random_problem(rng, 6, 12)
        g = gate(p.z, p.C, p.pred, cfg)
        r = make_associator(cfg)(p.z, p.C, p.pred)
        assert np.array_equal(r.n_candidates, [len(c) for c in g.candidates])
        for i, k in pairs_of(r):
            assert k in g.candidates[i]
            assert r.d2[i] == pytest.approx(g.d2[i, k]) and r.d2[i] < chi2_of(d)
        assert r.joint_d2 == pytest.approx(stacked_joint_d2(p.z, p.C, p.pred, pairs_of(r), d), rel=1e-9)


@pytest.mark.parametrize("name", list(ASSOCIATORS))
def test_invariant_to_landmark_and_corner_order(name):
    rng = np.random.default_rng(2)
    a = make_associator(cfg_for(name))
    for _ in range(8):
        p = random_problem(rng, 7, 12)
        r = a(p.z, p.C, p.pred)
        perm_k = rng.permutation(len(p.pred))
        idx = np.concatenate([np.arange(3), (3 + 3 * perm_k[:, None] + np.arange(3)).ravel()])
        pred2 = Prediction(
            p.pred.h[perm_k], p.pred.H_r[perm_k], p.pred.H_l[perm_k], p.pred.P[np.ix_(idx, idx)]
        )
        perm_i = rng.permutation(len(p.z))
        r2 = a(p.z[perm_i], p.C[perm_i], pred2)
        back = np.where(r2.pairs >= 0, perm_k[np.maximum(r2.pairs, 0)], -1)  # to original landmark ids
        assert np.array_equal(back, r.pairs[perm_i])


@pytest.mark.parametrize("name", list(ASSOCIATORS))
def test_euclidean_pregate_only_removes_far_pairs(name):
    rng = np.random.default_rng(3)
    for _ in range(5):
        p = random_problem(rng, 6, 12)
        r = make_associator(cfg_for(name))(p.z, p.C, p.pred)
        wide = make_associator(cfg_for(name, euclidean_gate=100.0))(p.z, p.C, p.pred)
        assert np.array_equal(r.pairs, wide.pairs)
        tight = make_associator(cfg_for(name, euclidean_gate=0.2))(p.z, p.C, p.pred)
        for i, k in pairs_of(tight):
            assert np.hypot(*(p.z[i, :2] - p.pred.h[k, :2])) <= 0.2


# ------------------------------------------------------------------ gating machinery


@pytest.mark.parametrize("use_phi", [True, False])
def test_vectorised_gate_and_icnn_equal_double_loop(use_phi):
    rng = np.random.default_rng(4)
    cfg = cfg_for("icnn", use_phi=use_phi)
    d = 3 if use_phi else 2
    for _ in range(10):
        p = random_problem(rng, 7, 15)
        g = gate(p.z, p.C, p.pred, cfg)
        np.testing.assert_allclose(g.d2, naive_d2(p.z, p.C, p.pred, d), rtol=1e-9)
        r = Icnn(cfg)(p.z, p.C, p.pred)
        assert np.array_equal(r.pairs, naive_icnn(p.z, p.C, p.pred, chi2_of(d), d))


def test_phi_innovation_is_wrapped():
    rng = np.random.default_rng(5)
    p = random_problem(rng, 4, 6)
    z = p.z.copy()
    z[:, 2] += 2 * np.pi
    g0, g1 = (
        gate(p.z, p.C, p.pred, AssociationConfig(euclidean_gate=0.0)),
        gate(z, p.C, p.pred, AssociationConfig(euclidean_gate=0.0)),
    )
    np.testing.assert_allclose(g0.d2, g1.d2, rtol=1e-9)


@pytest.mark.parametrize("use_phi", [True, False])
def test_incremental_joint_d2_equals_stacked_solve(use_phi):
    """Random push/pop sequences: every D² equals νᵀS⁻¹ν of the stacked hypothesis."""
    rng = np.random.default_rng(6)
    cfg = AssociationConfig(use_phi=use_phi, euclidean_gate=0.0)
    d = 3 if use_phi else 2
    for _ in range(10):
        p = random_problem(rng, 7, 12)
        g = gate(p.z, p.C, p.pred, cfg)
        jc = JointCompatibility(g, 7)
        for _ in range(25):
            if jc.size and rng.random() < 0.35:
                jc.pop()
            elif jc.size < 7:
                i = int(rng.integers(7))
                k = int(rng.integers(12))  # any landmark, not only candidates
                d2 = jc.try_add(i, k)
                if rng.random() < 0.2:
                    continue  # an uncommitted try must leave the state untouched
                jc.commit()
                assert d2 == pytest.approx(stacked_joint_d2(p.z, p.C, p.pred, jc.pairs(), d), rel=1e-8)
            assert jc.joint_d2 == pytest.approx(stacked_joint_d2(p.z, p.C, p.pred, jc.pairs(), d), rel=1e-8)


# ------------------------------------------------------------------ JCBB and PCA against brute force


@pytest.mark.parametrize("joint_gate", ["prefix", "exact"])
def test_jcbb_equals_brute_force(joint_gate):
    """exact: the best jointly compatible injective assignment of all; prefix (Neira & Tardós): the best
    one all of whose prefixes in scan order are jointly compatible."""
    rng = np.random.default_rng(7)
    cfg = cfg_for("jcbb", jcbb=JcbbConfig(joint_gate=joint_gate))
    for trial in range(40):
        m = int(rng.integers(1, 8))
        p = random_problem(rng, m, int(rng.integers(3, 11)), pose_sigma=(0.4, 0.4, 0.06))
        g = gate(p.z, p.C, p.pred, cfg)
        pairs, d2 = brute_force_best(
            p.z, p.C, p.pred, g.candidates, chi2_of, corners=scan_order(p.z), prefix=joint_gate == "prefix"
        )
        r = Jcbb(cfg)(p.z, p.C, p.pred)
        assert sorted(pairs_of(r)) == pairs, f"trial {trial}"
        assert r.joint_d2 == pytest.approx(d2, rel=1e-8)
        assert not r.budget_hit


@pytest.mark.parametrize("name", ["jcbb", "pca"])
def test_without_tie_search_the_pairing_count_is_still_optimal(name):
    rng = np.random.default_rng(11)
    cfg = cfg_for(name, jcbb=JcbbConfig(explore_ties=False), pca=PcaConfig(group_size=8))
    for _ in range(30):
        p = random_problem(rng, int(rng.integers(1, 8)), 10, pose_sigma=(0.4, 0.4, 0.06))
        g = gate(p.z, p.C, p.pred, cfg)
        pairs, _ = brute_force_best(
            p.z, p.C, p.pred, g.candidates, chi2_of, corners=scan_order(p.z), prefix=True
        )
        r = make_associator(cfg)(p.z, p.C, p.pred)
        assert r.n_matched == len(pairs)
        assert r.joint_d2 < chi2_of(3 * r.n_matched) or not r.n_matched


@pytest.mark.parametrize("joint_gate", ["prefix", "exact"])
def test_pca_with_one_group_is_jcbb(joint_gate):
    rng = np.random.default_rng(8)
    for _ in range(30):
        m = int(rng.integers(1, 9))
        p = random_problem(rng, m, 12, pose_sigma=(0.4, 0.4, 0.06))
        jcfg = JcbbConfig(joint_gate=joint_gate)
        r_j = Jcbb(cfg_for("jcbb", jcbb=jcfg))(p.z, p.C, p.pred)
        for grouping in ("scan", "spatial"):
            cfg = cfg_for("pca", jcbb=jcfg, pca=PcaConfig(group_size=m, grouping=grouping))
            r_p = Pca(cfg)(p.z, p.C, p.pred)
            assert np.array_equal(r_p.pairs, r_j.pairs)
            assert r_p.joint_d2 == pytest.approx(r_j.joint_d2, rel=1e-9)


def test_pca_with_groups_of_one_is_icnn_with_a_joint_check():
    """p = 1: the result is the largest subset of ICNN's pairs that is collision-free and whose every
    prefix in scan order is jointly compatible (ties: least joint D²) — checked by brute force."""
    rng = np.random.default_rng(9)
    cfg = cfg_for("pca", pca=PcaConfig(group_size=1))
    for _ in range(30):
        p = random_problem(rng, int(rng.integers(1, 9)), 10, pose_sigma=(0.4, 0.4, 0.06))
        icnn = Icnn(cfg)(p.z, p.C, p.pred)
        units = [[k] if k >= 0 else [] for k in icnn.pairs]
        pairs, d2 = brute_force_best(p.z, p.C, p.pred, units, chi2_of, corners=scan_order(p.z), prefix=True)
        r = Pca(cfg)(p.z, p.C, p.pred)
        assert sorted(pairs_of(r)) == pairs
        assert r.joint_d2 == pytest.approx(d2, rel=1e-8)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**32 - 1),
    m=st.integers(0, 10),
    n=st.integers(0, 14),
    p=st.integers(1, 5),
    grouping=st.sampled_from(["scan", "spatial"]),
    joint_gate=st.sampled_from(["prefix", "exact"]),
    near_singular=st.booleans(),
    use_phi=st.booleans(),
)
def test_pca_answer_is_jointly_compatible_and_collision_free(
    seed, m, n, p, grouping, joint_gate, near_singular, use_phi
):
    rng = np.random.default_rng(seed)
    prob = random_problem(rng, m, n, near_singular=near_singular) if n else None
    z, C, pred = (prob.z, prob.C, prob.pred) if prob else (rng.normal(size=(m, 3)), np.zeros((m, 3, 3)), None)
    pred = pred or empty_prediction()
    cfg = cfg_for("pca", use_phi=use_phi, jcbb=JcbbConfig(joint_gate=joint_gate), pca=PcaConfig(p, grouping))
    r = Pca(cfg)(z, C, pred)
    ks = r.pairs[r.pairs >= 0]
    assert len(ks) == len(set(ks.tolist()))
    assert r.pairs.shape == (m,)
    if not near_singular and len(ks):
        d = 3 if use_phi else 2
        assert stacked_joint_d2(z, C, pred, pairs_of(r), d) < chi2_of(d * len(ks)) * (1 + 1e-9)


@pytest.mark.parametrize("name", ["jcbb", "pca"])
def test_node_budget_stops_the_search(name):
    p = hard_step(np.random.default_rng(0))
    budget = {"jcbb": JcbbConfig(max_nodes=20)} if name == "jcbb" else {"pca": PcaConfig(max_nodes=20)}
    r = make_associator(cfg_for(name, **budget))(p.z, p.C, p.pred)
    assert r.budget_hit and r.nodes == 20
    assert r.n_matched > 0  # the greedy fallback
    assert r.n_matched == 0 or r.joint_d2 < chi2_of(3 * r.n_matched)
    full = make_associator(cfg_for(name))(p.z, p.C, p.pred)
    assert not full.budget_hit and full.nodes > 20


def test_hard_step_has_the_papers_candidate_counts_and_jcbb_beats_icnn():
    p = hard_step(np.random.default_rng(0))
    res = {name: make_associator(cfg_for(name))(p.z, p.C, p.pred) for name in ASSOCIATORS}
    for r in res.values():
        assert r.n_candidates.tolist() == list(PAPER_HARD_COUNTS)
    assert not res["icnn"].extra["jointly_compatible"]
    for name in ("jcbb", "pca"):
        assert res[name].joint_d2 < chi2_of(3 * res[name].n_matched)


def test_joint_methods_are_more_precise_than_icnn():
    """Coherent pose error and close landmark twins: ICNN takes wrong neighbours, JCBB/PCA less often."""
    rng = np.random.default_rng(10)
    correct = {name: 0 for name in ASSOCIATORS}
    matched = dict(correct)
    kw = {"pose_sigma": (0.3, 0.3, 0.05), "n": 30, "m_true": 8, "n_spurious": 2, "n_twins": 8}
    for _ in range(40):
        p = simulate_step(rng, **kw)
        for name in ASSOCIATORS:
            r = make_associator(cfg_for(name))(p.z, p.C, p.pred)
            ok = r.pairs >= 0
            matched[name] += int(ok.sum())
            correct[name] += int((r.pairs[ok] == p.truth[ok]).sum())
    prec = {name: correct[name] / matched[name] for name in ASSOCIATORS}
    assert prec["jcbb"] > prec["icnn"] + 0.02
    assert prec["pca"] > prec["icnn"] + 0.02
