"""What loop closing keeps between closes to find and verify candidates cheaply (graph/paths.py,
graph/submap.LocalMaps), against the plain computations they stand for."""

from __future__ import annotations

import numpy as np

from cornerslam_cli.geometry import transform_points
from cornerslam_cli.graph.paths import Paths
from cornerslam_cli.graph.submap import LocalMaps, Submap, local_map


def _brute_closest(paths: list[np.ndarray], b: int, last: int, poses: np.ndarray) -> np.ndarray:
    """Every earlier path's smallest distance to b's, over all point pairs."""
    path_b = transform_points(paths[b], poses[b])
    out = np.empty(last + 1)
    for a in range(last + 1):
        path_a = transform_points(paths[a], poses[a])
        out[a] = np.sqrt(((path_a[:, None, :] - path_b[None, :, :]) ** 2).sum(axis=2)).min()
    return out


def test_path_distances_behind_the_discs_are_the_brute_forces_exactly():
    """Discs rule out only paths farther than the radius; the distances kept are the brute force's bit
    for bit (same arithmetic per pair), so the candidates do not change."""
    rng = np.random.default_rng(4)
    paths = Paths()
    for _ in range(60):  # random walks of a few metres, each in its own frame
        steps = rng.normal(0.0, 0.4, (int(rng.integers(1, 40)), 2))
        paths.add(np.cumsum(steps, axis=0))
    poses = np.column_stack((rng.uniform(-30, 30, (60, 2)), rng.uniform(-np.pi, np.pi, 60)))
    kept = 0
    for b in range(10, 60, 7):
        for radius in (0.5, 3.0, 10.0):
            got = paths.closest(b, b - 2, poses, radius)
            want = _brute_closest(paths.paths, b, b - 2, poses)
            near = want <= radius
            assert np.array_equal(got[near], want[near])
            assert np.all(got[~near] > radius)
            kept += int(np.isinf(got).sum())
    assert kept > 0  # the discs did rule some out


def _submap(index: int, points: np.ndarray) -> Submap:
    z = np.zeros((0, 3))
    return Submap(index, 0, 0, z, np.zeros((0, 0)), np.zeros(0, int), points, np.zeros(3), np.eye(3), z)


def test_local_maps_are_built_once_kept_for_the_most_recent_and_equal_a_fresh_build():
    rng = np.random.default_rng(5)
    submaps = [_submap(i, rng.uniform(0, 10, (200, 2))) for i in range(4)]
    maps = LocalMaps(2)
    first = maps(submaps[0])
    assert maps(submaps[0]) is first  # asked again: the same map
    fresh = local_map(submaps[0])
    for name in ("points", "normals", "has_normal", "padded_points", "padded_normals"):
        assert np.array_equal(getattr(first, name), getattr(fresh, name))
    second = maps(submaps[1])
    maps(submaps[0])  # 0 is now the most recent, 1 the least
    maps(submaps[2])  # evicts 1
    assert maps(submaps[0]) is first
    assert maps(submaps[1]) is not second  # built again
    other = _submap(0, rng.uniform(0, 10, (200, 2)))  # another submap 0 (another run): its own map
    assert np.array_equal(maps(other).points, other.points)
