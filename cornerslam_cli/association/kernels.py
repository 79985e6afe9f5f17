"""Compiled (Numba) parts of gating.py: the individual gate of all corner–landmark pairs, the cross
covariances of the landmarks a search can pair, and the steps of :class:`gating.JointCompatibility` —
trying one more pairing on a hypothesis (block Cholesky of S_H, Schur complement) and keeping it.

A search tries ~17 pairings a step on the simulated lap; in numpy each try was ~10 calls on d·h × d
operands and the 3 × 3 factor in Python lists (~25 µs), each landmark's cross covariances ~17 µs, the gate
~0.2 ms. The kernels compute the same expressions in loops (products summed in index order: equal to
BLAS's to rounding). tests/test_association.py checks the gate against a naive evaluation and every joint
D² against a stacked solve.

State (gating.JointCompatibility): M = L_H⁻¹ (dh × dh lower triangular), y = M ν_H; ``row`` (u, d, d) the
cross covariances H_l P H_kᵀ of the new landmark k with every landmark l of the universe, ``locs`` the
universe positions of the committed landmarks.
"""

from __future__ import annotations

import math

import numpy as np

from ..features.jit import kernel
from ..smallmat import cholesky, product


@kernel
def _lower_inverse(L, d):
    """Inverse of a d × d lower-triangular L with positive diagonal, by forward substitution."""
    Minv = np.zeros((d, d))
    for c in range(d):
        Minv[c, c] = 1.0 / L[c, c]
        for i in range(c + 1, d):
            s = 0.0
            for t in range(c, i):
                s += L[i, t] * Minv[t, c]
            Minv[i, c] = -s / L[i, i]
    return Minv


@kernel
def try_pairing(M, y, row, locs, S_new, nu_new, h, rtol):
    """One more pairing (innovation ``nu_new``, covariance ``S_new``) on the h committed ones:
    (D² increase, W = M S_{H,new}, L_new⁻¹, y_new); the increase is inf when the Schur complement
    S_new − WᵀW is not positive definite or the result is not finite."""
    d = len(nu_new)
    dh = d * h
    W = np.zeros((dh, d))
    for a in range(dh):
        for c in range(d):
            s = 0.0
            for t in range(dh):
                s += M[a, t] * row[locs[t // d], t % d, c]
            W[a, c] = s
    schur, r = S_new.copy(), nu_new.copy()
    for a in range(d):
        for c in range(d):
            s = 0.0
            for t in range(dh):
                s += W[t, a] * W[t, c]
            schur[a, c] -= s
        s = 0.0
        for t in range(dh):
            s += W[t, a] * y[t]
        r[a] -= s
    L = cholesky(schur, d, rtol)
    ynew = np.zeros(d)
    if L[0, 0] == 0.0:
        return math.inf, W, L, ynew
    Minv = _lower_inverse(L, d)
    inc = 0.0
    for a in range(d):
        for t in range(a + 1):
            ynew[a] += Minv[a, t] * r[t]
        inc += ynew[a] * ynew[a]
    return (inc if math.isfinite(inc) else math.inf), W, Minv, ynew


@kernel
def commit_pairing(M, y, W, Minv, ynew, h):
    """Append the block row [−L_new⁻¹ Wᵀ M_H, L_new⁻¹] to M and y_new to y (in place)."""
    d = len(ynew)
    dh = d * h
    M[dh : dh + d, :dh] = product(-Minv, product(W[:dh].T, M[:dh, :dh]))  # −L_new⁻¹ Wᵀ M_H
    for a in range(d):
        for c in range(d):
            M[dh + a, dh + c] = Minv[a, c]
        y[dh + a] = ynew[a]


@kernel
def hph(P, H_r, H_l, i, j):
    """The 3 × 3 block H_i P H_jᵀ of landmarks i and j (``Prediction.hph_blocks``), H = [H_r  H_l] on the
    columns of the robot and the landmark."""
    ri, rj = 3 + 3 * i, 3 + 3 * j
    out = np.zeros((3, 3))
    for a in range(3):
        for b in range(3):
            s = 0.0
            for u in range(3):
                for v in range(3):
                    s += H_r[i, a, u] * (P[u, v] * H_r[j, b, v] + P[u, rj + v] * H_l[j, b, v])
                    s += H_l[i, a, u] * (P[ri + u, v] * H_r[j, b, v] + P[ri + u, rj + v] * H_l[j, b, v])
            out[a, b] = s
    return out


@kernel
def cross_blocks(P, H_r, H_l, universe, d):
    """(u, u, d, d) blocks H_l P H_kᵀ of every two landmarks of the universe (symmetric: computed once)."""
    u = len(universe)
    out = np.empty((u, u, d, d))
    for a in range(u):
        for b in range(a, u):
            blk = hph(P, H_r, H_l, universe[a], universe[b])
            for s in range(d):
                for t in range(d):
                    out[a, b, s, t] = blk[s, t]
                    out[b, a, t, s] = blk[s, t]
    return out


@kernel
def mahalanobis2(nu, S, d, rtol):
    """νᵀ S⁻¹ ν of the first d components by a Cholesky of S; inf where S is not positive definite or the
    result is not finite."""
    L = cholesky(S, d, rtol)
    if L[0, 0] == 0.0:
        return math.inf
    out = 0.0
    y = np.zeros(d)
    for a in range(d):
        s = nu[a]
        for t in range(a):
            s -= L[a, t] * y[t]
        y[a] = s / L[a, a]
        out += y[a] * y[a]
    return out if math.isfinite(out) else math.inf


@kernel
def gate_pairs(z, C, h, P, H_r, H_l, d, euclidean_gate, rtol):
    """Innovations (m, n, 3) (φ wrapped), individual D² (m, n) and the blocks H_k P H_kᵀ (n, 3, 3) of all
    m corners × n landmarks; with ``euclidean_gate`` > 0 only pairs that near get a D² (inf otherwise) and
    only their landmarks a block (zero otherwise)."""
    m, n = len(z), len(h)
    nu, d2 = np.empty((m, n, 3)), np.full((m, n), math.inf)
    blocks, done = np.zeros((n, 3, 3)), np.zeros(n, np.bool_)
    S = np.empty((3, 3))
    for i in range(m):
        for k in range(n):
            for a in range(3):
                nu[i, k, a] = z[i, a] - h[k, a]
            nu[i, k, 2] = (nu[i, k, 2] + np.pi) % (2.0 * np.pi) - np.pi
            if euclidean_gate > 0 and not math.hypot(nu[i, k, 0], nu[i, k, 1]) <= euclidean_gate:
                continue
            if not done[k]:
                blocks[k], done[k] = hph(P, H_r, H_l, k, k), True
            S[:, :] = blocks[k] + C[i]
            d2[i, k] = mahalanobis2(nu[i, k], S, d, rtol)
    if euclidean_gate <= 0:
        for k in range(n):  # every landmark's block, also with no corner
            if not done[k]:
                blocks[k] = hph(P, H_r, H_l, k, k)
    return nu, d2, blocks
