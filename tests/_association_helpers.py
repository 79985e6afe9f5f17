"""Synthetic association problems and independent reference implementations (tests and benchmarks).

A problem is a valid :class:`Prediction` built directly: landmark estimates seen from an estimated pose,
h_k = [R(θ)ᵀ(m_k − p); m_k,φ] with its exact Jacobians, and a state covariance
P = blockdiag(Σ_r, D_1 … D_n) + U Uᵀ (random SPD with robot–landmark correlations through U).
No dependency on the filter code.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from cornerslam_cli.geometry import wrap_angle
from cornerslam_cli.types import Prediction


def observe(pose: np.ndarray, lm: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """h (n, 3), H_r (n, 3, 3), H_l (n, 3, 3) of landmarks lm (n, 3) map frame, seen from pose (x, y, θ)."""
    x, y, th = pose
    c, s = np.cos(th), np.sin(th)
    dx, dy = lm[:, 0] - x, lm[:, 1] - y
    hx, hy = c * dx + s * dy, -s * dx + c * dy
    n = len(lm)
    h = np.column_stack((hx, hy, lm[:, 2]))
    Hr = np.zeros((n, 3, 3))
    Hr[:, 0, 0], Hr[:, 0, 1], Hr[:, 0, 2] = -c, -s, hy
    Hr[:, 1, 0], Hr[:, 1, 1], Hr[:, 1, 2] = s, -c, -hx
    Hl = np.zeros((n, 3, 3))
    Hl[:, 0, 0], Hl[:, 0, 1], Hl[:, 1, 0], Hl[:, 1, 1], Hl[:, 2, 2] = c, s, -s, c, 1.0
    return h, Hr, Hl


@dataclass
class StateCov:
    """P = blockdiag(Sr, D_1..D_n) + U Uᵀ in factored form, so it can be sampled without a big Cholesky."""

    Sr: np.ndarray  # (3, 3)
    D: np.ndarray  # (n, 3, 3)
    Ur: np.ndarray  # (3, r)
    Ul: np.ndarray  # (n, 3, r)

    def dense(self) -> np.ndarray:
        n, r = len(self.D), self.Ur.shape[1]
        U = np.concatenate([self.Ur, self.Ul.reshape(3 * n, r)])
        P = U @ U.T
        P[:3, :3] += self.Sr
        idx = 3 + 3 * np.arange(n)[:, None] + np.arange(3)
        P[idx[:, :, None], idx[:, None, :]] += self.D
        return P

    def sample(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """One draw e ~ N(0, P): robot part (3,), landmark part (n, 3)."""
        r = self.Ur.shape[1]
        xi = rng.standard_normal(r)
        er = np.linalg.cholesky(self.Sr) @ rng.standard_normal(3) + self.Ur @ xi
        el = np.einsum("nij,nj->ni", np.linalg.cholesky(self.D), rng.standard_normal((len(self.D), 3)))
        return er, el + self.Ul @ xi


def random_state_cov(
    rng: np.random.Generator,
    n: int,
    pose_sigma=(0.2, 0.2, 0.03),
    lm_sigma=(0.05, 0.05, 0.03),
    rank: int = 4,
    corr: float = 0.5,
) -> StateCov:
    """Random SPD state covariance with the given marginal scales and robot–landmark correlation."""
    ps, ls = np.asarray(pose_sigma), np.asarray(lm_sigma)
    Ur = corr * ps[:, None] * rng.standard_normal((3, rank)) / np.sqrt(rank)
    Ul = corr * ls[None, :, None] * rng.standard_normal((n, 3, rank)) / np.sqrt(rank)
    Sr = np.diag(ps**2 * (1 - corr**2))
    A = rng.standard_normal((n, 3, 3)) * 0.3 + np.eye(3)
    D = (ls[:, None] * A) @ (ls[:, None] * A).transpose(0, 2, 1) * (1 - corr**2)
    return StateCov(Sr, D, Ur, Ul)


def random_meas_cov(rng: np.random.Generator, m: int, sigma=(0.03, 0.03, 0.02)) -> np.ndarray:
    A = rng.standard_normal((m, 3, 3)) * 0.3 + np.eye(3)
    s = np.asarray(sigma)[:, None]
    return (s * A) @ (s * A).transpose(0, 2, 1)


@dataclass
class Problem:
    z: np.ndarray
    C: np.ndarray
    pred: Prediction
    truth: np.ndarray  # (m,) true landmark of each corner, -1 = spurious


def simulate_step(
    rng: np.random.Generator,
    n: int = 30,
    m_true: int = 8,
    n_spurious: int = 2,
    n_twins: int = 4,
    twin_dist=(0.25, 0.5),
    extent: float = 6.0,
    pose_sigma=(0.2, 0.2, 0.03),
    lm_sigma=(0.05, 0.05, 0.03),
    meas_sigma=(0.03, 0.03, 0.02),
    phi_range=(0.4, np.pi - 0.4),
) -> Problem:
    """One association step with known truth: m_true observed landmarks, spurious corners, close twins.

    The state estimate error is a draw from N(0, P), so the gates are consistent; the pose error
    (pose_sigma) shifts all innovations coherently, which is what ICNN cannot exploit.
    """
    n_base = n - n_twins
    lm = np.column_stack((rng.uniform(-extent, extent, (n_base, 2)), rng.uniform(*phi_range, n_base)))
    src = rng.choice(n_base, n_twins, replace=False)
    ang = rng.uniform(0, 2 * np.pi, n_twins)
    dist = rng.uniform(*twin_dist, n_twins)
    twins = lm[src] + np.column_stack((dist * np.cos(ang), dist * np.sin(ang), rng.normal(0, 0.02, n_twins)))
    lm = np.concatenate([lm, twins])
    pose = np.array([rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-np.pi, np.pi)])
    cov = random_state_cov(rng, n, pose_sigma, lm_sigma)
    er, el = cov.sample(rng)
    pose_est, lm_est = pose + er, lm + el
    seen = rng.choice(n, min(m_true, n), replace=False)
    C = random_meas_cov(rng, len(seen) + n_spurious, meas_sigma)
    h_true, _, _ = observe(pose, lm[seen])
    noise = np.einsum("mij,mj->mi", np.linalg.cholesky(C[: len(seen)]), rng.standard_normal((len(seen), 3)))
    z_true = h_true + noise
    z_spur = np.column_stack(
        (rng.uniform(-extent, extent, (n_spurious, 2)), rng.uniform(*phi_range, n_spurious))
    )
    z = np.concatenate([z_true, z_spur])
    z[:, 2] = wrap_angle(z[:, 2])
    truth = np.concatenate([seen, -np.ones(n_spurious, dtype=np.int64)])
    perm = rng.permutation(len(z))
    h, Hr, Hl = observe(pose_est, lm_est)
    pred = Prediction(h, Hr, Hl, cov.dense())
    return Problem(z[perm], C[perm], pred, truth[perm])


def random_problem(rng: np.random.Generator, m: int, n: int, near_singular: bool = False, **kw) -> Problem:
    """Small random problem for the exactness tests (few spurious corners, some twins)."""
    n_twins = min(n // 3, 3)
    m_true = min(n, max(m - 1, 0)) if m else 0
    kw = {"n": n, "m_true": m_true, "n_spurious": m - m_true, "n_twins": n_twins, "extent": 3.0, **kw}
    p = simulate_step(rng, **kw)
    if near_singular:  # rank-deficient measurement and state covariances (+ a whisper of noise)
        C = p.C.copy()
        v = rng.standard_normal((len(C), 3, 1))
        C = 1e-3 * v @ v.transpose(0, 2, 1) + 1e-14 * np.eye(3)
        P = p.pred.P.copy()
        w = rng.standard_normal((len(P), 2))
        P = 0.05 * w @ w.T + 1e-14 * np.eye(len(P))
        return Problem(p.z, C, Prediction(p.pred.h, p.pred.H_r, p.pred.H_l, P), p.truth)
    return p


# ---------------------------------------------------------------- independent references


def stacked_joint_d2(z, C, pred: Prediction, pairs, d: int = 3) -> float:
    """Direct νᵀ S⁻¹ ν of the stacked hypothesis (np.linalg.solve on the full joint S)."""
    if not pairs:
        return 0.0
    I = np.array([i for i, _ in pairs])
    K = np.array([k for _, k in pairs])
    nu = z[I] - pred.h[K]
    nu[:, 2] = wrap_angle(nu[:, 2])
    blocks = pred.hph_blocks(K, K)[:, :, :d, :d].copy()
    for a, i in enumerate(I):
        blocks[a, a] += C[i, :d, :d]
    h = len(pairs)
    S = blocks.transpose(0, 2, 1, 3).reshape(d * h, d * h)
    v = nu[:, :d].reshape(-1)
    return float(v @ np.linalg.solve(S, v))


def naive_d2(z, C, pred: Prediction, d: int = 3) -> np.ndarray:
    """(m, n) individual D² by a double loop."""
    m, n = len(z), len(pred)
    out = np.zeros((m, n))
    for i in range(m):
        for k in range(n):
            nu = z[i] - pred.h[k]
            nu[2] = wrap_angle(nu[2])
            A = np.concatenate([pred.H_r[k], pred.H_l[k]], axis=1)
            idx = np.r_[0:3, 3 + 3 * k : 6 + 3 * k]
            S = A @ pred.P[np.ix_(idx, idx)] @ A.T + C[i]
            out[i, k] = nu[:d] @ np.linalg.solve(S[:d, :d], nu[:d])
    return out


def naive_icnn(z, C, pred: Prediction, gate: float, d: int = 3) -> np.ndarray:
    D2 = naive_d2(z, C, pred, d)
    out = np.full(len(z), -1)
    for i in range(len(z)):
        best = np.inf
        for k in range(len(pred)):
            if D2[i, k] < gate and D2[i, k] < best:
                best, out[i] = D2[i, k], k
    return out


def brute_force_best(z, C, pred: Prediction, candidates, chi2_of, d: int = 3, corners=None, prefix=False):
    """Most pairings, then least joint D², over all injective partial assignments of compatible pairs.

    candidates : per corner, the allowed landmarks; corners: the corners in visiting order (default all).
    chi2_of(dof) gives the joint gate. prefix: also require every prefix of the hypothesis, in the order
    of ``corners``, to be jointly compatible (Neira & Tardós JCBB). Returns (sorted pairs, joint D²).
    """
    corners = list(range(len(z))) if corners is None else list(corners)
    options = [[None, *candidates[i]] for i in corners]
    best, best_d2 = [], 0.0
    for choice in itertools.product(*options):
        ks = [k for k in choice if k is not None]
        if len(ks) != len(set(ks)) or len(ks) < len(best):
            continue
        pairs = [(i, k) for i, k in zip(corners, choice, strict=True) if k is not None]
        prefixes = [pairs[:j] for j in range(1, len(pairs) + 1)] if prefix else [pairs]
        d2s = [stacked_joint_d2(z, C, pred, q, d) for q in prefixes]
        if pairs and not all(e < chi2_of(d * len(q)) for e, q in zip(d2s, prefixes, strict=True)):
            continue
        d2 = d2s[-1] if pairs else 0.0
        if len(pairs) > len(best) or d2 < best_d2:
            best, best_d2 = pairs, d2
    return sorted(best), best_d2


def pairs_of(result) -> list[tuple[int, int]]:
    return [(i, int(k)) for i, k in enumerate(result.pairs) if k >= 0]


PAPER_HARD_COUNTS = (0, 0, 0, 9, 8, 3, 6, 7, 1, 0, 1, 0)  # paper eq 35: candidates of the 12 corners


def hard_step(
    rng: np.random.Generator,
    counts=PAPER_HARD_COUNTS,
    n_background: int = 20,
    pose_sigma=(0.3, 0.3, 0.05),
    alpha: float = 0.05,
) -> Problem:
    """The paper's hard step (Fig 17, eq 35): corner i has exactly counts[i] individually compatible
    landmarks, clustered around it, each with an innovation drawn independently inside its gate — so
    pairs are individually plausible while few combinations are jointly compatible (large, strongly
    correlated pose uncertainty). Pose estimate at the origin; truth is all −1 (no correct answer).
    """
    from scipy.stats import chi2

    thr = chi2.ppf(1 - alpha, 3)
    m = len(counts)
    bearing = np.linspace(-np.pi * 0.9, np.pi * 0.9, m)
    rng_ = rng.uniform(5.0, 7.0, m)
    z = np.column_stack((rng_ * np.cos(bearing), rng_ * np.sin(bearing), rng.uniform(0.5, 2.6, m)))
    C = random_meas_cov(rng, m)
    cov0 = random_state_cov(rng, 1, pose_sigma)  # for Sr and Ur
    rank = cov0.Ur.shape[1]
    pose = np.zeros(3)
    P_r = cov0.Sr + cov0.Ur @ cov0.Ur.T

    def landmark_d2(lm, Ul, D):
        """D² of landmark (3,) with its covariance factors against every corner."""
        _, Hr, Hl = observe(pose, lm[None])
        Prl = cov0.Ur @ Ul.T
        Pll = D + Ul @ Ul.T
        hph = Hr[0] @ P_r @ Hr[0].T + Hr[0] @ Prl @ Hl[0].T
        hph = hph + hph.T - Hr[0] @ P_r @ Hr[0].T + Hl[0] @ Pll @ Hl[0].T
        nu = z - lm  # h = lm at the origin pose
        nu[:, 2] = wrap_angle(nu[:, 2])
        return np.array([nu[i] @ np.linalg.solve(hph + C[i], nu[i]) for i in range(m)])

    lms, Uls, Ds = [], [], []
    ls = np.array([0.05, 0.05, 0.03])

    def new_factors():
        Ul = 0.5 * ls[:, None] * rng.standard_normal((3, rank)) / np.sqrt(rank)
        A = rng.standard_normal((3, 3)) * 0.3 + np.eye(3)
        return Ul, 0.75 * (ls[:, None] * A) @ (ls[:, None] * A).T

    wanted = [(i, c) for i, c in enumerate(counts)] + [(-1, n_background)]
    for i, c in wanted:
        got = 0
        while got < c:
            Ul, D = new_factors()
            if i >= 0:  # inside corner i's gate only
                lm = z[i] - rng.normal(0, 1, 3) * np.array([0.35, 0.35, 0.05])
            else:  # far from every corner
                lm = np.array([*rng.uniform(-15, 15, 2), rng.uniform(0.5, 2.6)])
            d2 = landmark_d2(lm, Ul, D)
            ok = (d2 < thr).sum() == (1 if i >= 0 else 0) and (i < 0 or d2[i] < thr)
            if ok:
                lms.append(lm)
                Uls.append(Ul)
                Ds.append(D)
                got += 1
    lm = np.array(lms)
    cov = StateCov(cov0.Sr, np.array(Ds), cov0.Ur, np.array(Uls))
    h, Hr, Hl = observe(pose, lm)
    perm = rng.permutation(len(lm))  # landmark order carries no information
    pred = Prediction(h[perm], Hr[perm], Hl[perm], _permute_state(cov.dense(), perm))
    return Problem(z, C, pred, -np.ones(m, dtype=np.int64))


def _permute_state(P: np.ndarray, perm: np.ndarray) -> np.ndarray:
    idx = np.concatenate([np.arange(3), (3 + 3 * perm[:, None] + np.arange(3)).ravel()])
    return P[np.ix_(idx, idx)]
