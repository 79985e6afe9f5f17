"""SE(2) (geometry.py) against hand-computed poses, and its group laws as hypothesis invariants."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cornerslam_cli.geometry import (
    compose,
    compose_inverse,
    interpolate,
    inverse,
    matrix_from_pose,
    normalize_quaternion,
    pose_from_matrix,
    reanchor,
    relative,
    transform_points,
    wrap_angle,
    yaw_from_quaternion,
)

coord = st.floats(-50.0, 50.0, allow_nan=False)
angle = st.floats(-math.pi, math.pi, exclude_max=True, allow_nan=False)
pose = st.tuples(coord, coord, angle).map(np.array)


def close(a, b):
    """Poses equal up to round-off, θ compared on the circle."""
    a, b = np.asarray(a), np.asarray(b)
    assert a[..., :2] == pytest.approx(b[..., :2], abs=1e-9)
    assert np.all(np.abs(wrap_angle(a[..., 2] - b[..., 2])) < 1e-9)


# -- known answers -------------------------------------------------------------------------------


def test_laser_yawed_and_offset_on_the_robot_by_hand():
    """A laser 0.2 m ahead and 0.1 m left of the base, turned 90° left; the robot at (1, 2) facing -y.
    A point 1 m straight ahead of the laser is, in the base frame, 1 m to the left of the laser:
    (0.2, 1.1); in the map, facing -y, the robot's left is +x: (1 + 1.1, 2 - 0.2)."""
    laser2base = np.array([0.2, 0.1, math.pi / 2])
    base2map = np.array([1.0, 2.0, -math.pi / 2])
    assert transform_points(np.array([[1.0, 0.0]]), laser2base)[0] == pytest.approx([0.2, 1.1])
    laser2map = compose(base2map, laser2base)
    close(laser2map, [1.0 + 0.1, 2.0 - 0.2, 0.0])
    assert transform_points(np.array([[1.0, 0.0]]), laser2map)[0] == pytest.approx([2.1, 1.8])


def test_matrix_of_a_pose_by_hand():
    M = matrix_from_pose((3.0, -1.0, math.pi / 6))
    c, s = math.sqrt(3) / 2, 0.5
    assert M == pytest.approx(np.array([[c, -s, 3.0], [s, c, -1.0], [0.0, 0.0, 1.0]]))
    assert pose_from_matrix(M) == pytest.approx([3.0, -1.0, math.pi / 6])


def test_relative_pose_by_hand():
    """b at (1, 3) is 2 m straight ahead of a at (1, 1) facing +y, and turned 90° further."""
    a = np.array([[1.0, 1.0, np.pi / 2]])
    b = np.array([[1.0, 3.0, np.pi]])
    assert relative(a, b)[0] == pytest.approx([2.0, 0.0, np.pi / 2])


def test_inverse_by_hand():
    """The map origin seen from a robot at (2, 0) facing +y: 2 m to its left, i.e. at (0, 2)."""
    close(inverse([2.0, 0.0, math.pi / 2]), [0.0, 2.0, -math.pi / 2])


def test_odom2map_from_base2map_and_base2odom_by_hand():
    """The robot is at (1, 0) facing +y in the map and 1 m ahead of the odometry origin facing +x in
    the odometry frame: the odometry origin is 1 m behind it, at (1, -1), its x axis along +y."""
    close(compose_inverse([[1.0, 0.0, math.pi / 2]], [[1.0, 0.0, 0.0]]), [[1.0, -1.0, math.pi / 2]])


def test_interpolation_is_linear_and_takes_the_short_arc():
    stamps = np.array([0.0, 1.0])
    poses = np.array([[0.0, 0.0, np.pi - 0.1], [2.0, -4.0, -np.pi + 0.1]])
    p = interpolate(stamps, poses, 0.25)
    assert p.shape == (3,)
    assert p[:2] == pytest.approx([0.5, -1.0])
    # from π−0.1 to −π+0.1 is +0.2 the short way round; a quarter of it lands at π−0.05
    assert p[2] == pytest.approx(np.pi - 0.05)


def test_interpolation_picks_the_bracketing_samples_and_repeated_stamps():
    stamps = np.array([0.0, 1.0, 1.0, 3.0])
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [5.0, 0.0, 0.0], [9.0, 2.0, 1.0]])
    got = interpolate(stamps, poses, np.array([0.5, 1.0, 2.0]))
    assert got == pytest.approx(np.array([[0.5, 0.0, 0.0], [5.0, 0.0, 0.0], [7.0, 1.0, 0.5]]))


def test_wrap_angle_across_pi():
    assert wrap_angle(math.pi) == pytest.approx(-math.pi)
    assert wrap_angle(-math.pi) == pytest.approx(-math.pi)
    assert wrap_angle(math.pi + 0.1) == pytest.approx(-math.pi + 0.1)
    assert wrap_angle(-math.pi - 0.1) == pytest.approx(math.pi - 0.1)
    assert wrap_angle(np.array([7.0, -7.0])) == pytest.approx([7.0 - 2 * math.pi, -7.0 + 2 * math.pi])


def test_yaw_of_known_quaternions():
    h = math.sqrt(0.5)
    assert yaw_from_quaternion(0.0, 0.0, h, h) == pytest.approx(math.pi / 2)
    assert yaw_from_quaternion(0.0, 0.0, 1.0, 0.0) == pytest.approx(math.pi)
    assert yaw_from_quaternion(np.zeros(2), np.zeros(2), np.array([-h, 0.0]), np.array([h, 1.0])) == (
        pytest.approx([-math.pi / 2, 0.0])
    )
    # Rz(90°) Rx(90°): a quarter roll, then a quarter yaw; the yaw is still a quarter turn
    assert yaw_from_quaternion(0.5, 0.5, 0.5, 0.5) == pytest.approx(math.pi / 2)


def test_a_scaled_quaternion_needs_normalising():
    h = math.sqrt(0.5)
    assert yaw_from_quaternion(0.0, 0.0, 2 * h, 2 * h) != pytest.approx(math.pi / 2)
    assert yaw_from_quaternion(*normalize_quaternion(0.0, 0.0, 2 * h, 2 * h)) == pytest.approx(math.pi / 2)
    unit = (0.0, 0.0, h, h)
    assert normalize_quaternion(*unit) == unit  # within 1e-9 of unit length: returned as it is


def test_a_quaternion_whose_length_overflows_or_underflows_keeps_its_yaw():
    """Corrupt data: components of 1e200 (x² overflows to inf), 1.5e308 (past even math.hypot) or
    1e-170 (x² underflows to 0) are still the rotation of their direction, where the squared length
    inf was returned as given (yaw 3π/4 for π about (1, 1, 0), not π/2) and 0 divided by zero. As
    logs/ros.py's transform_matrix, a finite q is divided by its largest component first; a
    non-finite q is still returned as given and a zero q still raises."""
    for k in (1e200, 1.5e308, 1e-170):
        q = normalize_quaternion(k, k, 0.0, 0.0)  # π about (1, 1, 0)/√2: x turns onto y
        assert q == pytest.approx((math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0), abs=1e-15), k
        assert yaw_from_quaternion(*q) == pytest.approx(math.pi / 2), k
        q = normalize_quaternion(0.0, 0.0, k, k)  # a quarter turn about z
        assert yaw_from_quaternion(*q) == pytest.approx(math.pi / 2), k
    h = math.sqrt(0.5)
    assert yaw_from_quaternion(*normalize_quaternion(0.0, 0.0, 1.7e308, -1.7e308)) == pytest.approx(
        -math.pi / 2
    )
    assert normalize_quaternion(math.inf, 0.0, 0.0, 1.0) == (math.inf, 0.0, 0.0, 1.0)
    assert all(map(math.isnan, normalize_quaternion(math.nan, math.nan, math.nan, math.nan)))
    assert normalize_quaternion(0.0, 0.0, h, h) == (0.0, 0.0, h, h)
    with pytest.raises(ZeroDivisionError):
        normalize_quaternion(0.0, 0.0, 0.0, 0.0)


# -- invariants ----------------------------------------------------------------------------------


@settings(max_examples=200, deadline=None)
@given(pose)
def test_compose_with_inverse_is_identity(a):
    close(compose(a, inverse(a)), [0.0, 0.0, 0.0])
    close(compose(inverse(a), a), [0.0, 0.0, 0.0])
    close(inverse(inverse(a)), a)


@settings(max_examples=200, deadline=None)
@given(pose, pose)
def test_relative_undoes_compose(a, b):
    close(relative(a, compose(a, b)), b)
    close(compose(a, relative(a, b)), b)
    close(relative(a, b), compose(inverse(a), b))
    close(compose_inverse(a, b), compose(a, inverse(b)))


@settings(max_examples=200, deadline=None)
@given(pose, pose, pose)
def test_compose_is_associative_and_matches_matrices(a, b, c):
    close(compose(compose(a, b), c), compose(a, compose(b, c)))
    close(compose(a, b), pose_from_matrix(matrix_from_pose(a) @ matrix_from_pose(b)))


@settings(max_examples=100, deadline=None)
@given(pose, st.lists(st.tuples(coord, coord), min_size=1, max_size=5))
def test_transform_points_is_the_matrix_action(a, pts):
    pts = np.array(pts)
    homog = np.column_stack((pts, np.ones(len(pts)))) @ matrix_from_pose(a).T
    assert transform_points(pts, a) == pytest.approx(homog[:, :2], abs=1e-9)


@settings(max_examples=100, deadline=None)
@given(st.lists(pose, min_size=2, max_size=2), st.floats(0.0, 1.0))
def test_interpolate_hits_the_endpoints_and_stays_on_the_short_arc(poses, f):
    poses = np.array(poses)
    stamps = np.array([10.0, 12.0])
    close(interpolate(stamps, poses, 10.0), poses[0])
    close(interpolate(stamps, poses, 12.0), poses[1])
    p = interpolate(stamps, poses, 10.0 + 2.0 * f)
    turn = wrap_angle(poses[1, 2] - poses[0, 2])
    assert abs(wrap_angle(p[2] - poses[0, 2])) <= abs(turn) + 1e-9  # never the long way round
    assert p[:2] == pytest.approx(poses[0, :2] + f * (poses[1, :2] - poses[0, :2]), abs=1e-9)


@settings(max_examples=200, deadline=None)
@given(st.floats(-1e3, 1e3, allow_nan=False), st.integers(-5, 5))
def test_wrap_angle_lands_in_range_and_keeps_the_direction(a, k):
    w = float(wrap_angle(a + 2 * math.pi * k))
    assert -math.pi <= w < math.pi
    assert math.cos(w) == pytest.approx(math.cos(a), abs=1e-9)
    assert math.sin(w) == pytest.approx(math.sin(a), abs=1e-9)


@settings(max_examples=200, deadline=None)
@given(angle, angle, st.floats(0.01, 100.0))
def test_yaw_of_a_normalised_and_a_scaled_quaternion(yaw, roll, k):
    """q of Rz(yaw) Rx(roll) = qz ⊗ qx gives back the yaw, whatever the roll; scaled by k and
    normalised, the same yaw."""
    h, r = yaw / 2, roll / 2
    q = np.array(
        [
            math.cos(h) * math.sin(r),
            math.sin(h) * math.sin(r),
            math.sin(h) * math.cos(r),
            math.cos(h) * math.cos(r),
        ]
    )
    assert abs(wrap_angle(yaw_from_quaternion(*q) - yaw)) < 1e-9
    assert abs(wrap_angle(yaw_from_quaternion(*normalize_quaternion(*(k * q))) - yaw)) < 1e-9


def test_reanchor_moves_a_relative_pose_onto_two_poses_with_its_covariance():
    """a⁻¹ ∘ T ∘ b by hand (T a quarter turn), and its covariance against 20,000 draws of T."""
    T, a, b = np.array([2.0, 1.0, math.pi / 2]), np.array([1.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0])
    z, _ = reanchor(T, np.eye(3), a, b)
    np.testing.assert_allclose(z, [1.0, 2.0, math.pi / 2], atol=1e-12)  # b's x axis turned to +y
    rng = np.random.default_rng(4)
    T, a, b = np.array([3.0, -1.0, 0.7]), np.array([0.5, 2.0, -0.4]), np.array([4.0, 1.0, 0.3])
    cov = np.array([[0.02, 0.005, 0.001], [0.005, 0.01, -0.002], [0.001, -0.002, 0.004]])
    z, cz = reanchor(T, cov, a, b)
    np.testing.assert_allclose(z, relative(a, compose(T, b)), atol=1e-12)
    draws = relative(a, compose(rng.multivariate_normal(T, cov, 20000), b))
    d = draws - z
    d[:, 2] = wrap_angle(d[:, 2])
    np.testing.assert_allclose(np.cov(d.T), cz, rtol=0.08, atol=2e-4)
