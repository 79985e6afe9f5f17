"""Loop closing's cheaper paths (graph/loops.py, graph/submap.py) against the computations they
replaced, kept here verbatim: the same hypotheses and corner sets, bit for bit, on the simulated
submaps of test_loops.py and on random constellations (repeated structure, many corners, φ near ±π)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from submap_fixtures import build_submap, corners_submap, spin, symmetric_room_world
from test_loops import office_pair, room_pair, room_submap

from cornerslam_cli.association import AssociationConfig
from cornerslam_cli.filter import Ekf, EkfConfig
from cornerslam_cli.geometry import transform_points, wrap_angle
from cornerslam_cli.graph import loops
from cornerslam_cli.graph.params import LoopConfig
from cornerslam_cli.graph.submap import CornerPairs, diagonal_blocks

CFG = LoopConfig()


# ------------------------------------------------------------- the computations as they were written


def old_pair_hypotheses(a: np.ndarray, b: np.ndarray, cfg: LoopConfig) -> loops.Hypotheses:
    a, b = np.asarray(a, dtype=float).reshape(-1, 3), np.asarray(b, dtype=float).reshape(-1, 3)

    def corner_pairs(lm):
        i, j = np.triu_indices(len(lm), 1)
        return i, j, np.hypot(lm[j, 0] - lm[i, 0], lm[j, 1] - lm[i, 1])

    ai, aj, ad = corner_pairs(a)
    order = np.argsort(ad, kind="stable")
    ai, aj, ad = ai[order], aj[order], ad[order]
    bi, bj, bd = corner_pairs(b)
    lo = np.searchsorted(ad, bd - cfg.pair_distance, side="right")
    count = np.searchsorted(ad, bd + cfg.pair_distance, side="left") - lo
    rb = np.repeat(np.arange(len(bd)), count)
    ra = lo[rb] + np.arange(len(rb)) - np.repeat(np.cumsum(count) - count, count)
    I, J = np.tile(bi[rb], 2), np.tile(bj[rb], 2)
    K, L = np.concatenate((ai[ra], aj[ra])), np.concatenate((aj[ra], ai[ra]))
    ok = (np.abs(wrap_angle(b[I, 2] - a[K, 2])) < cfg.pair_phi) & (
        np.abs(wrap_angle(b[J, 2] - a[L, 2])) < cfg.pair_phi
    )
    pairs = np.column_stack((I, J, K, L))[ok]
    length = np.tile(bd[rb], 2)[ok]
    poses = loops.pair_transform(
        b[pairs[:, 0], :2], b[pairs[:, 1], :2], a[pairs[:, 2], :2], a[pairs[:, 3], :2]
    )
    votes, rank = old_votes(poses, length)
    order = np.lexsort((-length, -votes, rank))[: cfg.max_hypotheses]
    n = old_support(poses[order], a, b, cfg.pair_phi)
    order = order[np.argsort(-n, kind="stable")]
    return loops.Hypotheses(
        pairs[order].astype(np.int64), poses[order], length[order], votes[order], np.sort(n)[::-1]
    )


def old_votes(poses: np.ndarray, length: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    cells = np.floor(poses / np.array([loops.VOTE_XY, loops.VOTE_XY, 1.0]))
    n = 2 * round(np.pi / loops.VOTE_THETA)  # heading cells around the circle, centred on 0 and ±π
    cells[:, 2] = np.floor(poses[:, 2] * n / (2 * np.pi) + 0.5) % n
    cells = np.clip(cells, -(2**20), 2**20 - 1).astype(np.int64) + 2**20
    key = (cells[:, 0] << 42) | (cells[:, 1] << 21) | cells[:, 2]
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    by_cell = np.lexsort((-length, key))
    first = np.cumsum(counts) - counts
    rank = np.empty(len(key), dtype=np.int64)
    rank[by_cell] = np.arange(len(key)) - first[inverse[by_cell]]
    return counts[inverse], rank


def old_support(poses: np.ndarray, a: np.ndarray, b: np.ndarray, pair_phi: float) -> np.ndarray:
    c, s = np.cos(poses[:, 2])[:, None], np.sin(poses[:, 2])[:, None]
    x = poses[:, :1] + c * b[None, :, 0] - s * b[None, :, 1]
    y = poses[:, 1:2] + s * b[None, :, 0] + c * b[None, :, 1]
    d2 = (x[..., None] - a[None, None, :, 0]) ** 2 + (y[..., None] - a[None, None, :, 1]) ** 2
    same_phi = np.abs(wrap_angle(b[:, None, 2] - a[None, :, 2])) < pair_phi
    near = (d2 < loops.SUPPORT_DISTANCE**2) & same_phi[None]
    return near.any(axis=2).sum(axis=1)


def old_corner_sets(a, b, hyps, cfg, associate) -> list[loops.CornerSet]:
    if len(hyps) == 0:
        return []
    z, C = b.landmarks, diagonal_blocks(b.landmark_P)
    n = len(a.landmarks)
    P = np.zeros((3 + 3 * n, 3 + 3 * n))
    P[:3, :3] = np.diag([cfg.hypothesis_sigma_xy**2] * 2 + [cfg.hypothesis_sigma_theta**2])
    P[3:, 3:] = a.landmark_P
    found: list[loops.CornerSet] = []
    most = 0
    for h in range(len(hyps)):
        if h and hyps.support[h] < max(cfg.min_corners, most - loops.SUPPORT_SLACK):
            break
        if any(s.n >= cfg.min_corners and not loops._far_apart(s.pose, hyps.poses[h]) for s in found):
            continue
        ekf = Ekf.from_state(EkfConfig(), np.concatenate((hyps.poses[h], a.landmarks.reshape(-1))), P)
        result = associate(z, C, ekf.predict_observations())
        matched = np.flatnonzero(result.pairs >= 0)
        pairs = np.column_stack((matched, result.pairs[matched])).astype(np.int64)
        pose = old_fit_rigid(b, a, pairs) if len(pairs) >= 2 else hyps.poses[h]
        n_a = len(np.unique(pairs[:, 1]))
        found.append(loops.CornerSet(pairs, pose, n_a, result.joint_d2, h, result.budget_hit))
        if result.budget_hit:
            break
        most = max(most, found[-1].n)
    return found


def old_fit_rigid(b, a, pairs: np.ndarray) -> np.ndarray:
    p, q = b.landmarks[pairs[:, 0], :2], a.landmarks[pairs[:, 1], :2]
    Cb, Ca = diagonal_blocks(b.landmark_P, pairs[:, 0]), diagonal_blocks(a.landmark_P, pairs[:, 1])
    w = 2.0 / (np.trace(Cb[:, :2, :2], axis1=1, axis2=2) + np.trace(Ca[:, :2, :2], axis1=1, axis2=2))
    w = w / w.sum()
    mp, mq = w @ p, w @ q
    H = (w[:, None] * (p - mp)).T @ (q - mq)
    theta = np.arctan2(H[0, 1] - H[1, 0], H[0, 0] + H[1, 1])
    t = mq - transform_points(mp[None, :], (0.0, 0.0, theta))[0]
    return np.array([t[0], t[1], wrap_angle(theta)])


# ------------------------------------------------------------------------------------------ the pairs


def random_pair(seed: int, n_a: int, n_b: int):
    """Two constellations: b partly a's seen from elsewhere (noise of a few cm), partly its own; every
    third corner of a repeated 2 m to the side (a second pose with as many votes), φ across ±π."""
    rng = np.random.default_rng(seed)
    a = np.column_stack((rng.uniform(-8, 8, (n_a, 2)), rng.uniform(-np.pi, np.pi, n_a)))
    a[2::3] = a[0 : len(a[2::3]) * 3 : 3] + (2.0, 0.0, 0.0)
    a[:, 2] = wrap_angle(a[:, 2])
    truth = np.array([rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(-np.pi, np.pi)])
    shared = a[: n_b // 2]
    xy = transform_points(shared[:, :2] - truth[:2], (0.0, 0.0, -truth[2])) + rng.normal(
        0, 0.03, (len(shared), 2)
    )
    b = np.vstack(
        (
            np.column_stack((xy, shared[:, 2] + rng.normal(0, 0.03, len(shared)))),
            np.column_stack(
                (rng.uniform(-8, 8, (n_b - len(shared), 2)), rng.uniform(-np.pi, np.pi, n_b - len(shared)))
            ),
        )
    )
    return corners_submap(a), corners_submap(b)


def submap_pairs():
    a, b, _ = office_pair()
    yield "office", a, b
    a, b, _ = room_pair()
    yield "room", a, b
    yield "room itself", room_submap(), room_submap()
    world = symmetric_room_world()  # two poses with as many corners (ambiguous)
    a = build_submap(world, spin(3.0, 2.0, np.linspace(0.0, 2 * np.pi, 4, endpoint=False)), 0, seed=1)
    b = build_submap(world, spin(3.0, 2.0, np.linspace(0.4, 0.4 + 2 * np.pi, 4, endpoint=False)), 2, seed=2)
    yield "symmetric room", a, b
    a, b, _ = office_pair()  # b keeps three corners: few corners, every supported hypothesis tried
    keep = np.array([0, 3, 5])
    idx = (3 * keep[:, None] + np.arange(3)).ravel()
    yield (
        "three corners",
        a,
        replace(b, landmarks=b.landmarks[keep], landmark_P=b.landmark_P[np.ix_(idx, idx)]),
    )
    for seed, (n_a, n_b) in enumerate([(3, 2), (12, 9), (30, 25), (60, 40)]):
        yield f"random {n_a}×{n_b}", *random_pair(seed, n_a, n_b)


def same_hypotheses(h: loops.Hypotheses, ref: loops.Hypotheses) -> bool:
    fields = ("pairs", "poses", "length", "votes", "support")
    return all(
        getattr(h, f).dtype == getattr(ref, f).dtype and getattr(h, f).tobytes() == getattr(ref, f).tobytes()
        for f in fields
    )


@pytest.mark.parametrize("max_hypotheses", [200, 7])
def test_hypotheses_are_the_old_computation_bit_for_bit(max_hypotheses):
    cfg = replace(CFG, max_hypotheses=max_hypotheses)
    for name, a, b in submap_pairs():
        ref = old_pair_hypotheses(a.landmarks, b.landmarks, cfg)
        kept = loops.pair_hypotheses(a.landmarks, b.landmarks, cfg, a.corner_pairs, b.corner_pairs)
        made = loops.pair_hypotheses(a.landmarks, b.landmarks, cfg)
        assert same_hypotheses(kept, ref), name
        assert same_hypotheses(made, ref), name


@pytest.mark.parametrize("method,max_nodes", [("pca", 30_000), ("jcbb", 30_000), ("icnn", 0), ("pca", 40)])
def test_corner_sets_are_the_old_computation_bit_for_bit(method, max_nodes):
    cfg = replace(CFG, max_nodes=max_nodes)  # 40 nodes: searches cut short (budget_hit)
    associate = loops.loop_associator(AssociationConfig(method=method), cfg)
    for name, a, b in submap_pairs():
        hyps = old_pair_hypotheses(a.landmarks, b.landmarks, cfg)
        ref = old_corner_sets(a, b, hyps, cfg, associate)
        got = loops.corner_sets(a, b, hyps, cfg, associate)
        assert len(got) == len(ref), name
        for s, r in zip(got, ref, strict=True):
            assert s.pairs.tobytes() == r.pairs.tobytes() and s.pose.tobytes() == r.pose.tobytes(), name
            assert (s.n, s.joint_d2, s.hypothesis, s.budget_hit) == (
                r.n,
                r.joint_d2,
                r.hypothesis,
                r.budget_hit,
            )


def test_a_submaps_kept_tables_are_its_corners_and_cannot_be_changed():
    a, _, _ = office_pair()
    assert np.array_equal(a.landmark_blocks, diagonal_blocks(a.landmark_P))
    pairs = a.corner_pairs
    assert a.corner_pairs is pairs  # computed once
    i, j = np.triu_indices(len(a.landmarks), 1)
    assert np.array_equal(pairs.i, i) and np.array_equal(pairs.j, j)
    assert np.all(np.diff(pairs.sorted_length) >= 0)
    assert np.array_equal(CornerPairs.of(a.landmarks).sorted_i, pairs.sorted_i)
    with pytest.raises(ValueError):
        a.landmark_blocks[0, 0, 0] = 1.0
    with pytest.raises(ValueError):
        pairs.length[0] = 1.0
