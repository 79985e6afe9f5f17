"""``cornerslam info``'s rates: each topic's messages over its own time span, not over the whole log's —
``ros2 bag record -a`` started before the robot (map_server's latched /map 120 s before the first scan)
showed a 10 Hz laser at 2 Hz (a hostile-user probe). The spans come from each format's index: an MCAP's
message indexes (or its scan when it has no summary), a ROS 1 bag's index, a ROS 2 bag's sqlite3
timestamp index, a CARMEN log's stamps of each tag's whole lines."""

from __future__ import annotations

import pytest
from _log_fixtures import make_odoms, make_scans, write_log

from cornerslam_cli.logs import open_log
from cornerslam_cli.logs.writers import RosSerializer

ROS = RosSerializer("cdr")
T0 = 1_700_000_000.0


def prelude_log(path, chunk_size: int | None = None):
    """/map (a latched one) 120 s before 40 scans at 10 Hz and 40 odometry samples at 10 Hz."""
    from mcap.writer import CompressionType, Writer

    msgs = [("/map", "nav_msgs/msg/OccupancyGrid", int((T0 - 120) * 1e9), b"\x00\x01\x00\x00")]
    msgs += [
        ("/scan", "sensor_msgs/msg/LaserScan", int(s.stamp * 1e9), ROS.laserscan(s)) for s in make_scans(40)
    ]
    msgs += [("/odom", "nav_msgs/msg/Odometry", int(o.stamp * 1e9), ROS.odometry(o, "odom", "base_link"))
             for o in make_odoms(40)]  # fmt: skip
    msgs.sort(key=lambda m: m[2])
    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.NONE, chunk_size=chunk_size or 1024 * 1024)
        w.start(profile="ros2", library="test")
        chans = {}
        for topic, typename, t, data in msgs:
            if topic not in chans:
                sid = w.register_schema(
                    typename, "ros2msg", b"" if topic == "/map" else ROS.msgdef(typename).encode()
                )
                chans[topic] = w.register_channel(topic, "cdr", sid)
            w.add_message(chans[topic], t, data, t)
        w.finish()
    return path


def rates(log) -> dict[str, float | None]:
    return {t.name: t.rate_hz for t in open_log(log).info().topics}


@pytest.mark.parametrize("chunk_size", [None, 2000])  # one chunk; many (the first and last read)
def test_mcap_rates_are_over_each_topics_own_span(tmp_path, chunk_size):
    r = rates(prelude_log(tmp_path / "p.mcap", chunk_size))
    assert r["/scan"] == pytest.approx(10.0) and r["/odom"] == pytest.approx(10.0)
    assert r["/map"] is None


def test_mcap_rates_without_a_summary_come_from_its_scan(tmp_path):
    whole = prelude_log(tmp_path / "p.mcap", 2000).read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(whole[: len(whole) * 9 // 10])  # no summary, no footer: the data section is scanned
    log = open_log(cut)
    assert any("ends early" in w or "no end magic" in w for w in log.stats.warnings)
    r = {t.name: t.rate_hz for t in log.info().topics}
    assert r["/scan"] == pytest.approx(10.0)


@pytest.mark.parametrize("fmt", ["rosbag1", "rosbag2-sqlite3", "rosbag2-mcap", "mcap-cdr"])
def test_every_format_gives_each_topics_span(tmp_path, fmt):
    """The odometry runs 0.05 s before and after the scans: their rates differ from the log's span's."""
    scans, odoms = make_scans(20), make_odoms(22, t0=T0 - 0.05)
    log = write_log(fmt, tmp_path, scans, odoms)
    spans = open_log(log).source.topic_spans()
    assert spans["/scan"] == pytest.approx((scans[0].stamp * 1e9, scans[-1].stamp * 1e9), abs=1e3)  # ns
    r = rates(log)
    assert r["/scan"] == pytest.approx(10.0, rel=1e-6) and r["/odom"] == pytest.approx(10.0, rel=1e-6)


def test_carmen_rates_are_each_tags_over_its_own_stamps(tmp_path):
    """NEFF lines carry no stamp: no rate (they had the log's); FLASER's over its own lines' stamps."""
    p = tmp_path / "x.log"
    odom = "".join(f"ODOM 0 0 0 0 0 0 {T0 + 0.05 * i} h {T0 + 0.05 * i}\n" for i in range(101))
    laser = "".join(f"FLASER 3 1 1 1 0 0 0 0 0 0 {T0 + 1 + 0.5 * i} h {T0 + 1 + 0.5 * i}\n" for i in range(7))
    p.write_text(odom + laser + "NEFF 1 2 3\nNEFF 4 5 6\n")
    r = rates(p)
    assert r["ODOM"] == pytest.approx(20.0) and r["FLASER"] == pytest.approx(2.0) and r["NEFF"] is None


def test_a_topic_named_almost_right_gets_a_suggestion(tmp_path):
    """--scan-topic /sacn, --odom-topic /odm: "did you mean '/scan'?" (a probe's nits); a relative name
    (`--scan-topic scan`, as ROS 1 users give it: `rostopic echo scan`) is the root namespace's topic."""
    from cornerslam_cli.errors import LogError

    log = write_log("mcap-cdr", tmp_path)
    relative = open_log(log, scan_topic="scan", odom_topic="odom")
    relative.check()
    assert (relative.scan_topic, relative.odom_topic) == ("/scan", "/odom")
    for kw, said in (({"scan_topic": "/sacn"}, "/scan"), ({"odom_topic": "/odm"}, "/odom")):
        with pytest.raises(LogError) as err:
            open_log(log, **kw).check()
        assert f"did you mean '{said}'?" in err.value.hint
    with pytest.raises(LogError) as err:
        open_log(log, scan_topic="/nothing_alike").check()
    assert "did you mean" not in err.value.hint


def test_info_columns_line_up_under_a_long_type_name(tmp_path):
    from dataclasses import replace

    from cornerslam_cli.report.text import info_lines

    p = prelude_log(tmp_path / "p.mcap")
    info = open_log(p).info()
    long = replace(info.topics[0], msgtype="geometry_msgs/PoseWithCovarianceStamped")
    lines = info_lines(p, replace(info, topics=(long, *info.topics[1:])), None)
    rows = [line for line in lines if " msgs" in line]
    assert len({line.index(" msgs") for line in rows}) == 1  # the counts' column the same on every row


@pytest.mark.parametrize("zeroed", [(0, 8), (8,)])  # the start and end times' offsets; the end times' only
def test_mcap_rates_when_the_chunk_index_times_are_zero(tmp_path, zeroed):
    """Some writers leave a chunk's start and end times 0 (the reader trusts them nowhere): the first and
    last chunk by those times were the wrong ones (/scan at 39 Hz on 4 chunks, none on 28); now every
    chunk holding the topic is read."""
    import struct

    data = bytearray(prelude_log(tmp_path / "p.mcap", 2000).read_bytes())
    (summary_start,) = struct.unpack_from("<Q", data, len(data) - 8 - 20)  # the footer's
    for start, end, op in ((summary_start, len(data) - 8, 0x08), (8, summary_start, 0x06)):  # indexes, chunks
        pos = start
        while pos < end:
            code, length = struct.unpack_from("<BQ", data, pos)
            if code == op:
                for at in zeroed:
                    struct.pack_into("<Q", data, pos + 9 + at, 0)
            pos += 9 + length
    zero = tmp_path / "zero.mcap"
    zero.write_bytes(bytes(data))
    log = open_log(zero)
    assert len(log.source.index.chunks) > 3
    r = {t.name: t.rate_hz for t in log.info().topics}
    assert r["/scan"] == pytest.approx(10.0) and r["/odom"] == pytest.approx(10.0)


def test_messages_a_nanosecond_apart_get_no_rate(tmp_path):
    """Two static broadcasters latched at the start: two /tf_static messages 1 ns apart showed
    "1000000000.00 Hz" (a ROS-user probe); no rate under a millisecond's span."""
    from _log_fixtures import write_messages_mcap

    t = int(T0 * 1e9)
    msgs = [("/tf_static", "tf2_msgs/msg/TFMessage", t + i, ROS.tf(T0, "base_link", f"l{i}", 0.1, 0.0, 0.0))
            for i in range(2)]  # fmt: skip
    msgs += [
        ("/scan", "sensor_msgs/msg/LaserScan", int(s.stamp * 1e9), ROS.laserscan(s)) for s in make_scans(5)
    ]
    log = write_messages_mcap(tmp_path / "static.mcap", sorted(msgs, key=lambda m: m[2]))
    topics = {i.name: i for i in open_log(log).info().topics}
    assert topics["/tf_static"].count == 2 and topics["/tf_static"].rate_hz is None
    assert topics["/scan"].rate_hz == pytest.approx(10.0, rel=1e-6)


def test_the_clock_note_is_not_given_when_the_run_takes_the_recorders_times(sim_log, tmp_path):
    """Header stamps 1000 s behind the log times: info notes that a run stamps its outputs on the headers'
    — not so under input.stamps=receive, which takes the recorder's (a ROS-user probe: it said both)."""
    from _log_fixtures import rewrite_mcap

    log = rewrite_mcap(
        sim_log, tmp_path / "late.mcap", lambda schema, m: (m.log_time + 10**12, m.publish_time, m.data)
    )
    header = open_log(log).info().notes
    assert any("header stamps are 1000.0 s behind its record times" in n for n in header), header
    assert not any("record times" in n for n in open_log(log, stamps="receive").info().notes)
