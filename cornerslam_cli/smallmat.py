"""Compiled linear algebra on matrices of a few rows (the association's and the EKF's 3 × 3 blocks),
where numpy's per-call overhead is most of the cost."""

from __future__ import annotations

import math

import numpy as np

from .features.jit import kernel


@kernel
def cholesky(A, d, rtol):
    """Lower Cholesky factor of the d × d (d ≤ 3) SPD A; the zero matrix when A is not PD (a pivot at or
    below ``rtol`` times its diagonal entry)."""
    L = np.zeros((d, d))
    for j in range(d):
        s = A[j, j]
        for t in range(j):
            s -= L[j, t] * L[j, t]
        if not (s > rtol * A[j, j] if j else s > 0.0):
            return np.zeros((d, d))
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, d):
            s = A[i, j]
            for t in range(j):
                s -= L[i, t] * L[j, t]
            L[i, j] = s / L[j, j]
    return L


@kernel
def product(A, B):
    """A B of small matrices, summed in index order."""
    p, q, r = A.shape[0], A.shape[1], B.shape[1]
    out = np.zeros((p, r))
    for i in range(p):
        for j in range(r):
            s = 0.0
            for t in range(q):
                s += A[i, t] * B[t, j]
            out[i, j] = s
    return out
