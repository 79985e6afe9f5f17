"""The scan matcher's compiled parts (motion/nearest.py, motion/kernels.py) give exactly what the
kd-tree and the numpy expressions they replace give."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from cornerslam_cli.motion.icp import NORMAL_TIE
from cornerslam_cli.motion.kernels import line_terms, neighbour_scatter
from cornerslam_cli.motion.nearest import BucketGrid, nearest_within_moving


def point_sets(rng):
    """Random clouds, an ellipse of 'walls' and coordinates quantised to 1 cm (exact ties)."""
    for m in (1, 7, 300, 3000):
        yield rng.normal(0.0, rng.uniform(0.1, 30.0), (m, 2))
        yield np.round(rng.uniform(-20.0, 20.0, (m, 2)), 2)
        t = rng.uniform(0.0, 2 * np.pi, m)
        yield np.column_stack((5 * np.cos(t) + rng.normal(0, 0.01, m), 3 * np.sin(t)))


@pytest.mark.parametrize("bound", [0.05, 0.1, 1.0, 50.0])
def test_bucket_grid_answers_as_the_kd_tree(bound):
    rng = np.random.default_rng(3)
    for pts in point_sets(rng):
        near = pts[:50] + rng.normal(0.0, 0.05, (min(50, len(pts)), 2))
        q = np.vstack((near, rng.uniform(-60.0, 60.0, (400, 2)), pts[:20]))  # far, and on map points
        d_tree, i_tree = cKDTree(pts).query(q, distance_upper_bound=bound)
        d_grid, i_grid = BucketGrid.build(pts).query(q, bound)
        assert np.array_equal(d_grid, d_tree)
        ties = i_grid != i_tree  # only an exact tie may be broken otherwise (quantised points)
        assert np.array_equal(np.linalg.norm(pts[i_grid[ties]] - q[ties], axis=1), d_tree[ties])


@pytest.mark.parametrize("k", [1, 5, 7])
def test_bucket_grid_neighbours_are_the_kd_trees(k):
    """Each map point's k nearest map points (the normals' neighbourhoods), as the kd-tree orders them;
    an exact tie (quantised points) may be ordered otherwise, at the same distance."""
    rng = np.random.default_rng(6)
    for pts in point_sets(rng):
        kk = min(k, len(pts))
        d_tree, i_tree = cKDTree(pts).query(pts, kk)
        d_grid, i_grid = BucketGrid.build(pts).neighbours(kk)
        d_tree, i_tree = d_tree.reshape(len(pts), kk), i_tree.reshape(len(pts), kk)
        assert np.array_equal(d_grid, d_tree)
        ties = i_grid != i_tree
        assert np.array_equal(
            np.linalg.norm(pts[i_grid[ties]] - pts[np.nonzero(ties)[0]], axis=1), d_tree[ties]
        )
        if kk > 1:  # itself first (or a duplicate of it)
            assert np.all((i_grid[:, 0] == np.arange(len(pts))) | (d_grid[:, 1] == 0.0))


def test_bucket_grid_far_or_nan_queries_find_nothing():
    pts = np.array([[0.0, 0.0], [1.0, 0.0]])
    d, i = BucketGrid.build(pts).query(np.array([[np.nan, 0.0], [1e300, -1e300], [0.0, np.inf]]), 1.0)
    assert i.tolist() == [2, 2, 2] and np.all(d == np.inf)


def test_bucket_grid_of_points_1e30_apart_answers_as_the_kd_tree():
    """Beams at 1e30 m (a laser with range_max = inf, tests/fault_corpus.py) in the map: the
    neighbourhoods end (they once doubled their square for ever) and are the tree's."""
    pts = np.array([[0.0, 0.0], [0.05, 0.0], [1e30, 1e30], [-1e30, 5.0], [0.11, 0.0], [0.1, 0.2]])
    d_grid, i_grid = BucketGrid.build(pts).neighbours(3)
    d_tree, i_tree = cKDTree(pts).query(pts, 3)
    assert np.array_equal(d_grid, d_tree)
    ties = i_grid != i_tree  # from 1e30 m, the points 5 cm apart are exactly as far
    assert ties[:2].sum() == 0 and ties[4:].sum() == 0
    assert np.array_equal(np.linalg.norm(pts[i_grid[ties]] - pts[np.nonzero(ties)[0]], axis=1), d_tree[ties])
    d, i = BucketGrid.build(pts).query(pts + 0.01, 1.0)
    assert np.array_equal(i, cKDTree(pts).query(pts + 0.01, distance_upper_bound=1.0)[1])


def test_bucket_grid_none_in_range_is_k_and_inf():
    pts = np.array([[0.0, 0.0], [1.0, 0.0]])
    d, i = BucketGrid.build(pts).query(np.array([[0.5, 3.0], [0.1, 0.0]]), 1.0)
    assert i.tolist() == [2, 0] and d[0] == np.inf and d[1] == pytest.approx(0.1)


def test_line_terms_kernel_is_the_numpy_expression_bit_for_bit():
    rng = np.random.default_rng(4)
    pts = np.vstack((rng.normal(0, 5, (500, 2)), np.zeros((1, 2))))
    normals = rng.normal(0, 1, (501, 2))
    normals[rng.random(501) < 0.2] = 0.0  # points without a normal
    normals[-1] = 0.0
    q = rng.normal(0, 5, (400, 2))
    idx = rng.integers(0, 501, 400)
    t, scale = np.array([1.3, -0.7]), 0.05
    J, w, r = np.empty((400, 3)), np.empty(400), np.empty(400)
    used = line_terms(q, idx, pts, normals, t, scale, J, w, r)
    n = normals[idx]  # the numpy expressions the kernel replaced (icp._line_terms)
    r_np = np.einsum("ij,ij->i", q - pts[idx], n)
    rel = q - t
    J_np = np.column_stack((n[:, 0], n[:, 1], rel[:, 0] * n[:, 1] - rel[:, 1] * n[:, 0]))
    assert used == np.count_nonzero(np.abs(n).sum(axis=1))
    assert np.array_equal(r, r_np) and np.array_equal(J, J_np)
    assert np.array_equal(w, 1.0 / (1.0 + (r_np / scale) ** 2))


@pytest.mark.parametrize("quantised", [False, True])
def test_neighbour_scatter_kernel_is_the_numpy_expression_bit_for_bit(quantised):
    rng = np.random.default_rng(5)
    pts = rng.normal(0, 3, (2000, 2))
    pts = np.round(pts, 2) if quantised else pts  # quantised: neighbours tied with the 5th
    k, q = 5, 7
    dist, idx = cKDTree(pts).query(pts, q)
    out = np.empty((3, len(pts)))
    neighbour_scatter(pts, dist, idx, k, NORMAL_TIE, out)
    w = dist <= dist[:, k - 1 : k] * (1.0 + NORMAL_TIE)  # the numpy expressions it replaced
    mean = (pts[idx] * w[..., None]).sum(axis=1, keepdims=True) / w.sum(axis=1)[:, None, None]
    nb = (pts[idx] - mean) * w[..., None]
    expected = [(nb[..., 0] ** 2).sum(1), (nb[..., 0] * nb[..., 1]).sum(1), (nb[..., 1] ** 2).sum(1)]
    assert np.array_equal(out, np.array(expected))


def test_moving_queries_answer_as_single_queries():
    """nearest_within_moving (ICP's iterations: points that move a little between calls, most of them far
    from the map) gives nearest_within's answers at every call, whatever the points skipped: random walks
    of a scan near walls, far from them, off the grid, crossing its edges, shrinking bounds, NaN."""
    rng = np.random.default_rng(11)
    for pts in point_sets(rng):
        grid = BucketGrid.build(pts)
        lo, hi = pts.min(axis=0) - 3.0, pts.max(axis=0) + 3.0
        q = np.vstack(
            (pts[:60] + rng.normal(0.0, 0.2, (min(60, len(pts)), 2)), rng.uniform(lo, hi, (300, 2)))
        )
        q[-1] = np.nan
        clear, at = np.full(len(q), -1.0), np.empty((len(q), 2))
        moved = False
        for it in range(12):
            bound = max(0.1, 1.0 * 0.5**it)
            step = rng.normal(0.0, [0.05, 0.003, 0.0][it % 3], 2)  # big, small, none
            turn = rng.normal(0.0, 0.002)
            c, s = np.cos(turn), np.sin(turn)
            q = q @ np.array([[c, -s], [s, c]]).T + step
            d_ref, i_ref = grid.query(q, bound)
            d, i = np.empty(len(q)), np.empty(len(q), dtype=np.int64)
            nearest_within_moving(q, bound, *grid.arrays(), d, i, clear, at)
            assert np.array_equal(d, d_ref) and np.array_equal(i, i_ref)
            moved |= bool(np.any(clear > bound))
        assert moved or len(pts) < 10  # some points were answered from their clearance
