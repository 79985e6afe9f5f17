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
    ranges = rng.uniform(0, 30, 1081).astype(np.float32)
    s = RawScan(1234.5678, -2.1, 0.0043, ranges, 0.02, 30.0, frame, time_increment=1.3e-4)
    raw = ros.laserscan(s)
    if enc == "cdr-be":
        raw = bytes(
            ros.store.serialize_cdr(_ref(raw, "cdr"), "sensor_msgs/msg/LaserScan", little_endian=False)
        )
    ref = _ref(raw, "ros1" if enc == "ros1" else "cdr")
    dec = decode_laserscan_ros1 if enc == "ros1" else decode_laserscan_cdr
    (sec, nsec), fr, a_min, a_max, a_inc, r_min, r_max, ranges, t_inc = dec(raw)
    assert (sec, nsec) == (ref.header.stamp.sec, ref.header.stamp.nanosec)
    assert fr == ref.header.frame_id
    assert (a_min, a_max, a_inc, r_min, r_max, t_inc) == (
        ref.angle_min,
        ref.angle_max,
        ref.angle_increment,
        ref.range_min,
        ref.range_max,
        ref.time_increment,
    )
    assert t_inc == pytest.approx(1.3e-4)
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


# ---------------------------------------------------------------------------- JSON messages
@pytest.mark.parametrize("enc", ["json", "json-ros1"])
def test_json_messages_decode_to_what_cdr_ones_do(enc, tmp_path):
    """A foxglove_bridge / rosbridge recording (JSON, ROS 2 or ROS 1 field names, NaN/inf ranges as
    null) gives the same scans, odometry and laser mount as the CDR recording of the same data."""
    scans, odoms = make_scans(30), make_odoms(30)
    read = {}
    for e in ("cdr", enc):
        with open_log(
            write_mcap(tmp_path / f"{e}.mcap", scans, odoms, encoding=e, tf_static=(0.1, 0.0, 0.3))
        ) as log:
            read[e] = (list(log.messages()), log.laser_to_base(), log.stats)
    (want, mount, _), (got, json_mount, stats) = read["cdr"], read[enc]
    assert json_mount == pytest.approx(mount) and len(got) == len(want) == 60
    for a, b in zip(got, want, strict=True):
        assert type(a) is type(b) and a.stamp == b.stamp
        if hasattr(a, "ranges"):
            np.testing.assert_array_equal(a.ranges, b.ranges)
            np.testing.assert_array_equal(a.beam_index, b.beam_index)
        else:
            assert (a.x, a.y, a.theta) == pytest.approx((b.x, b.y, b.theta), abs=1e-12)
    assert stats.beams_dropped > 0 and stats.decode_failed == 0


@pytest.mark.parametrize(
    "payload, match",
    [
        (b"{not json", "not JSON"),
        (b"[1, 2]", "not an object"),
        (b'{"header": {"stamp": {"sec": 1, "nanosec": 0}, "frame_id": "l"}}', "no field 'ranges'"),
        (b'{"header": {"frame_id": "l"}, "ranges": []}', "no field 'header.stamp'|no field 'angle_min'"),
        (b'{"header": {"stamp": {"sec": 1, "nanosec": 0}, "frame_id": "l"}, "ranges": ["a"], "angle_min": 0}',
         "other than numbers"),
    ],
)  # fmt: skip
def test_json_decoder_names_what_is_wrong(payload, match):
    from cornerslam_cli.logs.base import Channel
    from cornerslam_cli.logs.jsonmsg import JsonDecoder

    with pytest.raises(DecodeError, match=match):
        JsonDecoder(Channel("/scan", "sensor_msgs/msg/LaserScan", "json")).laserscan(payload)


def test_undecodable_json_messages_are_counted_not_fatal(tmp_path):
    """Every fifth scan's JSON is cut in half: those are skipped, counted and warned, the rest read."""
    from _log_fixtures import write_messages_mcap

    from cornerslam_cli.logs.writers import JsonSerializer

    js = JsonSerializer()
    msgs = [("/odom", "nav_msgs/msg/Odometry", int(o.stamp * 1e9), js.odometry(o, "odom", "base_link"))
            for o in make_odoms(20)]  # fmt: skip
    for i, s in enumerate(make_scans(20)):
        data = js.laserscan(s)
        msgs.append(
            (
                "/scan",
                "sensor_msgs/msg/LaserScan",
                int(s.stamp * 1e9),
                data[: len(data) // 2] if i % 5 == 0 else data,
            )
        )
    p = write_messages_mcap(tmp_path / "j.mcap", sorted(msgs, key=lambda m: m[2]), encoding="json")
    with open_log(p) as log:
        scans = [m for m in log.messages() if hasattr(m, "ranges")]
        assert len(scans) == 16 and log.stats.decode_failed == 4
        assert "cannot decode" in log.stats.warnings[0] and "not JSON" in log.stats.warnings[0]


@pytest.mark.parametrize("topic", ["/scan", "/odom"])
def test_a_topic_in_another_encoding_is_a_log_error_naming_it(topic, tmp_path):
    """protobuf (or flatbuffer, cbor...) under a ROS type name: info shows it, run refuses it."""
    from mcap.writer import Writer

    from cornerslam_cli.logs.writers import JsonSerializer

    js = JsonSerializer()
    p = tmp_path / "p.mcap"
    with open(p, "wb") as f:
        w = Writer(f)
        w.start("", "test")
        ids = {}
        for name, typ in (("/scan", "sensor_msgs/msg/LaserScan"), ("/odom", "nav_msgs/msg/Odometry")):
            enc = "protobuf" if name == topic else "json"
            ids[name] = w.register_channel(name, enc, w.register_schema(typ, enc, b"x"))
        for s, o in zip(make_scans(5), make_odoms(5), strict=True):
            w.add_message(ids["/odom"], int(o.stamp * 1e9), js.odometry(o, "odom", "base_link"), 0)
            w.add_message(ids["/scan"], int(s.stamp * 1e9), js.laserscan(s), 0)
        w.finish()
    log = open_log(p)
    info = log.info()
    assert {t.name: t.encoding_note for t in info.topics}[topic] == "protobuf: not readable"
    assert f"topic '{topic}' of log 'p.mcap' has message encoding 'protobuf'" in info.problems[0]
    for call in (log.messages, log.laser_to_base, log.check):
        with pytest.raises(LogError, match=f"'{topic}' of log 'p.mcap' has message encoding 'protobuf'"):
            call()


# ---------------------------------------------------------------------------- reading order, memory
def test_chunks_out_of_time_order_are_read_in_log_time_order(tmp_path):
    """A valid file whose chunks are shuffled (blocks of 7 messages): the chunk index gives the order,
    so the read equals the read of the sorted file (it lost most messages to 'backwards' stamps)."""
    scans, odoms = make_scans(N, beams=91), make_odoms(N)
    ordered = [
        (m.stamp, type(m).__name__)
        for m in open_log(write_mcap(tmp_path / "a.mcap", scans, odoms)).messages()
    ]
    shuffled = write_mcap(tmp_path / "b.mcap", scans, odoms, shuffle_blocks=7)
    with open_log(shuffled) as log:
        got = [(m.stamp, type(m).__name__) for m in log.messages()]
        assert log.stats.warnings == []
    assert got == ordered and len(got) == 2 * N


def test_summary_without_channel_records_reads_the_channels_from_the_data(tmp_path):
    """A summary with statistics and chunk indexes but no channel/schema records (mcap's
    repeat_channels=False): the topics are those of the data section, not 'no LaserScan topic'."""
    scans, odoms = make_scans(N, beams=91), make_odoms(N)
    full = write_mcap(tmp_path / "a.mcap", scans, odoms, chunk_size=8_000)
    bare = write_mcap(tmp_path / "b.mcap", scans, odoms, chunk_size=8_000, repeat_channels=False)
    with open_log(full) as a, open_log(bare) as b:
        assert b.info().topics == a.info().topics and b.info().problems == ()
        want, got = list(a.messages()), list(b.messages())
        assert b.stats.warnings == []
    assert [m.stamp for m in got] == [m.stamp for m in want] and len(got) == 2 * N


@pytest.mark.parametrize("summary", [True, False])
def test_a_topic_on_several_channels_is_counted_as_one(tmp_path, summary):
    """A topic with two channel records (a ROS 1 bag's connections converted, a channel registered again;
    here the second after the last scan, with no messages): its count is the sum, not the last channel's
    0, which made ``check()`` say the topic has no messages."""
    from mcap.writer import IndexType, Writer

    from cornerslam_cli.logs.writers import serializer
    from cornerslam_cli.logs.writers.ros import RosTopics, ros_messages

    ros = serializer("cdr")
    kw = {} if summary else dict(use_statistics=False, use_summary_offsets=False, index_types=IndexType.NONE)
    p = tmp_path / "two_channels.mcap"
    with open(p, "wb") as f:
        w = Writer(f, **kw)
        w.start(profile="ros2", library="test")
        chans = {}
        for topic, typename, t, data in ros_messages(ros, make_scans(N), make_odoms(N), RosTopics()):
            if topic not in chans:
                sid = w.register_schema(typename, ros.schema_encoding, ros.msgdef(typename).encode())
                chans[topic] = (w.register_channel(topic, ros.message_encoding, sid), sid)
            w.add_message(chans[topic][0], t, data, t)
        w.register_channel("/scan", ros.message_encoding, chans["/scan"][1])
        w.finish()
    with open_log(p) as log:
        assert {t.name: t.count for t in log.info().topics} == {"/scan": N, "/odom": N}
        assert len([m for m in log.messages() if hasattr(m, "ranges")]) == N


def _zero_chunk_start_times(src, dst, keep_summary: bool):
    """Copy of an MCAP with message_start_time 0 in every chunk header and chunk index record (as some
    writers leave it); without the summary section if not ``keep_summary``."""
    import struct

    from fault_corpus import mcap_records

    data = bytearray(src.read_bytes())
    for op, start, _ in list(mcap_records(bytes(data))):
        if op in (0x06, 0x08):  # Chunk, ChunkIndex: message_start_time first
            struct.pack_into("<Q", data, start, 0)
    if not keep_summary:  # cut at the DataEnd record: a recording without summary and footer
        data = data[: next(s - 9 for op, s, _ in mcap_records(bytes(data)) if op == 0x0F)]
    dst.write_bytes(bytes(data))
    return dst


@pytest.mark.parametrize("keep_summary", [True, False])
def test_reorder_buffer_is_bounded_when_chunk_start_times_are_0(keep_summary, tmp_path, monkeypatch):
    """Chunk headers claiming start time 0 held every message back (up to 100,000 of them): the heap
    now releases on the chunks' real first message, holding about one chunk. With the buffer limited
    to two chunks' worth, the read is complete, in order, and never hits the limit."""
    import cornerslam_cli.logs.mcap as mcap_mod

    src = write_mcap(tmp_path / "s.mcap", make_scans(N, beams=361), make_odoms(N), chunk_size=32_000)
    p = _zero_chunk_start_times(src, tmp_path / "z.mcap", keep_summary)
    monkeypatch.setattr(mcap_mod, "REORDER_BYTES", 2 * 32_000)
    with open_log(p) as log:
        stamps = [m.stamp for m in log.messages()]
        assert not [w for w in log.stats.warnings if "overlap" in w]
    assert stamps == sorted(stamps) and len(stamps) == 2 * N


def test_reorder_buffer_limit_releases_early_with_a_warning(tmp_path, monkeypatch):
    """Chunks that all span the whole log (worst case) cannot be merged in bounded memory: past
    REORDER_BYTES the oldest messages go out early, warned; nothing is lost."""
    import cornerslam_cli.logs.mcap as mcap_mod

    p = write_mcap(tmp_path / "s.mcap", make_scans(N, beams=361), make_odoms(N), chunk_size=32_000)
    src = mcap_mod.McapSource(p, mcap_mod.ReadStats())
    ids = sorted(src.index.channels)
    every_third = [
        [(ids[i % 2], t, memoryview(bytes(1000))) for i, t in enumerate(range(k, 3000, 3))] for k in range(3)
    ]
    monkeypatch.setattr(src, "_index_order", lambda wanted: iter(every_third))
    monkeypatch.setattr(mcap_mod, "REORDER_BYTES", 1500 * 1000)
    got = [t for _, t, _ in src.raw_messages({"/scan", "/odom"})]
    assert sorted(got) == list(range(3000)) and got != sorted(got)
    assert any("overlap in log time" in w for w in src.stats.warnings)
    monkeypatch.setattr(mcap_mod, "REORDER_BYTES", 64 << 20)
    assert [t for _, t, _ in src.raw_messages({"/scan", "/odom"})] == list(range(3000))


def test_tf_quaternions_in_json_normalised_or_ignored(tmp_path):
    """tf as JSON: odometry from tf odom→base_link with a ×2 quaternion gives the right yaw; a static
    base_link→laser transform with a zero-length rotation is ignored (warned), not read as yaw 0; a
    schemaless channel shows as '(no schema)'."""
    import json
    import math

    from _log_fixtures import write_messages_mcap

    from cornerslam_cli.logs.writers import JsonSerializer

    js = JsonSerializer()

    def tf(stamp, parent, child, x, q):
        rot = dict(zip("xyzw", q, strict=True))
        t = {"header": js.header(stamp, parent), "child_frame_id": child,
             "transform": {"translation": {"x": x, "y": 0.0, "z": 0.0}, "rotation": rot}}  # fmt: skip
        return json.dumps({"transforms": [t]}).encode()

    scans, odoms = make_scans(10), make_odoms(10)
    msgs = [("/tf_static", "tf2_msgs/msg/TFMessage", 0, tf(0.0, "base_link", "laser", 0.2, (0.0,) * 4))]
    for o in odoms:
        q = (0.0, 0.0, 2 * math.sin(o.theta / 2), 2 * math.cos(o.theta / 2))
        msgs.append(
            ("/tf", "tf2_msgs/msg/TFMessage", int(o.stamp * 1e9), tf(o.stamp, "odom", "base_link", o.x, q))
        )
    msgs += [("/scan", "sensor_msgs/msg/LaserScan", int(s.stamp * 1e9), js.laserscan(s)) for s in scans]
    p = write_messages_mcap(tmp_path / "tf.mcap", sorted(msgs, key=lambda m: m[2]), encoding="json")
    with open_log(p) as log:
        got = [m for m in log.messages() if not hasattr(m, "ranges")]
        assert log.laser_to_base() is None
        assert any(
            "base_link→laser has a zero-length rotation quaternion, no rotation (tf2 refuses it): the "
            "transform is not used" in w
            for w in log.stats.warnings
        )
    assert [g.theta for g in got] == pytest.approx([o.theta for o in odoms], abs=1e-12)

    from mcap.writer import Writer

    with open(tmp_path / "nos.mcap", "wb") as f:
        w = Writer(f)
        w.start("", "test")
        w.add_message(w.register_channel("/points", "json", 0), 1, b"{}", 1)
        w.finish()
    assert [t.msgtype for t in open_log(tmp_path / "nos.mcap").info().topics] == ["(no schema)"]
