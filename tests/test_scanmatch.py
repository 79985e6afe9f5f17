"""Scan matching fused with odometry (motion/icp.py, correlative.py, fusion.py) against known poses in
ray-cast worlds."""

import math

import numpy as np
import pytest

from cornerslam_cli.config import load_config
from cornerslam_cli.errors import ConfigError, NumericalError
from cornerslam_cli.evaluate import ate
from cornerslam_cli.frontend import odometry_noise
from cornerslam_cli.geometry import compose, relative, transform_points, wrap_angle
from cornerslam_cli.motion import ScanMatchConfig, ScanMatcher
from cornerslam_cli.motion.correlative import BLOCK, PULL, Exclusion, Window, angle_steps, search
from cornerslam_cli.motion.icp import LocalMap, register, voxel_thin
from cornerslam_cli.simworld import OFFICE_LOOP, make_world, office_world, path_poses, polyline, raycast

ANGLES = np.radians(np.arange(-90.0, 90.5, 1.0))  # SICK-like: 181 beams, 1°


def scan_points(world, pose, rng=None, sigma=0.0, angles=ANGLES):
    r = raycast(world, pose, angles, max_range=30.0)
    ok = np.isfinite(r)
    r, a = r[ok], angles[ok]
    if rng is not None:
        r = r + rng.normal(0.0, sigma, r.shape)
    return np.column_stack((r * np.cos(a), r * np.sin(a)))


def pose_error(a, b):
    return math.hypot(a[0] - b[0], a[1] - b[1]), abs(wrap_angle(a[2] - b[2]))


@pytest.fixture(scope="module")
def office():
    return office_world()


def matcher(cfg: ScanMatchConfig | None = None, overrides=()) -> ScanMatcher:
    """A scan matcher with the default odometry noise model (``ekf.alpha*``)."""
    full = load_config(None, list(overrides))
    return ScanMatcher(cfg or full.scan_match, odometry_noise(full))


def test_register_recovers_a_known_pose(office):
    rng = np.random.default_rng(1)
    ref_pose, true_pose = np.array([6.0, 5.0, 0.1]), np.array([6.6, 5.2, 0.45])
    local = LocalMap.build(transform_points(scan_points(office, ref_pose, rng, 0.01), ref_pose))
    points = scan_points(office, true_pose, rng, 0.01)
    guess = true_pose + [0.15, -0.1, math.radians(4.0)]
    reg = register(points, local, guess, ScanMatchConfig())
    d, a = pose_error(reg.pose, true_pose)
    assert d < 0.02 and a < math.radians(0.3)
    assert reg.fit > 0.8


def _numpy_icp(points, local, start, guess, cfg):
    """register's Gauss–Newton loop as numpy ran it before its kernel (icp_iterations): the end pose."""
    from cornerslam_cli.geometry import matrix_from_pose, pose_from_matrix
    from cornerslam_cli.motion.icp import CONVERGED, SHRINK
    from cornerslam_cli.motion.kernels import gauss_newton_step, line_terms

    prior = np.array([cfg.prior_sigma_xy**-2, cfg.prior_sigma_xy**-2, cfg.prior_sigma_theta**-2])
    M, dmax, step, n = matrix_from_pose(start), cfg.max_distance, np.empty(3), len(points)
    for _ in range(cfg.max_iterations):
        q = points @ M[:2, :2].T + M[:2, 2]
        _, idx = local.grid.query(q, dmax)
        J, w, r = np.empty((n, 3)), np.empty(n), np.empty(n)
        if (
            line_terms(q, idx, local.padded_points, local.padded_normals, M[:2, 2], cfg.robust_scale, J, w, r)
            < 3
        ):
            break
        off = pose_from_matrix(M) - guess
        off[2] = wrap_angle(off[2])
        gauss_newton_step(J, w, r, prior * cfg.robust_scale**2, off, step)
        M = matrix_from_pose(pose_from_matrix(M) + step)
        dmax = max(cfg.min_distance, dmax * SHRINK)
        if np.abs(step).max() < CONVERGED and dmax <= cfg.min_distance:
            break
    return pose_from_matrix(M)


def test_compiled_icp_loop_equals_the_numpy_loop(office):
    """register's compiled iterations end where the numpy loop does (to rounding), from near and far
    starts, with a prior elsewhere, and with a short iteration budget."""
    rng = np.random.default_rng(21)
    for trial in range(12):
        ref_pose = np.array([rng.uniform(3, 27), rng.uniform(3, 17), rng.uniform(-3, 3)])
        local = LocalMap.build(transform_points(scan_points(office, ref_pose, rng, 0.01), ref_pose))
        true_pose = ref_pose + [*rng.normal(0, 0.3, 2), rng.normal(0, 0.1)]
        points = scan_points(office, true_pose, rng, 0.01)
        start = true_pose + [*rng.normal(0, 0.1, 2), rng.normal(0, 0.05)]
        guess = start if trial % 3 else true_pose
        cfg = ScanMatchConfig(max_iterations=3) if trial % 4 == 0 else ScanMatchConfig()
        reg = register(points, local, start, cfg, prior=guess)
        expected = _numpy_icp(points, local, start, guess, cfg)
        np.testing.assert_allclose(reg.pose[:2], expected[:2], rtol=0, atol=1e-9)
        assert abs(wrap_angle(reg.pose[2] - expected[2])) < 1e-9


def test_search_then_icp_recovers_from_half_a_metre_and_20_degrees(office):
    """From a guess 0.5 m and 20° off, the correlative search over a window that holds the truth finds
    the basin and ICP refines it to the truth."""
    rng = np.random.default_rng(2)
    ref_pose, true_pose = np.array([6.0, 5.0, 0.0]), np.array([6.8, 5.3, 0.5])
    map_pts = transform_points(scan_points(office, ref_pose, rng, 0.01), ref_pose)
    local = LocalMap.build(map_pts)
    points = scan_points(office, true_pose, rng, 0.01)
    guess = true_pose + [0.35, -0.35, math.radians(20.0)]
    cfg = ScanMatchConfig()
    found = search(points, map_pts, guess, Window(0.6, 0.45), cfg.search_resolution, cfg.search_sigma)
    reg = register(points, local, found.pose, cfg)
    d, a = pose_error(reg.pose, true_pose)
    assert d < 0.02 and a < math.radians(0.3)


def _search_case(office):
    """A scan 0.1 m / 0.1 rad from the guess, the map of a scan nearby, and the search's settings."""
    rng = np.random.default_rng(3)
    map_pts = transform_points(scan_points(office, np.array([6.0, 5.0, 0.0]), rng, 0.01), [6.0, 5.0, 0.0])
    points = scan_points(office, np.array([6.4, 5.1, 0.2]), rng, 0.01)
    return points, map_pts, np.array([6.3, 5.2, 0.1]), Window(0.35, 0.2), 0.1, 0.1


def _exhaustive_best(points, map_pts, guess, window, res, sigma, skip=lambda pose: False) -> float:
    """Brute force: every rotation and every cell offset of the window (but those ``skip`` says),
    scored by direct lookup."""
    W = int(np.ceil(window.xy / res))
    best = -np.inf
    for dth in angle_steps(points, window.theta, res):
        for i in range(-W, W + 1):
            for j in range(-W, W + 1):
                pose = np.array([guess[0] + i * res, guess[1] + j * res, guess[2] + dth])
                if not skip(pose):
                    best = max(best, _score(points, map_pts, pose, guess, window, res, sigma))
    return best


def test_branch_and_bound_equals_the_exhaustive_search(office):
    case = _search_case(office)
    points, _, _, window, res, _ = case
    got = search(*case)
    assert got.score == pytest.approx(_exhaustive_best(*case), abs=1e-12)
    W = int(np.ceil(window.xy / res))
    assert got.evaluated < 0.2 * len(angle_steps(points, window.theta, res)) * (2 * W + 1) ** 2


def test_a_window_of_no_width_still_searches_the_headings(office):
    """A window of 0 m (an odometry model with no translation noise on a turn in place: ekf.alpha4 = 0,
    min_sigma_xy = 0) and 0.3 rad: the turn is found at the guess's position, not lost to 0/0 in the
    pull towards the guess (NaN scores: the guess came back with score −1)."""
    rng = np.random.default_rng(3)
    ref_pose, true_pose = np.array([6.0, 5.0, 0.0]), np.array([6.0, 5.0, 0.2])
    map_pts = transform_points(scan_points(office, ref_pose, rng, 0.005), ref_pose)
    points = scan_points(office, true_pose, rng, 0.005)
    found = search(points, map_pts, ref_pose, Window(0.0, 0.3), 0.1, 0.1)
    assert np.isfinite(found.score) and found.score > 0.5
    np.testing.assert_array_equal(found.pose[:2], ref_pose[:2])
    assert abs(found.pose[2] - true_pose[2]) < 0.02


@pytest.mark.parametrize("nc", [1, 2, 6, 26])
def test_compiled_coarse_bounds_are_numpys_sums_of_the_whole_gather_bit_for_bit(nc):
    """The search's coarse bounds, summed in a compiled loop without the gather, are the sums numpy gives
    for the whole gather at once (pairwise over the points for one coarse cell, in order for more)."""
    from cornerslam_cli.motion.search_kernels import coarse_sums

    rng = np.random.default_rng(8)
    U = rng.random((4 * nc + 40, 4 * nc + 40))
    offs = BLOCK * np.arange(nc)
    for n in (1, 7, 8, 9, 127, 128, 129, 300, 1000):  # the branches of numpy's pairwise sum
        px, py = rng.integers(0, 40, (2, 31, n))
        whole = U[
            px[:, :, None, None] + offs[None, None, :, None], py[:, :, None, None] + offs[None, None, None, :]
        ]
        assert np.array_equal(coarse_sums(U, px, py, offs), whole.sum(axis=1))


def test_compiled_cell_sums_are_numpys_sums_of_the_gather_bit_for_bit():
    """One cell of fine offsets, summed in a compiled loop, is numpy's sum of the gather over its points:
    in order for cells of two or more offsets, pairwise for one (its gather is contiguous)."""
    from cornerslam_cli.motion.search_kernels import _offset_sums

    rng = np.random.default_rng(9)
    L = rng.random((60, 60))
    out = np.empty((BLOCK, BLOCK))
    for n in (1, 7, 8, 9, 127, 128, 129, 300, 1000):
        pxa, pya = rng.integers(0, 50, (2, n))
        for nx, ny in ((1, 1), (1, 4), (4, 1), (3, 2), (4, 4)):
            ox, oy = np.arange(2, 2 + nx), np.arange(5, 5 + ny)
            want = L[pxa[:, None, None] + ox[None, :, None], pya[:, None, None] + oy[None, None, :]].sum(
                axis=0
            )
            _offset_sums(L, pxa, pya, ox, oy, out, np.empty(n))
            assert np.array_equal(out[:nx, :ny], want), (n, nx, ny)


def _occupancy_grids(rng):
    """Grids of free cells with some not free: random densities and shapes, and the edge cases of the
    two passes (one row, one column, one cell not free, whole rows and columns not free)."""
    for _ in range(300):
        nx, ny = rng.integers(1, 45, 2)
        free = rng.random((nx, ny)) > rng.choice([0.002, 0.02, 0.2, 0.6, 0.95])
        free[rng.integers(nx), rng.integers(ny)] = False
        yield free
    for shape in ((1, 1), (1, 30), (30, 1), (200, 3), (3, 200)):
        free = np.ones(shape, dtype=bool)
        free[-1, -1] = False
        yield free
    free = np.ones((40, 50), dtype=bool)
    free[7], free[:, 13] = False, False
    yield free
    yield rng.random((430, 310)) > 0.003  # a real field's size (200–450 cells a side), sparse walls


def test_compiled_distance_transform_is_scipys_exactly():
    """The likelihood field's distances: the compiled transform's squared distances, square-rooted, are
    scipy's exact Euclidean distance transform bit for bit (ties between nearest cells included)."""
    from _correlative_reference import distances

    from cornerslam_cli.motion.search_kernels import squared_distances

    rng = np.random.default_rng(10)
    for free in _occupancy_grids(rng):
        assert np.array_equal(np.sqrt(squared_distances(free)), distances(free)), free.shape
    free = np.ones((3, 4), dtype=bool)  # nothing to be near: every cell beyond any real distance
    assert (squared_distances(free) > 3**2 + 4**2).all()


@pytest.mark.parametrize(
    "res,sigma",
    [(0.1, 0.1), (0.2, 0.1), (0.05, 0.1), (0.1, 0.5), (0.5, 0.02), (0.01, 10.0)],  # last: a table too large
)
def test_blur_by_table_is_the_direct_formula_bit_for_bit(res, sigma):
    """The likelihood field's blur exp(−d²/2σ²), d = √sq · res, looked up in a table of the distinct
    squared distances (cut where it underflows to 0) is the formula on the whole field, bit for bit."""
    from cornerslam_cli.motion.correlative import blur
    from cornerslam_cli.motion.search_kernels import squared_distances

    rng = np.random.default_rng(12)
    for free in _occupancy_grids(rng):
        if free.all():
            continue
        sq = squared_distances(free)
        direct = np.exp(-0.5 * ((np.sqrt(sq) * res) / sigma) ** 2)
        assert np.array_equal(blur(sq, res, sigma).view(np.int64), direct.view(np.int64)), free.shape


@pytest.mark.parametrize("b", [1, 2, 4, 5])
def test_compiled_block_max_is_numpys_shift_by_shift(b):
    """The coarse cells' bound: the compiled block maximum is numpy's shift-by-shift one, bit for bit,
    on fields (values in [0, 1], some exactly 0) of edge shapes and of sides not a multiple of b."""
    from _correlative_reference import block_max as numpy_block_max

    from cornerslam_cli.motion.search_kernels import block_max

    rng = np.random.default_rng(11)
    for nx, ny in ((1, 1), (1, 9), (9, 1), (3, 3), (17, 40), (64, 31)):
        L = np.where(rng.random((nx, ny)) < 0.3, 0.0, rng.random((nx, ny)))  # a field: ≥ 0, some zeros
        assert np.array_equal(block_max(L, b), numpy_block_max(L, b)), (nx, ny)


def test_compiled_search_equals_the_numpy_search_exactly(office):
    """The compiled branch and bound returns the numpy search's pose, score and count bit for bit (tests/
    _correlative_reference.py): windows whose side is and is not a multiple of the coarse cell (one-cell
    coarse rims, summed pairwise by numpy), one coarse cell in all, with and without an exclusion."""
    from _correlative_reference import search as numpy_search

    rng = np.random.default_rng(31)
    for trial in range(40):
        ref_pose = np.array([rng.uniform(3, 27), rng.uniform(3, 17), rng.uniform(-3, 3)])
        map_pts = transform_points(scan_points(office, ref_pose, rng, 0.01), ref_pose)
        true_pose = ref_pose + [*rng.normal(0, 0.3, 2), rng.normal(0, 0.1)]
        points = scan_points(office, true_pose, rng, 0.01)[:: 1 + trial % 5]
        guess = true_pose + [*rng.normal(0, 0.1, 2), rng.normal(0, 0.05)]
        res = (0.1, 0.2, 0.05)[trial % 3]
        window = Window(float(rng.uniform(0.0, 1.2)), float(rng.uniform(0.0, 0.5)))
        exclude = None
        if trial % 2:
            found = numpy_search(points, map_pts, guess, window, res, 0.1)
            exclude = Exclusion(found.pose, 0.3, float(rng.uniform(0.05, 0.3)))
        got = search(points, map_pts, guess, window, res, 0.1, exclude=exclude)
        want = numpy_search(points, map_pts, guess, window, res, 0.1, exclude=exclude)
        assert np.array_equal(got.pose, want.pose), trial
        assert got.score == want.score and got.evaluated == want.evaluated, trial


def test_a_wide_search_window_stays_within_bounded_memory(office):
    """A 5 m window (the largest search_max_xy) gathered its coarse bounds all at once (here 109 MB, with
    a real scan's points 293 MB); in blocks the search's peak stays below 60 MB (38 MB, most of it the
    likelihood field), and the truth is still found."""
    import tracemalloc

    rng = np.random.default_rng(9)
    ref_pose, true_pose = np.array([6.0, 5.0, 0.0]), np.array([6.8, 5.3, 0.3])
    map_pts = transform_points(scan_points(office, ref_pose, rng, 0.01), ref_pose)
    points = scan_points(office, true_pose, rng, 0.01)
    tracemalloc.start()
    found = search(points, map_pts, true_pose + [0.5, -0.4, 0.1], Window(5.0, 0.6), 0.1, 0.1)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    d, a = pose_error(found.pose, true_pose)
    assert d < 0.15 and a < 0.03
    assert peak < 60e6, f"{peak / 1e6:.0f} MB"


def test_an_excluded_neighbourhood_gives_the_best_pose_outside_it(office):
    # the runner-up of loop verification on points (graph/points.py): the best of the window's poses
    # that are not within xy / theta of the one found first, by brute force
    case = _search_case(office)
    first = search(*case)
    away = Exclusion(first.pose, 0.25, 0.05)

    def near(pose):
        return (
            np.hypot(*(pose[:2] - first.pose[:2])) <= 0.25
            and abs(wrap_angle(pose[2] - first.pose[2])) <= 0.05
        )

    got = search(*case, exclude=away)
    assert (
        got.score == pytest.approx(_exhaustive_best(*case, skip=near), abs=1e-12) and got.score < first.score
    )
    assert not near(got.pose)


def _score(points, map_pts, pose, guess, window, res, sigma):
    """Mean likelihood of ``points`` at ``pose`` on the field the search builds (cells anchored at the
    same corner), by a kd-tree distance from each cell to the nearest occupied cell."""
    from scipy.spatial import cKDTree

    thetas = guess[2] + angle_steps(points, window.theta, res)
    c, s = np.cos(thetas), np.sin(thetas)
    rx = c[:, None] * points[None, :, 0] - s[:, None] * points[None, :, 1] + guess[0]
    ry = s[:, None] * points[None, :, 0] + c[:, None] * points[None, :, 1] + guess[1]
    margin = window.xy + 3.0 * sigma + 2.0 * res
    lo = np.array([rx.min() - margin, ry.min() - margin])
    shape = np.ceil((np.array([rx.max() + margin, ry.max() + margin]) - lo) / res) + BLOCK
    occupied = np.unique(np.floor((map_pts - lo) / res).astype(np.int64), axis=0)
    occupied = occupied[((occupied >= 0) & (occupied < shape.astype(np.int64))).all(axis=1)]
    # the point's cell: its rotated position at the guess, shifted by whole cells (as the search does)
    th_rot = np.array([[np.cos(pose[2]), -np.sin(pose[2])], [np.sin(pose[2]), np.cos(pose[2])]])
    placed = points @ th_rot.T + guess[:2]
    shift = np.rint((pose[:2] - guess[:2]) / res).astype(np.int64)
    cells = np.floor((placed - lo) / res).astype(np.int64) + shift
    d, _ = cKDTree(occupied).query(cells)
    pull = PULL * (((pose[2] - guess[2]) / window.theta) ** 2 + np.sum((shift * res / window.xy) ** 2))
    return float(np.mean(np.exp(-0.5 * (d * res / sigma) ** 2))) - pull


def test_a_wide_turn_between_sparse_scans_is_found(office):
    """0.8 rad between two 1° scans with the odometry 10° and 0.15 m off: the window from the odometry
    model holds the truth, the matcher finds it and the gate accepts it."""
    rng = np.random.default_rng(4)
    poses = [np.array([6.0, 5.0, 0.0]), np.array([6.3, 5.2, 0.8])]
    m = matcher()
    m.step(scan_points(office, poses[0], rng, 0.01), poses[0])
    bad_odom = poses[1] + [0.15, 0.0, math.radians(10.0)]
    res = m.step(scan_points(office, poses[1], rng, 0.01), bad_odom)
    d, a = pose_error(res.pose, poses[1])
    assert res.searched and res.matched and d < 0.03 and a < math.radians(0.5)


def test_corridor_stays_well_posed_along_its_axis():
    """Two long parallel walls, nothing else in view: the scans cannot tell motion along the corridor.
    The match's covariance says so (large along the axis), the cross-track offset and heading come from
    the scans, and the fused increment's covariance stays large along the axis. (Noisy 5-point normals
    give ICP a spurious grip along the axis: see the closing note of issue 15.)"""
    world = make_world([polyline([(-50, -1), (50, -1)]), polyline([(-50, 1), (50, 1)])], "corridor")
    rng = np.random.default_rng(3)
    ref_pose, true_pose = np.array([0.0, 0.0, 0.0]), np.array([0.5, 0.1, 0.03])
    local = LocalMap.build(scan_points(world, ref_pose, rng, 0.005))
    guess = true_pose + [0.07, 0.08, 0.03]  # 7 cm along the axis (unobservable), 8 cm across, 1.7°
    reg = register(scan_points(world, true_pose, rng, 0.005), local, guess, ScanMatchConfig())
    assert np.sqrt(reg.cov[0, 0]) > 10 * np.sqrt(reg.cov[1, 1])  # ill-posed along, well-posed across
    m = matcher()
    m.step(scan_points(world, ref_pose, rng, 0.005), ref_pose)
    res = m.step(scan_points(world, true_pose, rng, 0.005), guess)
    assert abs(res.pose[1] - true_pose[1]) < 0.01 and abs(res.pose[2] - true_pose[2]) < math.radians(0.3)
    assert np.all(np.linalg.eigvalsh(res.cov) > 0)  # well-posed for the filter
    assert res.cov[0, 0] > 10 * res.cov[1, 1]  # and it knows the axis is the uncertain direction


def test_nothing_in_common_falls_back_to_the_odometry_increment(office):
    m = matcher()
    p0 = np.array([6.0, 5.0, 0.0])
    m.step(scan_points(office, p0), p0)
    far = np.random.default_rng(4).uniform(40.0, 60.0, (150, 2))  # points nowhere near the map
    odom = np.array([6.3, 5.0, 0.1])
    res = m.step(far, odom)
    assert not res.matched and res.fit < m.cfg.min_fit
    np.testing.assert_allclose(res.pose, odom, atol=1e-12)  # previous pose = odometry here
    assert m.n_fallback == 1


def noisy_odometry(truth, rng, scale=1.03, drift=0.01, sigma=0.02):
    odom = [truth[0]]
    for k in range(1, len(truth)):
        inc = relative(truth[k - 1], truth[k])
        inc = inc * [scale, scale, 1.0] + [0.0, 0.0, drift + rng.normal(0, sigma)]
        odom.append(compose(odom[-1], inc))
    return np.array(odom)


def test_fused_chain_beats_drifting_odometry_on_a_loop(office):
    """Once around the simulator's office loop (60 m) with 3 %-scale, heading-drifting wheel odometry:
    the fused chain stays a fraction of the odometry's error from the truth, and the learnt odometer
    scale error has the sign and size of the one put in."""
    rng = np.random.default_rng(5)
    truth = path_poses(OFFICE_LOOP, 0.6)
    odom = noisy_odometry(truth, rng)
    m = matcher()
    fused = [m.step(scan_points(office, p, rng, 0.01), o).pose for p, o in zip(truth, odom, strict=True)]
    err_odom = max(pose_error(o, p)[0] for o, p in zip(odom, truth, strict=True))
    err_fused = max(pose_error(r, p)[0] for r, p in zip(fused, truth, strict=True))
    assert err_odom > 1.0
    assert err_fused < 0.1 * err_odom
    assert m.n_matched == len(truth) - 1 and m.n_fallback == 0
    assert m.fusion.c[0] == pytest.approx(0.03, abs=0.01)  # odometer reads 3 % long


def test_exact_odometry_stays_exact(office):
    """Odometry that is the truth, scans with 1 cm noise: the fused chain must stay on it (the learnt
    odometry noise scale drops to its floor) — well under what the scans alone give. ATE (aligned): the
    few keyframes before the scale is learnt leave a small rigid offset on the rest of the chain."""
    rng = np.random.default_rng(8)
    truth = path_poses(OFFICE_LOOP, 0.6)
    m = matcher()
    fused = np.array([m.step(scan_points(office, p, rng, 0.01), p).pose for p in truth])
    alone = matcher(overrides=["scan_match.adapt_min=1.0", "scan_match.adapt_max=1.0", "ekf.alpha1=100",
                               "ekf.alpha2=100", "ekf.alpha3=100", "ekf.alpha4=100"])  # fmt: skip
    matched = np.array([alone.step(scan_points(office, p, rng, 0.01), p).pose for p in truth])
    t = np.arange(len(truth), dtype=float)
    err, err_alone = ate(t, fused, t, truth).rmse, ate(t, matched, t, truth).rmse
    assert m.odom_scale < 1e-3
    assert err < 0.01 and err < 0.2 * err_alone


def test_voxel_thin_matches_a_brute_force_cell_count():
    pts = np.random.default_rng(6).uniform(-2, 2, (500, 2)) + [-1e4, 3e4]  # negative and large cells
    thin = pts[voxel_thin(pts, 0.5)]
    cells = {(math.floor(x / 0.5), math.floor(y / 0.5)) for x, y in pts}
    assert len(thin) == len(cells)
    assert {(math.floor(x / 0.5), math.floor(y / 0.5)) for x, y in thin} == cells
    np.testing.assert_array_equal(voxel_thin(pts, 0.0), np.arange(len(pts)))


def _numpy_voxel_thin(points, size):
    """voxel_thin as numpy computed it before its kernel: the first index of each unique cell key."""
    cells = np.floor(np.clip(points / size, -(2**31), 2**31 - 1)).astype(np.int64)
    _, first = np.unique((cells[:, 0] << 32) + (cells[:, 1] & 0xFFFFFFFF), return_index=True)
    return np.sort(first)


@pytest.mark.parametrize("size", [0.05, 0.5])
def test_compiled_voxel_thin_keeps_the_same_points_as_numpy(size):
    """The same indices on scattered, quantised (many points per cell, exact cell edges), duplicated,
    huge and non-finite coordinates."""
    rng = np.random.default_rng(12)
    for trial in range(60):
        n = int(rng.integers(1, 2000))
        pts = [
            rng.normal(0, 10, (n, 2)),
            np.round(rng.uniform(-3, 3, (n, 2)), 2),
            np.repeat(rng.normal(0, 1, (n // 3 + 1, 2)), 3, axis=0),
            rng.normal(0, 1e12, (n, 2)),
        ][trial % 4]
        if trial % 5 == 0:
            pts[0, 0], pts[-1, 1] = np.nan, -np.inf
        with np.errstate(invalid="ignore"):
            np.testing.assert_array_equal(voxel_thin(pts, size), _numpy_voxel_thin(pts, size))


@pytest.mark.parametrize(
    "key,value",
    [
        ("window", "0"),
        ("min_fit", "1.5"),
        ("robust_scale", "0"),
        ("gate", "-1"),
        ("voxl", "0.1"),
        ("search_max_xy", "100"),
    ],
)
def test_bad_scan_match_keys_are_config_errors(key, value):
    with pytest.raises(ConfigError, match=f"scan_match.{key}"):
        load_config(None, [f"scan_match.{key}={value}"])


def test_closed_form_normals_match_eigh():
    from scipy.spatial import cKDTree

    from cornerslam_cli.motion.icp import line_normals
    from cornerslam_cli.motion.nearest import BucketGrid

    rng = np.random.default_rng(7)
    t = rng.uniform(0, 3, 200)
    pts = np.column_stack((t, 0.4 * t + rng.normal(0, 0.002, t.size)))  # a noisy line
    pts = np.vstack((pts, rng.uniform(5, 9, (60, 2))))  # and clutter
    normals, ok = line_normals(pts, BucketGrid.build(pts))
    _, idx = cKDTree(pts).query(pts, 5)
    nb = pts[idx] - pts[idx].mean(axis=1, keepdims=True)
    w, v = np.linalg.eigh(np.einsum("nki,nkj->nij", nb, nb))
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", normals, v[:, :, 0])), 1.0, atol=1e-6)
    assert ok[:200].mean() > 0.9 and ok[200:].mean() < 0.3


def test_run_reports_the_scan_matched_odometry_and_it_beats_the_wheels(sim_log, tmp_path):
    from cornerslam_cli.pipeline import run
    from cornerslam_cli.report.tables import read_csv

    s = run(sim_log, load_config(None), out=tmp_path / "on")
    acc = s.accuracy
    assert acc.scan_odom_ate.rmse < 0.5 * acc.odom_ate.rmse
    assert s.counts.scans_matched == s.counts.steps - 1 and s.counts.scans_match_fallback == 0
    traj = read_csv(tmp_path / "on" / "trajectory.csv")
    assert not np.allclose(traj["scan_odom_x"], traj["odom_x"])
    off = run(sim_log, load_config(None, ["scan_match.enabled=false"]), out=tmp_path / "off")
    assert off.accuracy.scan_odom_ate is None and off.counts.scans_matched is None and not off.scan_matching
    traj = read_csv(tmp_path / "off" / "trajectory.csv")
    np.testing.assert_array_equal(traj["scan_odom_x"], traj["odom_x"])


def test_normals_do_not_depend_on_which_tied_neighbour_is_fifth():
    """A point whose 5th and 6th neighbours are equidistant (beams either side of a point with equal
    quantised ranges): one would make the neighbourhood a line, the other not. A last-bit nudge of either,
    or another point order, must not change the normal or whether there is one (it did: the Intel
    figures then depended on the CPU's BLAS kernels, docs/results/intel_spread.md)."""
    from cornerslam_cli.motion.icp import line_normals
    from cornerslam_cli.motion.nearest import BucketGrid

    centre, on_line = [0.0, 0.0], [[0.05, 0.0], [-0.05, 0.0], [0.1, 0.0]]
    a, b = np.array([-0.15, 0.0]), np.array([0.0, 0.15])  # both exactly 0.15 m from the centre
    seen = set()
    for nudge_a, nudge_b in [(0, 0), (-1, 0), (1, 0), (0, -1), (0, 1)]:
        pa, pb = a.copy(), b.copy()
        pa[0] = np.nextafter(pa[0], pa[0] + nudge_a) if nudge_a else pa[0]  # one ulp nearer or farther
        pb[1] = np.nextafter(pb[1], pb[1] + nudge_b) if nudge_b else pb[1]
        for order in ([0, 1, 2, 3, 4, 5], [5, 4, 3, 2, 1, 0], [0, 5, 1, 4, 2, 3]):
            pts = np.array([centre, *on_line, pa, pb])[order]
            normals, ok = line_normals(pts, BucketGrid.build(pts))
            i = order.index(0)
            seen.add((bool(ok[i]), *np.round(np.abs(normals[i]), 12)))
    assert len(seen) == 1, seen


def test_the_compiled_gauss_newton_step_solves_icps_normal_equations():
    """gauss_newton_step against numpy's normal equations and LAPACK solve (register's before it):
    the same step to rounding, on point-to-line terms of a few hundred points, with and without
    zero rows (points with no neighbour or normal) and a prior that dominates a corridor's axis."""
    from cornerslam_cli.motion.kernels import gauss_newton_step

    rng = np.random.default_rng(8)
    for n, corridor in ((400, False), (300, True), (3, False)):
        normals = rng.normal(0.0, 1.0, (n, 2))
        if corridor:
            normals[:, 0] = 1e-3 * normals[:, 0]  # every wall along x: x is nearly unconstrained
        normals /= np.hypot(*normals.T)[:, None]
        J = np.column_stack((normals, rng.normal(0.0, 2.0, n)))
        J[::7] = 0.0
        w, r = rng.uniform(0.1, 1.0, n), rng.normal(0.0, 0.02, n)
        prior, off = np.array([4.0, 4.0, 30.0]), rng.normal(0.0, 0.05, 3)
        Jw = J * w[:, None]
        want = -np.linalg.solve(Jw.T @ J + np.diag(prior), Jw.T @ r + prior * off)
        got = np.empty(3)
        gauss_newton_step(J, w, r, prior, off, got)
        np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-14)


def test_compiled_search_breaks_ties_as_the_numpy_search():
    """Where many poses score the same — an empty map (every score 0 but the pull), a lattice matched
    against itself (a translation of one lattice step fits as well) — with and without an exclusion of
    the best, the compiled search keeps the pose, score and count numpy's argmax order gives."""
    from _correlative_reference import search as numpy_search

    grid = np.stack(np.meshgrid(np.arange(7.0), np.arange(7.0)), axis=-1).reshape(-1, 2) * 0.5
    far = grid + 100.0  # nothing of the map near where the scan can land
    cases = [(grid, np.zeros(3)), (far, np.zeros(3)), (grid, np.array([0.05, -0.05, 0.0]))]
    for map_pts, guess in cases:
        for window in (Window(0.6, 0.1), Window(0.5, 0.0), Window(0.1, 0.2)):
            found = numpy_search(grid, map_pts, guess, window, 0.1, 0.1)
            for exclude in (None, *(Exclusion(found.pose, xy, 0.2) for xy in (0.05, 0.3, 10.0))):
                got = search(grid, map_pts, guess, window, 0.1, 0.1, exclude=exclude)
                want = numpy_search(grid, map_pts, guess, window, 0.1, 0.1, exclude=exclude)
                assert np.array_equal(got.pose, want.pose) and got.score == want.score
                assert got.evaluated == want.evaluated


def test_search_refuses_what_its_compiled_sums_cannot_take(office):
    """A blur of zero (a field of NaN) and poses so far out that the field's cells cannot hold them are
    errors, never a read beyond the field."""
    points = scan_points(office, np.array([6.0, 5.0, 0.0]))
    with pytest.raises(ValueError, match="sigma"):
        search(points, points, np.zeros(3), Window(0.5, 0.1), 0.1, 0.0)
    with pytest.raises(NumericalError, match="off the field"):
        search(points, points + 1e16, np.array([1e16, 1e16, 0.0]), Window(0.5, 0.1), 0.1, 0.1)


def test_compiled_pairwise_sum_is_numpys_bit_for_bit():
    """The compiled pairwise sum adds as numpy's sum of a contiguous float64 run: below 8, blocks of
    8 partial sums up to 128, halves above (split at a multiple of 8), at any start."""
    from cornerslam_cli.smallmat import pairwise_sum

    rng = np.random.default_rng(10)
    v = rng.random(5000) * 10.0 ** rng.integers(-8, 8, 5000)  # magnitudes apart: the order shows
    for n in (0, 1, 7, 8, 9, 15, 16, 127, 128, 129, 130, 255, 256, 257, 1000, 1023, 4096, 4999):
        for lo in (0, 1):
            assert pairwise_sum(v, lo, n) == np.sum(v[lo : lo + n]), (n, lo)
