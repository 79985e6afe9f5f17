"""Simulated world: ray caster, true and visible corners, ready-made worlds."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cornerslam_cli import simworld as sw


def test_raycast_room_known_ranges():
    world = sw.make_world([sw.room(0, 0, 10, 6)])
    angles = np.array([0.0, np.pi / 2, np.pi, -np.pi / 2, np.arctan2(3, 5)])
    r = sw.raycast(world, (5.0, 3.0, 0.0), angles)
    np.testing.assert_allclose(r, [5.0, 3.0, 5.0, 3.0, math.hypot(5, 3)], atol=1e-12)
    # the sensor heading rotates the beams
    r2 = sw.raycast(world, (5.0, 3.0, np.pi / 2), np.array([0.0, -np.pi / 2]))
    np.testing.assert_allclose(r2, [3.0, 5.0], atol=1e-12)


def test_raycast_nearest_wall_max_range_and_misses():
    world = sw.make_world([sw.polyline([(2, -1), (2, 1)]), sw.polyline([(4, -5), (4, 5)])])
    r = sw.raycast(world, (0.0, 0.0, 0.0), np.array([0.0, 0.6, np.pi]), max_range=10.0)
    assert r[0] == pytest.approx(2.0)  # first of two walls
    assert r[1] == pytest.approx(4.0 / math.cos(0.6))  # passes the short wall
    assert r[2] == np.inf  # nothing behind
    assert sw.raycast(world, (0.0, 0.0, 0.0), np.array([0.0]), max_range=1.5)[0] == np.inf


def test_raycast_points_lie_on_walls():
    world = sw.office_world()
    pose = (5.0, 5.0, 0.3)
    r = sw.raycast(world, pose, np.linspace(-np.pi, np.pi, 721, endpoint=False))
    pts = np.column_stack(
        (
            pose[0] + r * np.cos(np.linspace(-np.pi, np.pi, 721, endpoint=False) + 0.3),
            pose[1] + r * np.sin(np.linspace(-np.pi, np.pi, 721, endpoint=False) + 0.3),
        )
    )
    a, b = world.walls[:, 0], world.walls[:, 1]
    e = b - a
    t = np.clip(np.einsum("pwk,wk->pw", pts[:, None] - a, e) / np.einsum("wk,wk->w", e, e), 0, 1)
    d = np.hypot(*(a + t[..., None] * e - pts[:, None]).transpose(2, 0, 1)).min(axis=1)
    assert np.all(np.isfinite(r)) and d.max() < 1e-9


def test_true_corners_room_box_and_angles():
    tc = sw.true_corners(sw.make_world([sw.room(0, 0, 4, 3)]))
    assert len(tc) == 4
    np.testing.assert_allclose(np.sort(tc[:, 0]), [0, 0, 4, 4])
    np.testing.assert_allclose(tc[:, 2], np.pi / 2)
    # a 135° bend: the wedge is 135°, φ = 45°
    tc = sw.true_corners(sw.make_world([sw.polyline([(0, 0), (2, 0), (4, 2)])]))
    assert len(tc) == 1 and tc[0] == pytest.approx([2, 0, np.pi / 4])
    # a flat joint is no corner; a T junction is two
    assert len(sw.true_corners(sw.make_world([sw.polyline([(0, 0), (1, 0), (2, 0)])]))) == 0
    t = sw.true_corners(sw.make_world([sw.polyline([(0, 0), (4, 0)]), sw.polyline([(2, 0), (2, 2)])]))
    assert len(t) == 2 and np.allclose(t[:, :2], [2, 0])


def test_visible_corners_occlusion_fov_and_range():
    room = sw.room(0, 0, 8, 6)
    angles = np.linspace(-np.pi, np.pi, 1440, endpoint=False)
    assert len(sw.visible_corners(sw.make_world([room]), (4.0, 3.0, 0.0), angles, 30.0)) == 4
    # a box in front of the corner (8, 6) hides it
    world = sw.make_world([room, sw.rectangle(7.0, 5.2, 0.6, 0.6)])
    vis = sw.visible_corners(world, (4.0, 3.0, 0.0), angles, 30.0)
    assert not np.any(np.hypot(vis[:, 0] - 8, vis[:, 1] - 6) < 1e-6)
    # field of view: only the corners ahead; range: none within 2 m
    ahead = sw.visible_corners(sw.make_world([room]), (4.0, 3.0, 0.0), np.linspace(-0.9, 0.9, 200), 30.0)
    assert len(ahead) == 2 and np.all(ahead[:, 0] == 8)
    assert len(sw.visible_corners(sw.make_world([room]), (4.0, 3.0, 0.0), angles, 2.0)) == 0


def test_office_world_loop_is_clear():
    world = sw.office_world()
    xmin, ymin, xmax, ymax = world.bounds
    assert (xmax - xmin, ymax - ymin) == (30, 20)
    poses = sw.path_poses(sw.OFFICE_LOOP, 0.25)
    assert len(poses) == int(60 / 0.25)
    around = np.linspace(-np.pi, np.pi, 72, endpoint=False)
    for p in poses:
        assert sw.raycast(world, p, around).min() > 0.3  # no wall or box on the robot's path
    assert len(sw.true_corners(world)) > 60


def test_scan_from_ranges_keeps_valid_beams():
    scan = sw.scan_from_ranges(np.array([1.0, np.inf, 0.01, 2.0, 40.0]), np.linspace(0, 1, 5), 0.02, 30.0)
    np.testing.assert_array_equal(scan.beam_index, [0, 3])
    np.testing.assert_allclose(scan.ranges, [1.0, 2.0])
    assert scan.n_beams == 5 and scan.n_invalid == 3 and scan.angle_increment == pytest.approx(0.25)


def test_simulate_log_takes_another_lasers_field_of_view_and_noise(tmp_path):
    """simulate_log's library-only fov and sigma_a (benchmarks/reference_check.py's controls): the scans
    span the field of view given, and the noise given is the one drawn (same seed, other σ: other ranges)."""
    from cornerslam_cli.logs import open_log
    from cornerslam_cli.simulate import simulate_log

    first = []
    for sigma in (0.01, 0.01, 0.03):
        log = tmp_path / f"s{len(first)}.mcap"
        simulate_log(log, seed=4, rate=1.0, beams=181, fov=math.radians(180.0), sigma_a=sigma)
        reader = open_log(log)
        scan = next(m for m in reader.messages() if hasattr(m, "ranges"))
        reader.close()
        assert scan.n_beams == 181 and scan.angle_increment * 180 == pytest.approx(math.pi)
        first.append(np.asarray(scan.ranges, dtype=float))
    assert np.array_equal(first[0], first[1]) and not np.array_equal(first[0], first[2])


def test_simulated_odometry_error_terms(tmp_path):
    """simulate_log's ``odometry``: all terms 0 is the truth itself; a drift alone turns the odometry's
    heading by odom_drift per metre travelled, a scale alone lengthens its path by odom_scale."""
    from cornerslam_cli.logs import open_log
    from cornerslam_cli.simulate import OFFICE_LOOP, SimParams, corrupt_odometry, drive, simulate_log
    from cornerslam_cli.types import OdomSample

    def odometry(**terms):
        out = tmp_path / f"o{len(list(tmp_path.iterdir()))}.mcap"
        simulate_log(out, seed=2, rate=2.0, beams=91, odometry=terms)
        odom = np.array([[m.x, m.y, m.theta] for m in open_log(out).messages() if isinstance(m, OdomSample)])
        return odom, out

    zero = dict(odom_scale=0.0, odom_drift=0.0, odom_sigma_trans=0.0, odom_sigma_rot=0.0)
    p = SimParams(**zero)
    truth = drive(OFFICE_LOOP, 1, p, 1.0 / p.odom_rate)
    np.testing.assert_allclose(corrupt_odometry(truth, p, np.random.default_rng(0)), truth, atol=1e-9)
    exact, _ = odometry(**zero)
    path = np.sum(np.hypot(*np.diff(exact[:, :2], axis=0).T))
    drift, _ = odometry(**{**zero, "odom_drift": 0.01})
    turned = np.unwrap(drift[:, 2]) - np.unwrap(exact[:, 2])
    assert turned[-1] == pytest.approx(0.01 * path, rel=1e-3)
    scaled, _ = odometry(**{**zero, "odom_scale": 0.02})
    assert np.sum(np.hypot(*np.diff(scaled[:, :2], axis=0).T)) == pytest.approx(1.02 * path, rel=1e-3)
    with pytest.raises(ValueError, match="odom_bias"):
        odometry(odom_bias=1.0)
