"""Compiled (Numba) sequential block update of ekf.py, standard form with the rank-3 terms fused
(the defaults ``update: sequential``, ``fuse``, no ``joseph``).

Per matched pair the numpy version made ~25 calls on (N, 6) and 3 × 3 operands (≈ 60 µs a pair, most of
it call overhead); this kernel runs the same steps in loops — eq 30 ΣHᵀ from the robot's and the
landmark's columns of Σ with the pending terms applied, eq 31 S, a 3 × 3 Cholesky, eq 23 the mean, the
rank-3 term V = ΣHᵀ L⁻ᵀ — summing products in index order, so it equals the numpy update to rounding.
The O(N²) pass Σ ← Σ − U Uᵀ stays in ``Ekf._apply_low_rank`` (BLAS). tests/test_ekf.py compares the
update with a dense EKF.
"""

from __future__ import annotations

import math

import numpy as np

from ..features.jit import kernel
from ..smallmat import cholesky


@kernel
def _observe_one(mu, k):
    """``models.observe_one`` of landmark k from the pose mu[:3]: h (3,), H (3, 6) = [H_r, H_l]."""
    c, s = math.cos(mu[2]), math.sin(mu[2])
    dx, dy = mu[3 + 3 * k] - mu[0], mu[4 + 3 * k] - mu[1]
    hx = c * dx + s * dy
    hy = -s * dx + c * dy
    H = np.array([[-c, -s, hy, c, s, 0.0], [s, -c, -hx, -s, c, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 1.0]])
    return np.array([hx, hy, mu[5 + 3 * k]]), H


@kernel
def _columns(P, U, r, k):
    """(d, 6) columns of the robot and landmark k of Σ − U[:, :r] U[:, :r]ᵀ."""
    d = P.shape[0]
    A = np.empty((d, 6))
    for j in range(6):
        col = j if j < 3 else 3 * k + j
        for row in range(d):
            s = P[row, col]
            for q in range(r):
                s -= U[row, q] * U[col, q]
            A[row, j] = s
    return A


@kernel
def _forward(L, b):
    """L⁻¹ b for a 3 × 3 lower-triangular L."""
    x = np.empty(3)
    for i in range(3):
        s = b[i]
        for t in range(i):
            s -= L[i, t] * x[t]
        x[i] = s / L[i, i]
    return x


@kernel
def sequential_update(P, mu, ids, z, C, U):
    """Eq 23/28–31 pair by pair: μ (in place) and the rank-3 terms V of every pair into the columns of U
    (d, 3k), Σ itself untouched. Returns (summed νᵀS⁻¹ν, the index of the first pair whose S is not
    positive definite, −1 if none: the pairs before it are applied to μ and U)."""
    d = P.shape[0]
    nis = 0.0
    PHt = np.empty((d, 3))
    for t in range(len(ids)):
        k, r = ids[t], 3 * t
        A = _columns(P, U, r, k)
        h, H = _observe_one(mu, k)
        for row in range(d):  # eq 30: ΣHᵀ = A_0 H_rᵀ + A_k H_kᵀ
            for a in range(3):
                s = 0.0
                for j in range(6):
                    s += A[row, j] * H[a, j]
                PHt[row, a] = s
        S = np.empty((3, 3))
        for a in range(3):  # eq 31: S = H (ΣHᵀ)[robot, landmark] + C
            for b in range(3):
                s = 0.0
                for j in range(6):
                    s += H[a, j] * PHt[j if j < 3 else 3 * k + j, b]
                S[a, b] = s + C[t, a, b]
        S = 0.5 * (S + S.T)
        L = cholesky(S, 3, 0.0)
        if L[0, 0] == 0.0:
            return nis, t
        nu = z[t] - h
        nu[2] = (nu[2] + np.pi) % (2.0 * np.pi) - np.pi
        a_ = _forward(L, nu)  # L⁻¹ν
        for row in range(d):  # V = ΣHᵀ L⁻ᵀ; eq 23: μ += V L⁻¹ν
            v = _forward(L, PHt[row])
            U[row, r : r + 3] = v
            mu[row] += v[0] * a_[0] + v[1] * a_[1] + v[2] * a_[2]
        nis += a_[0] * a_[0] + a_[1] * a_[1] + a_[2] * a_[2]
    return nis, -1
