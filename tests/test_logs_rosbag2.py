"""ROS 2 bags as recorders leave them: a topic whose message definition is "unknown" (rosbag2 Iron+
records that for a type whose .msg it could not find), an MCAP cut by a killed recorder, a directory
without metadata.yaml, a metadata.yaml whose counts are stale, a ``.db3`` given alone. Each read
gives the scans and odometry of the intact bag (or of the part that is there)."""

from __future__ import annotations

import shutil
import sqlite3
from pathlib import Path

import numpy as np
import pytest
import yaml
from _log_fixtures import make_odoms, make_scans, split, write_log
from mcap.reader import make_reader
from mcap.writer import Writer

from cornerslam_cli.errors import LogError
from cornerslam_cli.logs import open_log


def _read(path):
    with open_log(path) as log:
        scans, odoms = split(log.messages())
        return scans, odoms, list(log.stats.warnings), log.info()


def _same(a, b) -> None:
    """Two reads' scans and odometry are the same (b may stop early: a cut file)."""
    (sa, oa), (sb, ob) = a[:2], b[:2]
    assert len(sb) > 0 and len(ob) > 0
    assert [s.stamp for s in sb] == [s.stamp for s in sa[: len(sb)]]
    for x, y in zip(sa, sb, strict=False):
        np.testing.assert_array_equal(x.ranges, y.ranges)
    assert [(o.stamp, o.x, o.y, o.theta) for o in ob] == [(o.stamp, o.x, o.y, o.theta) for o in oa[: len(ob)]]


@pytest.fixture
def bags(tmp_path):
    scans, odoms = make_scans(40), make_odoms(42)
    sq = write_log("rosbag2-sqlite3", tmp_path / "sq", scans, odoms)
    mc = write_log("rosbag2-mcap", tmp_path / "mc", scans, odoms)
    return sq, mc, _read(sq)


@pytest.mark.parametrize("encoding", ["unknown", ""])
def test_an_unknown_message_definition_in_sqlite3_storage_is_read_past(bags, tmp_path, encoding):
    sq, _, ref = bags
    bag = tmp_path / "unknown"
    shutil.copytree(sq, bag)
    with sqlite3.connect(next(bag.glob("*.db3"))) as db:
        db.execute(
            "INSERT INTO topics (name, type, serialization_format, offered_qos_profiles, "
            "type_description_hash) VALUES ('/custom', 'my_msgs/msg/Foo', 'cdr', '[]', 'RIHS01_00')"
        )
        db.execute(
            "INSERT INTO message_definitions (topic_type, encoding, encoded_message_definition, "
            "type_description_hash) VALUES ('my_msgs/msg/Foo', ?, '', 'RIHS01_00')",
            (encoding,),
        )
    got = _read(bag)  # rosbags 0.11 alone: KeyError 'unknown' ("cannot read ROS 2 bag 'unknown': 'unknown'")
    _same(ref, got)
    assert len(got[0]) == len(ref[0])


def _rewrite_mcap(src, dst, unknown_topic: bool = False, keep: float = 1.0) -> None:
    """``src`` copied to ``dst`` (with a channel of schema encoding "unknown" added; cut to ``keep``)."""
    with open(src, "rb") as f, open(dst, "wb") as g:
        w = Writer(g)
        w.start(profile="ros2", library="test")
        schemas, chans = {}, {}
        for schema, ch, m in make_reader(f).iter_messages():
            if schema.id not in schemas:
                schemas[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
            if ch.id not in chans:
                chans[ch.id] = w.register_channel(
                    ch.topic, ch.message_encoding, schemas[schema.id], ch.metadata
                )
            w.add_message(chans[ch.id], m.log_time, m.data, m.publish_time)
        if unknown_topic:
            sid = w.register_schema("my_msgs/msg/Foo", "unknown", b"")
            w.add_message(w.register_channel("/custom", "cdr", sid), 1, b"\x00\x01\x00\x00", 1)
        w.finish()
    if keep < 1.0:
        data = dst.read_bytes()
        dst.write_bytes(data[: int(len(data) * keep)])


def test_an_unknown_schema_encoding_in_mcap_storage_is_read_past(bags):
    _, mc, ref = bags
    f = next(mc.glob("*.mcap"))
    _rewrite_mcap(f, f.with_suffix(".tmp"), unknown_topic=True)
    f.with_suffix(".tmp").replace(f)
    got = _read(mc)
    _same(ref, got)
    assert got[3].format == "rosbag2" and "/custom" in {t.name for t in got[3].topics}


def test_a_bag_whose_mcap_was_cut_is_read_up_to_the_cut(bags):
    _, mc, ref = bags
    f = next(mc.glob("*.mcap"))
    data = f.read_bytes()
    f.write_bytes(data[: len(data) * 2 // 3])  # a killed recorder: no summary, no footer, a record cut
    scans, odoms, warnings, _ = got = _read(mc)
    _same(ref, got)
    assert len(scans) < len(ref[0]) and any("ends early" in w or "no end magic" in w for w in warnings)


@pytest.mark.parametrize("which", [0, 1])
def test_a_bag_without_metadata_is_read_from_its_one_storage_file_warned(bags, which):
    bag = bags[which]
    (bag / "metadata.yaml").unlink()
    scans, odoms, warnings, info = got = _read(bag)
    _same(bags[2], got)
    assert len(scans) == len(bags[2][0]) and info.format == "rosbag2"
    assert any("has no metadata.yaml" in w and "read alone" in w for w in warnings)


def test_a_bag_without_metadata_and_two_storage_files_says_to_reindex(bags, monkeypatch):
    sq = bags[0]
    (sq / "metadata.yaml").unlink()
    db = next(sq.glob("*.db3"))
    shutil.copy(db, sq / "second.db3")
    with pytest.raises(LogError, match="has no metadata.yaml and 2 storage files") as err:
        open_log(sq)
    assert "ros2 bag reindex" in err.value.hint and "give one log file" in err.value.hint
    # given as `.` from inside it: named by its own name, not '' (a hostile-user probe)
    monkeypatch.chdir(sq)
    with pytest.raises(LogError) as err:
        open_log(Path("."))
    assert f"directory '{sq.name}' has no metadata.yaml and 2 storage files (" in str(err.value)
    assert "`ros2 bag reindex .` writes" in err.value.hint


@pytest.mark.parametrize("which, edit", [(0, "empty"), (1, "empty"), (0, "start as text")])  # (mcap: unread)
def test_a_metadata_yaml_with_a_field_missing_or_mistyped_says_so(bags, which, edit):
    """rosbags' own words came through: "'NoneType' object is not subscriptable", "can only concatenate
    str (not "int") to str" (a hostile-user probe)."""
    bag = bags[which]
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())
    if edit == "empty":
        text = ""
    else:
        meta["rosbag2_bagfile_information"]["starting_time"]["nanoseconds_since_epoch"] = "abc"
        text = yaml.safe_dump(meta)
    (bag / "metadata.yaml").write_text(text)
    with pytest.raises(LogError, match="a field of its metadata.yaml or storage is missing or mis") as err:
        open_log(bag)
    assert "ros2 bag reindex" in err.value.hint


def test_negative_metadata_counts_are_unknown(bags):
    """`info` printed an edited metadata.yaml's "-5 msgs" as they were (a hostile-user probe)."""
    sq, _, ref = bags
    meta = yaml.safe_load((sq / "metadata.yaml").read_text())
    meta["rosbag2_bagfile_information"]["topics_with_message_count"][0]["message_count"] = -5
    (sq / "metadata.yaml").write_text(yaml.safe_dump(meta))
    scans, _, warnings, li = got = _read(sq)
    _same(ref, got)
    assert all(t.count is None for t in li.topics)
    assert any("counts a negative number of messages" in w for w in warnings)


def test_a_db3_given_alone_is_read(bags):
    sq, _, ref = bags
    got = _read(next(sq.glob("*.db3")))
    _same(ref, got)
    assert len(got[0]) == len(ref[0])


def test_stale_metadata_counts_are_unknown_not_an_empty_bag(bags):
    sq, _, ref = bags
    meta = yaml.safe_load((sq / "metadata.yaml").read_text())
    info = meta["rosbag2_bagfile_information"]
    info["message_count"] = 0
    for t in info["topics_with_message_count"]:
        t["message_count"] = 0
    (sq / "metadata.yaml").write_text(yaml.safe_dump(meta))
    scans, _, warnings, li = got = _read(sq)  # before: "topic '/scan' … has no messages"
    _same(ref, got)
    assert len(scans) == len(ref[0]) and li.n_messages is None
    assert any("metadata.yaml counts no messages" in w for w in warnings)


def test_a_split_mcap_bag_with_an_unknown_definition_names_it(bags):
    """Several MCAP files go through rosbags, which refuses an "unknown" schema encoding: say that, not
    a bare KeyError text ("cannot read ROS 2 bag 'mc': 'unknown' (check the bag)")."""
    _, mc, _ = bags
    f = next(mc.glob("*.mcap"))
    for name in ("a.mcap", "b.mcap"):
        _rewrite_mcap(f, mc / name, unknown_topic=True)
    f.unlink()
    meta = yaml.safe_load((mc / "metadata.yaml").read_text())
    meta["rosbag2_bagfile_information"]["relative_file_paths"] = ["a.mcap", "b.mcap"]
    (mc / "metadata.yaml").write_text(yaml.safe_dump(meta))
    with pytest.raises(
        LogError, match=r"a message definition is in an encoding rosbags does not read"
    ) as err:
        open_log(mc)
    assert "'unknown'" in str(err.value) and "one at a time" in err.value.hint


@pytest.mark.parametrize("storage", ["mcap", "db3"])
def test_a_split_bag_whose_last_file_is_cut_names_that_file(bags, storage):
    """A recorder killed mid-file leaves a split bag's last storage file cut: rosbags refused the whole
    bag with "File end magic is invalid. (check the bag)", naming no file (a ROS-user probe). The error
    now names the file and says to give the others one at a time."""
    sq, mc, _ = bags
    bag = sq if storage == "db3" else mc
    f = next(bag.glob(f"*.{storage}"))
    first, cut = bag / f"a.{storage}", bag / f"b.{storage}"
    f.rename(first)
    data = first.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())
    meta["rosbag2_bagfile_information"]["relative_file_paths"] = [first.name, cut.name]
    (bag / "metadata.yaml").write_text(yaml.safe_dump(meta))
    with pytest.raises(LogError, match=rf"its storage file 'b\.{storage}' cannot be read") as err:
        open_log(bag)
    assert "one at a time" in err.value.hint


def test_a_file_compressed_split_bag_names_no_file_it_cannot_open_alone(bags):
    """A review: in a file-compressed split bag (.db3.zstd) no file opens alone, so the first, good one
    was named as the cut one. Such a bag names none (rosbags' own error stands)."""
    from cornerslam_cli.logs.rosbag import _unreadable_storage

    sq, _, _ = bags
    meta = yaml.safe_load((sq / "metadata.yaml").read_text())
    info = meta["rosbag2_bagfile_information"]
    info["relative_file_paths"], info["compression_format"] = ["a.db3.zstd", "b.db3.zstd"], "zstd"
    (sq / "metadata.yaml").write_text(yaml.safe_dump(meta))
    (sq / "a.db3.zstd").write_bytes(b"\x28\xb5\x2f\xfd")
    (sq / "b.db3.zstd").write_bytes(b"")
    assert _unreadable_storage(sq) is None
    info["compression_format"] = ""  # (the same names, not compressed: the first is named)
    (sq / "metadata.yaml").write_text(yaml.safe_dump(meta))
    assert _unreadable_storage(sq) == "a.db3.zstd"


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_a_storage_file_of_a_bag_compressed_message_by_message_is_refused_alone(tmp_path, storage):
    """`compression_mode: message`: each message's bytes are zstd-compressed, so the storage file read
    alone gave "unsupported CDR encapsulation 28b5" for every message, then an error blaming --max-scans
    (a ROS-user probe). Refused in one line naming the bag's directory, which reads as the bag it is."""
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as BagWriter
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

    from cornerslam_cli.logs.writers import RosSerializer
    from cornerslam_cli.logs.writers.ros import RosTopics, ros_messages

    ros, bag = RosSerializer("cdr"), tmp_path / "packed"
    w = BagWriter(
        bag, version=9, storage_plugin={"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}[storage]
    )
    w.set_compression(CompressionMode.MESSAGE, CompressionFormat.ZSTD)
    w.open()
    conns = {}
    for topic, typename, t, data in ros_messages(ros, make_scans(10), make_odoms(12), RosTopics()):
        if topic not in conns:
            conns[topic] = w.add_connection(topic, typename, typestore=ros.store)
        w.write(conns[topic], t, data)
    w.close()
    (alone,) = [f for f in bag.iterdir() if f.name != "metadata.yaml"]
    with pytest.raises(LogError) as e:
        open_log(alone)
    assert str(e.value) == (
        f"'{alone}' is a storage file of the ROS 2 bag 'packed', whose messages are compressed one by one "
        f"(zstd): read alone, they cannot be decoded (give the bag's directory: {bag})"
    )
    scans, odoms, warnings, _ = _read(bag)
    assert len(scans) == 10 and len(odoms) == 12 and not warnings
