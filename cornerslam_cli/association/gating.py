"""Gating shared by all associators (NOTES §4).

Individual compatibility of corner i and landmark k: innovation ν_ik = z_i − h_k (φ wrapped),
S_ik = H_k P H_kᵀ + C_i, D²_ik = ν_ikᵀ S_ik⁻¹ ν_ik < χ²(d, 1 − α), d = 3 (x, y, φ) or 2 (x, y) when
``use_phi`` is off. :func:`gate` evaluates all m × n pairs at once (compiled, a closed-form Cholesky of
the 3 × 3 blocks), optionally skipping the Mahalanobis test for pairs farther apart than a Euclidean gate.

Joint compatibility of a hypothesis H = {(i_1↔k_1), …, (i_h↔k_h)}: ν_H stacked, S_H the block matrix
with blocks H_{k_a} P H_{k_b}ᵀ + δ_ab C_{i_a}, D²_H = ν_Hᵀ S_H⁻¹ ν_H < χ²(d·h, 1 − α).
:class:`JointCompatibility` keeps the Cholesky factor L_H of S_H and y_H = L_H⁻¹ ν_H while a search
adds and removes pairings: adding one pairing is a block-Cholesky (Schur complement) step,

    W = L_H⁻¹ S_{H,new},   L_new L_newᵀ = S_new − Wᵀ W,   y_new = L_new⁻¹ (ν_new − Wᵀ y_H),
    D²_{H+new} = D²_H + |y_new|²,

one product of size d·h × d per try; S_H is never refactored or inverted. D² never decreases when a
pairing is added, which the branch and bound searches use to prune.
"""

from __future__ import annotations

import functools
import itertools
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.special import gammaincinv

from ..types import AssociationResult, Prediction
from .kernels import commit_pairing, cross_blocks, gate_pairs, try_pairing
from .params import AssociationConfig

PIVOT_RTOL = 1e-12  # a Cholesky pivot below this fraction of its diagonal entry means "not positive definite"


def row_offsets(rows) -> np.ndarray:
    """(len(rows) + 1,) where each row of ``rows`` starts in their concatenation, and its end."""
    return np.array([*itertools.accumulate(map(len, rows), initial=0)], dtype=np.int64)


def csr(rows, *shape: int) -> tuple[np.ndarray, np.ndarray]:
    """(offsets, flat) of a list of lists: row r is flat[offsets[r] : offsets[r + 1]], items of ``shape``."""
    return row_offsets(rows), np.array([x for r in rows for x in r], dtype=np.int64).reshape(-1, *shape)


@functools.lru_cache(maxsize=32)
def _chi2_table(alpha: float, size: int) -> np.ndarray:
    # scipy.stats.chi2.ppf(q, dof) is 2·gammaincinv(dof/2, q), the same digits, without importing
    # scipy.stats (~0.4 s of every command's start-up)
    dof = np.arange(size)
    return np.where(dof > 0, 2.0 * gammaincinv(np.maximum(dof, 1) / 2, 1.0 - alpha), 0.0)


def chi2_gate(dof: int | np.ndarray, alpha: float) -> np.ndarray:
    """χ²(dof, 1 − α) quantile(s); dof 0 gives 0. Tabulated once per α (scipy's ppf costs ~0.4 ms a call)."""
    dof = np.asarray(dof, dtype=np.int64)
    size = max(256, 1 << int(dof.max(initial=0) + 1).bit_length())  # powers of two: few cache entries
    return _chi2_table(float(alpha), size)[dof]


@functools.lru_cache(maxsize=64)
def _gate_threshold(d: int, alpha: float) -> float:
    """``float(chi2_gate(d, alpha))``, kept: :func:`gate` asks it at every call."""
    return float(chi2_gate(d, alpha))


@functools.lru_cache(maxsize=64)
def _gate_ladder(d: int, capacity: int, alpha: float) -> np.ndarray:
    """``chi2_gate(d * np.arange(capacity + 2), alpha)``, kept (read-only: callers copy it)."""
    ladder = chi2_gate(d * np.arange(capacity + 2), alpha)
    ladder.flags.writeable = False
    return ladder


def scan_order(z: np.ndarray) -> list[int]:
    """Corner indices by increasing bearing atan2(y, x): the order a scan sweeps them."""
    return np.argsort(np.arctan2(z[:, 1], z[:, 0]), kind="stable").tolist() if len(z) else []


@dataclass
class Gated:
    """Individual compatibility of all m corners × n landmarks of one step.

    d : measurement dimension used (3, or 2 without φ);  alpha : significance level
    nu : (m, n, 3) innovations z_i − h_k, φ wrapped (all three components, even when d = 2)
    d2 : (m, n) individual D², ``inf`` where skipped by the Euclidean gate or S not positive definite
    candidates : m int arrays, the individually compatible landmarks of each corner by increasing D²
    hph : (n, 3, 3) H_k P H_kᵀ (zero for landmarks no corner came near)
    cand_flat : the candidate lists in one array (corner i's from row_offsets(candidates)[i] on)
    """

    z: np.ndarray
    C: np.ndarray
    pred: Prediction
    d: int
    alpha: float
    nu: np.ndarray
    d2: np.ndarray
    candidates: list[np.ndarray]
    hph: np.ndarray
    _universe: list[int] = field(default_factory=list, repr=False)
    _loc: dict[int, int] = field(default_factory=dict, repr=False)
    _blocks: np.ndarray | None = field(default=None, repr=False)  # (u, u, d, d) cross covariances
    _search: tuple | None = field(default=None, repr=False)  # search_arrays()
    cand_flat: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        self.cand_flat = np.concatenate([np.zeros(0, np.int64), *self.candidates]).astype(
            np.int64, copy=False
        )
        universe = np.unique(self.cand_flat)
        self._universe = universe.tolist()
        self._loc = {k: j for j, k in enumerate(self._universe)}

    def loc(self, k: int) -> int:
        """Position of landmark k in the universe of cross-covariance rows (added if new)."""
        j = self._loc.get(k)
        if j is None:  # outside every candidate list (e.g. a forced pairing): widen the universe
            j = len(self._universe)
            self._universe.append(k)
            self._loc[k] = j
            self._blocks = self._search = None
        return j

    def cross_row(self, k: int) -> np.ndarray:
        """(u, d, d) blocks H_l P H_kᵀ for every landmark l of the universe.

        The universe is the landmarks of all candidate lists: only those can enter a hypothesis. Its
        blocks are computed together, at the first row asked for (again when the universe widens).
        """
        return self.universe_blocks()[:, self._loc[k]]

    def universe_blocks(self) -> np.ndarray:
        """(u, u, d, d) blocks H_l P H_kᵀ of every two landmarks of the universe (computed once)."""
        if self._blocks is None:
            p, universe = self.pred, np.asarray(self._universe, dtype=np.int64)
            H_r, H_l = np.ascontiguousarray(p.H_r, dtype=float), np.ascontiguousarray(p.H_l, dtype=float)
            self._blocks = cross_blocks(p.P, H_r, H_l, universe, self.d)
        return self._blocks

    def search_arrays(self) -> tuple:
        """(nu, C, hph, blocks, loc_of, cand_off, cand_flat), what the compiled searches read
        (search_kernels.py): the universe's cross covariances (:meth:`universe_blocks`), loc_of[k] landmark
        k's position in the universe (−1 outside it: a search pairs only landmarks of the candidate
        lists), the candidate lists (:func:`row_offsets`, ``cand_flat``). Built once (again when the
        universe widens): only the searches ask, so ICNN's calls never build it."""
        if self._search is None:
            loc_of = np.full(len(self.hph), -1, dtype=np.int64)
            loc_of[self._universe] = np.arange(len(self._universe))
            self._search = (
                self.nu,
                self.C,
                self.hph,
                self.universe_blocks(),
                loc_of,
                row_offsets(self.candidates),
                self.cand_flat,
            )
        return self._search

    @property
    def m(self) -> int:
        return len(self.z)

    @property
    def n(self) -> int:
        return len(self.pred)

    @property
    def n_candidates(self) -> np.ndarray:
        return np.array([len(c) for c in self.candidates], dtype=np.int64)

    def nearest(self) -> np.ndarray:
        """(m,) ICNN choice: the compatible landmark of least D² per corner, −1 where none."""
        return np.array([c[0] if len(c) else -1 for c in self.candidates], dtype=np.int64)


def gate(z: np.ndarray, C: np.ndarray, pred: Prediction, cfg: AssociationConfig) -> Gated:
    """Innovations and individual D² of all m × n pairs, and each corner's candidate list.

    z : (m, 3) corners (x, y, φ), base frame;  C : (m, 3, 3) their covariances.
    """
    z = np.ascontiguousarray(z, dtype=float).reshape(-1, 3)
    C = np.ascontiguousarray(C, dtype=float).reshape(-1, 3, 3)
    m, d = len(z), 3 if cfg.use_phi else 2
    h, H_r, H_l = (np.ascontiguousarray(a, dtype=float) for a in (pred.h, pred.H_r, pred.H_l))
    nu, d2, hph = gate_pairs(z, C, h.reshape(-1, 3), pred.P, H_r, H_l, d, cfg.euclidean_gate, PIVOT_RTOL)
    threshold = _gate_threshold(d, float(cfg.alpha))
    # each row by increasing D² (stable: ties by landmark id); its first `count` entries pass the gate
    # (d2 holds no NaN: gate_pairs returns inf for those)
    order = np.argsort(d2, axis=1, kind="stable")
    count = (d2 < threshold).sum(axis=1).tolist()
    candidates = [order[i, : count[i]] for i in range(m)]
    return Gated(z, C, pred, d, cfg.alpha, nu, d2, candidates, hph)


class JointCompatibility:
    """Joint D² of a hypothesis grown and shrunk one pairing at a time (block Cholesky of S_H).

    Usage in a depth-first search::

        d2 = jc.try_add(i, k)              # D² of H ∪ {(i↔k)}, inf if S is not positive definite
        if d2 < jc.gate[jc.size + 1]:
            jc.commit(); ...recurse...; jc.pop()

    State: M_H = L_H⁻¹ (lower triangular, grown one block row per commit from the 3 × 3 factors, never by
    inverting a matrix) and y_H = M_H ν_H. ``try_add`` costs one product W = M_H S_{H,new} (d·h × d) and a
    3 × 3 Cholesky; ``commit`` appends the block row [−L_new⁻¹ Wᵀ M_H, L_new⁻¹]; ``pop`` just forgets
    rows. Both run compiled (kernels.py: ~25 µs a try in numpy calls, call overhead on these tiny
    operands, against a few µs).
    Cross covariances H_k P H_lᵀ are computed for the whole universe at the first row asked for (again
    when the universe widens) and cached by :meth:`Gated.cross_row`, so searches on the same ``Gated``
    share them.
    """

    def __init__(self, g: Gated, capacity: int):
        self.g = g
        d = g.d
        self.d = d
        self.capacity = capacity
        self.M = np.zeros((d * capacity, d * capacity))  # L_H⁻¹
        self.y = np.zeros(d * capacity)
        self.d2 = np.zeros(capacity + 1)  # d2[h] = joint D² of the first h committed pairings
        self.gate = _gate_ladder(d, capacity, float(g.alpha)).copy()  # gate[h] = χ²(d·h, 1 − α)
        self.corners = np.zeros(capacity, dtype=np.int64)
        self.landmarks = np.zeros(capacity, dtype=np.int64)
        self.locs = np.zeros(capacity, dtype=np.int64)  # landmark index into the row universe
        self.size = 0
        self._pending: tuple | None = None
        self._no_row = np.zeros((0, d, d))

    def try_add(self, i: int, k: int) -> float:
        """Joint D² of the committed hypothesis plus (i↔k); ``inf`` if the joint S is not PD."""
        g, d, h = self.g, self.d, self.size
        loc = g.loc(k)
        row = g.cross_row(k) if h else self._no_row  # blocks H_{k_a} P H_kᵀ of S_{H,new}
        S_new = g.hph[k, :d, :d] + g.C[i, :d, :d]
        inc, W, Minv, ynew = try_pairing(self.M, self.y, row, self.locs, S_new, g.nu[i, k, :d], h, PIVOT_RTOL)
        d2 = self.d2[h] + inc
        if not math.isfinite(d2):
            return math.inf
        self.d2[h + 1] = d2
        self.corners[h], self.landmarks[h], self.locs[h] = i, k, loc
        self._pending = (h, W, Minv, ynew)
        return d2

    def commit(self) -> None:
        """Keep the pairing of the last successful ``try_add``."""
        h, W, Minv, ynew = self._pending
        assert h == self.size, "commit() must follow a successful try_add()"
        commit_pairing(self.M, self.y, W, Minv, ynew, h)
        self._pending = None
        self.size += 1

    def pop(self, count: int = 1) -> None:
        self.size -= count
        self._pending = None

    @property
    def joint_d2(self) -> float:
        return float(self.d2[self.size])

    def pairs(self) -> list[tuple[int, int]]:
        return [(int(self.corners[a]), int(self.landmarks[a])) for a in range(self.size)]

    def arrays(self) -> tuple:
        """(M, y, d2, corners, landmarks, locs, gate), the state the compiled searches grow and shrink
        in place as try_add / commit do (search_kernels.py)."""
        return self.M, self.y, self.d2, self.corners, self.landmarks, self.locs, self.gate


def joint_d2_of(g: Gated, pairs: list[tuple[int, int]]) -> float:
    """Joint D² of a whole hypothesis by the incremental machinery; ``inf`` if S_H is not PD."""
    jc = JointCompatibility(g, max(len(pairs), 1))
    for i, k in pairs:
        if not math.isfinite(jc.try_add(i, k)):
            return math.inf
        jc.commit()
    return jc.joint_d2


def build_result(
    g: Gated,
    pairs: list[tuple[int, int]],
    joint_d2: float,
    nodes: int = 0,
    budget_hit: bool = False,
    extra: dict | None = None,
) -> AssociationResult:
    """The :class:`AssociationResult` of a hypothesis given as (corner, landmark) pairings."""
    assoc = np.full(g.m, -1, dtype=np.int64)
    d2 = np.full(g.m, np.nan)
    for i, k in pairs:
        assoc[i] = k
        d2[i] = g.d2[i, k]
    return AssociationResult(
        pairs=assoc,
        d2=d2,
        n_candidates=g.n_candidates,
        joint_d2=float(joint_d2) if pairs else 0.0,
        nodes=int(nodes),
        budget_hit=bool(budget_hit),
        extra=dict(extra or {}),
    )


def warm_up_problems() -> list[tuple[np.ndarray, np.ndarray, Prediction, AssociationConfig]]:
    """(z, C, pred, cfg) of the kernels' warm-up: two corners on two landmarks, with the state covariance
    a view of a larger buffer (the filter's, while it has spare capacity) and a whole array (full
    capacity), both gate settings, both dimensions."""
    h = np.array([[1.0, 0.0, 1.5], [0.0, 1.0, 1.5]])
    H = np.tile(np.eye(3), (2, 1, 1))
    C = np.tile(0.01 * np.eye(3), (2, 1, 1))
    configs = (AssociationConfig(), AssociationConfig(use_phi=False, euclidean_gate=0.0))
    return [(h, C, Prediction(h, -H, H, P), cfg) for P in (np.eye(12)[:9, :9], np.eye(9)) for cfg in configs]


def load_kernels() -> None:
    """Load (on a machine's first run: compile) the kernels of kernels.py now, so that the first timed
    association of a run does not pay it: a two-corner, two-landmark hypothesis tried and kept on each
    :func:`warm_up_problems` problem."""
    for z, C, pred, cfg in warm_up_problems():
        jc = JointCompatibility(gate(z, C, pred, cfg), 2)
        for i in range(2):
            jc.try_add(i, i)
            jc.commit()
