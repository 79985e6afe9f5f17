"""MCAP reading: damage tolerance (truncation, corrupt chunks) and the LaserScan decoders."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from _log_fixtures import make_odoms, make_scans

from cornerslam_cli.errors import LogError
from cornerslam_cli.logs import open_log
from cornerslam_cli.logs.cdr import DecodeError, decode_laserscan_cdr, decode_laserscan_ros1, typestore
from cornerslam_cli.logs.writers import RawScan, RosSerializer, write_mcap

N = 120


@pytest.fixture(scope="module", params=["zstd", "none", "lz4"])
def full_log(request, tmp_path_factory):
    """A 120-scan log in ~10 chunks, and the stamps a complete read yields."""
    p = tmp_path_factory.mktemp("m") / f"full-{request.param}.mcap"
    write_mcap(p, make_scans(N, beams=361), make_odoms(N), compression=request.param, chunk_size=32_000)
    stamps = [m.stamp for m in open_log(p).messages()]
    assert len(stamps) == 2 * N
    return p, stamps


@pytest.mark.parametrize("frac", [0.12, 0.35, 0.5, 0.77, 0.93, 0.999])
def test_truncated_yields_prefix_with_warning(full_log, frac, tmp_path, caplog):
    p, stamps = full_log
    data = p.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * frac)])
    with caplog.at_level(logging.WARNING, logger="cornerslam.logs"):
        log = open_log(cut)
        got = [m.stamp for m in log.messages()]
    assert got == stamps[: len(got)]  # a prefix, in order
    assert len(got) >= int(0.7 * frac * len(stamps)) - 30  # everything before the cut but the last chunk tail
    assert "no end magic" in caplog.text
    assert log.stats.warnings


def test_truncated_inside_cut_chunk_keeps_readable_part(full_log, tmp_path):
    p, stamps = full_log
    data = p.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    assert len(list(open_log(cut).messages())) > 0


def test_cut_after_magic_is_a_log_error(full_log, tmp_path):
    p, _ = full_log
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(p.read_bytes()[:20])
    with pytest.raises(LogError, match="no sensor_msgs/LaserScan"):
        open_log(cut).messages()


def test_corrupt_chunk_skipped_with_warning(tmp_path, caplog):
    p = tmp_path / "c.mcap"
    write_mcap(p, make_scans(N, beams=361), make_odoms(N), compression="none", chunk_size=32_000)
    from mcap.reader import make_reader

    with open(p, "rb") as f:
        chunk = make_reader(f).get_summary().chunk_indexes[3]
    data = bytearray(p.read_bytes())
    mid = chunk.chunk_start_offset + chunk.chunk_length // 2
    data[mid : mid + 64] = bytes(64)  # zero 64 bytes inside a chunk: CRC fails
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    with caplog.at_level(logging.WARNING, logger="cornerslam.logs"):
        log = open_log(bad)
        stamps = [m.stamp for m in log.messages()]
    assert 0 < len(stamps) < 2 * N and stamps == sorted(stamps)
    assert "CRC" in caplog.text or "skipped" in caplog.text
    assert "summary lists" in caplog.text  # lost count known from the summary


def test_overlapping_chunks_merged_in_log_time_order(tmp_path):
    """Two chunks whose time ranges interleave (as written by two recorders) come out sorted."""
    from mcap.writer import CompressionType, Writer

    ros = RosSerializer("cdr")
    scans, odoms = make_scans(40), make_odoms(40)
    p = tmp_path / "o.mcap"
    with open(p, "wb") as f:
        w = Writer(f, compression=CompressionType.NONE, chunk_size=10**9)
        w.start("ros2", "t")
        s = w.register_schema(
            "sensor_msgs/msg/LaserScan", "ros2msg", ros.msgdef("sensor_msgs/msg/LaserScan").encode()
        )
        o = w.register_schema(
            "nav_msgs/msg/Odometry", "ros2msg", ros.msgdef("nav_msgs/msg/Odometry").encode()
        )
        cs, co = w.register_channel("/scan", "cdr", s), w.register_channel("/odom", "cdr", o)
        for sc in scans:  # all scans in one chunk ...
            w.add_message(cs, int(sc.stamp * 1e9), ros.laserscan(sc), 0)
        w._maybe_finalize_chunk(force=True) if hasattr(w, "_maybe_finalize_chunk") else None
        for od in odoms:  # ... all odometry after them
            w.add_message(co, int(od.stamp * 1e9), ros.odometry(od, "odom", "base_link"), 0)
        w.finish()
    got = [m.stamp for m in open_log(p).messages()]
    assert len(got) == 80 and got == sorted(got)


def _ref(raw, enc):
    store = typestore(enc)
    if enc == "ros1":
        return store.deserialize_ros1(raw, "sensor_msgs/msg/LaserScan")
    return store.deserialize_cdr(raw, "sensor_msgs/msg/LaserScan")


@pytest.mark.parametrize("enc", ["cdr", "ros1", "cdr-be"])
@pytest.mark.parametrize("frame", ["", "l", "la", "las", "laser", "base_laser_link", "ünï"])
def test_decoder_equals_rosbags(enc, frame):
    rng = np.random.default_rng(len(frame))
    ros = RosSerializer("ros1" if enc == "ros1" else "cdr")
    s = RawScan(1234.5678, -2.1, 0.0043, rng.uniform(0, 30, 1081).astype(np.float32), 0.02, 30.0, frame)
    raw = ros.laserscan(s)
    if enc == "cdr-be":
        raw = bytes(
            ros.store.serialize_cdr(_ref(raw, "cdr"), "sensor_msgs/msg/LaserScan", little_endian=False)
        )
    ref = _ref(raw, "ros1" if enc == "ros1" else "cdr")
    dec = decode_laserscan_ros1 if enc == "ros1" else decode_laserscan_cdr
    (sec, nsec), fr, a_min, a_max, a_inc, r_min, r_max, ranges = dec(raw)
    assert (sec, nsec) == (ref.header.stamp.sec, ref.header.stamp.nanosec)
    assert fr == ref.header.frame_id
    assert (a_min, a_max, a_inc, r_min, r_max) == (
        ref.angle_min,
        ref.angle_max,
        ref.angle_increment,
        ref.range_min,
        ref.range_max,
    )
    np.testing.assert_array_equal(ranges, ref.ranges)


@pytest.mark.parametrize("dec", [decode_laserscan_cdr, decode_laserscan_ros1])
def test_decoder_rejects_short_messages(dec):
    ros = RosSerializer("ros1" if dec is decode_laserscan_ros1 else "cdr")
    raw = ros.laserscan(RawScan(1.0, -1.0, 0.01, np.ones(50), 0.0, 5.0))
    for n in (0, 3, 20, 40, len(raw) - 1):
        with pytest.raises(DecodeError):
            dec(raw[:n])


@pytest.mark.parametrize("enc", ["cdr", "ros1"])
@pytest.mark.parametrize(
    "frames", [("", ""), ("o", "b"), ("odom", "base_link"), ("odom_x", "base_footprint1")]
)
def test_odometry_decoder_equals_rosbags(enc, frames):
    from cornerslam_cli.logs.cdr import decode_odometry_cdr, decode_odometry_ros1
    from cornerslam_cli.types import OdomSample

    ros = RosSerializer(enc)
    raw = ros.odometry(OdomSample(1234.5, 1.25, -3.5, 2.0), *frames)
    store = typestore(enc)
    name = "nav_msgs/msg/Odometry"
    ref = store.deserialize_ros1(raw, name) if enc == "ros1" else store.deserialize_cdr(raw, name)
    stamp, x, y, q = (decode_odometry_ros1 if enc == "ros1" else decode_odometry_cdr)(raw)
    p, o = ref.pose.pose.position, ref.pose.pose.orientation
    assert stamp == (ref.header.stamp.sec, ref.header.stamp.nanosec)
    assert (x, y, q) == (p.x, p.y, (o.x, o.y, o.z, o.w))
    with pytest.raises(DecodeError):
        (decode_odometry_ros1 if enc == "ros1" else decode_odometry_cdr)(raw[:40])
