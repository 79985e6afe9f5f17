"""Compiled linear algebra on matrices of a few rows (the association's and the EKF's 3 × 3 blocks),
where numpy's per-call overhead is most of the cost; and numpy's float64 summation order, for kernels
that must add as numpy does (the line fit, the correlative search)."""

from __future__ import annotations

import math

import numpy as np

from .features.jit import kernel

_PW_BLOCK = 128  # numpy's PW_BLOCKSIZE


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


@kernel
def _block_sum(v, lo, n):
    """Σ v[lo : lo + n], n ≤ 128, as numpy's pairwise sum adds a block: in order below 8 numbers, else 8
    partial sums combined in a tree, then the rest in order."""
    if n < 8:
        res = -0.0
        for i in range(lo, lo + n):
            res += v[i]
        return res
    r = v[lo : lo + 8].copy()
    i = 8
    while i < n - n % 8:
        for k in range(8):
            r[k] += v[lo + i + k]
        i += 8
    res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    while i < n:
        res += v[lo + i]
        i += 1
    return res


@kernel
def pairwise_sum(v, lo, n):
    """Σ v[lo : lo + n] as numpy's float64 pairwise summation adds them: blocks of at most 128
    (:func:`_block_sum`), longer runs split in two halves (the first a multiple of 8) summed apart and
    added. Without recursion (Numba's cache loads recursive kernels broken): a stack of the halves
    pending, each frame's state 0 = not split yet, 1 = its first half being summed, 2 = its second."""
    if n <= _PW_BLOCK:
        return _block_sum(v, lo, n)
    starts, lengths = np.empty(64, np.int64), np.empty(64, np.int64)
    state, first = np.zeros(64, np.int64), np.empty(64)
    starts[0], lengths[0], top = lo, n, 0
    ret, returning = 0.0, False
    while True:
        if returning:
            if top < 0:
                return ret
            if state[top] == 1:  # its first half is summed: sum the second
                first[top], state[top] = ret, 2
                half = lengths[top] // 2 - (lengths[top] // 2) % 8
                starts[top + 1], lengths[top + 1], state[top + 1] = starts[top] + half, lengths[top] - half, 0
                top += 1
                returning = False
            else:  # both halves summed
                ret = first[top] + ret
                top -= 1
            continue
        if lengths[top] <= _PW_BLOCK:
            ret = _block_sum(v, starts[top], lengths[top])
            top -= 1
            returning = True
            continue
        half = lengths[top] // 2 - (lengths[top] // 2) % 8
        state[top] = 1
        starts[top + 1], lengths[top + 1], state[top + 1] = starts[top], half, 0
        top += 1
