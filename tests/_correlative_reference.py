"""The numpy version of the correlative search's branch and bound (cornerslam_cli/motion/correlative.py
before its loop was compiled, search_kernels.branch_and_bound): the reference the compiled search is
compared with. The field and the coarse bounds are Search.prepare's (the compiled coarse sums are
compared with numpy's gather on their own). Also what the compiled field inputs replaced (scipy's
distance transform for search_kernels.squared_distances, numpy's block maximum). Kept only for the tests.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from cornerslam_cli.motion.correlative import BLOCK, PULL, Exclusion, Search, SearchResult, Window


def search(
    points: np.ndarray,
    map_points: np.ndarray,
    guess: np.ndarray,
    window: Window,
    res: float,
    sigma: float,
    exclude: Exclusion | None = None,
) -> SearchResult:
    """correlative.search with the branch and bound in numpy, one coarse cell at a time."""
    prepared = Search.prepare(points, map_points, guess, window, res, sigma)
    L, px, py, bound, dthetas, W = (
        prepared.L,
        prepared.px,
        prepared.py,
        prepared.bound,
        prepared.dthetas,
        prepared.W,
    )
    n_side, n = 2 * W + 1, px.shape[1]
    thetas = guess[2] + dthetas
    best, best_pose, evaluated = -1.0, guess.copy(), 0
    fine = np.arange(BLOCK)
    for flat in prepared.order:
        a, i, j = np.unravel_index(flat, bound.shape)
        if bound[a, i, j] <= best:
            break
        ox = (BLOCK * i + fine)[BLOCK * i + fine < n_side]
        oy = (BLOCK * j + fine)[BLOCK * j + fine < n_side]
        sc = (
            L[px[a][:, None, None] + ox[None, :, None], py[a][:, None, None] + oy[None, None, :]].sum(axis=0)
            / n
        )
        sc = sc - PULL * (
            (dthetas[a] / max(window.theta, 1e-9)) ** 2
            + ((ox - W) * res / max(window.xy, 1e-9))[:, None] ** 2
            + ((oy - W) * res / max(window.xy, 1e-9))[None, :] ** 2
        )
        if exclude is not None:
            covered = exclude.near(guess, ox - W, oy - W, res) & exclude.turned(thetas[a])
            sc = np.where(covered, -np.inf, sc)
        evaluated += sc.size
        k = int(np.argmax(sc))
        if sc.flat[k] > best:
            bi, bj = np.unravel_index(k, sc.shape)
            best = float(sc.flat[k])
            best_pose = np.array([guess[0] + (ox[bi] - W) * res, guess[1] + (oy[bj] - W) * res, thetas[a]])
    return SearchResult(best_pose, best, evaluated)


def distances(free: np.ndarray) -> np.ndarray:
    """The likelihood field's distances in cells before search_kernels.squared_distances: scipy's exact
    Euclidean distance transform."""
    return ndimage.distance_transform_edt(free)


def block_max(L: np.ndarray, b: int) -> np.ndarray:
    """U[i, j] = max of L[i : i + b, j : j + b] (cells beyond the edge count as 0): numpy, shift by shift."""
    P = np.zeros((L.shape[0] + b - 1, L.shape[1] + b - 1))
    P[: L.shape[0], : L.shape[1]] = L
    U = L.copy()
    for di in range(b):
        for dj in range(b):
            if di or dj:
                np.maximum(U, P[di : di + L.shape[0], dj : dj + L.shape[1]], out=U)
    return U
