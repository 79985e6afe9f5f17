"""EKF-SLAM (NOTES §5): block-matrix filter vs a dense textbook EKF, Jacobians vs finite differences,
consistency (NEES) on simulated runs with known data association, and health checks."""

from __future__ import annotations

import dataclasses

import _ekf_textbook as textbook
import numpy as np
import pytest
from _ekf_dense import DenseEkf
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2

from cornerslam_cli.errors import NumericalError
from cornerslam_cli.filter import (
    Ekf,
    EkfConfig,
    inverse_observe,
    motion_model,
    motion_noise,
    observe,
    odometry_increment,
)
from cornerslam_cli.filter.models import increment_noise
from cornerslam_cli.geometry import relative, wrap_angle

TOL = 1e-9


# ---------------------------------------------------------------------------- helpers
def random_state(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """A random SLAM state: pose, n landmarks within 10 m, a correlated SPD covariance."""
    d = 3 + 3 * n
    mu = np.concatenate(([*rng.uniform(-2, 2, 2), rng.uniform(-np.pi, np.pi)], rng.uniform(-10, 10, 3 * n)))
    mu[5::3] = rng.uniform(0.3, 2.8, n)
    A = rng.standard_normal((d, d)) * 0.05
    P = A @ A.T / d + np.diag(rng.uniform(0.001, 0.05, d))
    return mu, P


def random_corner_cov(rng: np.random.Generator, k: int) -> np.ndarray:
    A = rng.standard_normal((k, 3, 3)) * 0.02
    return A @ A.transpose(0, 2, 1) + np.diag([1e-3, 1e-3, 1e-4])


def measurements(rng, mu, ids, noise=0.05):
    """Measurements of landmarks ``ids`` near their predicted values (so the innovations are small)."""
    h, _, _ = observe(mu[:3], mu[3:].reshape(-1, 3)[ids])
    return h + rng.normal(0.0, noise, h.shape)


def assert_same_state(ekf: Ekf, ref: DenseEkf) -> None:
    assert ekf.mu.shape == ref.mu.shape
    np.testing.assert_allclose(ekf.mu, ref.mu, rtol=0, atol=TOL)
    np.testing.assert_allclose(ekf.P, ref.P, rtol=0, atol=TOL)


def numeric_jacobian(f, x, eps=1e-6):
    x = np.asarray(x, dtype=float)
    cols = []
    for i in range(len(x)):
        dx = np.zeros_like(x)
        dx[i] = eps
        diff = np.asarray(f(x + dx)) - np.asarray(f(x - dx))
        cols.append(diff / (2 * eps))
    return np.stack(cols, axis=-1)


# ---------------------------------------------------------------------------- models
def test_observation_jacobians_match_finite_differences():
    rng = np.random.default_rng(1)
    for _ in range(20):
        pose = np.array([*rng.uniform(-3, 3, 2), rng.uniform(-np.pi, np.pi)])
        lm = np.array([*rng.uniform(-8, 8, 2), rng.uniform(0.2, 3.0)])
        _, H_r, H_l = observe(pose, lm[None])
        fd_r = numeric_jacobian(lambda p, lm=lm: observe(p, lm[None])[0][0], pose)
        fd_l = numeric_jacobian(lambda m, pose=pose: observe(pose, m[None])[0][0], lm)
        np.testing.assert_allclose(H_r[0], fd_r, atol=1e-7)
        np.testing.assert_allclose(H_l[0], fd_l, atol=1e-7)


def test_observation_is_the_inverse_of_landmark_initialisation():
    rng = np.random.default_rng(2)
    pose = np.array([1.0, -2.0, 2.5])
    z = np.column_stack((rng.uniform(-5, 5, (10, 2)), rng.uniform(0.2, 3, 10)))
    m, _, _ = inverse_observe(pose, z)
    h, _, _ = observe(pose, m)
    np.testing.assert_allclose(h, z, atol=1e-12)
    # a landmark straight ahead of a robot heading +y is seen at (d, 0)
    h, _, _ = observe(np.array([0.0, 0.0, np.pi / 2]), np.array([[0.0, 2.0, 1.0]]))
    np.testing.assert_allclose(h, [[2.0, 0.0, 1.0]], atol=1e-12)


def test_inverse_observation_jacobians_match_finite_differences():
    rng = np.random.default_rng(3)
    for _ in range(20):
        pose = np.array([*rng.uniform(-3, 3, 2), rng.uniform(-np.pi, np.pi)])
        z = np.array([*rng.uniform(-8, 8, 2), rng.uniform(0.2, 3.0)])
        _, G_r, G_z = inverse_observe(pose, z[None])
        fd_r = numeric_jacobian(lambda p, z=z: inverse_observe(p, z[None])[0][0], pose)
        fd_z = numeric_jacobian(lambda q, pose=pose: inverse_observe(pose, q[None])[0][0], z)
        np.testing.assert_allclose(G_r[0], fd_r, atol=1e-7)
        np.testing.assert_allclose(G_z[0], fd_z, atol=1e-7)


def unwrapped_motion(pose, u):
    """motion_model's pose without wrapping the heading, for finite differences."""
    out = motion_model(pose, tuple(u))[0]
    out[2] = pose[2] + u[0] + u[2]
    return out


def test_motion_jacobians_match_finite_differences():
    rng = np.random.default_rng(4)
    for _ in range(20):
        pose = np.array([*rng.uniform(-3, 3, 2), rng.uniform(-3.0, 3.0)])
        u = np.array([rng.uniform(-1, 1), rng.uniform(-0.5, 1), rng.uniform(-1, 1)])
        _, G, V = motion_model(pose, tuple(u))
        np.testing.assert_allclose(
            G, numeric_jacobian(lambda p, u=u: unwrapped_motion(p, u), pose), atol=1e-7
        )
        np.testing.assert_allclose(
            V, numeric_jacobian(lambda q, p=pose: unwrapped_motion(p, q), u), atol=1e-7
        )


@settings(max_examples=60, deadline=None)
@given(
    st.floats(-5, 5),
    st.floats(-5, 5),
    st.floats(-np.pi, np.pi),
    st.floats(-1.0, 1.0),
    st.floats(-1.0, 1.0),
    st.floats(-np.pi, np.pi),
)
def test_odometry_increment_reproduces_the_odometry_pose(x, y, th, dx, dy, dth):
    """Applying (rot1, trans, rot2) from two odometry poses to the first gives the second."""
    prev = np.array([x, y, th])
    cur = np.array([x + dx, y + dy, wrap_angle(th + dth)])
    u = odometry_increment(prev, cur, eps_trans=1e-3)
    pose, _, _ = motion_model(prev, u)
    if np.hypot(*(cur[:2] - prev[:2])) >= 1e-3:  # as rounded in cur, which is what the increment sees
        np.testing.assert_allclose(pose[:2], cur[:2], atol=1e-9)
    else:  # pure rotation: the translation (< eps) is applied along the heading
        assert np.hypot(*(pose[:2] - cur[:2])) <= 2e-3
        assert u.rot1 == 0.0
    assert abs(wrap_angle(pose[2] - cur[2])) < 1e-9
    assert abs(u.rot1) <= np.pi / 2 + 1e-12  # reverse driving is a negative translation


def test_odometry_increment_pure_rotation_and_reverse():
    u = odometry_increment(np.array([1.0, 1.0, 0.3]), np.array([1.0, 1.0, 1.3]))
    assert u == (0.0, 0.0, pytest.approx(1.0))
    u = odometry_increment(np.array([0.0, 0.0, 0.0]), np.array([-0.5, 0.0, 0.0]))  # backing up
    assert u.rot1 == pytest.approx(0.0, abs=1e-12) and u.trans == pytest.approx(-0.5)
    u = odometry_increment(np.array([0.0, 0.0, 0.0]), np.array([-0.5, 0.0, 0.0]), reverse=False)
    assert abs(u.rot1) == pytest.approx(np.pi) and u.trans == pytest.approx(0.5)


def test_motion_noise_is_proportional_to_motion_with_a_floor():
    cfg = EkfConfig()
    R0 = motion_noise((0.0, 0.0, 0.0), 0.3, cfg.alphas, cfg.min_sigma_xy, cfg.min_sigma_theta)
    np.testing.assert_allclose(R0, np.diag([cfg.min_sigma_xy**2] * 2 + [cfg.min_sigma_theta**2]))
    R1 = motion_noise((0.1, 0.5, -0.1), 0.3, cfg.alphas, cfg.min_sigma_xy, cfg.min_sigma_theta)
    R2 = motion_noise((0.2, 1.0, -0.2), 0.3, cfg.alphas, cfg.min_sigma_xy, cfg.min_sigma_theta)
    assert np.linalg.eigvalsh(R1).min() > 0
    assert np.trace(R2) > 3 * np.trace(R1)  # ~4× for twice the motion, minus the floor


# ---------------------------------------------------------------------------- block == dense
UPDATE_MODES = [
    pytest.param(dict(update="sequential", fuse=True), id="sequential-fused"),
    pytest.param(dict(update="sequential", fuse=False), id="sequential-per-pair"),
    pytest.param(dict(update="batched"), id="batched"),
    pytest.param(dict(update="sequential", joseph=True), id="sequential-joseph"),
    pytest.param(dict(update="batched", joseph=True), id="batched-joseph"),
]


@pytest.mark.parametrize("mode", UPDATE_MODES)
@pytest.mark.parametrize("n", [1, 7, 60, 200])
def test_block_update_equals_dense_update(mode, n):
    rng = np.random.default_rng(100 + n)
    cfg = EkfConfig(**mode)
    mu, P = random_state(rng, n)
    ekf, ref = Ekf.from_state(cfg, mu, P), DenseEkf(cfg, mu, P)
    for _ in range(3):
        k = int(rng.integers(1, min(n, 8) + 1))
        ids = rng.choice(n, size=k, replace=False)
        z, C = measurements(rng, ekf.mu, ids), random_corner_cov(rng, k)
        ekf.update(ids, z, C)
        ref.update(ids, z, C)
        assert_same_state(ekf, ref)
    assert np.array_equal(ekf.P, ekf.P.T)  # symmetric bit for bit, by construction


def test_sequential_and_batched_agree_for_small_innovations():
    """They differ only by re-linearisation between pairs: close when the corrections are small."""
    rng = np.random.default_rng(7)
    mu, P = random_state(rng, 30)
    P *= 0.01
    ids = np.array([3, 17, 4, 29])
    z, C = measurements(rng, mu, ids, noise=0.001), random_corner_cov(rng, 4)
    a = Ekf.from_state(EkfConfig(update="sequential"), mu, P)
    b = Ekf.from_state(EkfConfig(update="batched"), mu, P)
    a.update(ids, z, C)
    b.update(ids, z, C)
    np.testing.assert_allclose(a.mu, b.mu, atol=1e-6)
    np.testing.assert_allclose(a.P, b.P, atol=1e-7)


@pytest.mark.parametrize("n", [0, 5, 200])
def test_prediction_equals_dense_prediction(n):
    rng = np.random.default_rng(200 + n)
    cfg = EkfConfig()
    mu, P = random_state(rng, n)
    ekf, ref = Ekf.from_state(cfg, mu, P), DenseEkf(cfg, mu, P)
    odom = np.array([0.3, -0.2, 0.1])
    for step in range(4):
        nxt = odom + [rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(-0.4, 0.4)]
        if step == 2:
            nxt[:2] = odom[:2]  # pure rotation
        ekf.predict(odom, nxt)
        ref.predict(odom, nxt)
        odom = nxt
        assert_same_state(ekf, ref)
    assert np.array_equal(ekf.P, ekf.P.T)


@pytest.mark.parametrize("n", [0, 3, 200])
def test_augmentation_equals_dense_augmentation(n):
    rng = np.random.default_rng(300 + n)
    cfg = EkfConfig(initial_capacity=4)  # forces the buffers to grow
    mu, P = random_state(rng, n)
    ekf, ref = Ekf.from_state(cfg, mu, P), DenseEkf(cfg, mu, P)
    for k in (1, 5, 2):
        z = np.column_stack((rng.uniform(-6, 6, (k, 2)), rng.uniform(0.2, 3, k)))
        C = random_corner_cov(rng, k)
        ids = ekf.augment(z, C)
        ref.augment(z, C)
        assert ids.tolist() == list(range(ekf.n_landmarks - k, ekf.n_landmarks))
        assert_same_state(ekf, ref)
    assert np.array_equal(ekf.P, ekf.P.T)
    assert ekf.landmarks.shape == (n + 8, 3)


def test_a_whole_slam_sequence_equals_the_dense_filter():
    """predict → update → augment interleaved, buffer growth included."""
    rng = np.random.default_rng(9)
    for mode in ({"update": "sequential"}, {"update": "batched"}):
        cfg = EkfConfig(initial_capacity=2, init_sigma_xy=0.01, init_sigma_theta=0.01, **mode)
        ekf = Ekf(cfg, pose0=(1.0, 2.0, 0.5))
        ref = DenseEkf(cfg, ekf.mu, ekf.P)
        odom = np.zeros(3)
        for _ in range(15):
            nxt = odom + [rng.uniform(0, 0.4), rng.uniform(-0.1, 0.1), rng.uniform(-0.3, 0.3)]
            ekf.predict(odom, nxt)
            ref.predict(odom, nxt)
            odom = nxt
            n = ekf.n_landmarks
            if n:
                ids = rng.choice(n, size=min(n, 4), replace=False)
                z, C = measurements(rng, ekf.mu, ids, 0.02), random_corner_cov(rng, len(ids))
                ekf.update(ids, z, C)
                ref.update(ids, z, C)
            z = np.column_stack((rng.uniform(-5, 5, (2, 2)), rng.uniform(0.2, 3, 2)))
            C = random_corner_cov(rng, 2)
            ekf.augment(z, C)
            ref.augment(z, C)
            assert_same_state(ekf, ref)
            ekf.check_health(0)


def test_prediction_object_shares_the_live_covariance():
    rng = np.random.default_rng(10)
    mu, P = random_state(rng, 12)
    ekf = Ekf.from_state(EkfConfig(), mu, P)
    pred = ekf.predict_observations()
    assert np.shares_memory(pred.P, ekf._P_buf)
    assert pred.h.shape == (12, 3) and pred.H_r.shape == (12, 3, 3) and pred.H_l.shape == (12, 3, 3)
    _, H = DenseEkf(ekf.cfg, mu, P)._full_H(np.arange(12))
    np.testing.assert_allclose(
        pred.hph_diag(), [H[3 * i : 3 * i + 3] @ P @ H[3 * i : 3 * i + 3].T for i in range(12)]
    )


# ---------------------------------------------------------------------------- consistency
def simulate_nees(seed: int, cfg: EkfConfig, n_steps: int = 40) -> np.ndarray:
    """Robot-pose NEES per step of one run with known data association.

    The robot follows odometry increments u (a loop of radius ~3 m); the true pose gets the
    model's own process noise N(0, R(u)) and each landmark within 5 m is measured with
    z = h(true pose, landmark) + N(0, C). Landmarks are added at first sight, then updated.
    """
    rng = np.random.default_rng(seed)
    lm_true = np.column_stack((rng.uniform(-6, 6, (40, 2)), rng.uniform(0.3, 2.8, 40)))
    C = np.diag([0.03**2, 0.03**2, 0.02**2])
    Lc = np.linalg.cholesky(C)
    ekf = Ekf(cfg, pose0=(3.0, 0.0, np.pi / 2))
    true = np.array([3.0, 0.0, np.pi / 2])
    odom = np.zeros(3)
    lm_id = -np.ones(len(lm_true), dtype=np.int64)
    nees = np.empty(n_steps)
    for t in range(n_steps):
        u = (0.05, 0.25, 0.05)  # 0.1 rad per 0.25 m: a circle of radius 2.5 m
        odom_next = motion_model(odom, u)[0]
        R = motion_noise(u, true[2], cfg.alphas, cfg.min_sigma_xy, cfg.min_sigma_theta)
        true = motion_model(true, u)[0] + np.linalg.cholesky(R) @ rng.standard_normal(3)
        true[2] = wrap_angle(true[2])
        ekf.predict(odom, odom_next)
        odom = odom_next
        h, _, _ = observe(true, lm_true)
        seen = np.flatnonzero(np.hypot(h[:, 0], h[:, 1]) < 5.0)
        z = h[seen] + rng.standard_normal((len(seen), 3)) @ Lc.T
        known = lm_id[seen] >= 0
        if known.any():
            ekf.update(lm_id[seen[known]], z[known], np.broadcast_to(C, (known.sum(), 3, 3)))
        if (~known).any():
            lm_id[seen[~known]] = ekf.augment(z[~known], np.broadcast_to(C, ((~known).sum(), 3, 3)))
        e = true - ekf.pose
        e[2] = wrap_angle(e[2])
        nees[t] = e @ np.linalg.solve(ekf.P[:3, :3], e)
        ekf.check_health(t)
    return nees


@pytest.mark.parametrize("update", ["sequential", "batched"])
def test_robot_pose_nees_is_consistent_on_simulated_runs(update):
    """NEES of the pose (dof 3) averaged over R = 20 runs, at each of 40 steps.

    Asserted: (a) the average over runs and steps lies in the 95% band of the run average,
    chi2.ppf([0.025, 0.975], 3R)/R; (b) the run average lies in that band at >= 85% of the steps
    (95% expected if perfectly consistent and Gaussian; EKF linearisation costs a little).
    """
    cfg = EkfConfig(update=update, alpha1=0.02, alpha2=0.002, alpha3=0.02, alpha4=0.002)
    R = 20
    nees = np.array([simulate_nees(seed, cfg) for seed in range(R)])  # (R, steps)
    lo, hi = chi2.ppf([0.025, 0.975], 3 * R) / R
    per_step = nees.mean(axis=0)
    assert lo < per_step.mean() < hi, (per_step.mean(), lo, hi)
    inside = np.mean((per_step > lo) & (per_step < hi))
    assert inside >= 0.85, (inside, per_step.round(2))


# ---------------------------------------------------------------------------- health
def test_covariance_stays_symmetric_positive_definite_on_a_long_random_run():
    rng = np.random.default_rng(11)
    cfg = EkfConfig(initial_capacity=1)
    ekf = Ekf(cfg)
    odom = np.zeros(3)
    for step in range(300):
        nxt = odom + [rng.normal(0, 0.2), rng.normal(0, 0.2), rng.normal(0, 0.3)]
        ekf.predict(odom, nxt)
        odom = nxt
        n = ekf.n_landmarks
        if n:
            ids = rng.choice(n, size=min(n, int(rng.integers(1, 6))), replace=False)
            z, C = measurements(rng, ekf.mu, ids, 0.05), random_corner_cov(rng, len(ids))
            ekf.update(ids, z, C)
        if step % 3 == 0 and n < 80:
            k = int(rng.integers(1, 3))
            z = np.column_stack((rng.uniform(-5, 5, (k, 2)), rng.uniform(0.2, 3, k)))
            ekf.augment(z, random_corner_cov(rng, k))
        ekf.check_health(step)
        assert np.array_equal(ekf.P, ekf.P.T)
        if step % 50 == 49:
            assert ekf.min_eigenvalue() > 0.0
    assert ekf.n_landmarks >= 80 and ekf.capacity >= ekf.n_landmarks


@pytest.mark.parametrize("where", ["mu", "P", "diag", "asym"])
def test_health_check_raises_numerical_error_naming_the_step(where):
    rng = np.random.default_rng(12)
    mu, P = random_state(rng, 5)
    ekf = Ekf.from_state(EkfConfig(), mu, P)
    ekf.check_health(0)
    if where == "mu":
        ekf.mu[7] = np.nan
    elif where == "P":
        ekf.P[4, 9] = np.inf
    elif where == "diag":
        ekf.P[6, 6] = -1e-3
    else:
        ekf.P[2, 10] += 1e-3
    with pytest.raises(NumericalError, match="step 42"):
        ekf.check_health(42)


def test_update_with_non_positive_definite_innovation_raises_numerical_error():
    ekf = Ekf.from_state(EkfConfig(), np.array([0, 0, 0, 1.0, 1.0, 1.0]), np.zeros((6, 6)))
    with pytest.raises(NumericalError):
        ekf.update([0], [[1.4, 0.0, 1.0]], -np.eye(3)[None])


def test_config_rejects_invalid_values():
    for bad in (
        dict(alpha1=-0.1),
        dict(min_sigma_xy=float("nan")),
        dict(update="both"),
        dict(initial_capacity=0),
    ):
        with pytest.raises(ValueError):
            EkfConfig(**bad)
    assert dataclasses.replace(EkfConfig(), update="batched").update == "batched"


def test_update_validates_its_arguments():
    ekf = Ekf.from_state(EkfConfig(), *random_state(np.random.default_rng(13), 3))
    with pytest.raises(ValueError):
        ekf.update([3], np.zeros((1, 3)), np.eye(3)[None])
    with pytest.raises(ValueError):
        ekf.update([0, 1], np.zeros((1, 3)), np.eye(3)[None])
    before = ekf.mu.copy()
    assert ekf.update([], np.zeros((0, 3)), np.zeros((0, 3, 3))) == 0.0
    np.testing.assert_array_equal(ekf.mu, before)


# ---------------------------------------------------------------------------- tentative landmarks
def test_remove_landmarks_marginalises_them_out():
    rng = np.random.default_rng(14)
    mu, P = random_state(rng, 9)
    ekf = Ekf.from_state(EkfConfig(), mu, P)
    remap = ekf.remove_landmarks([7, 2, 2])
    keep_l = [0, 1, 3, 4, 5, 6, 8]
    keep = np.r_[0:3, (3 + 3 * np.array(keep_l)[:, None] + np.arange(3)).ravel()]
    assert remap.tolist() == [0, 1, -1, 2, 3, 4, 5, -1, 6]
    np.testing.assert_array_equal(ekf.mu, mu[keep])
    np.testing.assert_array_equal(ekf.P, 0.5 * (P + P.T)[np.ix_(keep, keep)])
    ekf.check_health(0)


def test_tentative_landmarks_are_confirmed_or_dropped():
    cfg = EkfConfig(tentative_sightings=2, tentative_max_age=2)
    ekf = Ekf(cfg)
    C = np.broadcast_to(np.diag([1e-3, 1e-3, 1e-4]), (3, 3, 3))
    ekf.augment([[1.0, 0.0, 1.0], [2.0, 1.0, 1.5], [3.0, -1.0, 0.7]], C)
    assert ekf.tentative.tolist() == [True, True, True]
    odom = np.zeros(3)
    for step in range(4):
        nxt = odom + [0.01, 0.0, 0.0]
        ekf.predict(odom, nxt)
        odom = nxt
        if step == 0:
            h = ekf.predict_observations().h
            ekf.update([1], h[1:2], C[:1])  # landmark 1 seen a second time: confirmed
        remap = ekf.prune_tentative()
        if step < 2:
            assert ekf.n_landmarks == 3 and remap.tolist() == [0, 1, 2]
    # landmarks 0 and 2 were unseen for more than 2 keyframes: dropped; landmark 1 is now id 0
    assert ekf.n_landmarks == 1 and ekf.tentative.tolist() == [False] and ekf.n_obs.tolist() == [2]
    np.testing.assert_allclose(ekf.landmarks[0, :2], [2.0, 1.0], atol=0.05)
    assert Ekf(EkfConfig()).prune_tentative().tolist() == []  # stage off: identity remap


def test_per_increment_motion_noise_equals_a_filter_configured_with_it():
    """A fused increment brings its own covariance (in the frame of the pose it starts from): given
    the α-model covariance of other alphas, the filter equals a dense filter whose config holds those
    alphas — the rotation into the map frame included — and differs from the wheel-odometry defaults."""
    rng = np.random.default_rng(7)
    mu, P = random_state(rng, 20)
    alphas, floor = (0.0002, 0.0001, 0.0002, 0.0001), (0.01, 0.005)
    own = dataclasses.replace(
        EkfConfig(), alpha1=alphas[0], alpha2=alphas[1], alpha3=alphas[2], alpha4=alphas[3],
        min_sigma_xy=floor[0], min_sigma_theta=floor[1],
    )  # fmt: skip
    ekf, ref, wheel = (
        Ekf.from_state(EkfConfig(), mu, P),
        DenseEkf(own, mu, P),
        Ekf.from_state(EkfConfig(), mu, P),
    )
    a, b = np.array([0.3, -0.2, 0.1]), np.array([0.9, 0.1, 0.5])
    cov = increment_noise(relative(a, b), alphas, *floor)
    ekf.predict(a, b, cov)
    ref.predict(a, b)
    wheel.predict(a, b)
    assert_same_state(ekf, ref)
    assert wheel.P[2, 2] > 2 * ekf.P[2, 2] - P[2, 2]


@pytest.mark.parametrize("mode", UPDATE_MODES)
def test_filter_equals_a_textbook_ekf_sharing_no_code_with_it(mode):
    """predict (odometry noise model and a given increment covariance), update and augment against
    tests/_ekf_textbook.py, which re-derives h, every Jacobian and the odometry model instead of taking
    them from filter/models.py; headings on both sides of ±π, a landmark matched twice in one call."""
    rng = np.random.default_rng(41)
    cfg = EkfConfig(**mode)
    batched = cfg.update == "batched"
    for trial in range(6):
        n = 6
        mu, P = random_state(rng, n)
        mu[2] = (np.pi - 1e-3, -np.pi + 1e-4, 0.7)[trial % 3]
        ekf, x, S = Ekf.from_state(cfg, mu, P), mu.copy(), P.copy()
        o0 = np.array([1.0, -2.0, 3.1])
        o1 = o0 + (rng.uniform(-0.4, 0.4), rng.uniform(-0.4, 0.4), rng.uniform(-0.4, 0.4))
        ekf.predict(o0, o1)
        x, S = textbook.predict(x, S, o0, o1, cfg.alphas, cfg.min_sigma_xy, cfg.min_sigma_theta)
        Q = random_corner_cov(rng, 1)[0]
        o2 = o1 + (rng.uniform(-0.4, 0.4), rng.uniform(-0.4, 0.4), rng.uniform(-0.4, 0.4))
        ekf.predict(o1, o2, cov=Q)
        x, S = textbook.predict(x, S, o1, o2, None, 0.0, 0.0, cov=Q)
        ids = np.array([2, 5, 0]) if batched else np.array([2, 5, 2, 0])
        z, C = measurements(rng, ekf.mu, ids), random_corner_cov(rng, len(ids))
        nis = ekf.update(ids, z, C)
        x, S, nis_ref = textbook.update(x, S, ids, z, C, joseph=cfg.joseph, batched=batched)
        assert nis == pytest.approx(nis_ref, rel=1e-9)
        zn = np.column_stack((rng.uniform(-6, 6, (2, 2)), rng.uniform(0.5, 2.5, 2)))
        Cn = random_corner_cov(rng, 2)
        ekf.augment(zn, Cn)
        x, S = textbook.augment(x, S, zn, Cn)
        np.testing.assert_allclose(ekf.mu, x, rtol=0, atol=TOL)
        np.testing.assert_allclose(ekf.P, S, rtol=0, atol=TOL)
