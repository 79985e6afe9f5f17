"""ATE/RPE/relation metrics against hand-computed values on tiny trajectories."""

import numpy as np
import pytest

from cornerslam_cli.evaluate import align_se2, apply_se2, ate, relation_error, relative, rpe


def square(n=40):
    t = np.arange(n, dtype=float)
    s = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return t, np.column_stack((5 * np.cos(s), 3 * np.sin(s), s + np.pi / 2))


def test_ate_is_zero_for_a_rigidly_moved_copy():
    t, gt = square()
    est = apply_se2(0.7, np.array([3.0, -2.0]), gt)
    r = ate(t, est, t, gt)
    assert r["rmse"] == pytest.approx(0.0, abs=1e-9) and r["n"] == len(t)


def test_ate_of_a_constant_offset_in_one_axis_after_alignment():
    # gt visits each point of a line twice; est is off by +d then -d at each: symmetric, so no
    # rotation or translation can remove it and the RMSE is d
    t = np.arange(10.0)
    gt = np.column_stack((np.repeat(np.arange(5.0), 2), np.zeros(10), np.zeros(10)))
    est = gt.copy()
    est[:, 1] = np.where(np.arange(10) % 2 == 0, 0.1, -0.1)
    r = ate(t, est, t, gt)
    assert r["rmse"] == pytest.approx(0.1, rel=1e-6)
    assert r["max"] == pytest.approx(0.1, rel=1e-6)


def test_align_se2_recovers_a_known_transform():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(30, 2))
    ang, t = 0.3, np.array([1.0, 2.0])
    c, s = np.cos(ang), np.sin(ang)
    b = a @ np.array([[c, -s], [s, c]]).T + t
    ang2, t2 = align_se2(a, b)
    assert ang2 == pytest.approx(ang) and t2 == pytest.approx(t)


def test_relative_pose_by_hand():
    a = np.array([[1.0, 1.0, np.pi / 2]])
    b = np.array([[1.0, 3.0, np.pi]])
    assert relative(a, b)[0] == pytest.approx([2.0, 0.0, np.pi / 2])


def test_rpe_per_step_of_a_scaled_trajectory():
    t = np.arange(11.0)
    gt = np.column_stack((t, np.zeros(11), np.zeros(11)))
    est = gt * [1.1, 1, 1]  # each 1 m step measured as 1.1 m
    r = rpe(t, est, t, gt, delta_m=2.0)
    assert r["rpe_step_rmse"] == pytest.approx(0.1)
    assert r["rpe_per_m"] == pytest.approx(0.1)


def test_relation_error_with_time_offset_and_interpolation():
    t = np.array([0.0, 1.0, 2.0])
    est = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    off = 100.0
    # relation 0.5 → 1.5: truth says 1.2 m forward; estimate says 1.0 m: error 0.2 m
    rel = np.array(
        [[100.5, 101.5, 1.2, 0.0, 0.0], [100.0, 102.0, 2.0, 0.0, np.radians(10)], [50, 51, 0, 0, 0]]
    )
    e = relation_error(t, est, rel, time_offset=off)
    assert e["n"] == 2 and e["n_total"] == 3
    assert e["trans_mean"] == pytest.approx(0.1)
    assert e["rot_mean_deg"] == pytest.approx(5.0)
