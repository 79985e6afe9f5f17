"""Compiled (Numba) searches of the associators: JCBB's interpretation tree (jcbb.jcbb_search, and PCA's
JCBB of each group, pca.group_searches) and PCA's combination of its groups, PCBB + NUBB
(pca.combine_groups), bit for bit the Python searches they replace.

In Python every node of these searches called the compiled try / commit kernels (kernels.py) through
:class:`gating.JointCompatibility`, and the recursion around them was most of an association's time (in
infinite-corridor's loop closing ~0.5 ms a PCA call). Here the same kernels are called from compiled loops,
on the same arrays, in the same order: the same pairings tried with the same floating-point operations,
the same nodes counted, the same budget stop, the same winner of every tie. tests/test_search_kernels.py
compares them with the Python searches (tests/_assoc_reference.py).

Without recursion (Numba's cache loads recursive kernels broken, docs/results/reliability.md): each search
keeps a stack of frames, one per pending call of the recursive step it replaces. Arguments:

jc : (M, y, d2, corners, landmarks, locs, gate), :meth:`gating.JointCompatibility.arrays` (changed in place
     as its try_add / commit change them); ``size`` its committed pairings, where the search starts
g : (nu, C, hph, blocks, loc_of, cand_off, cand_flat), :meth:`gating.Gated.search_arrays`
budget : int64 [max_nodes (0 = none), nodes, hit] (jcbb.Budget), ``deadline`` its perf_counter() end
     (inf = none), checked every 256 nodes through object mode (Numba has no clock)
rtol : the Cholesky pivot tolerance (gating.PIVOT_RTOL)
best : (int64 [count], float64 [joint D²], int64 (capacity, 2) pairs), :class:`jcbb.Best`'s fields
"""

from __future__ import annotations

import math
import time

import numba
import numpy as np

from ..features.jit import kernel
from .kernels import commit_pairing, try_pairing

PCBB, NUBB, RETURN = 0, 1, -1  # combine's frame kinds; RETURN: a frame step's "return to the caller"
KIND, T, S, TAKEN, H, STAGE, ADDED = range(7)  # columns of a combine frame


@kernel
def _now():
    """time.perf_counter(), in object mode."""
    with numba.objmode(t="float64"):
        t = time.perf_counter()
    return t


@kernel
def _tick(budget, deadline):
    """Count one node: False (and the budget marked hit) once ``max_nodes`` are spent or, checked when the
    count reaches a multiple of 256, ``deadline`` has passed."""
    if budget[0] and budget[1] >= budget[0]:
        budget[2] = 1
        return False
    budget[1] += 1
    if budget[1] & 255 == 0 and deadline < math.inf and _now() > deadline:
        budget[2] = 1
        return False
    return True


@kernel
def _can_improve(best, explore_ties, count, remaining, d2):
    """Could a hypothesis with ``count`` pairings, ``remaining`` corners to go and D² ``d2`` still beat the
    best (jcbb's bound and tie rule)?"""
    reach = count + remaining
    return reach > best[0][0] or (explore_ties and reach == best[0][0] and d2 < best[1][0])


@kernel
def _offer(best, jc, h):
    """The first h pairings of jc become the best if more, or as many with a smaller joint D²."""
    d2 = jc[2][h]
    if h > best[0][0] or (h == best[0][0] and d2 < best[1][0]):
        best[0][0], best[1][0] = h, d2
        for a in range(h):
            best[2][a, 0], best[2][a, 1] = jc[3][a], jc[4][a]


@kernel
def _try_add(jc, g, i, k, h, rtol):
    """JointCompatibility.try_add(i, k) on h committed pairings: (joint D², inf if S is not PD; and the
    W, L_new⁻¹, y_new that commit_pairing keeps)."""
    M, y, d2s, corners, landmarks, locs, _ = jc
    nu, C, hph, blocks, loc_of, _, _ = g
    d = blocks.shape[3]
    loc = loc_of[k]
    S_new = hph[k, :d, :d] + C[i, :d, :d]
    inc, W, Minv, ynew = try_pairing(M, y, blocks[:, loc], locs, S_new, nu[i, k, :d], h, rtol)
    d2 = d2s[h] + inc
    if not math.isfinite(d2):
        return math.inf, W, Minv, ynew
    d2s[h + 1] = d2
    corners[h], landmarks[h], locs[h] = i, k, loc
    return d2, W, Minv, ynew


@kernel
def _jcbb_leaf(jc, best, size, exact):
    """A leaf of JCBB's tree (every corner visited): offered as the best (exact: if it passes its gate)."""
    if not exact or jc[2][size] < jc[6][size]:
        _offer(best, jc, size)


@kernel
def jcbb_kernel(jc, g, size, budget, deadline, rtol, corners, exact, explore_ties, best):
    """jcbb.jcbb_search over ``corners``, in that order; those without candidates are skipped. Frame t
    visits the t-th corner with candidates, order[t] (the stack's depth is t; a leaf is no frame): nxt[t]
    its next candidate, child[t] the landmark its running child committed (−1: the "no match" child, or
    none), skipped[t] whether it took that "no match" branch."""
    cand_off, flat = g[5], g[6]
    order = corners[cand_off[corners + 1] > cand_off[corners]]
    first, last = cand_off[order], cand_off[order + 1]
    n, gate = len(order), jc[6]
    used = np.zeros(len(g[2]), np.bool_)
    for a in range(size):
        used[jc[4][a]] = True
    at, nxt = np.empty(n, np.int64), first.copy()
    child, skipped = np.full(n, -1, np.int64), np.zeros(n, np.bool_)
    if not _tick(budget, deadline):
        return
    if n == 0:
        _jcbb_leaf(jc, best, size, exact)
        return
    t, at[0] = 0, size
    while t >= 0:
        if child[t] >= 0:  # its child returned: forget that pairing
            used[child[t]], child[t] = False, -1
            size -= 1
        h, rest, go = at[t], n - t - 1, False
        if not skipped[t]:
            gate_next = gate[h + 1 + rest] if exact else gate[h + 1]
            while not go and nxt[t] < last[t]:
                k = flat[nxt[t]]
                nxt[t] += 1
                if used[k]:
                    continue
                d2, W, Minv, ynew = _try_add(jc, g, order[t], k, h, rtol)
                if d2 < gate_next and _can_improve(best, explore_ties, h + 1, rest, d2):
                    commit_pairing(jc[0], jc[1], W, Minv, ynew, h)
                    used[k], child[t] = True, k
                    size, go = size + 1, True
            if not go:  # corner order[t] unmatched
                skipped[t] = True
                d2 = jc[2][h]
                go = _can_improve(best, explore_ties, h, rest, d2) and (not exact or d2 < gate[h + rest])
        if not go:
            t -= 1
        elif not _tick(budget, deadline):
            return
        elif t + 1 == n:
            _jcbb_leaf(jc, best, size, exact)
        else:
            t += 1
            at[t], nxt[t], child[t], skipped[t] = size, first[t], -1, False


@kernel
def groups_kernel(jc, g, size, budget, deadline, rtol, group_off, group_corners, exact, explore_ties, out):
    """PCA's per-group JCBB (Algorithm 3): jcbb_kernel over each group group_corners[group_off[t] :
    group_off[t + 1]] in turn, from the same ``size`` committed pairings, the budget shared. Group t's
    best pairs go to out[t] (G, capacity, 2); returns their counts."""
    counts = np.zeros(len(group_off) - 1, np.int64)
    for t in range(len(counts)):
        best = (np.zeros(1, np.int64), np.full(1, math.inf), out[t])
        corners = group_corners[group_off[t] : group_off[t + 1]]
        jcbb_kernel(jc, g, size, budget, deadline, rtol, corners, exact, explore_ties, best)
        counts[t] = best[0][0]
    return counts


@kernel
def _pcbb_step(f, size, jc, g, gb_off, gb, used, rem_after, explore_ties, best, rtol):
    """Run PCBB frame f (group f[T]) to its next call: (size, kind of the call or RETURN, its t, s,
    taken). Stage 0: entered; 1: its H_g branch running; 2: its NUBB running."""
    t, G = f[T], len(gb_off) - 1
    if f[STAGE] == 0:
        if t == G:
            _offer(best, jc, size)
            return size, RETURN, 0, 0, 0
        lo, hi = gb_off[t], gb_off[t + 1]
        f[STAGE] = 2
        if hi > lo and not used[gb[lo:hi, 1]].any():  # Alg 4 lines 14–17: take H_g whole
            gate_all, added = jc[6][size + hi - lo], 0
            for a in range(lo, hi):
                d2, W, Minv, ynew = _try_add(jc, g, gb[a, 0], gb[a, 1], size, rtol)
                if not d2 < gate_all:  # D² only grows: already beyond the final gate
                    break
                commit_pairing(jc[0], jc[1], W, Minv, ynew, size)
                size, added = size + 1, added + 1
            if added == hi - lo and _can_improve(best, explore_ties, size, rem_after[t + 1], jc[2][size]):
                used[gb[lo:hi, 1]] = True
                f[STAGE], f[ADDED] = 1, added
                return size, PCBB, t + 1, 0, 0
            size -= added
        return size, NUBB, t, 0, 0  # Alg 4 line 19
    if f[STAGE] == 1:  # H_g's branch returned
        used[gb[gb_off[t] : gb_off[t + 1], 1]] = False
        f[STAGE] = 2
        return size - f[ADDED], NUBB, t, 0, 0
    return size, RETURN, 0, 0, 0


@kernel
def _nubb_step(f, size, jc, g, u_off, units, used, same, rem_after, explore_ties, best, rtol):
    """Run NUBB frame f (group f[T], unit pair f[S], f[TAKEN] of the group's pairs taken) to its next
    call: (size, kind of the call or RETURN, its t, s, taken). Stage 0: entered; 1: its "append" branch
    running; 2: done or its last call running."""
    t, s, taken = f[T], f[S], f[TAKEN]
    lo = u_off[t]
    count = u_off[t + 1] - lo
    if f[STAGE] == 2:
        return size, RETURN, 0, 0, 0
    if s == count:  # after the group's last unit pair: the next group, unless this repeats H_g
        f[STAGE] = 2
        if same[t] and taken == count and count:
            return size, RETURN, 0, 0, 0
        return size, PCBB, t + 1, 0, 0
    i, k = units[lo + s, 0], units[lo + s, 1]
    rest = count - s - 1 + rem_after[t + 1]
    if f[STAGE] == 0:
        f[H] = size
        if not used[k]:  # Alg 5 lines 1–9: append the unit pair
            d2, W, Minv, ynew = _try_add(jc, g, i, k, size, rtol)
            if d2 < jc[6][size + 1] and _can_improve(best, explore_ties, size + 1, rest, d2):
                commit_pairing(jc[0], jc[1], W, Minv, ynew, size)
                used[k], f[STAGE] = True, 1
                return size + 1, NUBB, t, s + 1, taken + 1
    else:  # the "append" branch returned
        used[k] = False
        size -= 1
    f[STAGE] = 2
    if _can_improve(best, explore_ties, f[H], rest, jc[2][f[H]]):  # Alg 5 lines 10–16: skip it
        return size, NUBB, t, s + 1, taken
    return size, RETURN, 0, 0, 0


@kernel
def combine_kernel(
    jc, g, size, budget, deadline, rtol, gb_off, gb, u_off, units, same, rem_after, explore_ties, best
):
    """pca.combine_groups: group t's H_g is gb[gb_off[t] : gb_off[t + 1]], its unit pairs units[u_off[t] :
    u_off[t + 1]] ((corner, landmark) rows), ``same[t]`` whether they are the same set, rem_after[t] the
    unit pairs of groups t, t + 1, … Frames (KIND, T, S, TAKEN, H, STAGE, ADDED): a PCBB call pcbb(t) or
    a NUBB call nubb(t, s, taken)."""
    used = np.zeros(len(g[2]), np.bool_)
    frames = np.zeros((2 * len(gb_off) + len(units) + 1, 7), np.int64)
    depth, kind, t, s, taken = 0, PCBB, 0, 0, 0
    while True:
        if kind != RETURN:
            if not _tick(budget, deadline):
                return
            frames[depth] = 0
            frames[depth, KIND], frames[depth, T], frames[depth, S], frames[depth, TAKEN] = kind, t, s, taken
            depth += 1
        else:
            depth -= 1
            if depth == 0:
                return
        f = frames[depth - 1]
        if f[KIND] == PCBB:
            size, kind, t, s, taken = _pcbb_step(
                f, size, jc, g, gb_off, gb, used, rem_after, explore_ties, best, rtol
            )
        else:
            size, kind, t, s, taken = _nubb_step(
                f, size, jc, g, u_off, units, used, same, rem_after, explore_ties, best, rtol
            )
