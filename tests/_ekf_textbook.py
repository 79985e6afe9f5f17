"""A second dense EKF-SLAM reference that shares no code with cornerslam_cli.filter (tests only).

``_ekf_dense.DenseEkf`` checks the block-matrix algebra but takes h, its Jacobians, the odometry
decomposition and the motion noise from filter/models.py; an error there would be in both. Here every
function is written out again from the textbook (Thrun, Burgard & Fox §5.4, §10.2): the observation
h = R(θ)ᵀ(m − p) and its Jacobian by hand, the (rot1, trans, rot2) decomposition, V M Vᵀ, the
composition of a pose with an increment, augmentation through the full Jacobian of [x; m_new(x, z)].
"""

from __future__ import annotations

import math

import numpy as np


def wrap(a: float) -> float:
    return math.remainder(a, 2.0 * math.pi)


def observation(x: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """h (3,) of landmark k and its dense Jacobian H (3, d)."""
    px, py, th = x[:3]
    mx, my, mphi = x[3 + 3 * k : 6 + 3 * k]
    c, s = math.cos(th), math.sin(th)
    dx, dy = mx - px, my - py
    h = np.array([c * dx + s * dy, -s * dx + c * dy, mphi])
    H = np.zeros((3, len(x)))
    H[:, :3] = [[-c, -s, -s * dx + c * dy], [s, -c, -c * dx - s * dy], [0.0, 0.0, 0.0]]
    H[:, 3 + 3 * k : 6 + 3 * k] = [[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]
    return h, H


def update(x, P, ids, z, C, joseph=False, batched=False):
    """Sequential (re-linearised per pair) or batched EKF correction; returns x, P, Σ νᵀS⁻¹ν."""
    x, P = x.astype(float).copy(), P.astype(float).copy()
    groups = [list(range(len(ids)))] if batched else [[i] for i in range(len(ids))]
    nis = 0.0
    for g in groups:
        hs, Hs = zip(*(observation(x, int(ids[i])) for i in g), strict=True)
        H = np.vstack(Hs)
        nu = np.concatenate([z[i] - h for i, h in zip(g, hs, strict=True)])
        nu[2::3] = [wrap(a) for a in nu[2::3]]
        R = np.zeros((3 * len(g), 3 * len(g)))
        for j, i in enumerate(g):
            R[3 * j : 3 * j + 3, 3 * j : 3 * j + 3] = C[i]
        S = H @ P @ H.T + R
        K = np.linalg.solve(S, H @ P).T  # P Hᵀ S⁻¹ (S and P symmetric)
        x = x + K @ nu
        nis += float(nu @ np.linalg.solve(S, nu))
        IKH = np.eye(len(x)) - K @ H
        P = IKH @ P @ IKH.T + K @ R @ K.T if joseph else IKH @ P
    x[2] = wrap(x[2])
    return x, 0.5 * (P + P.T), nis


def odometry_controls(o0, o1) -> tuple[float, float, float]:
    """(rot1, trans, rot2) between two odometry poses; backwards when travel is > 90° off the heading."""
    dx, dy = o1[0] - o0[0], o1[1] - o0[1]
    trans = math.hypot(dx, dy)
    rot1 = wrap(math.atan2(dy, dx) - o0[2])
    if abs(rot1) > math.pi / 2:
        rot1, trans = wrap(rot1 - math.pi), -trans
    return rot1, trans, wrap(o1[2] - o0[2] - rot1)


def predict(x, P, o0, o1, alphas, floor_xy, floor_th, cov=None):
    """EKF prediction by the odometry from o0 to o1: the alphas' noise model, or ``cov`` (3, 3) of the
    increment in o0's frame."""
    th = x[2]
    if cov is None:
        r1, t, r2 = odometry_controls(o0, o1)
        c, s = math.cos(th + r1), math.sin(th + r1)
        new = np.array([x[0] + t * c, x[1] + t * s, th + r1 + r2])
        G = np.array([[1.0, 0.0, -t * s], [0.0, 1.0, t * c], [0.0, 0.0, 1.0]])
        V = np.array([[-t * s, c, 0.0], [t * c, s, 0.0], [1.0, 0.0, 1.0]])
        a1, a2, a3, a4 = alphas
        M = np.diag([a1 * r1**2 + a2 * t**2, a3 * t**2 + a4 * (r1**2 + r2**2), a1 * r2**2 + a2 * t**2])
        Q = V @ M @ V.T + np.diag([floor_xy**2, floor_xy**2, floor_th**2])
    else:  # x ⊕ u, u the increment in o0's frame
        c0, s0 = math.cos(o0[2]), math.sin(o0[2])
        dx, dy = o1[0] - o0[0], o1[1] - o0[1]
        u = (c0 * dx + s0 * dy, -s0 * dx + c0 * dy, wrap(o1[2] - o0[2]))
        c, s = math.cos(th), math.sin(th)
        new = np.array([x[0] + c * u[0] - s * u[1], x[1] + s * u[0] + c * u[1], th + u[2]])
        G = np.array([[1.0, 0.0, -s * u[0] - c * u[1]], [0.0, 1.0, c * u[0] - s * u[1]], [0.0, 0.0, 1.0]])
        J = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        Q = J @ cov @ J.T
    F = np.eye(len(x))
    F[:3, :3] = G
    x = x.copy()
    x[:3] = new
    x[2] = wrap(x[2])
    P = F @ P @ F.T
    P[:3, :3] += Q
    return x, 0.5 * (P + P.T)


def augment(x, P, z, C):
    """Append landmarks m = [p + R(θ) z_xy; z_φ]: Σ' = J blockdiag(Σ, C_1..C_k) Jᵀ, J = ∂[x; m]/∂[x; z]."""
    d, k = len(x), len(z)
    c, s = math.cos(x[2]), math.sin(x[2])
    J = np.zeros((d + 3 * k, d + 3 * k))
    J[:d, :d] = np.eye(d)
    B = np.zeros((d + 3 * k, d + 3 * k))
    B[:d, :d] = P
    new = []
    for i, (zx, zy, zphi) in enumerate(z):
        rx, ry = c * zx - s * zy, s * zx + c * zy
        new += [x[0] + rx, x[1] + ry, zphi]
        rows = slice(d + 3 * i, d + 3 * i + 3)
        J[rows, :3] = [[1.0, 0.0, -ry], [0.0, 1.0, rx], [0.0, 0.0, 0.0]]
        J[rows, rows] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
        B[rows, rows] = C[i]
    return np.concatenate((x, new)), J @ B @ J.T
