"""Motion and observation models of the corner EKF-SLAM (NOTES §5, paper eq 19–27), pure maths.

Frames: the robot pose ``pose = (x, y, θ)`` is the base frame in the map frame; a landmark
``m = (m_x, m_y, m_φ)`` is a corner in the map frame, ``m_φ`` the pose-invariant angle between its two
lines; a measurement ``z = (z_x, z_y, z_φ)`` is the corner in the base frame. Metres and radians.

Nothing here keeps state; :mod:`cornerslam_cli.filter.ekf` owns the filter.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..geometry import wrap_angle


class OdometryIncrement(NamedTuple):
    """Odometry between two poses as (rot1, trans, rot2): turn, drive straight, turn (Thrun §5.4)."""

    rot1: float
    trans: float
    rot2: float


def odometry_increment(
    odom_prev: np.ndarray, odom_cur: np.ndarray, eps_trans: float = 1e-4, reverse: bool = True
) -> OdometryIncrement:
    """(rot1, trans, rot2) from two consecutive odometry poses (x, y, θ) in the odometry frame.

    Pure rotation: when the translation is below ``eps_trans`` metres the heading of travel is
    undefined, so rot1 = 0 and the whole turn goes to rot2 (trans is kept, possibly tiny).
    Reverse driving: with ``reverse`` a heading of travel more than 90° from the robot's heading is
    read as driving backwards (trans < 0, rot1 small) instead of "turn ~180°, drive, turn back", so
    the rotation noise does not explode for a robot that backs up.
    """
    x0, y0, t0 = (float(v) for v in odom_prev)
    x1, y1, t1 = (float(v) for v in odom_cur)
    dx, dy = x1 - x0, y1 - y0
    trans = float(np.hypot(dx, dy))
    dtheta = float(wrap_angle(t1 - t0))
    if trans < eps_trans:
        return OdometryIncrement(0.0, trans, dtheta)
    rot1 = float(wrap_angle(np.arctan2(dy, dx) - t0))
    if reverse and abs(rot1) > 0.5 * np.pi:
        rot1 = float(wrap_angle(rot1 - np.pi))
        trans = -trans
    rot2 = float(wrap_angle(dtheta - rot1))
    return OdometryIncrement(rot1, trans, rot2)


def motion_model(pose: np.ndarray, u: OdometryIncrement) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Apply the odometry increment ``u`` to ``pose`` (eq 19 with the rot1/trans/rot2 model).

    Returns (pose_new (3,), G (3, 3) = ∂pose_new/∂pose (eq 21), V (3, 3) = ∂pose_new/∂(rot1, trans, rot2)).
    """
    x, y, theta = pose
    rot1, trans, rot2 = u
    heading = theta + rot1
    c, s = np.cos(heading), np.sin(heading)
    pose_new = np.array([x + trans * c, y + trans * s, wrap_angle(theta + rot1 + rot2)])
    G = np.array([[1.0, 0.0, -trans * s], [0.0, 1.0, trans * c], [0.0, 0.0, 1.0]])
    V = np.array([[-trans * s, c, 0.0], [trans * c, s, 0.0], [1.0, 0.0, 1.0]])
    return pose_new, G, V


def motion_noise(
    u: OdometryIncrement,
    theta: float,
    alphas: tuple[float, float, float, float],
    min_sigma_xy: float = 0.0,
    min_sigma_theta: float = 0.0,
) -> np.ndarray:
    """Process noise R (3, 3) in the pose space for the increment ``u`` from heading ``theta``.

    Control-space variances (Thrun's α1..α4, angles in rad, lengths in m):
    var(rot1) = α1·rot1² + α2·trans², var(trans) = α3·trans² + α4·(rot1² + rot2²),
    var(rot2) = α1·rot2² + α2·trans²;  R = V M Vᵀ + diag(σ_xy², σ_xy², σ_θ²), the floor keeping R
    positive definite when the robot stands still.  (V M Vᵀ: V the Jacobian of :func:`motion_model`
    with respect to (rot1, trans, rot2), which depends on the heading.)
    """
    a1, a2, a3, a4 = alphas
    rot1, trans, rot2 = u
    M = np.diag(
        [
            a1 * rot1**2 + a2 * trans**2,
            a3 * trans**2 + a4 * (rot1**2 + rot2**2),
            a1 * rot2**2 + a2 * trans**2,
        ]
    )
    V = motion_model(np.array([0.0, 0.0, theta]), u)[2]  # ∂pose/∂(rot1, trans, rot2)
    R = V @ M @ V.T
    R += np.diag([min_sigma_xy**2, min_sigma_xy**2, min_sigma_theta**2])
    return 0.5 * (R + R.T)


def increment_noise(
    inc: np.ndarray,
    alphas: tuple[float, float, float, float],
    min_sigma_xy: float,
    min_sigma_theta: float,
    eps_trans: float = 1e-4,
    reverse: bool = True,
) -> np.ndarray:
    """Covariance (3, 3) of an odometry increment ``inc`` = (dx, dy, dθ) given in the frame of the
    pose it starts from: :func:`motion_noise` of its (rot1, trans, rot2) at heading 0."""
    u = odometry_increment(np.zeros(3), inc, eps_trans, reverse)
    return motion_noise(u, 0.0, alphas, min_sigma_xy, min_sigma_theta)


def observe(pose: np.ndarray, landmarks: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Predicted measurements of landmarks (n, 3) from ``pose`` and their exact Jacobians (NOTES §4).

    h_k = [R(θ)ᵀ(m_k,xy − p); m_k,φ].  Returns h (n, 3), H_r (n, 3, 3) = ∂h_k/∂(x, y, θ),
    H_l (n, 3, 3) = ∂h_k/∂m_k.  (The paper's eq 27 drops the heading column; this is the exact one.)
    """
    x, y, theta = pose
    landmarks = np.asarray(landmarks, dtype=float).reshape(-1, 3)
    n = len(landmarks)
    c, s = np.cos(theta), np.sin(theta)
    dx = landmarks[:, 0] - x
    dy = landmarks[:, 1] - y
    hx = c * dx + s * dy
    hy = -s * dx + c * dy
    h = np.column_stack((hx, hy, landmarks[:, 2]))
    H_r = np.zeros((n, 3, 3))
    H_r[:, 0, 0] = -c
    H_r[:, 0, 1] = -s
    H_r[:, 0, 2] = hy
    H_r[:, 1, 0] = s
    H_r[:, 1, 1] = -c
    H_r[:, 1, 2] = -hx
    H_l = np.broadcast_to(np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]), (n, 3, 3)).copy()
    return h, H_r, H_l


def observe_one(pose: np.ndarray, landmark: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`observe` of one landmark (3,) with its Jacobian stacked as H = [H_r, H_l] (3, 6).

    The same arithmetic, operation for operation, on Python floats (``math.cos``/``sin`` round as
    numpy's float64 loops do): the per-pair step of the sequential update, where building and slicing
    (1, 3, 3) arrays cost more than the maths.
    """
    x, y, theta = pose.tolist()
    mx, my, mphi = landmark.tolist()
    c, s = math.cos(theta), math.sin(theta)
    dx, dy = mx - x, my - y
    hx = c * dx + s * dy
    hy = -s * dx + c * dy
    H = np.array([[-c, -s, hy, c, s, 0.0], [s, -c, -hx, -s, c, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 1.0]])
    return np.array([hx, hy, mphi]), H


def inverse_observe(pose: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """New landmarks from measurements z (k, 3) seen at ``pose`` (landmark initialisation).

    m_xy = p + R(θ) z_xy, m_φ = z_φ.  Returns m (k, 3), G_r (k, 3, 3) = ∂m/∂pose, G_z (k, 3, 3) = ∂m/∂z.
    """
    x, y, theta = pose
    z = np.asarray(z, dtype=float).reshape(-1, 3)
    k = len(z)
    c, s = np.cos(theta), np.sin(theta)
    rx = c * z[:, 0] - s * z[:, 1]  # R(θ) z_xy
    ry = s * z[:, 0] + c * z[:, 1]
    m = np.column_stack((x + rx, y + ry, z[:, 2]))
    G_r = np.zeros((k, 3, 3))
    G_r[:, 0, 0] = 1.0
    G_r[:, 1, 1] = 1.0
    G_r[:, 0, 2] = -ry
    G_r[:, 1, 2] = rx
    G_z = np.broadcast_to(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), (k, 3, 3)).copy()
    return m, G_r, G_z
