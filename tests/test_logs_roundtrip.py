"""Every writer/reader pair round-trips scans (valid beams, angles, stamps) and odometry."""

from __future__ import annotations

import gzip
import math

import numpy as np
import pytest
from _log_fixtures import ROS_WRITERS, WRITERS, make_odoms, make_scans, split, write_log

from cornerslam_cli.logs import open_log
from cornerslam_cli.logs.writers import write_carmen


def expected_valid(raw, range_min):
    r = np.asarray(raw.ranges, dtype=np.float32).astype(np.float64)
    with np.errstate(invalid="ignore"):
        return np.flatnonzero(np.isfinite(r) & (r > 0) & (r >= range_min) & (r < raw.range_max))


@pytest.mark.parametrize("fmt", sorted(WRITERS))
def test_round_trip(fmt, tmp_path):
    raw, odoms = make_scans(), make_odoms()
    path = write_log(fmt, tmp_path, raw, odoms)
    with open_log(path) as log:
        scans, got_odoms = split(log.messages())
        info = log.info()
        stats = log.stats
    assert len(scans) == len(raw) and len(got_odoms) == len(odoms)
    dropped = 0
    for s, r in zip(scans, raw, strict=True):
        idx = expected_valid(r, 0.0 if fmt == "carmen" else r.range_min)  # CARMEN has no range_min
        dropped += len(r.ranges) - len(idx)
        assert s.stamp == pytest.approx(r.stamp, abs=1e-6)
        assert s.n_beams == len(r.ranges)
        np.testing.assert_array_equal(s.beam_index, idx)
        np.testing.assert_allclose(s.ranges, r.ranges[idx], rtol=1e-6)
        np.testing.assert_allclose(s.angles, r.angle_min + idx * r.angle_increment, atol=1e-6)
        assert np.all(np.diff(s.angles) > 0)
    for o, e in zip(got_odoms, odoms, strict=True):
        assert (o.stamp, o.x, o.y) == pytest.approx((e.stamp, e.x, e.y), abs=1e-6)
        assert math.remainder(o.theta - e.theta, math.tau) == pytest.approx(0, abs=1e-9)
    assert stats.scans == len(raw) and stats.odoms == len(odoms)
    assert stats.beams_dropped == dropped > 0 and stats.decode_failed == 0
    assert info.scan_topic and info.odom_topic
    assert info.start == pytest.approx(odoms[0].stamp, abs=1e-6)
    assert info.end == pytest.approx(raw[-1].stamp, abs=1e-6)


@pytest.mark.parametrize("fmt", sorted(WRITERS))
def test_messages_in_time_order_and_rereadable(fmt, tmp_path):
    with open_log(write_log(fmt, tmp_path)) as log:
        first = [m.stamp for m in log.messages()]
        second = [m.stamp for m in log.messages()]
    assert first == sorted(first) and first == second and len(first) == 24


@pytest.mark.parametrize("fmt", sorted(ROS_WRITERS))
def test_tf_static_laser_offset(fmt, tmp_path):
    path = write_log(fmt, tmp_path, tf_static=(0.145, -0.02, 0.3))
    with open_log(path) as log:
        assert log.laser_to_base() == pytest.approx((0.145, -0.02, 0.3), abs=1e-6)
        assert "/tf_static" in [t.name for t in log.info().topics]


@pytest.mark.parametrize("fmt", sorted(ROS_WRITERS))
def test_no_tf_static_gives_none(fmt, tmp_path):
    with open_log(write_log(fmt, tmp_path)) as log:
        assert log.laser_to_base() is None


@pytest.mark.parametrize("fmt", sorted(ROS_WRITERS))
def test_odometry_from_tf(fmt, tmp_path):
    odoms = make_odoms()
    path = write_log(fmt, tmp_path, odoms=odoms, odom_as_tf=True, tf_static=(0.2, 0.0, 0.0))
    with open_log(path) as log:
        info = log.info()
        assert info.odom_source == "tf odom→base_link" and info.odom_topic == "/tf"
        _, got = split(log.messages())
        # tf_static base_link→laser must not be taken as odometry; laser offset still found
        assert log.laser_to_base() == pytest.approx((0.2, 0.0, 0.0))
    np.testing.assert_allclose(
        [(o.stamp, o.x, o.y) for o in got], [(o.stamp, o.x, o.y) for o in odoms], atol=1e-6
    )


def test_laser_mount_on_tf_after_the_first_scan(tmp_path):
    """ROS 1's tf static_transform_publisher sends the mount on /tf every 100 ms, between the odometry's
    tf messages, and the log has no /tf_static: a mount first sent 5 ms after the first scan is found
    (the read stopped at the first tf message after that scan, an odom→base_link one)."""
    from _log_fixtures import odom_messages, scan_messages, write_messages_mcap

    from cornerslam_cli.logs.writers import RosSerializer

    ros = RosSerializer("cdr")
    scans = scan_messages(n=12)
    t0 = scans[0][2]

    def tf(t, parent, child, x):
        return ("/tf", "tf2_msgs/msg/TFMessage", t, ros.tf(t * 1e-9, parent, child, x, 0.0, 0.0))

    odom = [tf(t0 - 200_000_000 + 20_000_000 * i, "odom", "base_link", 0.01 * i) for i in range(70)]
    mount = [tf(t0 + 5_000_000 + 100_000_000 * i, "base_link", "laser", 0.2) for i in range(10)]
    path = write_messages_mcap(tmp_path / "tf.mcap", sorted(scans + odom + mount, key=lambda m: m[2]))
    with open_log(path) as log:
        assert log.odom_topic == "/tf" and log.laser_to_base() == pytest.approx((0.2, 0.0, 0.0))
    # nav_msgs/Odometry, the mount on /tf_static, odom→base_link on /tf only from after the first scan:
    # the tf odometry is still seen (odom_on_tf: the results MCAP then writes no second odom→base_link)
    static = [("/tf_static", "tf2_msgs/msg/TFMessage", t0 - 1, tf(t0 - 1, "base_link", "laser", 0.2)[3])]
    late = [tf(t0 + 10_000_000 + 20_000_000 * i, "odom", "base_link", 0.01 * i) for i in range(20)]
    msgs = sorted(scans + odom_messages(n=12) + static + late, key=lambda m: m[2])
    with open_log(write_messages_mcap(tmp_path / "odom.mcap", msgs)) as log:
        assert log.odom_topic == "/odom" and log.laser_to_base() == pytest.approx((0.2, 0.0, 0.0))
        assert log.odom_on_tf


def test_tf_odometry_wrong_frames_is_an_error(tmp_path):
    from cornerslam_cli.errors import LogError

    path = write_log("mcap-cdr", tmp_path, odom_as_tf=True)
    with open_log(path, base_frame="base_footprint") as log:
        with pytest.raises(LogError, match="odom→base_footprint"):
            list(log.messages())


def test_carmen_without_odom_lines_uses_laser_pose_fields(tmp_path):
    raw, odoms = make_scans(), make_odoms()
    path = write_carmen(tmp_path / "x.log", raw, odoms, odom_lines=False)
    with open_log(path) as log:
        assert log.info().odom_source.endswith("odometry fields")
        msgs = list(log.messages())
    scans, got = split(msgs)
    assert len(got) == len(scans) == len(raw)
    # one odometry sample just before each scan, at the scan stamp, holding the latest odometry pose
    assert [o.stamp for o in got] == [s.stamp for s in scans]
    np.testing.assert_allclose([(o.x, o.y) for o in got], [(e.x, e.y) for e in odoms])


@pytest.mark.parametrize("gz", [False, True])
def test_carmen_flaser_convention(tmp_path, gz):
    raw = make_scans(n=3, beams=180, range_max=81.83)
    path = write_carmen(tmp_path / ("f.log.gz" if gz else "f.log"), raw, make_odoms(3), gzip=gz)
    data = path.read_bytes()
    assert (data[:2] == b"\x1f\x8b") == gz  # gzip magic: the .gz file really is compressed
    text = (gzip.decompress(data) if gz else data).decode()
    assert text.count("FLASER") == 3 and "ODOM" in text
    with open_log(path) as log:
        scans, _ = split(log.messages())
    s = scans[0]
    assert s.range_max == 81.83 and s.angle_increment == pytest.approx(math.pi / 180)
    full = -math.pi / 2 + np.arange(180) * math.pi / 180
    np.testing.assert_allclose(s.angles, full[s.beam_index])


def _quaternion_times(k: float):
    """Orientation quaternions k times unit length (k = 0: zero length) for the odometry writers."""
    return lambda o: tuple(k * v for v in (0.0, 0.0, math.sin(o.theta / 2), math.cos(o.theta / 2)))


@pytest.mark.parametrize("fmt", sorted(ROS_WRITERS))
@pytest.mark.parametrize("k", [2.0, 0.5, -3.0])
def test_odometry_quaternions_are_normalised(fmt, k, tmp_path):
    """A quaternion k times unit length is the same rotation: the same theta (unnormalised, a ×2 one
    turned 0.3 rad into 0.9 rad), with one warning."""
    odoms = make_odoms()
    path = write_log(fmt, tmp_path, odoms=odoms, odom_quaternion=_quaternion_times(k))
    with open_log(path) as log:
        _, got = split(log.messages())
        warnings = log.stats.warnings
    assert [math.remainder(o.theta - e.theta, math.tau) for o, e in zip(got, odoms, strict=True)] == (
        pytest.approx([0.0] * len(odoms), abs=1e-12)
    )
    assert sum("not of unit length: normalised" in w for w in warnings) == 1


@pytest.mark.parametrize("fmt", sorted(ROS_WRITERS))
def test_zero_length_quaternion_skips_the_sample(fmt, tmp_path):
    """All-zero orientation is no rotation (it was read as theta 0): skipped, counted, warned."""
    unit, third = _quaternion_times(1.0), make_odoms()[3].stamp

    def zero_in_3(o):
        return (0.0,) * 4 if o.stamp == third else unit(o)

    path = write_log(fmt, tmp_path, odom_quaternion=zero_in_3)
    with open_log(path) as log:
        _, got = split(log.messages())
        stats = log.stats
    assert len(got) == len(make_odoms()) - 1 and third not in [o.stamp for o in got]
    assert stats.decode_failed == 1 and "zero-length orientation quaternion" in stats.warnings[0]


@pytest.mark.parametrize("fmt", sorted(ROS_WRITERS))
def test_zero_is_a_valid_stamp(fmt, tmp_path):
    """Simulated time (Gazebo, use_sim_time): header stamps from exactly 0.0 while the log times are
    wall-clock. The header stamps are used, 0.0 included (it used to fall back to the log time)."""
    raw = make_scans(t0=-0.05)  # scan stamps 0.0, 0.1, ...
    odoms = make_odoms(t0=0.0)
    path = write_log(fmt, tmp_path, raw, odoms, log_time_offset=1_700_000_000.0)
    with open_log(path) as log:
        scans, got = split(log.messages())
    assert scans[0].stamp == 0.0 and got[0].stamp == 0.0
    assert [s.stamp for s in scans] == pytest.approx([r.stamp for r in raw], abs=1e-9)
    assert [o.stamp for o in got] == pytest.approx([o.stamp for o in odoms], abs=1e-9)


def test_float32_round_off_in_quaternions_is_normalised_silently(tmp_path):
    """A quaternion computed in float32 (norm off by ~1e-7) is normalised without a warning."""

    def float32(o):
        return tuple(float(np.float32(v)) for v in _quaternion_times(1.0)(o))

    odoms = make_odoms()
    with open_log(write_log("mcap-cdr", tmp_path, odoms=odoms, odom_quaternion=float32)) as log:
        _, got = split(log.messages())
        assert log.stats.warnings == []
    assert [o.theta for o in got] == pytest.approx([o.theta for o in odoms], abs=1e-6)
