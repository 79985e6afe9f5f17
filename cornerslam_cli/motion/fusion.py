"""Fusion of the odometry increment with the scan match: never worse than the odometry it is given.

Each keyframe brings two estimates of the same increment (previous keyframe → this one, in the
previous keyframe's frame): the odometry's ``o`` with the noise model of the filter (``ekf.alpha*``,
Thrun §5.4) and the scan match's ``m`` with the covariance of its fit (motion/icp.py). The increment
handed to the filter is their information-weighted combination (a Kalman update of the odometry by the
match), with the combined covariance — in a featureless corridor the match is uncertain along the axis
and the odometry keeps it; with exact odometry the match hardly moves it.

**Both noise levels, and the odometry's bias, are learnt from the data.** A config cannot know whether
this robot's odometry is a drifting wheel encoder or already-corrected poses, and a fit's residuals
miss what makes real matches wrong (sparse beams, the map's own errors). The disagreements
d = m − o of the last ``adapt_window`` keyframes tell them apart because the two sources scale
differently: odometry noise grows with the motion (Σ_o from the α-model is large on long steps and
turns), the match's does not. The model is

    d ~ Student-t₄(−B(o)·c, k·Σ_o + s·Σ_m),  B(o)·c = (c_s·o_x, c_s·o_y, c_θ·|o_xy|)

with k the odometry's noise scale, s ≥ 1 the match's, c_s an odometer scale error and c_θ a heading
drift per metre (systematic errors that no noise scale absorbs: they add up along the path). k and s
maximise the likelihood (Nelder–Mead on log k, log s; c solved by weighted least squares inside,
re-weighted for the Student-t so that up to a few wrong matches do not move them); a drift term is
kept only when it is at least ``BIAS_SIGMAS`` standard errors from zero, and a scale error only when it is
also at least ``SCALE_MIN``: the matches have a scale error of their own along the direction of travel —
where few scan points face it (a corridor), ICP's increments fall short of the reference by ~1 %
(docs/results/reference_check.md: infinite-corridor-exact −0.98 % over its 912 such keyframes, −0.31 %
over the others) —, and over a window of such steps that shortfall is "significant": the 3σ rule alone
took a scale error out of infinite-corridor-exact's exact odometry at a quarter of its re-estimates
(median 0.43 %) and shrank its corridors with it (docs/results/scale_learnt.md). A real odometer's
scale error worth taking out is larger than what the matches themselves can be off by.

**Where the drift acts.** An odometry integrated along the path (wheel encoders at a high rate) drifts
*during* an increment of length L, so its direction of travel turns by c_θ·L/2 as well: B(o) gains the
sideways step c_θ·L/2·(−o_y, o_x) (:func:`bias_matrices`, ``along``). One whose drift is added to the
heading at each increment's end has none. Both models have the same two parameters; each is fitted at
every re-estimate and the along-the-path one is taken when its likelihood is higher by
``ALONG_EVIDENCE`` (the evidence the 3σ rule asks of a drift term: χ²₁ = 9, ΔNLL 4.5) — left out, it
biases c_θ (a simulated hall with a biased but noiseless odometry: 0.25 m ATE against 0.03 with it,
benchmarks/odometry_regimes.py). k and s are then scaled
together so that the median normalised disagreement is χ²₃'s (a Student-t's scale is smaller than
the covariance of the Gaussian core it is fitted to). Until ``adapt_min_samples``
keyframes have been seen the model itself is used (k = s = 1, no bias); then they are re-estimated
at every keyframe up to 2·``adapt_every`` samples, every ``adapt_every`` after that. Nothing here looks at a
reference trajectory.

**Gate.** Once the scales are learnt, a match whose disagreement with the corrected odometry exceeds the
χ²₃ ``gate`` under max(k, 1)·Σ_o + s·Σ_m is not taken on trust: the odometry increment is used alone
(counted as rejected) — unless the scans themselves clearly prefer the match (they fit the map better at
its pose than at the odometry's): then the odometry is the outlier (a wheel slip) and the match is used
alone. The gate keeps the configured model as a floor: real odometry errors are heavy-tailed (a wheel
slipping in a turn), and a scale learnt on the bulk of the increments would reject the true match of
such a turn.
"""

from __future__ import annotations

import copy
import math
from array import array
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from ..features.jit import kernel
from ..geometry import wrap_angle
from .params import ScanMatchConfig

NU = 4.0  # degrees of freedom of the Student-t: heavy tails, so a few wrong matches do not set the scales
IRLS = 4  # re-weighting passes
CHI2_3_MEDIAN = 2.365974  # median of χ² with 3 degrees of freedom
S_MAX = 1e4  # the match's covariance is inflated at most this much
BIAS_SIGMAS = 3.0  # a drift term is kept when it is this many standard errors from zero
# (not shrunk by 1 − se²/c² instead: 10 of the 15 panel logs worse, every exact one among them —
# docs/results/variant_bias_shrinkage_vs_50a4f18.md)
SCALE_MIN = 0.01  # a scale error is taken out from 1 %: the matches' own shortfall can reach it (docstring)
ALONG_EVIDENCE = BIAS_SIGMAS**2 / 2  # the drift along the path is taken when likelier by this (NLL)
SAMPLE = 24  # numbers a sample is kept as for the whole run: d (3), Σ_o (9), Σ_m (9), o (3)


@dataclass(frozen=True)
class Fused:
    inc: np.ndarray  # the increment handed to the filter (previous keyframe's frame)
    cov: np.ndarray  # its covariance (3, 3)
    accepted: bool  # False: the match failed the gate and the odometry increment was used alone
    gain: np.ndarray  # (3, 3) the weight the match got: inc = corrected odometry + gain·(m − it)


@dataclass(frozen=True)
class BiasTaken:
    """How one increment was fused, as far as taking a bias term out of it afterwards needs: the smoothed
    trajectory moves it by what it did not take (OdometryFusion.carry_back, graph/smooth.py
    ``recalibrated``)."""

    odom: np.ndarray  # (3,) the odometry increment
    keep: np.ndarray  # (3, 3) I − gain: the share of the corrected odometry in the increment

    def row(self) -> list[float]:
        """Its 12 numbers, flat (the hierarchy keeps one row per step)."""
        return [*self.odom, *self.keep.ravel()]


def nis(d: np.ndarray, S: np.ndarray) -> np.ndarray:
    """dᵢᵀ Sᵢ⁻¹ dᵢ for stacks d (n, 3), S (n, 3, 3)."""
    return np.einsum("ni,ni->n", d, np.linalg.solve(S, d[..., None])[..., 0])


class OdometryFusion:
    """Combines odometry and scan-match increments; learns the noise scales k, s and the bias c."""

    def __init__(self, cfg: ScanMatchConfig, whole_run: bool = False):
        self.gate, self.min_samples, self.every = cfg.gate, cfg.adapt_min_samples, cfg.adapt_every
        self.k_min, self.k_max = cfg.adapt_min, cfg.adapt_max
        self.k, self.s = 1.0, 1.0
        self.c = np.zeros(2)
        self.along = False  # the drift acts along each increment (module docstring), once the data say so
        self.samples: deque[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = deque(
            maxlen=cfg.adapt_window
        )
        self.n_rejected = 0
        self._since = 0
        self.n_steps = 0  # increments seen (:meth:`note_step`): fused, gated or fallen back to odometry
        # the step (trajectory.csv's) whose increment first had each bias term (scale, drift) taken out —
        # None: never yet (summary.json odometry_model: until then the odometry's share carried it)
        self.first_taken: list[int | None] = [None, None]
        # a term taken out and later dropped again (its 3σ test, or a scale error's SCALE_MIN, failed in a
        # later window): not held as a constant of this odometry, so graph.recalibrate does not carry it
        # back (:meth:`carry_back`)
        self.dropped = [False, False]
        # with ``whole_run``, every sample of the run, SAMPLE numbers each (d, Σ_o, Σ_m, o): the bias
        # fitted on all of them (:meth:`fit_whole_run`, graph.recalibrate's) — 192 bytes a keyframe
        self.every_sample = array("d") if whole_run else None
        self.whole_run_fit: tuple[np.ndarray, bool] | None = None  # (c, along) :meth:`fit_whole_run` found

    def corrected(self, o: np.ndarray) -> np.ndarray:
        """The odometry increment with the learnt scale error and drift taken out."""
        return o - bias_matrix(o, self.along) @ self.c

    def taken(self, o: np.ndarray, gain: np.ndarray) -> BiasTaken | None:
        """The increment ``o`` and the weight ``gain`` (Fused.gain) it was fused with; None unless this
        fusion keeps the whole run (``whole_run``: only graph.recalibrate reads it)."""
        if self.every_sample is None:
            return None
        return BiasTaken(np.array(o, dtype=float), np.eye(3) - gain)

    def fuse(
        self,
        o: np.ndarray,
        cov_o: np.ndarray,
        m: np.ndarray,
        cov_m: np.ndarray,
        scans_prefer_match: Callable[[], bool] | None = None,
    ) -> Fused:
        """The fused increment of odometry ``o`` (model covariance ``cov_o``) and match ``m``
        (covariance ``cov_m`` from its fit), both in the previous keyframe's frame.

        When the two disagree beyond the gate one of them is an outlier, and the scans decide which:
        ``scans_prefer_match`` (the scan fits the map clearly better at the match than at the
        odometry's pose) keeps the match alone — the odometry slipped —, otherwise the odometry is kept
        alone and the match is counted as rejected. (A callable: asked only past the gate.)"""
        d = m - o
        d[2] = wrap_angle(d[2])
        self.samples.append((d, cov_o, cov_m, np.array(o, dtype=float)))
        if self.every_sample is not None:
            self.every_sample.extend((*d, *np.ravel(cov_o), *np.ravel(cov_m), *o))
        self._since += 1
        if len(self.samples) >= self.min_samples and (
            self._since >= self.every or len(self.samples) < 2 * self.every
        ):
            self._learn()
            self._since = 0
        oc = self.corrected(o)
        dc = m - oc
        dc[2] = wrap_angle(dc[2])
        So, Sm = self.k * cov_o, self.s * cov_m
        S = So + Sm
        # the gate: the configured model (or the learnt scale, if larger) — a learnt k fits the bulk of
        # the increments and would reject the true match of a rare large odometry error
        score = float(dc @ np.linalg.solve(max(self.k, 1.0) * cov_o + Sm, dc))
        learnt = len(self.samples) >= self.min_samples  # before that, no basis to judge a match on
        if not np.isfinite(score) or (learnt and score > self.gate):
            if np.isfinite(score) and scans_prefer_match is not None and scans_prefer_match():
                return Fused(oc + dc, 0.5 * (Sm + Sm.T), True, np.eye(3))  # the odometry is the outlier
            self.n_rejected += 1  # the odometry alone, as uncertain as the gate's model
            return Fused(oc, self.fallback_cov(cov_o), False, np.zeros((3, 3)))
        K = So @ np.linalg.inv(S)  # Kalman gain of the odometry prior updated by the match
        inc = oc + K @ dc
        inc[2] = wrap_angle(inc[2])
        cov = (np.eye(3) - K) @ So
        return Fused(inc, 0.5 * (cov + cov.T), True, K)

    def note_step(self) -> None:
        """One more increment went out, with the bias as it stands (ScanMatcher.step, after the first
        scan): counted; the first step each term was taken out of, noted; a term taken before but not
        now, marked dropped."""
        self.n_steps += 1
        for i in range(2):
            if self.c[i] != 0.0:
                self.first_taken[i] = self.first_taken[i] or self.n_steps
            self.dropped[i] = self.dropped[i] or bool(self.first_taken[i] is not None and self.c[i] == 0.0)

    def fallback_cov(self, cov_o: np.ndarray) -> np.ndarray:
        """Covariance of an odometry increment used without a match: the configured model at least."""
        return max(self.k, 1.0) * cov_o

    def fit_whole_run(self) -> tuple[np.ndarray, bool]:
        """The bias terms c and model ``along`` fitted once on every sample of the run instead of the last
        ``adapt_window`` (what :meth:`carry_back` carries back: one robot's odometry bias is taken as
        constant, and the whole run estimates it best); fewer than ``adapt_min_samples`` samples: the bias
        learnt so far. Also kept as ``whole_run_fit`` (summary.json reads it); this fusion's own state is
        left as it was. Needs ``whole_run`` (ValueError)."""
        if self.every_sample is None:
            raise ValueError("fit_whole_run: this fusion was made without whole_run, it kept no samples")
        rows = np.frombuffer(self.every_sample).reshape(-1, SAMPLE)
        fit = copy.copy(self)
        if len(rows) >= self.min_samples:
            So, Sm = rows[:, 3:12].reshape(-1, 3, 3), rows[:, 12:21].reshape(-1, 3, 3)
            fit._fit(rows[:, :3], So, Sm, rows[:, 21:])
        self.whole_run_fit = (fit.c.copy(), bool(fit.along))
        return self.whole_run_fit

    def carry_back(self, taken: np.ndarray) -> np.ndarray:
        """(n, 3) how far each step's increment moves (graph.recalibrate) when the bias terms it was fused
        without — the learner had not yet taken them out: the steps before ``first_taken`` — are taken out
        as fitted on the whole run (:meth:`fit_whole_run`, run here): only terms the whole run holds and
        that, once taken, the learner never dropped again (a term that comes and goes is no constant of
        the odometry: exact odometry's disagreement with the scans along one stretch). ``taken``: the
        steps' BiasTaken rows (n, 12; row k = trajectory.csv step k; zeros: it took none). An increment
        inc = (I − K)·(o − B(o)·c) + K·m moves by −(I − K)·B(o)·c_added."""
        c, along = self.fit_whole_run()
        B = bias_matrices(taken[:, :3], along)
        step = np.arange(len(taken))
        added = np.zeros((len(taken), 3))
        for i in range(2):
            first = self.first_taken[i]
            if first is None or self.dropped[i]:  # (a term the whole run does not hold has c[i] = 0)
                continue
            before = step < first
            added[before] += B[before, :, i] * c[i]
        return -np.einsum("nij,nj->ni", taken[:, 3:].reshape(-1, 3, 3), added)

    def _learn(self) -> None:
        """Re-estimate the scales and bias on the window's samples."""
        self._fit(*(np.array([x[i] for x in self.samples]) for i in range(4)))

    def _fit(self, d: np.ndarray, So: np.ndarray, Sm: np.ndarray, o: np.ndarray) -> None:
        """Set k, s, c and the drift model from disagreements d (n, 3), the odometry's and the matches'
        covariances So, Sm (n, 3, 3) and the odometry increments o (n, 3) (module docstring)."""
        lo = np.array([np.log(self.k_min), 0.0])
        hi = np.array([np.log(self.k_max), np.log(S_MAX)])
        x0 = np.clip(np.log([self.k, self.s]), lo, hi)
        fits = {}  # drift along the path or not: (the likelihood's minimum, log k and log s there, B)
        for along in (False, True):
            B = bias_matrices(o, along)

            def cost(v: np.ndarray, B: np.ndarray = B) -> float:
                v = np.clip(v, lo, hi)
                return student_fit(d, np.exp(v[0]) * So + np.exp(v[1]) * Sm, B)[0]

            res = optimize.minimize(
                cost, x0, method="Nelder-Mead", options={"xatol": 0.05, "fatol": 1e-3, "maxiter": 80}
            )
            fits[along] = (float(res.fun), np.clip(res.x, lo, hi), B)
        self.along = fits[False][0] - fits[True][0] > ALONG_EVIDENCE
        _, v, B = fits[self.along]
        k, s = float(np.exp(v[0])), float(np.exp(v[1]))
        _, c, se = student_fit(d, k * So + s * Sm, B)
        self.c = np.where((np.abs(c) >= BIAS_SIGMAS * se) & (np.abs(c) >= (SCALE_MIN, 0.0)), c, 0.0)
        # a Student-t's scale is not the covariance of a Gaussian core: rescale both so the median
        # normalised disagreement is χ²₃'s (robust to the tail the Student-t was there to ignore)
        r = d + np.einsum("nij,j->ni", B, self.c)
        q = nis(r, k * So + s * Sm)
        g = float(np.median(q)) / CHI2_3_MEDIAN
        self.k = float(np.clip(k * g, self.k_min, self.k_max))
        self.s = float(np.clip(s * g, 1.0, S_MAX))


def bias_matrix(o: np.ndarray, along: bool = False) -> np.ndarray:
    """B (3, 2) with B·(c_s, c_θ) the increment error of an odometer scale error c_s and a heading
    drift c_θ per metre travelled (``along``: acting along the increment; :func:`bias_matrices`)."""
    return bias_matrices(np.asarray(o, dtype=float)[None], along)[0]


def bias_matrices(o: np.ndarray, along: bool) -> np.ndarray:
    """(n, 3, 2) the B of each increment of ``o`` (n, 3): B·(c_s, c_θ) = (c_s·o_x, c_s·o_y, c_θ·L),
    L = |o_xy|, plus with ``along`` the sideways step c_θ·L/2·(−o_y, o_x) of a drift that turns the
    heading during the increment (its direction of travel turns by half of it, to first order)."""
    L = np.hypot(o[:, 0], o[:, 1])
    half = 0.5 * L if along else np.zeros_like(L)
    B = np.zeros((len(o), 3, 2))
    B[:, 0, 0], B[:, 1, 0], B[:, 2, 1] = o[:, 0], o[:, 1], L
    B[:, 0, 1], B[:, 1, 1] = -half * o[:, 1], half * o[:, 0]
    return B


def student_fit(d: np.ndarray, S: np.ndarray, B: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Negative Student-t log likelihood of d (n, 3) with covariances S (n, 3, 3) and mean −B·c, c
    (2,) by iteratively re-weighted least squares, and the standard errors of c."""
    c, se = np.empty(2), np.empty(2)
    nll = _student_fit(np.ascontiguousarray(d, dtype=float), np.ascontiguousarray(S, dtype=float),
                       np.ascontiguousarray(B, dtype=float), c, se)  # fmt: skip
    return nll, c, se


@kernel
def _student_fit(d, S, B, c, se):
    """:func:`student_fit` in loops (Numba; it runs ~35 times a re-estimate, on up to ``adapt_window``
    samples): fill c and se, return the negative log likelihood. Each S is inverted by its cofactors
    (3 × 3, symmetric positive definite); a singular one gives an infinite likelihood cost (and c = 0)."""
    n = len(d)
    Sinv = np.empty((n, 3, 3))
    A0 = np.zeros((n, 2, 2))  # Bᵀ S⁻¹ B
    b0 = np.zeros((n, 2))  # Bᵀ S⁻¹ d
    logdet = 0.0
    for t in range(n):
        det = _inverse3(S[t], Sinv[t])
        if not det > 0.0:
            c[:], se[:] = 0.0, np.inf  # no bias to learn from it
            return np.inf
        logdet += math.log(det)
        for j in range(2):
            for a in range(3):
                BtS = B[t, 0, j] * Sinv[t, 0, a] + B[t, 1, j] * Sinv[t, 1, a] + B[t, 2, j] * Sinv[t, 2, a]
                b0[t, j] += BtS * d[t, a]
                for l in range(2):
                    A0[t, j, l] += BtS * B[t, a, l]
    w = np.ones(n)
    q = np.zeros(n)
    A = np.zeros((2, 2))
    for _ in range(IRLS):
        A[:] = 0.0
        rhs0 = rhs1 = 0.0
        for t in range(n):
            A += w[t] * A0[t]
            rhs0 -= w[t] * b0[t, 0]
            rhs1 -= w[t] * b0[t, 1]
        A[0, 0] += 1e-12
        A[1, 1] += 1e-12
        det = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
        c[0] = (A[1, 1] * rhs0 - A[0, 1] * rhs1) / det
        c[1] = (A[0, 0] * rhs1 - A[1, 0] * rhs0) / det
        for t in range(n):
            q[t] = max(_residual_nis(d[t], B[t], c, Sinv[t]), 0.0)
            w[t] = (NU + 3.0) / (NU + q[t])
    se[0] = math.sqrt(max(A[1, 1] / det, 0.0))
    se[1] = math.sqrt(max(A[0, 0] / det, 0.0))
    return 0.5 * logdet + 0.5 * (NU + 3.0) * np.sum(np.log1p(q / NU))


@kernel
def _residual_nis(d, B, c, Sinv):
    """rᵀ S⁻¹ r of the residual r = d + B·c of one sample."""
    r0 = d[0] + B[0, 0] * c[0] + B[0, 1] * c[1]
    r1 = d[1] + B[1, 0] * c[0] + B[1, 1] * c[1]
    r2 = d[2] + B[2, 0] * c[0] + B[2, 1] * c[1]
    return (
        r0 * (Sinv[0, 0] * r0 + Sinv[0, 1] * r1 + Sinv[0, 2] * r2)
        + r1 * (Sinv[1, 0] * r0 + Sinv[1, 1] * r1 + Sinv[1, 2] * r2)
        + r2 * (Sinv[2, 0] * r0 + Sinv[2, 1] * r1 + Sinv[2, 2] * r2)
    )


@kernel
def _inverse3(M, out):
    """Fill ``out`` with the inverse of the 3 × 3 ``M`` (adjugate / determinant); return the determinant
    (``out`` untouched when it is not positive)."""
    c00 = M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1]
    c01 = M[1, 2] * M[2, 0] - M[1, 0] * M[2, 2]
    c02 = M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0]
    det = M[0, 0] * c00 + M[0, 1] * c01 + M[0, 2] * c02
    if not det > 0.0:
        return det
    out[0, 0], out[1, 0], out[2, 0] = c00 / det, c01 / det, c02 / det
    out[0, 1] = (M[0, 2] * M[2, 1] - M[0, 1] * M[2, 2]) / det
    out[1, 1] = (M[0, 0] * M[2, 2] - M[0, 2] * M[2, 0]) / det
    out[2, 1] = (M[0, 1] * M[2, 0] - M[0, 0] * M[2, 1]) / det
    out[0, 2] = (M[0, 1] * M[1, 2] - M[0, 2] * M[1, 1]) / det
    out[1, 2] = (M[0, 2] * M[1, 0] - M[0, 0] * M[1, 2]) / det
    out[2, 2] = (M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0]) / det
    return det
