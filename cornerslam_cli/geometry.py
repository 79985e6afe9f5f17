"""SE(2): planar poses, their matrices, composition, interpolation, and yaw from a quaternion.

A pose is ``(x, y, θ)``, metres and radians: the pose of a frame in its parent frame. Names follow
pytransform3d: ``laser2base`` is the pose of the laser in the robot base frame (it maps laser
coordinates to base coordinates), ``base2map`` the pose of the robot in the map, and
``compose(base2map, laser2base)`` is ``laser2map``. The functions that take poses accept one pose
``(3,)`` or a stack ``(n, 3)`` and work row-wise; angles come back wrapped to [-π, π) unless a
docstring says otherwise.

The arithmetic of each function is the one its callers used before it moved here, operation for
operation, so results are bit-for-bit unchanged: ``compose`` and ``relative`` in closed form,
``matrix_from_pose``/``pose_from_matrix`` for chains of 3×3 products (scan matching), and
``yaw_from_quaternion`` through ``math.atan2`` for scalars (numpy's vectorised ``arctan2`` may differ
from it in the last bit).
"""

from __future__ import annotations

import math
import sys

import numpy as np


def wrap_angle(a):
    """Angle(s) ``a`` (radians, scalar or array) wrapped to [-π, π)."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


def matrix_from_pose(pose) -> np.ndarray:
    """(3, 3) homogeneous matrix ``[[R(θ), t], [0, 1]]`` of one pose ``(x, y, θ)``."""
    x, y, t = pose
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


def pose_from_matrix(M: np.ndarray) -> np.ndarray:
    """Pose ``(x, y, θ)`` (3,) of a (3, 3) homogeneous matrix; θ = atan2(M₁₀, M₀₀) in [-π, π]."""
    return np.array([M[0, 2], M[1, 2], np.arctan2(M[1, 0], M[0, 0])])


def transform_points(points: np.ndarray, pose) -> np.ndarray:
    """Points (k, 2) given in a frame moved into its parent by that frame's pose: R(θ) p + t."""
    M = matrix_from_pose(pose)
    return points @ M[:2, :2].T + M[:2, 2]


def rotate_covariance(cov: np.ndarray, yaw: float) -> np.ndarray:
    """(n, 2, 2) position covariances of points moved into a frame turned by ``yaw``: R Σ Rᵀ."""
    R = matrix_from_pose((0.0, 0.0, yaw))[:2, :2]
    return R @ np.asarray(cov, dtype=float) @ R.T


def rotate_pose_covariance(cov: np.ndarray, yaw: float) -> np.ndarray:
    """(3, 3) covariance of a pose (x, y, θ) moved into a frame turned by ``yaw``: J Σ Jᵀ with
    J = blockdiag(R(yaw), 1) (θ itself does not change with the frame)."""
    J = np.eye(3)
    J[:2, :2] = matrix_from_pose((0.0, 0.0, yaw))[:2, :2]
    return J @ np.asarray(cov, dtype=float) @ J.T


def compose(a, b) -> np.ndarray:
    """a ∘ b: with a = ``base2map`` and b = ``laser2base``, ``laser2map``. Row-wise for (n, 3)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    return np.stack((x, y, wrap_angle(a[..., 2] + b[..., 2])), axis=-1)


def inverse(a) -> np.ndarray:
    """a⁻¹: with a = ``base2map``, ``map2base``. θ is -θₐ, not wrapped (in (-π, π] for a wrapped θₐ)."""
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack((-c * a[..., 0] - s * a[..., 1], s * a[..., 0] - c * a[..., 1], -a[..., 2]), axis=-1)


def relative(a, b) -> np.ndarray:
    """a⁻¹ ∘ b, the pose of b in the frame of a: with a = ``base2map`` at one step and b at the next,
    the motion between them in the first base frame. Row-wise for (n, 3)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    dx, dy = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    return np.stack((c * dx + s * dy, -s * dx + c * dy, wrap_angle(b[..., 2] - a[..., 2])), axis=-1)


def chain(increments: np.ndarray) -> np.ndarray:
    """(n, 3) the poses p₀ ∘ … ∘ pₖ of consecutive ``increments`` (n, 3) from the origin: each pose the
    one before composed with its increment."""
    inc = np.asarray(increments, dtype=float)
    heading = np.cumsum(inc[:, 2])
    before = np.concatenate(([0.0], heading[:-1]))
    c, s = np.cos(before), np.sin(before)
    x = np.cumsum(c * inc[:, 0] - s * inc[:, 1])
    y = np.cumsum(s * inc[:, 0] + c * inc[:, 1])
    return np.column_stack((x, y, wrap_angle(heading)))


def compose_inverse(a, b) -> np.ndarray:
    """a ∘ b⁻¹: with a = ``base2map`` and b = ``base2odom``, ``odom2map``. Row-wise for (n, 3).

    θ = θₐ − θ_b is not wrapped (in (-2π, 2π) for wrapped inputs): a caller that needs it in
    [-π, π) wraps it (a quaternion of it is the same rotation either way)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    th = a[..., 2] - b[..., 2]
    c, s = np.cos(th), np.sin(th)
    bx, by = b[..., 0], b[..., 1]
    return np.stack((a[..., 0] - (c * bx - s * by), a[..., 1] - (s * bx + c * by), th), axis=-1)


def compose_inverse_cov(a, cov_a: np.ndarray, b, cov_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """a ∘ b⁻¹ (θ wrapped) of two independent uncertain poses, with its covariance to first order; the
    poses' covariances of (x, y, θ) in their parent frame, the result's in a's (two loop closures of one
    submap b, a1→b and a2→b: the a1→a2 pose they imply)."""
    pose = compose_inverse(a, b)
    pose[2] = wrap_angle(pose[2])
    c, s = np.cos(pose[2]), np.sin(pose[2])
    rb = np.array([c * b[0] - s * b[1], s * b[0] + c * b[1]])  # R(θₐ − θ_b) t_b
    lever = np.array([-rb[1], rb[0]])  # its derivative by θₐ − θ_b
    Ja = np.eye(3)
    Ja[:2, 2] = -lever
    Jb = -np.eye(3)
    Jb[:2, :2] = -np.array([[c, -s], [s, c]])
    Jb[:2, 2] = lever
    return pose, Ja @ cov_a @ Ja.T + Jb @ cov_b @ Jb.T


def reanchor(pose, cov: np.ndarray, a, b) -> tuple[np.ndarray, np.ndarray]:
    """A relative pose a→b (``pose``: frame b's origin in frame a, covariance ``cov`` of its (x, y, θ) in
    a) re-expressed between two poses known exactly in those frames, ``a`` in frame a and ``b`` in frame
    b: a⁻¹ ∘ pose ∘ b, with its covariance (in a's frame at ``a``) to first order. A loop closure
    between two submaps' origins, moved onto the keyframes where the submaps overlap."""
    pose = np.asarray(pose, dtype=float)
    z = relative(a, compose(pose, b))
    c, s = np.cos(pose[2]), np.sin(pose[2])
    rb = np.array([c * b[0] - s * b[1], s * b[0] + c * b[1]])  # R(θ) t_b: its lever arm on θ
    J = np.eye(3)
    J[:2, 2] = (-rb[1], rb[0])
    ca, sa = np.cos(a[2]), np.sin(a[2])
    J[:2, :] = np.array([[ca, sa], [-sa, ca]]) @ J[:2, :]
    return z, J @ cov @ J.T


def interpolate(stamps: np.ndarray, poses: np.ndarray, t):
    """Poses at time(s) ``t`` between the poses (n, 3) at increasing ``stamps`` (n,): linear in x, y,
    along the shorter arc in θ (the SE(2) geodesic differs by O(Δθ·Δd), negligible between samples
    close in time). ``t`` is a scalar (returns (3,)) or an array (returns (len(t), 3)).

    Each t is interpolated between the last stamp at or before it and the next one; a t outside
    [stamps[0], stamps[-1]] is extrapolated from the first or last interval, so callers select the t
    inside the span first. At a stamp held by two samples the later one's pose is taken."""
    tq = np.atleast_1d(np.asarray(t, dtype=float))
    j = np.clip(np.searchsorted(stamps, tq, side="right"), 1, len(stamps) - 1)
    i = j - 1
    dt = stamps[j] - stamps[i]
    s = np.where(dt > 0, (tq - stamps[i]) / np.where(dt > 0, dt, 1.0), 0.0)
    xy = poses[i, :2] + s[:, None] * (poses[j, :2] - poses[i, :2])
    th = wrap_angle(poses[i, 2] + s * wrap_angle(poses[j, 2] - poses[i, 2]))
    out = np.column_stack((xy, th))
    return out[0] if np.ndim(t) == 0 else out


def normalize_quaternion(x: float, y: float, z: float, w: float, tol: float = 1e-9) -> tuple:
    """Quaternion (x, y, z, w) scaled to unit length; returned as given when its squared length is
    within ``tol`` of 1 or a component is not finite. It must not be zero (callers check: it has no
    direction; it raises ZeroDivisionError).

    A q whose squared length overflows (components from about 1.3e154: corrupt data) or falls below
    float's smallest normal number (all under about 1.5e-154) is first divided by its largest
    component, as logs/ros.py's ``transform_matrix`` does, so it keeps its rotation (the squared
    length inf was returned as given: yaw 3π/4 for (1e200, 1e200, 0, 0), π about (1, 1, 0), not
    π/2); any other q is scaled as it always was (bit for bit)."""
    n2 = x * x + y * y + z * z + w * w
    if abs(n2 - 1.0) <= tol or not all(math.isfinite(v) for v in (x, y, z, w)):
        return x, y, z, w
    if not sys.float_info.min <= n2 < math.inf and (big := max(abs(x), abs(y), abs(z), abs(w))) > 0:
        x, y, z, w = x / big, y / big, z / big, w / big
        n2 = x * x + y * y + z * z + w * w
    s = 1.0 / math.sqrt(n2)
    return x * s, y * s, z * s, w * s


def yaw_from_quaternion(x, y, z, w):
    """Yaw θ (rotation about z, radians in [-π, π]) of a *unit* quaternion (x, y, z, w), scalars or
    arrays: θ = atan2(2(wz + xy), 1 − 2(y² + z²)). A quaternion not of unit length gives a wrong θ:
    pass it through :func:`normalize_quaternion` first."""
    sy = 2.0 * (w * z + x * y)
    cy = 1.0 - 2.0 * (y * y + z * z)
    return math.atan2(sy, cy) if np.ndim(sy) == 0 else np.arctan2(sy, cy)


def within_range(points: np.ndarray, reach: float) -> np.ndarray:
    """The ``points`` (k, 2) within ``reach`` of the origin."""
    return points[np.einsum("ij,ij->i", points, points) <= reach**2]


def apart(a: np.ndarray, b: np.ndarray, distance: float, angle: float) -> bool:
    """Whether poses ``a`` and ``b`` lie ``distance`` or more apart, or differ by ``angle`` or more in
    heading."""
    return bool(np.hypot(a[0] - b[0], a[1] - b[1]) >= distance or abs(wrap_angle(a[2] - b[2])) >= angle)
