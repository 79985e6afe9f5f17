"""Line segments (Algorithm 1) and their covariance (eq 2–8)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from _features_helpers import (
    HOKUYO,
    PRECISE,
    URG04LX,
    beam_covariance,
    beam_jacobian,
    clutter_room,
    mean_nees,
    nees_band,
    noisy_ranges,
    to_world,
    wall_bearings,
)

from cornerslam_cli import simworld as sw
from cornerslam_cli.features import LinesConfig, SensorConfig, extract_segments, fit_lines, sigma_range
from cornerslam_cli.features.lines import fit_ranges
from cornerslam_cli.features.sensor import beam_variances


def test_sensor_models():
    pw = SensorConfig()
    np.testing.assert_allclose(sigma_range(np.array([0.5, 1.0, 2.0, 8.0]), pw), [0.03, 0.03, 0.06, 0.24])
    lin = SensorConfig(model="linear", a=0.01, b=0.005)
    np.testing.assert_allclose(sigma_range(np.array([0.0, 2.0]), lin), [0.01, 0.02])
    assert beam_variances(np.ones(3), pw)[1] == pytest.approx(np.full(3, (math.pi / 1024) ** 2))


@pytest.mark.parametrize(
    "cls, kwargs",
    [
        (SensorConfig, {"sigma_theta": -1.0}),
        (LinesConfig, {"min_points": 1}),
        (LinesConfig, {"split_distance": 0}),
    ],
)
def test_config_rejects_invalid_values(cls, kwargs):
    with pytest.raises(ValueError):
        cls(**kwargs)


def _wall_error(world: sw.World, pose, p1, p2, alpha) -> tuple[float, float]:
    """Smallest (max end-point distance, angle error) of a segment against the world's walls."""
    a, b = to_world(p1[None], pose)[0], to_world(p2[None], pose)[0]
    best = (np.inf, np.inf)
    for w0, w1 in world.walls:
        e = (w1 - w0) / np.hypot(*(w1 - w0))
        n = np.array([-e[1], e[0]])
        d = max(abs((a - w0) @ n), abs((b - w0) @ n))
        # the segment's direction is the normal α + π/2, in the world α + θ + π/2
        da = abs(math.remainder(alpha + pose[2] + math.pi / 2 - math.atan2(e[1], e[0]), math.pi))
        best = min(best, (d, da))
    return best


NOISELESS_CASES = [
    (clutter_room(), (3.0, 3.0, 0.0)),
    (clutter_room(), (6.8, 1.0, 2.2)),
    (clutter_room(), (1.0, 5.0, -0.8)),
] + [(sw.office_world(), tuple(p)) for p in sw.path_poses(sw.OFFICE_LOOP, 4.0)]


@pytest.mark.parametrize("world, pose", NOISELESS_CASES)
def test_noiseless_segments_lie_on_true_walls(world, pose):
    scan = sw.simulate_scan(world, pose, HOKUYO, max_range=8.0)
    segs, _ = extract_segments(scan, PRECISE, LinesConfig())
    assert len(segs) >= 3
    for k in range(len(segs)):
        d, da = _wall_error(world, pose, segs.p1[k], segs.p2[k], segs.alpha[k])
        assert d < 1e-3, f"segment {k} is {d * 1e3:.2f} mm off its wall"
        assert da < math.radians(0.1), f"segment {k} is {math.degrees(da):.3f} deg off its wall"
    # Hessian form invariants and end points on the line
    assert np.all(segs.r >= 0) and np.all((segs.alpha > -np.pi) & (segs.alpha <= np.pi))
    for p in (segs.p1, segs.p2):
        np.testing.assert_allclose(
            p[:, 0] * np.cos(segs.alpha) + p[:, 1] * np.sin(segs.alpha), segs.r, atol=1e-9
        )


def test_breakpoint_and_merge_in_a_simple_scene():
    # one wall with a gap of 3 dropped beams (still one segment) and a box well in front (its own segments)
    world = sw.make_world([sw.polyline([(3, -4), (3, 4)]), sw.rectangle(1.5, 0.0, 0.4, 0.4)])
    angles = np.linspace(-0.9, 0.9, 400)
    ranges = sw.raycast(world, (0, 0, 0), angles)
    ranges[300:303] = np.inf
    scan = sw.scan_from_ranges(ranges, angles)
    segs, _ = extract_segments(scan, PRECISE, LinesConfig())
    on_wall = np.isclose(segs.r, 3.0) & np.isclose(segs.alpha, 0.0)
    assert on_wall.sum() == 2  # the box's shadow splits the wall; the dropped beams do not
    assert np.all(segs.n_points[~on_wall] >= LinesConfig().min_points)
    assert np.any(np.isclose(segs.r, 1.3))  # the box's front face


def _line_scene(n=150, r=3.0, alpha=0.4, half_width=1.2):
    """Beams hitting the line (r, α) over a chord of ±half_width metres about its foot point."""
    foot = r * np.array([math.cos(alpha), math.sin(alpha)])
    d = np.array([-math.sin(alpha), math.cos(alpha)])
    pts = foot + np.linspace(-half_width, half_width, n)[:, None] * d
    return np.hypot(pts[:, 0], pts[:, 1]), np.arctan2(pts[:, 1], pts[:, 0])


def test_line_jacobian_matches_finite_differences():
    # the analytic covariance is J C Jᵀ; check J (with the r–α coupling) through one-beam covariances
    rho, theta = _line_scene(n=40)
    rng = np.random.default_rng(3)
    rho = rho + rng.normal(0, 0.01, rho.shape)  # off the line, so residual terms matter
    var_r, var_t = beam_variances(rho, PRECISE)
    w = 1.0 / (var_r + rho**2 * var_t)
    fit = fit_lines(rho, theta, var_r, var_t, [0], [len(rho)], w)
    J = np.zeros((2, 2 * len(rho)))
    h = 1e-7
    for i in range(len(rho)):
        for k, (dr, dt) in enumerate(((h, 0.0), (0.0, h))):
            rp, tp = rho.copy(), theta.copy()
            rp[i] += dr
            tp[i] += dt
            f = fit_lines(rp, tp, var_r, var_t, [0], [len(rho)], w)  # weights fixed, as in the model
            J[:, 2 * i + k] = (
                (f.r[0] - fit.r[0]) / h,
                math.remainder(f.alpha[0] - fit.alpha[0], 2 * math.pi) / h,
            )
    C = J @ np.diag(np.ravel(np.column_stack((var_r, np.broadcast_to(var_t, rho.shape))))) @ J.T
    np.testing.assert_allclose(fit.cov[0], C, rtol=1e-4, atol=1e-12)
    np.testing.assert_allclose(fit.jac_ends[0, 0], J[:, :2], rtol=1e-4, atol=1e-10)
    np.testing.assert_allclose(fit.jac_ends[0, 1], J[:, -2:], rtol=1e-4, atol=1e-10)


@pytest.mark.parametrize("alpha, sensor", [(0.4, PRECISE), (-2.5, SensorConfig())])
def test_line_covariance_monte_carlo(alpha, sensor):
    """NEES of (r, α) over 1000 noisy draws lies in the 95 % chi² band: the covariance is honest.

    The default sensor (σρ = 3 % of the range) also checks the two-pass weights: with weights from the
    measured ranges, r is biased by about 0.7σ and the mean NEES is 2.6.
    """
    rho0, theta0 = _line_scene(r=3.0, alpha=alpha)
    sig_r = sigma_range(rho0, sensor)
    rng = np.random.default_rng(7)
    n = 1000
    err, covs = np.zeros((n, 2)), np.zeros((n, 2, 2))
    for k in range(n):
        rho = rho0 + rng.normal(0, 1, rho0.shape) * sig_r
        theta = theta0 + rng.normal(0, sensor.sigma_theta, theta0.shape)
        f = fit_ranges(rho, theta, sensor, [0], [len(rho)])
        err[k] = f.r[0] - 3.0, math.remainder(f.alpha[0] - alpha, 2 * math.pi)
        covs[k] = f.cov[0]
    lo, hi = nees_band(n, 2)
    assert lo < mean_nees(err, covs) < hi
    # the empirical covariance itself agrees within sampling error (~10 % for 1000 draws)
    emp = np.cov(err.T)
    np.testing.assert_allclose(np.sqrt(np.diag(emp)), np.sqrt(np.diag(covs.mean(0))), rtol=0.1)


def test_segments_monte_carlo_through_extract():
    """End to end: the (r, α) of a room wall extracted from 500 noisy scans is consistent."""
    world = sw.make_world([sw.room(0, 0, 8, 6)])
    pose = (3.0, 3.0, 0.0)
    rng = np.random.default_rng(11)
    n = 500
    err, covs = [], []
    r_true, a_true = 5.0, 0.0  # east wall x = 8 seen from x = 3
    for _ in range(n):
        scan = sw.simulate_scan(world, pose, HOKUYO, 8.0, PRECISE.a, PRECISE.sigma_theta, rng)
        segs, _ = extract_segments(scan, PRECISE, LinesConfig())
        k = np.flatnonzero((np.abs(segs.r - r_true) < 0.05) & (np.abs(segs.alpha - a_true) < 0.05))
        assert len(k) == 1
        err.append((segs.r[k[0]] - r_true, segs.alpha[k[0]] - a_true))
        covs.append(segs.cov[k[0]])
    lo, hi = nees_band(n, 2)
    assert lo < mean_nees(np.asarray(err), np.asarray(covs)) < hi


def test_breakpoint_breaks_across_runs_of_no_return_beams():
    """Two points 8° apart with 15 no-return beams between: the adaptive breakpoint alone joins them
    (d_max = ρ sin Δφ / sin(λ − Δφ) is ~4 m there), the missing-beam rule breaks."""
    from cornerslam_cli.features.lines import breakpoint_starts
    from cornerslam_cli.features.params import LinesConfig

    inc = np.radians(0.5)
    idx = np.array([0, 1, 2, 18, 19, 20])
    theta = idx * inc
    rho = np.array([1.2, 1.2, 1.2, 3.5, 3.5, 3.5])
    x, y = rho * np.cos(theta), rho * np.sin(theta)
    assert list(breakpoint_starts(x, y, rho, theta, LinesConfig(max_missing_beams=0), idx)) == [0]
    assert list(breakpoint_starts(x, y, rho, theta, LinesConfig(max_missing_beams=3), idx)) == [0, 3]
    few = np.array([0, 1, 2, 6, 7, 8])  # 3 missing beams: a dropout, not a gap
    t2 = few * inc
    assert list(breakpoint_starts(x, y, rho, t2, LinesConfig(max_missing_beams=3), few)) == [0, 3]  # far jump
    r_same = np.full(6, 2.0)
    xs, ys = r_same * np.cos(t2), r_same * np.sin(t2)
    assert list(breakpoint_starts(xs, ys, r_same, t2, LinesConfig(max_missing_beams=3), few)) == [0]


SAMPLES = Path(__file__).resolve().parents[1] / "sample_logs"


def _partition_scans():
    """Scans that exercise every step of the partition: the simulated office (1,081 beams), with beams
    dropped at random (gaps); the real scans of the sample logs (Intel: 180 beams, centimetre-quantised
    ranges, so exact ties between farthest points; Mines: URG-04LX with dropouts); random clutter.
    All noisy: on a noiseless scan the residuals are rounding noise (~1e-16 m), and whether a boundary
    beam is 1 ulp closer to one line than the other, or an end beam 4 "RMS" off, is decided by the last
    bit of numpy's pairwise sums and SIMD arctan2 against the kernels' sequential sums and libm — either
    answer is arbitrary there."""
    from cornerslam_cli.logs import open_log
    from cornerslam_cli.types import Scan

    rng = np.random.default_rng(7)
    world = sw.office_world()
    scans = []
    for pose in sw.path_poses(sw.OFFICE_LOOP, 2.0):
        scan = sw.simulate_scan(world, pose, HOKUYO, 30.0, 0.01, math.radians(0.05), rng)
        dropped = np.where(rng.random(len(scan.ranges)) > 0.1, scan.ranges, np.inf)
        scans += [scan, sw.scan_from_ranges(dropped, scan.angles)]
    for log in ("intel_cut.clf", "mines_exp3_cut.bag"):
        scans += [m for m in open_log(SAMPLES / log).messages() if isinstance(m, Scan)][::5]
    for _ in range(20):
        boxes = [
            sw.rectangle(*rng.uniform(1, 7, 2), *rng.uniform(0.2, 1.5, 2), rng.uniform(0, 3))
            for _ in range(4)
        ]
        world = sw.make_world([sw.room(0, 0, 10, 8), *boxes], "random")
        scans.append(sw.simulate_scan(world, (5.0, 4.0, rng.uniform(-3, 3)), HOKUYO, 30.0, 0.02, 0.001, rng))
    return scans


@pytest.mark.parametrize(
    "cfg",
    [LinesConfig(), LinesConfig(split_distance=0.02, min_points=3, max_missing_beams=0),
     LinesConfig(merge_angle=0.2, merge_gap=0.5, angle_split_max=0.3, angle_split_sigmas=5.0)],
)  # fmt: skip
def test_compiled_partition_makes_the_numpy_reference_decisions(cfg):
    """segment_kernels (Numba) against the numpy steps 1–6 of lines.py: the same range starts on every
    scan, so the fitted segments and corners cannot differ."""
    from cornerslam_cli.features.lines import beam_weights, partition

    n_ranges = 0
    for scan in _partition_scans():
        rho, theta = scan.ranges, scan.angles
        var_rho, var_theta = beam_variances(rho, PRECISE)
        x, y, w = rho * np.cos(theta), rho * np.sin(theta), beam_weights(rho, var_rho, var_theta)
        args = (x, y, rho, theta, w, scan.beam_index, scan.angle_increment, cfg)
        with np.errstate(all="ignore"):
            ref = partition(*args, compiled=False)
        np.testing.assert_array_equal(partition(*args), ref)
        n_ranges += len(ref)
    assert n_ranges > 2000  # the scans were not trivial


@pytest.mark.parametrize("sensor", [PRECISE, SensorConfig()], ids=["linear", "piecewise"])
def test_compiled_fit_equals_the_numpy_fit_bit_for_bit(sensor):
    """fit_kernels (Numba, with numpy's arctan2/hypot between the kernels) against the numpy two-pass fit:
    every r, α, covariance, end point and end-beam Jacobian equal to the last bit (bytes compared, so a
    signed zero counts), on the ranges the partition finds and on ranges of one and two beams."""
    from cornerslam_cli.features.lines import beam_weights, partition

    n_lines = 0
    for scan in _partition_scans():
        rho, theta = scan.ranges, scan.angles
        var_rho, var_theta = beam_variances(rho, sensor)
        w = beam_weights(rho, var_rho, var_theta)
        x, y = rho * np.cos(theta), rho * np.sin(theta)
        starts = partition(x, y, rho, theta, w, scan.beam_index, scan.angle_increment, LinesConfig())
        ends = np.append(starts[1:], len(rho))
        wide = starts[:-1][np.diff(starts) >= 2][:3]  # ranges must not overlap (a partition's never do)
        for s, e in ((starts, ends), (starts[:3], starts[:3] + 1), (wide, wide + 2)):
            with np.errstate(all="ignore"):
                ref = fit_ranges(rho, theta, sensor, s, e, compiled=False)
                got = fit_ranges(rho, theta, sensor, s, e)
            for name in ("r", "alpha", "cov", "p1", "p2", "jac_ends", "ok"):
                assert getattr(got, name).tobytes() == getattr(ref, name).tobytes(), name
        n_lines += len(starts)
    assert n_lines > 2000


def test_kernels_compile_without_a_writable_cache(monkeypatch, caplog):
    """Where Numba can write no cache (a read-only install and no writable home: here no cache locator
    at all), a kernel is compiled uncached, with one warning naming NUMBA_CACHE_DIR, instead of the
    import failing."""
    import logging

    import numba.core.caching as caching

    from cornerslam_cli.features import jit

    def twice(v):
        return 2.0 * v

    monkeypatch.setattr(caching.CacheImpl, "_locator_classes", [])
    monkeypatch.setattr(jit, "_warned", [])
    with pytest.raises(RuntimeError):  # what kernel() guards against
        jit.njit(cache=True)(twice)
    with caplog.at_level(logging.WARNING, logger="cornerslam.features"):
        assert jit.kernel(twice)(1.5) == 3.0
        jit.kernel(twice)
    assert caplog.text.count("NUMBA_CACHE_DIR") == 1


@pytest.mark.skipif(not hasattr(__import__("signal"), "pthread_sigmask"), reason="POSIX signal masks")
def test_a_signal_waits_until_the_kernels_are_loaded(monkeypatch):
    """Ctrl-C inside Numba's compiler breaks it half-way (an internal error instead of exit 130), so
    load_kernels holds SIGINT until the kernels are loaded; then it is delivered as usual."""
    import signal
    import threading
    import time

    from cornerslam_cli import features

    real, delivered, seen_while_loading = features.extract_segments, [], []

    def interrupted_while_loading(*args):
        # to this (the main) thread: a process-wide kill may go to a thread of an earlier test instead
        signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)
        time.sleep(0.05)  # an unblocked SIGINT reaches the handler by now
        seen_while_loading.extend(delivered)
        return real(*args)

    monkeypatch.setattr(features, "extract_segments", interrupted_while_loading)
    previous = signal.signal(signal.SIGINT, lambda signum, frame: delivered.append(signum))
    try:
        features.load_kernels(SensorConfig(), LinesConfig())
        time.sleep(0.05)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert seen_while_loading == [] and delivered == [signal.SIGINT]


def _weighted_tls(rho, theta, w):
    """Reference line fit written out again: the eigenvector of least weighted scatter, r >= 0."""
    x, y = rho * np.cos(theta), rho * np.sin(theta)
    mx, my = np.average(x, weights=w), np.average(y, weights=w)
    dx, dy = x - mx, y - my
    scatter = np.array([[w @ (dx * dx), w @ (dx * dy)], [w @ (dx * dy), w @ (dy * dy)]])
    n = np.linalg.eigh(scatter)[1][:, 0]
    r = n @ (mx, my)
    if r < 0:
        n, r = -n, -r
    return r, math.atan2(n[1], n[0])


def test_line_fit_equals_an_independent_weighted_tls_and_its_first_order_covariance():
    """(r, α) equal an eigenvector TLS written in the test; C_l equals J C Jᵀ with J by central
    differences of that reference (weights fixed, as in eq 5–8), end-beam Jacobians included."""
    rng = np.random.default_rng(21)
    theta = wall_bearings(2.0, 0.0, 0.9, 2.5)  # incidence 24°–51°
    rho = noisy_ranges(2.0, 0.0, theta, URG04LX, rng)
    var_r, var_t = beam_variances(rho, URG04LX)
    w = 1.0 / (var_r + rho**2 * var_t)
    fit = fit_lines(rho, theta, var_r, var_t, [0], [len(rho)], w)
    r0, a0 = _weighted_tls(rho, theta, w)
    assert (fit.r[0], fit.alpha[0]) == pytest.approx((r0, a0), abs=1e-12)
    J = beam_jacobian(lambda rh, th: _weighted_tls(rh, th, w), rho, theta)
    C = J @ beam_covariance(var_r, var_t) @ J.T
    np.testing.assert_allclose(fit.cov[0], C, rtol=1e-6)
    np.testing.assert_allclose(fit.jac_ends[0, 0], J[:, :2], rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(fit.jac_ends[0, 1], J[:, -2:], rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize(
    "r, u0, u1",
    [(1.0, 0.5, 1.5), (2.0, -0.5, 0.5), (4.0, 3.5, 4.5), (2.0, 4.0, 7.0)],
    ids=["1m-45deg", "2m-normal", "4m-45deg", "2m-grazing-63-74deg"],
)
def test_line_covariance_is_honest_on_a_short_range_hokuyo(r, u0, u1):
    """URG-04LX preset, 1 m segments of 20–140 beams from 1 to 4 m, up to grazing: the predicted variance
    of r and of α each within 20 % of the Monte Carlo variance (docs/results/review_features_filter.md §1)."""
    rng = np.random.default_rng(5)
    theta = wall_bearings(r, 0.0, u0, u1)
    err, cov = np.zeros((400, 2)), np.zeros((400, 2, 2))
    for k in range(400):
        fit = fit_ranges(noisy_ranges(r, 0.0, theta, URG04LX, rng), theta, URG04LX, [0], [len(theta)])
        err[k], cov[k] = (fit.r[0] - r, math.remainder(fit.alpha[0], 2 * math.pi)), fit.cov[0]
    pred = np.diag(cov.mean(0))
    spread = np.var(err, axis=0) / pred  # variance about the mean / predicted σ²
    assert np.all((spread > 0.8) & (spread < 1.2)), spread
    second = np.mean(err**2, axis=0) / pred  # E[e²] / σ²: with the oblique-incidence bias (below) up to ~1.3
    assert np.all(second < 1.4), second


@pytest.mark.xfail(strict=True, reason="finding, not fixed: isotropic-weight TLS tilts at oblique incidence")
def test_line_fit_is_unbiased_at_oblique_incidence():
    """Range noise lies along the beam, not across the line: E[scatter] gains Σ w_i Cov(p_i), which is not
    a multiple of I at oblique incidence, so the TLS direction tilts towards the beams. Default sensor
    (σρ 3 % of the range), a 1 m wall at 2 m seen at 45°: r and α are biased by −1.2 σ
    (docs/results/review_features_filter.md §1). Passes once the fit removes that term."""
    sensor = SensorConfig()
    rng = np.random.default_rng(6)
    theta = wall_bearings(2.0, 0.0, 1.5, 2.5)
    err, cov = np.zeros((400, 2)), np.zeros((400, 2, 2))
    for k in range(400):
        fit = fit_ranges(noisy_ranges(2.0, 0.0, theta, sensor, rng), theta, sensor, [0], [len(theta)])
        err[k], cov[k] = (fit.r[0] - 2.0, math.remainder(fit.alpha[0], 2 * math.pi)), fit.cov[0]
    bias = err.mean(0) / np.sqrt(np.diag(cov.mean(0)))
    assert np.all(np.abs(bias) < 0.3), bias
