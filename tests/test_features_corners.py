"""Natural corners (Algorithm 2, eq 9–13), the public ``extract`` and its robustness."""

from __future__ import annotations

import math
from dataclasses import replace

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
from hypothesis import given, settings
from hypothesis import strategies as st

from cornerslam_cli import simworld as sw
from cornerslam_cli.features import CornersConfig, LinesConfig, SensorConfig, extract
from cornerslam_cli.features.corner_kernels import end_corner, intersection
from cornerslam_cli.features.corners import type_one
from cornerslam_cli.features.lines import fit_lines, fit_ranges
from cornerslam_cli.features.sensor import beam_variances
from cornerslam_cli.types import Scan, Segments

CFG = (LinesConfig(), CornersConfig())


def _extract(world, pose, max_range=8.0, corners=None, angles=HOKUYO, **noise):
    corners = corners or CornersConfig()
    scan = sw.simulate_scan(world, pose, angles, max_range, **noise)
    return scan, *extract(scan, PRECISE, LinesConfig(), corners)


NOISELESS_CASES = [
    (clutter_room(), (3.0, 3.0, 0.0)),
    (clutter_room(), (6.8, 1.0, 2.2)),
    (clutter_room(), (1.0, 5.0, -0.8)),
    (clutter_room(), (4.0, 3.5, 3.0)),
] + [(sw.office_world(), tuple(p)) for p in sw.path_poses(sw.OFFICE_LOOP, 2.0)]


@pytest.mark.parametrize("world, pose", NOISELESS_CASES)
def test_noiseless_corners_match_the_world(world, pose):
    _, _, corners = _extract(world, pose)
    z = to_world(corners.z[:, :2], pose) if len(corners) else np.zeros((0, 2))
    truth = sw.true_corners(world)
    # every corner seen with both walls within 8 m is found within 1 cm, with the right φ
    for c in sw.visible_corners(world, pose, HOKUYO, 8.0):
        d = np.hypot(*(z - c[:2]).T)
        assert d.size and d.min() < 0.01, (
            f"visible corner {c} missed (nearest {d.min() if d.size else np.inf:.3f} m)"
        )
        assert corners.z[np.argmin(d), 2] == pytest.approx(c[2], abs=math.radians(0.2))
    # every type I corner is a true corner (1 cm); every type II corner a true corner or a wall end (edge
    # found within half a beam gap); none is an occlusion shadow on a farther wall
    ends = world.walls.reshape(-1, 2)
    for zi, kind in zip(z, corners.kind, strict=True):
        if kind == 1:
            assert np.hypot(*(truth[:, :2] - zi).T).min() < 0.01, f"type I corner {zi} is not a true corner"
        else:
            assert np.hypot(*(ends - zi).T).min() < 0.05, f"type II corner {zi} is not at a wall end"


def test_occluded_corner_is_not_reported():
    # a box just in front of the room's far corner hides it; the extended walls would meet there
    world = sw.make_world([sw.room(0, 0, 8, 6), sw.rectangle(7.2, 5.2, 0.8, 0.8)])
    pose = (2.0, 1.5, 0.6)
    assert not np.any(np.hypot(*(sw.visible_corners(world, pose, HOKUYO, 30)[:, :2] - (8, 6)).T) < 1e-6)
    for drop in (True, False):
        _, _, corners = _extract(world, pose, 30.0, CornersConfig(drop_occluded=drop))
        z = to_world(corners.z[:, :2], pose)
        assert not np.any(np.hypot(*(z - (8, 6)).T) < 0.3)


def test_drop_occluded_removes_shadow_edges_only():
    # a box in front of a wall: its edges are corners, the ends of its shadow on the wall are not
    world = sw.make_world([sw.polyline([(5, -4), (5, 4)]), sw.rectangle(2.5, 0.0, 0.6, 0.6)])
    pose = (0.0, 0.0, 0.0)
    angles = np.linspace(-0.7, 0.7, 500)
    on = _extract(world, pose, 30.0, CornersConfig(drop_occluded=True), angles)[2]
    off = _extract(world, pose, 30.0, CornersConfig(drop_occluded=False), angles)[2]
    shadow = lambda c: np.isclose(c.z[:, 0], 5.0, atol=0.01) & (c.kind == 2)  # noqa: E731
    edges = lambda c: np.isclose(c.z[:, 0], 2.2, atol=0.01) & (c.kind == 2)  # noqa: E731
    assert shadow(off).sum() == 2 and shadow(on).sum() == 0
    assert edges(off).sum() == 2 and edges(on).sum() == 2
    np.testing.assert_allclose(np.sort(on.z[edges(on), 1]), [-0.3, 0.3], atol=0.01)


def test_virtual_intersection_in_free_space_is_rejected():
    # a box 15 cm in front of a wall: its face extended meets the wall within dp_max, but the scan saw
    # through the gap
    world = sw.make_world([sw.room(0, 0, 8, 6), sw.rectangle(7.6, 3.0, 0.5, 0.8)])
    pose = (4.0, 1.0, 0.5)
    _, _, corners = _extract(world, pose, 30.0)
    z = to_world(corners.z[:, :2], pose)
    assert not np.any(np.hypot(*(z - (8.0, 2.6)).T) < 0.05)
    _, _, loose = _extract(world, pose, 30.0, CornersConfig(free_space_check=False))
    assert np.any(np.hypot(*(to_world(loose.z[:, :2], pose) - (8.0, 2.6)).T) < 0.01)


def _segments(lines):
    """Segments from ((r, α), p1, p2) tuples, unit covariances."""
    k = len(lines)
    return Segments(
        r=np.array([ln[0][0] for ln in lines]),
        alpha=np.array([ln[0][1] for ln in lines]),
        cov=np.tile(np.eye(2) * 1e-4, (k, 1, 1)),
        p1=np.array([ln[1] for ln in lines], float),
        p2=np.array([ln[2] for ln in lines], float),
        n_points=np.full(k, 9),
        first=np.arange(k),
        last=np.arange(k),
    )


def test_all_pairs_not_only_neighbours():
    # wall x = 6 and wall y = 3 meet at (6, 3); a short piece of rubbish between them in scan order
    segs = _segments(
        [
            ((6.0, 0.0), (6, -2), (6, 2.9)),
            ((5.0, 0.7), (3.6, 3.0), (3.9, 2.6)),
            ((3.0, np.pi / 2), (5.85, 3), (1, 3)),
        ]
    )
    z, _, which = type_one(segs, CornersConfig())
    assert len(z) == 1 and which[0].tolist() == [0, 2]
    np.testing.assert_allclose(z[0], [6.0, 3.0, np.pi / 2], atol=1e-12)
    # too far from a segment (dp_max) or too parallel (min_angle): none
    far = _segments([((6.0, 0.0), (6, -2), (6, 2.7)), ((3.0, np.pi / 2), (6.1, 3), (1, 3))])
    assert len(type_one(far, CornersConfig(d_min=1.0))[0]) == 0
    flat = _segments([((6.0, 0.0), (6, -2), (6, 2.9)), ((6.0, 0.3), (6.2, 3), (3, 4))])
    assert len(type_one(flat, CornersConfig())[0]) == 0


def test_duplicates_are_merged():
    for world, pose in NOISELESS_CASES[:4]:
        _, _, corners = _extract(world, pose)
        d = np.hypot(*(corners.z[:, None, :2] - corners.z[None, :, :2]).transpose(2, 0, 1))
        np.fill_diagonal(d, np.inf)
        assert d.min() >= CornersConfig().duplicate_radius
        b = np.arctan2(corners.z[:, 1], corners.z[:, 0])
        assert np.all(np.diff(b) >= 0)  # bearing order


def intersections(segs, i, j):
    """Eq 9–13 of the compiled kernel for the line pairs (i, j): (m, 3) corners, (m, 3, 3) covariances."""
    out = [intersection(segs.alpha[a], segs.alpha[b], segs.r[a], segs.r[b], segs.cov[a], segs.cov[b])
           for a, b in zip(i, j, strict=True)]  # fmt: skip
    return np.array([z for z, _ in out]), np.array([c for _, c in out])


def test_intersection_jacobian_matches_finite_differences():
    segs = Segments(
        r=np.array([2.0, 3.0]),
        alpha=np.array([0.3, 2.0]),
        cov=np.tile(np.eye(2), (2, 1, 1)),
        p1=np.zeros((2, 2)),
        p2=np.zeros((2, 2)),
        n_points=np.array([9, 9]),
        first=np.zeros(2, int),
        last=np.zeros(2, int),
    )
    z, _ = intersections(segs, np.array([0]), np.array([1]))
    c = z[0, :2]
    assert c @ [math.cos(0.3), math.sin(0.3)] == pytest.approx(2.0)
    assert c @ [math.cos(2.0), math.sin(2.0)] == pytest.approx(3.0)
    F = np.zeros((3, 4))
    h = 1e-7
    for k in range(4):
        p = np.array([2.0, 0.3, 3.0, 2.0])
        p[k] += h
        s2 = replace(segs, r=p[[0, 2]], alpha=p[[1, 3]])
        F[:, k] = (intersections(s2, np.array([0]), np.array([1]))[0][0] - z[0]) / h
    C = np.diag([1e-4, 2e-4, 3e-4, 4e-4])
    segs_c = replace(segs, cov=np.array([C[:2, :2], C[2:, 2:]]))
    np.testing.assert_allclose(
        intersections(segs_c, np.array([0]), np.array([1]))[1][0], F @ C @ F.T, rtol=1e-5
    )


def _monte_carlo(world_of, truth_of, pose, kind, n, dims, rng, angles=HOKUYO):
    err, covs = [], []
    for _ in range(n):
        world, truth = world_of(rng), truth_of
        scan = sw.simulate_scan(world, pose, angles, 30.0, PRECISE.a, PRECISE.sigma_theta, rng)
        _, corners = extract(scan, PRECISE, *CFG)
        t = truth(world) if callable(truth) else truth
        z = to_world(corners.z[:, :2], pose)
        d = np.hypot(*(z - t[:2]).T)
        i = int(np.argmin(d))
        assert d[i] < 0.1 and corners.kind[i] == kind
        c, s = math.cos(pose[2]), math.sin(pose[2])
        R = np.array([[c, -s], [s, c]])
        e = np.append(R.T @ (z[i] - t[:2]), corners.z[i, 2] - t[2])  # error in the sensor frame
        err.append(e[:dims])
        covs.append(corners.cov[i][:dims, :dims])
    lo, hi = nees_band(n, dims)
    nees = mean_nees(np.asarray(err), np.asarray(covs))
    assert lo < nees < hi, f"mean NEES {nees:.3f} outside [{lo:.3f}, {hi:.3f}]"


def test_type_one_covariance_monte_carlo():
    """(x, y, φ) of a 120° room corner over 500 noisy scans: NEES in the 95 % band for d = 3."""
    world = sw.make_world([sw.polyline([(6, -3), (6, 1), (6 - 2 * math.sqrt(3), 3)])])
    truth = np.array([6.0, 1.0, math.pi / 3])  # the wedge is 120°, φ = 60°
    _monte_carlo(lambda rng: world, truth, (0.0, 0.0, 0.2), 1, 500, 3, np.random.default_rng(5))


def test_type_two_covariance_monte_carlo():
    """(x, y) of a wall's free end over 500 noisy scans, the end drawn anywhere in the gap between two beams:
    the covariance covers both the noise and where the edge lies between beams (d = 2; φ is a prior)."""
    angles = np.linspace(-1.0, 1.0, 400)
    step = angles[1] - angles[0]
    base = math.atan2(-0.0, 2.0)  # the free end is near bearing 0 at 2 m

    def world_of(rng):
        end = 2.0 * math.tan(base + (rng.uniform(0, 1) + 0.5) * step)
        return sw.make_world([sw.polyline([(2.0, -1.5), (2.0, end)]), sw.polyline([(5.0, -4), (5.0, 4)])])

    truth = lambda w: np.array([2.0, w.walls[0, 1, 1], 0.0])  # noqa: E731
    _monte_carlo(world_of, truth, (0.0, 0.0, 0.0), 2, 500, 2, np.random.default_rng(9), angles)


# --- robustness -------------------------------------------------------------------------------------------


def _check_output(segs, corners):
    for a in (segs.r, segs.alpha, segs.cov, segs.p1, segs.p2, corners.z, corners.cov):
        assert np.all(np.isfinite(a))
    for C in list(segs.cov) + list(corners.cov):
        np.testing.assert_array_equal(C, C.T)
        np.linalg.cholesky(C)  # positive definite
    assert len(corners.kind) == len(corners.z) == len(corners.segs)
    assert np.all(corners.segs[:, 0] < len(segs))


def _scan(ranges, angles):
    ranges, angles = np.asarray(ranges, float), np.asarray(angles, float)
    return Scan(0.0, ranges, angles, np.arange(len(ranges)), len(ranges), 0.0, np.inf, 0.0)


def test_degenerate_scans_give_no_features():
    for ranges, angles in [
        ([], []),
        ([1.0], [0.0]),
        ([2.0] * 5, [0.1] * 5),
        ([1e-9] * 50, np.linspace(0, 1, 50)),
    ]:
        segs, corners = extract(_scan(ranges, angles), SensorConfig(), *CFG)
        _check_output(segs, corners)
        assert len(corners) == 0


@st.composite
def scans(draw):
    n = draw(st.integers(0, 300))
    kind = draw(st.sampled_from(["random", "equal", "tiny", "huge", "walls"]))
    finite = st.floats(1e-6, 1e6, allow_nan=False, allow_infinity=False)
    if kind == "random":
        ranges = draw(st.lists(finite, min_size=n, max_size=n))
    elif kind == "equal":
        ranges = [draw(finite)] * n
    elif kind == "tiny":
        ranges = draw(st.lists(st.floats(0.0, 1e-3), min_size=n, max_size=n))
    elif kind == "huge":
        ranges = draw(st.lists(st.floats(1e3, 1e12), min_size=n, max_size=n))
    else:  # piecewise-constant ranges: many short "walls" and jumps
        ranges = np.repeat(draw(st.lists(st.floats(0.05, 50.0), min_size=1, max_size=20)), max(1, n // 10))[
            :n
        ]
    steps = draw(st.lists(st.floats(0.0, 0.2), min_size=n, max_size=n))
    angles = np.cumsum(steps) + draw(st.floats(-math.pi, 0.0))
    return _scan(np.asarray(ranges, float)[:n], angles[: len(ranges)])


@settings(max_examples=100, deadline=None)
@given(
    scans(),
    st.sampled_from(
        [SensorConfig(), PRECISE, SensorConfig(sigma_r_near=0.0, sigma_r_rel=0.0, sigma_theta=0.0)]
    ),
)
def test_any_scan_gives_finite_features_or_none(scan, sensor):
    segs, corners = extract(scan, sensor, *CFG)
    _check_output(segs, corners)


@settings(max_examples=30, deadline=None)
@given(st.floats(0.5, 29.5), st.floats(0.5, 19.5), st.floats(-math.pi, math.pi), st.integers(0, 2**31))
def test_noisy_office_scans_give_finite_spd_features(x, y, th, seed):
    rng = np.random.default_rng(seed)
    scan = sw.simulate_scan(
        sw.office_world(), (x, y, th), HOKUYO, 30.0, lambda r: 0.03 * np.maximum(r, 1.0), 0.003, rng
    )
    _check_output(*extract(scan, SensorConfig(), *CFG))


# --- the compiled extraction against the numpy version ------------------------------------------------


def _same_corners(got, ref):
    assert got.kind.tolist() == ref.kind.tolist() and got.segs.tolist() == ref.segs.tolist()
    np.testing.assert_allclose(got.z, ref.z, rtol=1e-12, atol=1e-12)
    scale = np.abs(ref.cov).max() if len(ref) else 1.0
    np.testing.assert_allclose(got.cov, ref.cov, rtol=1e-9, atol=1e-12 * scale)


@pytest.mark.parametrize(
    "corners",
    [
        CornersConfig(),
        CornersConfig(endpoints=False),
        CornersConfig(drop_occluded=False, free_space_check=False),
        CornersConfig(d_min=1.0, dp_max=0.5, duplicate_radius=0.3),
    ],
)
@pytest.mark.parametrize("sensor", [SensorConfig(), PRECISE])
def test_compiled_corners_equal_the_numpy_version(corners, sensor):
    """Corners of noisy office and clutter-room scans from every pose of a path: the same corners (kind,
    segments, order) as tests/_corners_reference.py's numpy extraction, equal to rounding."""
    from _corners_reference import extract_corners as reference

    from cornerslam_cli.features import extract_corners, extract_segments

    rng = np.random.default_rng(11)
    cases = [(sw.office_world(), p) for p in sw.path_poses(sw.OFFICE_LOOP, 1.5)]
    cases += [
        (clutter_room(), (x, y, th)) for x, y, th in rng.uniform([0.5, 0.5, -3], [7.5, 5.5, 3], (15, 3))
    ]
    kinds = []
    with np.errstate(all="ignore"):
        for world, pose in cases:
            scan = sw.simulate_scan(world, pose, HOKUYO, 30.0, PRECISE.a, PRECISE.sigma_theta, rng)
            segs, jac = extract_segments(scan, sensor, LinesConfig())
            got = extract_corners(scan, segs, jac, sensor, corners)
            _same_corners(got, reference(scan, segs, jac, sensor, corners))
            kinds += got.kind.tolist()
    assert len(kinds) > len(cases) and set(kinds) == ({1, 2} if corners.endpoints else {1})  # many compared


def test_type_one_covariance_from_the_true_beams_is_honest_at_far_range():
    """Eq 9–13 on the lines fitted to each wall's own beams (URG-04LX preset, a room corner 3.6 m away,
    arms 2.5 and 1.5 m): the corner's (x, y, φ) covariance matches the Monte Carlo spread. The extractor
    itself is over-confident there (segmentation: docs/results/review_features_filter.md §2); this
    separates the covariance algebra from that."""
    rng = np.random.default_rng(13)
    walls = ((3.0, 0.0, -0.5, 2.0), (2.0, math.pi / 2, -3.0, -1.5))  # (r, α, u0, u1): x = 3 and y = 2
    truth = np.array([3.0, 2.0, math.pi / 2])
    bearings = [wall_bearings(r, a, u0, u1) for r, a, u0, u1 in walls]
    err, cov = np.zeros((300, 3)), np.zeros((300, 3, 3))
    for k in range(300):
        fits = [
            fit_ranges(noisy_ranges(r, a, th, URG04LX, rng), th, URG04LX, [0], [len(th)])
            for (r, a, _, _), th in zip(walls, bearings, strict=True)
        ]
        (f1, f2) = fits
        z, cov[k] = intersection(f1.alpha[0], f2.alpha[0], f1.r[0], f2.r[0], f1.cov[0], f2.cov[0])
        err[k] = z - truth
    pred = np.diag(cov.mean(0))
    spread = np.var(err, axis=0) / pred
    assert np.all((spread > 0.8) & (spread < 1.25)), spread
    assert np.all(np.mean(err**2, axis=0) / pred < 1.4)  # bias included (lines.py's oblique-incidence bias)


def test_type_two_covariance_is_exact_to_first_order_in_every_beam():
    """end_corner's (x, y) covariance equals J C Jᵀ, J by central differences of "the end beam's point
    projected on the TLS line of all the segment's beams" written in the test (weights fixed)."""
    rng = np.random.default_rng(17)
    theta = wall_bearings(2.0, 0.3, 0.2, 1.2)
    rho = noisy_ranges(2.0, 0.3, theta, URG04LX, rng)
    var_r, var_t = beam_variances(rho, URG04LX)
    w = 1.0 / (var_r + rho**2 * var_t)
    fit = fit_lines(rho, theta, var_r, var_t, [0], [len(rho)], w)

    def corner(rh, th):
        x, y = rh * np.cos(th), rh * np.sin(th)
        mx, my = np.average(x, weights=w), np.average(y, weights=w)
        sc = np.cov(np.vstack((x - mx, y - my)), aweights=w, bias=True)
        n = np.linalg.eigh(sc)[1][:, 0]
        q = np.array([x[-1], y[-1]])
        return q - (n @ q - n @ (mx, my)) * n

    J = beam_jacobian(corner, rho, theta)
    C = J @ beam_covariance(var_r, var_t) @ J.T
    c, cxy, _ = end_corner(rho[-1], theta[-1], fit.alpha[0], fit.r[0], fit.cov[0], fit.jac_ends[0, 1],
                           float(var_r[-1]), float(var_t[-1]))  # fmt: skip
    np.testing.assert_allclose(c, corner(rho, theta), atol=1e-12)
    np.testing.assert_allclose(cxy, C, rtol=1e-6)
