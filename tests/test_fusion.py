"""Odometry–scan-match fusion (motion/fusion.py) and the match covariance (motion/icp.py) against
Monte Carlo references: data drawn from known noise scales, bias and poses."""

from __future__ import annotations

from array import array

import numpy as np
import pytest
from scipy.stats import chi2

from cornerslam_cli.config import load_config
from cornerslam_cli.frontend import odometry_noise
from cornerslam_cli.geometry import compose, relative, transform_points
from cornerslam_cli.motion import ScanMatchConfig
from cornerslam_cli.motion.fusion import SCALE_MIN, OdometryFusion, bias_matrices, bias_matrix, student_fit
from cornerslam_cli.motion.icp import LocalMap, ScanMatcher, register
from cornerslam_cli.simworld import office_world, raycast

ANGLES = np.radians(np.arange(-90.0, 90.5, 1.0))


def fusion(**kw) -> OdometryFusion:
    return OdometryFusion(ScanMatchConfig(**kw))


def draw(rng, k, s, c, n, noise, along=False):
    """n increments with the α-model covariance, match covariances of a few mm, and matches drawn
    from m = o − B(o)·c + e, e ~ N(0, k·Σ_o + s·Σ_m) (the model the fusion assumes)."""
    for _ in range(n):
        o = np.array([rng.uniform(0.2, 1.0), rng.normal(0, 0.05), rng.normal(0, 0.4)])
        So = noise(o)
        A = rng.normal(0, 1, (3, 3))
        D = np.diag([3e-3, 3e-3, 1e-3])
        Sm = D @ (A @ A.T + np.eye(3)) @ D
        m = o - bias_matrix(o, along) @ c + rng.multivariate_normal(np.zeros(3), k * So + s * Sm)
        yield o, So, m, Sm


def test_learnt_noise_scales_and_bias_recover_the_ones_drawn():
    rng = np.random.default_rng(11)
    noise = odometry_noise(load_config(None))
    k, s, c = 0.05, 6.0, np.array([0.02, 0.01])
    f = fusion()
    for o, So, m, Sm in draw(rng, k, s, c, 100, noise):
        f.fuse(o, So, m, Sm)
    assert f.k == pytest.approx(k, rel=0.5) and f.s == pytest.approx(s, rel=0.5)
    d, So, Sm, o = (np.array([x[i] for x in f.samples]) for i in range(4))
    B = bias_matrices(o, f.along)
    assert not f.along  # drawn with the drift at the increments' ends
    _, _, se = student_fit(d, f.k * So + f.s * Sm, B)
    assert np.all(np.abs(f.c - c) < 3 * se) and np.all(se < 0.01)


def test_no_bias_is_invented_and_exact_odometry_is_learnt_as_exact():
    rng = np.random.default_rng(12)
    noise = odometry_noise(load_config(None))
    f = fusion()
    for o, So, m, Sm in draw(rng, 0.0, 4.0, np.zeros(2), 100, noise):
        fused = f.fuse(o, So, m, Sm)
    assert f.k < 1e-3 and f.s == pytest.approx(4.0, rel=0.5)
    assert np.all(f.c == 0.0)  # not significant: not applied
    assert np.abs(fused.inc - o).max() < 1e-3  # the fused increment stays on the odometry


def test_a_scale_error_below_scale_min_is_left_in_even_when_significant():
    # exact odometry and matches 0.5 % short along the direction of travel (ICP along a corridor,
    # motion/fusion.py SCALE_MIN): significant over the window, but no odometer's error to take out
    rng = np.random.default_rng(13)
    noise = odometry_noise(load_config(None))
    f = fusion()
    for o, So, m, Sm in draw(rng, 0.0, 4.0, np.array([SCALE_MIN / 2, 0.0]), 300, noise):
        fused = f.fuse(o, So, m, Sm)
        f.note_step()
    assert np.abs(fused.inc - o).max() < 1e-3  # the odometry is kept as it is
    d, So, Sm, o = (np.array([x[i] for x in f.samples]) for i in range(4))
    _, c, se = student_fit(d, f.k * So + f.s * Sm, bias_matrices(o, f.along))
    assert abs(c[0]) >= 3 * se[0]  # the 3σ rule alone would take it out
    assert f.c[0] == 0.0
    assert f.first_taken[0] is None or f.dropped[0]  # a cold start's term (its first samples): dropped
    # an odometer 2 % off is still taken out
    f = fusion()
    for o, So, m, Sm in draw(rng, 0.0, 4.0, np.array([0.02, 0.0]), 300, noise):
        f.fuse(o, So, m, Sm)
    assert f.c[0] == pytest.approx(0.02, abs=0.004)


def test_each_bias_term_records_the_first_step_it_was_taken_out_of():
    # summary.json's odometry_model.*_from_keyframe: the step (1 = the first increment) whose increment
    # first used the term, checked against the fusion's own state step by step; never taken: None
    rng = np.random.default_rng(11)
    noise = odometry_noise(load_config(None))
    f, taken = fusion(), [[], []]
    for o, So, m, Sm in draw(rng, 0.05, 6.0, np.array([0.02, 0.01]), 100, noise):
        f.fuse(o, So, m, Sm)
        f.note_step()
        for i in range(2):
            taken[i].append(f.c[i] != 0.0)
    want = [taken[i].index(True) + 1 for i in range(2)]
    assert f.first_taken == want and f.n_steps == 100 and all(w > f.min_samples - 1 for w in want)
    exact = fusion()
    for o, So, m, Sm in draw(rng, 0.0, 4.0, np.zeros(2), 100, noise):
        exact.fuse(o, So, m, Sm)
        exact.note_step()
    assert exact.first_taken == [None, None]
    # the first time, not the latest: a term dropped and taken again keeps its first step; a step with
    # no match (the odometry alone, no fuse) still counts
    g = fusion()
    for c, want_first in (((0.0, 0.0), [None, None]), ((0.01, 0.0), [2, None]), ((0.0, 0.0), [2, None]),
                          ((0.01, 0.002), [2, 4])):  # fmt: skip
        g.c = np.array(c)
        g.note_step()
        assert g.first_taken == want_first
    assert g.dropped == [True, False]  # the scale was taken at step 2 and dropped at step 3; the drift held


def test_the_matcher_counts_every_step_after_the_first_fallbacks_too():
    # the step numbers are trajectory.csv's: a keyframe that fell back to the odometry (no map to match,
    # a fit below min_fit) is a step too
    matcher = ScanMatcher(ScanMatchConfig(), odometry_noise(load_config(None)))
    world, rng = office_world(), np.random.default_rng(3)
    for i in range(4):
        pose = np.array([2.0 + 0.3 * i, 2.0, 0.0])
        # after the first, scans of nowhere the map has been: no point fits, the odometry alone is used
        points = scan(world, pose, rng) if i == 0 else rng.uniform(50.0, 60.0, (100, 2))
        matcher.step(points, pose)
        matcher.fusion.c = np.array([0.01, 0.0]) if i == 1 else matcher.fusion.c
    assert matcher.n_fallback == 3 and matcher.fusion.n_steps == 3
    assert matcher.fusion.first_taken == [2, None]  # set after step 1's increment: step 2's took it


def test_the_fused_increment_is_the_information_weighted_mean():
    """Before any learning (k = s = 1): the fused increment and its covariance equal the product of
    the two Gaussians, computed in information form."""
    f = fusion()
    o, m = np.array([0.5, 0.02, 0.1]), np.array([0.47, 0.0, 0.12])
    So, Sm = np.diag([4e-3, 1e-3, 2e-3]), np.diag([1e-3, 2e-3, 1e-4])
    got = f.fuse(o, So, m, Sm)
    info = np.linalg.inv(So) + np.linalg.inv(Sm)
    want = np.linalg.solve(info, np.linalg.solve(So, o) + np.linalg.solve(Sm, m))
    assert got.accepted
    np.testing.assert_allclose(got.inc, want, atol=1e-12)
    np.testing.assert_allclose(got.cov, np.linalg.inv(info), atol=1e-12)


def test_a_match_far_beyond_both_covariances_is_rejected_once_the_scales_are_learnt():
    rng = np.random.default_rng(14)
    noise = odometry_noise(load_config(None))
    f = fusion()
    o = np.array([0.5, 0.0, 0.1])
    wrong = o + [0.0, 0.0, 1.2]  # 69° off: a wrong basin
    assert f.fuse(o, noise(o), wrong, np.diag([1e-4, 1e-4, 1e-5])).accepted  # nothing to judge it by yet
    for oi, So, m, Sm in draw(rng, 0.05, 3.0, np.zeros(2), f.min_samples, noise):
        assert f.fuse(oi, So, m, Sm).accepted
    got = f.fuse(o, noise(o), wrong, np.diag([1e-4, 1e-4, 1e-5]))
    assert not got.accepted and f.n_rejected == 1
    np.testing.assert_array_equal(got.inc, o)


def test_match_covariance_is_consistent_over_monte_carlo_runs():
    """NEES of registered poses in a ray-cast office (independent range noise on both scans): its
    mean over the runs lies in the 95 % band of χ²₃."""
    world = office_world()
    rng = np.random.default_rng(13)
    cfg = ScanMatchConfig()
    ref_pose, true_pose = np.array([6.0, 5.0, 0.1]), np.array([6.5, 5.2, 0.35])
    runs, nees = 60, []
    for _ in range(runs):
        map_pts = transform_points(scan(world, ref_pose, rng), ref_pose)
        reg = register(
            scan(world, true_pose, rng), LocalMap.build(map_pts), true_pose + rng.normal(0, 0.03, 3), cfg
        )
        e = relative(true_pose, reg.pose)
        R = np.array(
            [
                [np.cos(true_pose[2]), -np.sin(true_pose[2]), 0],
                [np.sin(true_pose[2]), np.cos(true_pose[2]), 0],
                [0, 0, 1],
            ]
        )
        e = R @ e  # back into the map frame the covariance is in
        nees.append(float(e @ np.linalg.solve(reg.cov, e)))
    lo, hi = chi2.ppf([0.025, 0.975], 3 * runs) / runs
    assert lo < np.mean(nees) < hi, (np.mean(nees), lo, hi)


def scan(world, pose, rng, sigma=0.01):
    r = raycast(world, pose, ANGLES, max_range=30.0)
    ok = np.isfinite(r)
    r = r[ok] + rng.normal(0.0, sigma, ok.sum())
    return np.column_stack((r * np.cos(ANGLES[ok]), r * np.sin(ANGLES[ok])))


def test_compose_and_relative_round_trip_used_by_the_matcher():
    a, b = np.array([1.0, 2.0, 0.3]), np.array([-0.5, 0.7, -1.2])
    np.testing.assert_allclose(compose(a, relative(a, b)), b, atol=1e-12)


def numpy_student_fit(d, S, B):
    """The Student-t fit in numpy (LAPACK inverses, einsums): the reference for the compiled one."""
    from cornerslam_cli.motion.fusion import IRLS, NU

    Sinv = np.linalg.inv(S)
    w = np.ones(len(d))
    BtS = np.einsum("nij,nik->njk", B, Sinv)
    A0, b0 = np.einsum("njk,nkl->njl", BtS, B), np.einsum("njk,nk->nj", BtS, d)
    for _ in range(IRLS):
        A = np.einsum("n,njl->jl", w, A0) + 1e-12 * np.eye(2)
        c = np.linalg.solve(A, -np.einsum("n,nj->j", w, b0))
        r = d + np.einsum("nij,j->ni", B, c)
        q = np.maximum(np.einsum("ni,nij,nj->n", r, Sinv, r), 0.0)
        w = (NU + 3.0) / (NU + q)
    nll = float(np.sum(0.5 * np.linalg.slogdet(S)[1] + 0.5 * (NU + 3.0) * np.log1p(q / NU)))
    return nll, c, np.sqrt(np.diag(np.linalg.inv(A)))


@pytest.mark.parametrize("scales", [(1.0, 1.0), (0.01, 6.0), (1e-4, 100.0)])
def test_the_compiled_student_fit_is_the_numpy_one(scales):
    """Likelihood, bias and standard errors as numpy computes them (to rounding), over samples with a
    bias and a few wrong matches; a singular covariance gives an infinite cost, not an exception."""
    rng = np.random.default_rng(15)
    noise = odometry_noise(load_config(None))
    samples = list(draw(rng, 0.05, 6.0, np.array([0.02, 0.01]), 300, noise))
    d = np.array([m - o for o, _, m, _ in samples])
    d[::50] += 0.3  # wrong matches
    So, Sm = np.array([x[1] for x in samples]), np.array([x[3] for x in samples])
    B = np.array([bias_matrix(x[0]) for x in samples])
    S = scales[0] * So + scales[1] * Sm
    nll, c, se = student_fit(d, S, B)
    want_nll, want_c, want_se = numpy_student_fit(d, S, B)
    assert nll == pytest.approx(want_nll, rel=1e-12)
    np.testing.assert_allclose(c, want_c, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(se, want_se, rtol=1e-9)
    S[7] = 0.0
    nll, c, se = student_fit(d, S, B)
    assert nll == np.inf and np.all(c == 0.0) and np.all(se == np.inf)


def integrated(fwd: float, turn: float, scale: float, drift: float, steps: int = 2000) -> np.ndarray:
    """The increment an odometry integrated along an arc (``fwd`` m, ``turn`` rad) reports when it reads
    the distance ``scale`` long and its heading drifts ``drift`` rad per metre it reads: summed over
    ``steps`` small steps (an independent reference for bias_matrices' first-order model)."""
    pose = np.zeros(3)
    for _ in range(steps):
        ds = fwd / steps * (1 + scale)
        pose = compose(pose, (ds, 0.0, turn / steps + drift * ds))
    return pose


@pytest.mark.parametrize("fwd, turn", [(1.0, 0.0), (0.8, 0.4), (0.5, -0.9), (1.2, 0.05)])
def test_drift_along_the_path_is_the_integrated_odometry_to_first_order(fwd, turn):
    """B(o, along)·c is the error of an odometry integrated along the arc, to first order in c; without
    ``along``, the error of one whose drift is added at the end (its direction of travel untouched)."""
    truth = integrated(fwd, turn, 0.0, 0.0)
    for c in (np.array([0.02, 0.0]), np.array([0.0, 0.01]), np.array([0.02, 0.01])):
        got = integrated(fwd, turn, *c)
        want = truth + bias_matrix(got, along=True) @ c
        tol = 2 * np.abs(c).max() ** 2 + 2e-5  # second order in c; the sideways step is ~c_θ·L²/2 = 5e-3
        np.testing.assert_allclose(got, want, atol=tol)
        ended = compose(integrated(fwd, turn, c[0], 0.0), (0.0, 0.0, c[1] * np.hypot(*got[:2])))
        np.testing.assert_allclose(ended, truth + bias_matrix(ended) @ c, atol=tol)
        if c[1] and fwd >= 0.8:  # and each model is wrong for the other odometry (a step of mm)
            assert np.abs(got - (truth + bias_matrix(got) @ c)).max() > 3 * tol
    # the along-the-path model's sideways step is the one the end model lacks: c_θ·L²/2 across
    o = integrated(1.0, 0.0, 0.0, 0.01)
    assert o[1] == pytest.approx(0.01 / 2, rel=1e-2) and bias_matrix(o)[1, 1] == 0.0


def test_the_drift_model_follows_the_data_and_needs_evidence_to_change():
    """Matches drawn with the drift acting along the path from a precise odometry: the learner takes that
    model and recovers c; drawn with it at the increments' end, or with no bias (exact odometry), it keeps
    the end model. (With a noisy odometry, k = 0.05, 200 samples are not evidence enough to change.)"""
    noise = odometry_noise(load_config(None))
    c = np.array([0.02, 0.01])
    for along, k in ((True, 0.0), (True, 0.001), (False, 0.0), (False, 0.05)):
        f = fusion()
        for o, So, m, Sm in draw(np.random.default_rng(21), k, 4.0, c, 200, noise, along=along):
            f.fuse(o, So, m, Sm)
        assert f.along == along, (along, k)
        if k < 0.01:  # (with the noisy odometry c is test_learnt_noise_scales_and_bias_…'s business)
            np.testing.assert_allclose(f.c, c, atol=2e-3)
    f = fusion()
    for o, So, m, Sm in draw(np.random.default_rng(22), 0.0, 4.0, np.zeros(2), 200, noise, along=True):
        f.fuse(o, So, m, Sm)
    assert not f.along and np.all(f.c == 0.0)


def test_fit_whole_run_fits_every_sample_and_leaves_the_fusion_as_it_was():
    """fit_whole_run against a fit by hand on all the samples drawn (the same learner on a fusion whose
    window holds them all), while the fusion keeps its last window's state; without whole_run it refuses."""
    rng = np.random.default_rng(21)
    noise = odometry_noise(load_config(None))
    c = np.array([0.02, 0.01])
    drawn = list(draw(rng, 0.05, 6.0, c, 300, noise))
    f, everything = fusion(adapt_window=60, adapt_min_samples=5), fusion(adapt_window=300)
    f.every_sample = array("d")  # (as whole_run=True makes it)
    for o, So, m, Sm in drawn:
        f.fuse(o, So, m, Sm)
        everything.samples.append((m - o, So, Sm, o))
    state = (f.k, f.s, f.c.copy(), f.along)
    c_fit, along = f.fit_whole_run()
    assert (
        f.whole_run_fit is not None
        and np.array_equal(f.whole_run_fit[0], c_fit)
        and f.whole_run_fit[1] == along
    )
    assert (f.k, f.s, f.along) == (state[0], state[1], state[3]) and np.array_equal(f.c, state[2])
    everything.k, everything.s = state[0], state[1]  # (the same starting point as the copy's fit)
    everything._learn()
    o = np.array([x[0] for x in drawn])
    want = bias_matrices(o, everything.along) @ everything.c  # (the bias the by-hand fit takes out)
    np.testing.assert_allclose(bias_matrices(o, along) @ c_fit, want, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(c_fit, everything.c, rtol=1e-9)
    assert along == everything.along
    assert np.all(np.abs(everything.c - c) < 0.005)  # (the drawn bias, found)
    with pytest.raises(ValueError, match="whole_run"):
        fusion().fit_whole_run()


@pytest.mark.parametrize("along", [False, True])
@pytest.mark.parametrize("outcome", ["fused", "rejected"])
def test_carry_back_moves_only_the_steps_before_a_held_term_was_taken_as_fusing_with_it_would(along, outcome):
    """carry_back() against the fusion itself: an increment fused with no bias taken out, fused again with
    the whole run's terms taken out, moves by carry_back's row — for each term only at the steps before
    the learner first took it, and not when it dropped the term once taken or never took it; accepted
    (the match weighted in) or rejected (the corrected odometry alone)."""
    o, m = np.array([0.5, 0.02, 0.1]), np.array([0.47, 0.0, 0.12])
    So, Sm = np.diag([4e-3, 1e-3, 2e-3]), np.diag([1e-3, 2e-3, 1e-4])
    if outcome == "rejected":
        m = m + np.array([2.0, 0.0, 0.0])
    whole = np.array([0.025, 0.008])
    fused = {}
    for terms in ((), (0,), (1,), (0, 1)):  # the whole run's terms taken out of this increment
        f = fusion(adapt_min_samples=2, adapt_every=1000)
        f.every_sample = array("d")
        f.fuse(o, So, o, Sm)
        f._learn = lambda: None  # noqa: SLF001 — the state below, not a learnt one
        f.k, f.s, f.c, f.along = 1.0, 1.0, np.where(np.isin([0, 1], terms), whole, 0.0), along
        out = f.fuse(o, So, m, Sm)
        assert out.accepted == (outcome == "fused")
        fused[terms] = out.inc
    taken = f.taken(o, out.gain)  # (the gain and gate verdict do not depend on the bias: k, s fixed)
    rows = np.array([[0.0] * 12, *[taken.row()] * 4])  # steps 0 (no increment) to 4

    def moved(terms):
        return fused[terms] - fused[()]

    def carried(first, dropped):
        f.first_taken, f.dropped = first, dropped
        f.fit_whole_run = lambda: (whole, along)  # the run's fit, stood in
        return f.carry_back(rows)

    for first, dropped, want in (  # want: the terms carried back to steps 1, 2, 3, 4
        ([2, 4], [False, False], [(0, 1), (1,), (1,), ()]),
        ([3, 2], [False, False], [(0, 1), (0,), (), ()]),
        ([2, 4], [True, False], [(1,), (1,), (1,), ()]),
        ([2, 4], [False, True], [(0,), (), (), ()]),
        ([None, 4], [False, False], [(1,), (1,), (1,), ()]),
        ([2, None], [False, False], [(0,), (), (), ()]),
    ):
        shift = carried(first, dropped)
        assert not shift[0].any(), first
        for k, terms in enumerate(want, start=1):
            np.testing.assert_allclose(shift[k], moved(terms), atol=1e-12, err_msg=f"{first} {dropped} {k}")
    assert np.abs(moved((0,))).max() > 1e-4 and np.abs(moved((1,))).max() > 1e-4  # (cases that move)
    with pytest.raises(ValueError, match="whole_run"):
        fusion().carry_back(rows)  # (no samples kept: fit_whole_run refuses)
    assert fusion().taken(o, np.eye(3)) is None  # not kept without whole_run
