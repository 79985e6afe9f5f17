"""EKF-SLAM over natural corners with the paper's block-matrix update (NOTES §5, eq 18–32).

State μ = [x, y, θ, m1x, m1y, m1φ, …] and covariance Σ live in preallocated buffers that double when
full, so adding a landmark costs amortised O(N); ``mu`` and ``P`` are views of the live part (a view
taken before :meth:`Ekf.augment` may point to the old buffer afterwards: take it again).

Costs per call, N landmarks, k matched corners:
- :meth:`predict`: O(N), only Σ_rr and the robot rows/columns Σ_rm change (eq 22).
- :meth:`update`: per pair ΣHᵀ = A_0 H_rᵀ + A_k H_kᵀ from two column blocks, S 3×3, Cholesky (eq 28–31),
  O(N) each, and the rank-3 terms Σ ← Σ − (ΣHᵀ)S⁻¹(ΣHᵀ)ᵀ applied to Σ in one O(N²) pass per call
  (``fuse``) or one per pair; ``batched`` stacks all k pairs into one rank-3k update.
- :meth:`augment`: O(N) per new landmark.

Σ is kept *exactly* symmetric: every O(N²) write computes the upper triangle in row panels and
mirrors it into the lower one, prediction and augmentation write cross blocks as transposes.

Over 400 lines because it is the one class that owns μ and Σ: predict, the block update and
augment share the buffers and the symmetric panel writes.
"""

from __future__ import annotations

import numpy as np

from ..errors import NumericalError
from ..geometry import rotate_pose_covariance, wrap_angle
from ..types import Prediction
from .kernels import sequential_update
from .models import (
    inverse_observe,
    motion_model,
    motion_noise,
    observe,
    observe_one,
    odometry_increment,
)
from .params import EkfConfig

_PANEL = 128  # rows per panel of the O(N²) passes: a panel of Σ and its product stay in cache
# state columns of the robot and of landmark k: _ROBOT_AND_LANDMARK + _LANDMARK_OFFSET * k
_ROBOT_AND_LANDMARK = np.array([0, 1, 2, 3, 4, 5])
_LANDMARK_OFFSET = np.array([0, 0, 0, 3, 3, 3])


class Ekf:
    """EKF-SLAM filter: the only mutable state of cornerslam (STYLE: filter/ekf.py).

    >>> ekf = Ekf(EkfConfig(), pose0=(0.0, 0.0, 0.0))
    >>> ekf.predict(odom_prev, odom_cur)            # odometry poses (x, y, θ) of two keyframes
    >>> pred = ekf.predict_observations()           # for the associator
    >>> ekf.update(ids, z[matched], C[matched])     # z base frame (k, 3), C (k, 3, 3)
    >>> new_ids = ekf.augment(z[new], C[new])
    >>> ekf.check_health(step)
    """

    def __init__(self, cfg: EkfConfig | None = None, pose0=(0.0, 0.0, 0.0)):
        self.cfg = cfg if cfg is not None else EkfConfig()
        cap = 3 + 3 * self.cfg.initial_capacity
        self._mu_buf = np.zeros(cap)
        self._P_buf = np.zeros((cap, cap))
        self._dim = 3
        self._mu_buf[:3] = np.asarray(pose0, dtype=float)
        self._mu_buf[2] = wrap_angle(self._mu_buf[2])
        s_xy, s_th = self.cfg.init_sigma_xy, self.cfg.init_sigma_theta
        self._P_buf[:3, :3] = np.diag([s_xy**2, s_xy**2, s_th**2])
        self.last_nis = 0.0  # νᵀS⁻¹ν of the last update() (sum over its sequential pairs)
        # tentative-landmark bookkeeping (cfg.tentative_sightings > 1): sightings and last keyframe seen
        self.n_steps = 0  # predict() calls so far
        self._n_obs = np.zeros(self.cfg.initial_capacity, dtype=np.int64)
        self._last_seen = np.zeros(self.cfg.initial_capacity, dtype=np.int64)

    @classmethod
    def from_state(cls, cfg: EkfConfig, mu: np.ndarray, P: np.ndarray) -> Ekf:
        """A filter holding a given state mean (3 + 3n,) and covariance (3 + 3n, 3 + 3n) (copied)."""
        mu = np.asarray(mu, dtype=float).reshape(-1)
        P = np.asarray(P, dtype=float)
        d = len(mu)
        if d < 3 or (d - 3) % 3 or P.shape != (d, d):
            raise ValueError(f"from_state: mu {mu.shape} and P {P.shape} are not a (3 + 3n) state")
        ekf = cls(cfg, pose0=mu[:3])
        ekf._reserve(d)
        ekf._dim = d
        ekf._mu_buf[:d] = mu
        ekf._P_buf[:d, :d] = 0.5 * (P + P.T)
        ekf._n_obs[: ekf.n_landmarks] = cfg.tentative_sightings  # given landmarks count as confirmed
        return ekf

    # ------------------------------------------------------------------ views
    @property
    def mu(self) -> np.ndarray:
        """(3 + 3n,) state mean, a view of the live buffer."""
        return self._mu_buf[: self._dim]

    @property
    def P(self) -> np.ndarray:
        """(3 + 3n, 3 + 3n) state covariance Σ, a view of the live buffer (treat as read only)."""
        return self._P_buf[: self._dim, : self._dim]

    @property
    def pose(self) -> np.ndarray:
        """(3,) robot pose (x, y, θ) in the map frame (a copy)."""
        return self._mu_buf[:3].copy()

    @property
    def n_landmarks(self) -> int:
        return (self._dim - 3) // 3

    @property
    def landmarks(self) -> np.ndarray:
        """(n, 3) landmarks (x, y, φ), map frame, a view of the live buffer."""
        return self._mu_buf[3 : self._dim].reshape(-1, 3)

    @property
    def capacity(self) -> int:
        """Landmarks the current buffers hold before they are reallocated."""
        return (len(self._mu_buf) - 3) // 3

    # ------------------------------------------------------------------ prediction (eq 19–22)
    def predict(
        self,
        odom_prev: np.ndarray,
        odom_cur: np.ndarray,
        cov: np.ndarray | None = None,
    ) -> np.ndarray:
        """Move the robot by the odometry between two keyframe poses (x, y, θ); O(N).

        ``cov``: the covariance (3, 3) of this increment in the frame of ``odom_prev`` (the fused
        increments of motion/ bring their own); None: the odometry noise model ``ekf.alpha1..4`` with
        the floor ``ekf.min_sigma_xy/theta``. Returns the increment (rot1, trans, rot2) applied.
        """
        cfg = self.cfg
        u = odometry_increment(odom_prev, odom_cur, cfg.pure_rotation_eps, cfg.reverse_motion)
        pose_new, G, _ = motion_model(self._mu_buf[:3], u)
        if cov is None:
            R = motion_noise(u, self._mu_buf[2], cfg.alphas, cfg.min_sigma_xy, cfg.min_sigma_theta)
        else:  # rotated from the robot's frame into the map's
            R = rotate_pose_covariance(cov, float(self._mu_buf[2]))
        P, d = self._P_buf, self._dim
        P_rr = G @ P[:3, :3] @ G.T + R  # eq 22, robot block
        P[:3, :3] = 0.5 * (P_rr + P_rr.T)
        if d > 3:
            P_rm = G @ P[:3, 3:d]  # eq 22, robot–map cross covariance
            P[:3, 3:d] = P_rm
            P[3:d, :3] = P_rm.T
        self._mu_buf[:3] = pose_new
        self.n_steps += 1
        return np.array(u)

    def inflate_pose(self, sigma_xy: float, sigma_theta: float) -> None:
        """Σ_rr += diag(σ_xy², σ_xy², σ_θ²): robot motion the odometry cannot tell (a jump); O(1)."""
        self._P_buf[:3, :3] += np.diag([sigma_xy**2, sigma_xy**2, sigma_theta**2])

    # ------------------------------------------------------------------ observation (NOTES §4)
    def predict_observations(self) -> Prediction:
        """Predicted measurements h, Jacobians H_r, H_l of all n landmarks and the live Σ; O(n)."""
        h, H_r, H_l = observe(self._mu_buf[:3], self.landmarks)
        return Prediction(h=h, H_r=H_r, H_l=H_l, P=self.P)

    # ------------------------------------------------------------------ correction (eq 23–32)
    def update(self, landmark_ids, z, C) -> float:
        """Correct with k matched corners: landmark_ids (k,) int, z (k, 3) base frame, C (k, 3, 3).

        ``cfg.update``: "sequential" applies the paper's block update pair by pair, re-linearising at
        the updated mean; "batched" applies one update with the stacked H (3k × dim), linearised once.
        Returns the summed normalised innovation squared νᵀS⁻¹ν (also kept in ``last_nis``).
        """
        ids, z, C = self._check_pairs(landmark_ids, z, C)
        if len(ids) == 0:
            self.last_nis = 0.0
            return 0.0
        if self.cfg.update == "batched":
            U, Y, nis = self._batched_terms(ids, z, C)
            self._apply_low_rank(U, Y)
        else:
            nis = self._sequential(ids, z, C)
        self._mu_buf[2] = wrap_angle(self._mu_buf[2])
        np.add.at(self._n_obs, ids, 1)
        self._last_seen[ids] = self.n_steps
        self.last_nis = float(nis)
        return self.last_nis

    def _sequential(self, ids: np.ndarray, z: np.ndarray, C: np.ndarray) -> float:
        """Per pair: eq 30 (ΣHᵀ from two column blocks), eq 31 (S), eq 23/28 (μ, Σ).

        With ``fuse`` the rank-3 terms wait in (U, Y) and are applied to Σ in one pass at the end;
        each pair reads its 6 columns of the current Σ as Σ[:, cols] − U Yᵀ[cols] (exact, O(N·rank)).
        """
        P, mu, d = self._P_buf[: self._dim, : self._dim], self._mu_buf, self._dim
        fuse = self.cfg.fuse
        if fuse and not self.cfg.joseph:  # the defaults: compiled (filter/kernels.py)
            U = np.empty((d, 3 * len(ids)))
            nis, failed = sequential_update(P, mu, ids, np.ascontiguousarray(z), np.ascontiguousarray(C), U)
            if failed >= 0:
                raise self._not_positive_definite()
            self._apply_low_rank(U, U)
            return nis
        width = 6 if self.cfg.joseph else 3
        if fuse:
            U = np.empty((d, width * len(ids)))
            Y = np.empty_like(U) if self.cfg.joseph else U  # standard form: U Yᵀ = V Vᵀ
        r = 0  # pending rank
        nis = 0.0
        for k, z_i, C_i in zip(ids.tolist(), z, C, strict=True):
            cols = _ROBOT_AND_LANDMARK + _LANDMARK_OFFSET * k
            A = P[:, cols]  # (d, 6) column blocks A_0, A_k of eq 29 (a copy)
            if r:
                A -= U[:, :r] @ Y[cols, :r].T  # the same columns of Σ with the pending terms applied
            h, H = observe_one(mu[:3], mu[3 + 3 * k : 6 + 3 * k])  # H (3, 6): eq 26's non-zero blocks
            PHt = A @ H.T  # eq 30: A_0 H_rᵀ + A_k H_kᵀ, (d, 3)
            S = H @ PHt[cols] + C_i  # eq 31
            nu = z_i - h
            nu[2] = wrap_angle(nu[2])
            U_i, Y_i, nis_i = self._gain_terms(PHt, 0.5 * (S + S.T), nu[:, None], mu, d)
            nis += nis_i
            if fuse:
                U[:, r : r + width] = U_i
                if Y is not U:
                    Y[:, r : r + width] = Y_i
                r += width
            else:
                self._apply_low_rank(U_i, Y_i)
        if r:
            self._apply_low_rank(U[:, :r], Y[:, :r])
        return nis

    def _batched_terms(self, ids: np.ndarray, z: np.ndarray, C: np.ndarray):
        """One update with the stacked H of all k pairs: ΣHᵀ (d, 3k) still from column blocks."""
        P, mu, d = self._P_buf[: self._dim, : self._dim], self._mu_buf, self._dim
        k = len(ids)
        h, H_r, H_l = observe(mu[:3], mu[3 : self._dim].reshape(-1, 3)[ids])
        lcols = 3 + 3 * ids[:, None] + np.arange(3)  # (k, 3) state indices of the landmarks
        A_l = P[:, lcols.ravel()].reshape(d, k, 3).transpose(1, 0, 2)  # (k, d, 3)
        PHt = P[:, :3] @ H_r.transpose(0, 2, 1) + A_l @ H_l.transpose(0, 2, 1)  # (k, d, 3), eq 30
        PHt = PHt.transpose(1, 0, 2).reshape(d, 3 * k)
        # S = H Σ Hᵀ + C: row block i is H_r,i (ΣHᵀ)[robot] + H_l,i (ΣHᵀ)[landmark i]
        S = H_r @ PHt[:3] + H_l @ PHt[lcols]  # (k, 3, 3k)
        S = S.reshape(3 * k, 3 * k)
        S[np.arange(3 * k)[:, None] // 3 == np.arange(3 * k)[None, :] // 3] += C.ravel()
        nu = z - h
        nu[:, 2] = wrap_angle(nu[:, 2])
        return self._gain_terms(PHt, 0.5 * (S + S.T), nu.reshape(-1, 1), mu, d)

    def _gain_terms(self, PHt: np.ndarray, S: np.ndarray, nu: np.ndarray, mu: np.ndarray, d: int):
        """Mean update (eq 23, in place) and the low-rank covariance term Σ ← Σ − U Yᵀ (eq 28).

        Standard: U = Y = ΣHᵀ L⁻ᵀ with S = L Lᵀ, so U Yᵀ = (ΣHᵀ) S⁻¹ (ΣHᵀ)ᵀ = K (ΣHᵀ)ᵀ.
        Joseph: (I−KH)Σ(I−KH)ᵀ + KCKᵀ = Σ − WKᵀ − KWᵀ + KSKᵀ with W = ΣHᵀ, i.e. U = [W, K],
        Y = [K, W − KS] (rank 6 per pair).
        """
        try:
            L = np.linalg.cholesky(S)  # S = L Lᵀ
        except np.linalg.LinAlgError:
            raise self._not_positive_definite() from None
        B = np.linalg.solve(L, np.hstack((nu, PHt.T)))  # L⁻¹ [ν, (ΣHᵀ)ᵀ]
        a = B[:, :1]  # L⁻¹ν
        V = B[:, 1:].T  # ΣHᵀ L⁻ᵀ, (d, r)
        mu[:d] += (V @ a).ravel()  # eq 23: μ += K ν = ΣHᵀ S⁻¹ ν = V L⁻¹ν
        nis = float((a * a).sum())  # νᵀS⁻¹ν
        if self.cfg.joseph:
            K = np.linalg.solve(L.T, B[:, 1:]).T  # eq 25, K = ΣHᵀ S⁻¹ = V L⁻¹ (solve, never inv)
            return np.hstack((PHt, K)), np.hstack((K, PHt - K @ S)), nis
        return V, V, nis

    def _not_positive_definite(self) -> NumericalError:
        return NumericalError(  # n_steps = predictions so far = the pipeline's step index
            f"innovation covariance S is not positive definite at step {self.n_steps}",
            "corner covariances or Σ are corrupt; check the corner extractor's covariances",
        )

    def _apply_low_rank(self, U: np.ndarray, Y: np.ndarray) -> None:
        """Σ ← Σ − U Yᵀ in place, O(N²·rank), U Yᵀ symmetric by construction.

        Row panels of the upper triangle are computed once and mirrored into the lower triangle, so
        Σ stays bitwise symmetric without a separate symmetrisation pass.
        """
        P, d = self._P_buf[: self._dim, : self._dim], self._dim
        for i in range(0, d, _PANEL):
            e = min(i + _PANEL, d)
            T = U[i:e] @ Y[i:].T  # rows i:e, columns i: (diagonal tile and the panel right of it)
            D = T[:, : e - i]
            P[i:e, i:e] -= 0.5 * (D + D.T)
            if e < d:
                R = T[:, e - i :]
                P[i:e, e:] -= R
                P[e:, i:e] -= R.T

    def _check_pairs(self, landmark_ids, z, C):
        ids = np.asarray(landmark_ids, dtype=np.int64).reshape(-1)
        z = np.asarray(z, dtype=float).reshape(-1, 3)
        C = np.asarray(C, dtype=float).reshape(-1, 3, 3)
        if not (len(ids) == len(z) == len(C)):
            raise ValueError(f"update: {len(ids)} ids, {len(z)} measurements, {len(C)} covariances")
        n = self.n_landmarks
        if len(ids) and (ids.min() < 0 or ids.max() >= n):
            raise ValueError(f"update: landmark ids must be in [0, {n}), got {ids.tolist()}")
        return ids, z, C

    # ------------------------------------------------------------------ new landmarks
    def augment(self, z, C) -> np.ndarray:
        """Add k landmarks from unmatched corners z (k, 3) base frame, C (k, 3, 3); O(N) each.

        m_xy = p + R(θ) z_xy, m_φ = z_φ; Σ_new,· = G_r Σ_r,·, Σ_new,new = G_r Σ_rr G_rᵀ + G_z C G_zᵀ.
        Returns the new landmark ids (k,).
        """
        z = np.asarray(z, dtype=float).reshape(-1, 3)
        C = np.asarray(C, dtype=float).reshape(-1, 3, 3)
        if len(z) != len(C):
            raise ValueError(f"augment: {len(z)} measurements, {len(C)} covariances")
        k, d = len(z), self._dim
        n0 = self.n_landmarks
        if k == 0:
            return np.zeros(0, dtype=np.int64)
        self._reserve(d + 3 * k)
        mu, P = self._mu_buf, self._P_buf
        m, G_r, G_z = inverse_observe(mu[:3], z)
        G_rs = G_r.reshape(3 * k, 3)  # stacked robot Jacobians of the k landmarks
        X = G_rs @ P[:3, :d]  # (3k, d) cross covariance new–old
        P_nn = X[:, :3] @ G_rs.T  # (3k, 3k) G_r,i Σ_rr G_r,jᵀ
        P_nn = 0.5 * (P_nn + P_nn.T)
        blocks = G_z @ C @ G_z.transpose(0, 2, 1)
        for i in range(k):
            b = 0.5 * (blocks[i] + blocks[i].T)
            P_nn[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] += b
        dn = d + 3 * k
        P[d:dn, :d] = X
        P[:d, d:dn] = X.T
        P[d:dn, d:dn] = P_nn
        mu[d:dn] = m.ravel()
        self._dim = dn
        self._n_obs[n0 : n0 + k] = 1
        self._last_seen[n0 : n0 + k] = self.n_steps
        return np.arange(n0, n0 + k, dtype=np.int64)

    def _reserve(self, dim: int) -> None:
        """Make the buffers hold ``dim`` state entries, doubling the capacity (amortised O(N))."""
        cap = len(self._mu_buf)
        if dim <= cap:
            return
        new_cap = max(dim, 2 * cap - 3)
        d = self._dim
        mu_buf = np.zeros(new_cap)
        P_buf = np.zeros((new_cap, new_cap))
        mu_buf[:d] = self._mu_buf[:d]
        P_buf[:d, :d] = self._P_buf[:d, :d]
        self._mu_buf, self._P_buf = mu_buf, P_buf
        n_cap = (new_cap - 3) // 3
        self._n_obs = np.resize(self._n_obs, n_cap)
        self._last_seen = np.resize(self._last_seen, n_cap)

    # ------------------------------------------------------------------ tentative landmarks
    @property
    def n_obs(self) -> np.ndarray:
        """(n,) times each landmark was seen (creation counts as one), a view."""
        return self._n_obs[: self.n_landmarks]

    @property
    def tentative(self) -> np.ndarray:
        """(n,) bool, landmarks seen fewer than ``cfg.tentative_sightings`` times (all False when 1)."""
        return self.n_obs < self.cfg.tentative_sightings

    def remove_landmarks(self, landmark_ids) -> np.ndarray:
        """Marginalise landmarks out of the state (delete their rows/columns of μ, Σ); O(N²).

        Returns remap (n_old,): the new id of each old landmark, -1 for the removed ones. The
        remaining landmarks keep their order.
        """
        n = self.n_landmarks
        ids = np.unique(np.asarray(landmark_ids, dtype=np.int64).reshape(-1))
        if len(ids) and (ids[0] < 0 or ids[-1] >= n):
            raise ValueError(f"remove_landmarks: ids must be in [0, {n}), got {ids.tolist()}")
        keep_l = np.setdiff1d(np.arange(n), ids)
        remap = -np.ones(n, dtype=np.int64)
        remap[keep_l] = np.arange(len(keep_l))
        if len(ids) == 0:
            return remap
        keep = np.concatenate((np.arange(3), (3 + 3 * keep_l[:, None] + np.arange(3)).ravel()))
        d = len(keep)
        self._P_buf[:d, :d] = self.P[np.ix_(keep, keep)]
        self._mu_buf[:d] = self.mu[keep]
        self._n_obs[: len(keep_l)] = self._n_obs[keep_l]
        self._last_seen[: len(keep_l)] = self._last_seen[keep_l]
        self._dim = d
        return remap

    def prune_tentative(self) -> np.ndarray:
        """Drop tentative landmarks not seen for more than ``cfg.tentative_max_age`` keyframes.

        Call once per step after update/augment. Returns the remap of :meth:`remove_landmarks`
        (identity when nothing is dropped or the tentative stage is off).
        """
        n = self.n_landmarks
        if self.cfg.tentative_sightings <= 1 or n == 0:
            return np.arange(n, dtype=np.int64)
        age = self.n_steps - self._last_seen[:n]
        stale = np.flatnonzero(self.tentative & (age > self.cfg.tentative_max_age))
        return self.remove_landmarks(stale)

    # ------------------------------------------------------------------ health
    def check_health(self, step: int) -> None:
        """Raise NumericalError naming ``step`` if μ or Σ is non-finite, Σ asymmetric or diag Σ < 0.

        One O(N²) read of Σ (row panels against their mirrored column panels).
        """
        mu, P, d = self.mu, self.P, self._dim
        hint = "the filter diverged; check odometry, corner covariances and the EKF noise settings"
        if not np.isfinite(mu).all():
            bad = np.flatnonzero(~np.isfinite(mu))[:5].tolist()
            raise NumericalError(f"EKF state mean is not finite at step {step} (entries {bad})", hint)
        # one pass: row panel i:e of the upper triangle against its mirror; the panels cover all of Σ,
        # so a non-finite entry anywhere makes the difference non-finite
        asym = 0.0
        for i in range(0, d, _PANEL):
            e = min(i + _PANEL, d)
            a = float(np.abs(P[i:e, i:] - P[i:, i:e].T).max())
            if not np.isfinite(a):
                raise NumericalError(f"EKF covariance is not finite at step {step}", hint)
            asym = max(asym, a)
        diag = np.diagonal(P)
        if diag.min() < 0.0:
            i = int(np.argmin(diag))
            raise NumericalError(
                f"EKF covariance has a negative variance at step {step} (Σ[{i},{i}] = {diag[i]:.3g})", hint
            )
        tol = self.cfg.symmetry_tol * max(1.0, float(diag.max()))
        if asym > tol:
            raise NumericalError(
                f"EKF covariance is not symmetric at step {step} (max|Σ − Σᵀ| = {asym:.3g})", hint
            )

    def min_eigenvalue(self) -> float:
        """Smallest eigenvalue of Σ, O(N³): for health reports only, computed on demand."""
        return float(np.linalg.eigvalsh(self.P)[0])
