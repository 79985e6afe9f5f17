"""A dense textbook EKF-SLAM, the reference the block-matrix filter must equal (tests only).

Everything is written with full matrices: F (d × d) for the prediction, H (3k × d) for the correction,
K = Σ Hᵀ S⁻¹ explicitly (by solve), Σ ← (I − K H) Σ (the (3n+3)³ form of the paper's Table 1), and
augmentation as Σ' = J blockdiag(Σ, C) Jᵀ with the full Jacobian J. Slow on purpose.
"""

from __future__ import annotations

import numpy as np

from cornerslam_cli.filter.models import (
    inverse_observe,
    motion_model,
    motion_noise,
    observe,
    odometry_increment,
)
from cornerslam_cli.filter.params import EkfConfig
from cornerslam_cli.geometry import wrap_angle


class DenseEkf:
    def __init__(self, cfg: EkfConfig, mu: np.ndarray, P: np.ndarray):
        self.cfg = cfg
        self.mu = np.array(mu, dtype=float)
        self.P = np.array(P, dtype=float)

    @property
    def dim(self) -> int:
        return len(self.mu)

    def predict(self, odom_prev, odom_cur) -> None:
        cfg = self.cfg
        u = odometry_increment(odom_prev, odom_cur, cfg.pure_rotation_eps, cfg.reverse_motion)
        pose, G, _ = motion_model(self.mu[:3], u)
        R = motion_noise(u, self.mu[2], cfg.alphas, cfg.min_sigma_xy, cfg.min_sigma_theta)
        F = np.eye(self.dim)
        F[:3, :3] = G
        Fx = np.zeros((3, self.dim))
        Fx[:, :3] = np.eye(3)
        self.P = F @ self.P @ F.T + Fx.T @ R @ Fx
        self.mu[:3] = pose

    def _full_H(self, ids) -> tuple[np.ndarray, np.ndarray]:
        ids = np.asarray(ids)
        lm = self.mu[3:].reshape(-1, 3)[ids]
        h, H_r, H_l = observe(self.mu[:3], lm)
        H = np.zeros((3 * len(ids), self.dim))
        for i, k in enumerate(ids):
            H[3 * i : 3 * i + 3, :3] = H_r[i]
            H[3 * i : 3 * i + 3, 3 + 3 * k : 6 + 3 * k] = H_l[i]
        return h, H

    def _correct(self, ids, z, C) -> None:
        h, H = self._full_H(ids)
        k = len(ids)
        Cb = np.zeros((3 * k, 3 * k))
        for i in range(k):
            Cb[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = C[i]
        S = H @ self.P @ H.T + Cb
        K = np.linalg.solve(S, H @ self.P).T  # K = Σ Hᵀ S⁻¹ (S, Σ symmetric)
        nu = (np.asarray(z) - h).copy()
        nu[:, 2] = wrap_angle(nu[:, 2])
        self.mu = self.mu + K @ nu.ravel()
        self.mu[2] = wrap_angle(self.mu[2])
        I_KH = np.eye(self.dim) - K @ H
        if self.cfg.joseph:
            self.P = I_KH @ self.P @ I_KH.T + K @ Cb @ K.T
        else:
            self.P = I_KH @ self.P

    def update(self, ids, z, C) -> None:
        if self.cfg.update == "batched":
            self._correct(ids, z, C)
        else:
            for k, z_i, C_i in zip(ids, z, C, strict=True):
                self._correct([k], [z_i], [C_i])

    def augment(self, z, C) -> None:
        z = np.asarray(z).reshape(-1, 3)
        k, d = len(z), self.dim
        m, G_r, G_z = inverse_observe(self.mu[:3], z)
        J = np.zeros((d + 3 * k, d + 3 * k))
        J[:d, :d] = np.eye(d)
        Pe = np.zeros((d + 3 * k, d + 3 * k))
        Pe[:d, :d] = self.P
        for i in range(k):
            r = slice(d + 3 * i, d + 3 * i + 3)
            J[r, :3] = G_r[i]
            J[r, r] = G_z[i]
            Pe[r, r] = C[i]
        self.P = J @ Pe @ J.T
        self.mu = np.concatenate((self.mu, m.ravel()))
