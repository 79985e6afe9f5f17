"""The robot's frame is the one the odometry gives the pose of: a nav_msgs/Odometry's child_frame_id.

A TurtleBot's tree: /odom tracks base_footprint, /tf_static has base_footprint→base_link (x = −0.5
here) and base_link→laser (x = 0.6). The laser is then at x = 0.1 on the robot the odometry moves —
not at base_link's 0.6, which a run took before (exit 0, no warning) when input.base_frame was left
at base_link.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from _log_fixtures import make_odoms, make_scans, write_messages_mcap
from click.testing import CliRunner
from mcap.reader import make_reader
from rosbags.typesys import Stores, get_typestore

from cornerslam_cli.cli import cli
from cornerslam_cli.errors import LogError
from cornerslam_cli.logs import open_log
from cornerslam_cli.logs.cdr import odometry_frame_cdr, odometry_frame_ros1
from cornerslam_cli.logs.writers import RawScan, serializer
from cornerslam_cli.types import OdomSample

ENCODINGS = ("cdr", "ros1", "json")


def _turtlebot(path, encoding: str, child: str = "base_footprint", tf=(("base_footprint", "base_link", -0.5),
               ("base_link", "laser", 0.6)), scans=None, odoms=None, on_tf=()):  # fmt: skip
    """An MCAP of scans on frame ``laser``, odometry odom→``child`` and a /tf_static of ``tf`` (parent,
    child, x) edges; with ``on_tf`` (children of odom) the odometry as /tf odom→each of them instead."""
    ros = serializer(encoding)
    scans = make_scans(6) if scans is None else scans
    odoms = make_odoms(8) if odoms is None else odoms
    t0 = min(scans[0].stamp, odoms[0].stamp) - 0.01
    msgs = [
        ("/tf_static", "tf2_msgs/msg/TFMessage", int(t0 * 1e9), ros.tf(t0, p, c, x, 0.0, 0.0))
        for p, c, x in tf
    ]
    msgs += [("/scan", "sensor_msgs/msg/LaserScan", int(s.stamp * 1e9), ros.laserscan(s)) for s in scans]
    msgs += [
        ("/odom", "nav_msgs/msg/Odometry", int(o.stamp * 1e9), ros.odometry(o, "odom", child))
        for o in odoms
        if not on_tf
    ]
    msgs += [
        ("/tf", "tf2_msgs/msg/TFMessage", int(o.stamp * 1e9), ros.tf(o.stamp, "odom", c, o.x, o.y, o.theta))
        for o in odoms
        for c in on_tf
    ]
    return write_messages_mcap(path, sorted(msgs, key=lambda m: m[2]), encoding=encoding)


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_the_mount_is_taken_in_the_odometry_s_child_frame(tmp_path, encoding):
    log = _turtlebot(tmp_path / "tb.mcap", encoding)
    with open_log(log) as r:
        assert r.laser_to_base() == pytest.approx((0.1, 0.0, 0.0), abs=1e-12)
        assert r.base_frame == "base_footprint"
        assert not r.stats.warnings
    # with the config's base_link named by the messages themselves: base_link's mount, as before
    same = _turtlebot(tmp_path / "bl.mcap", encoding, child="base_link")
    with open_log(same) as r:
        assert r.laser_to_base() == pytest.approx((0.6, 0.0, 0.0), abs=1e-12) and r.base_frame == "base_link"


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_an_empty_child_frame_leaves_the_config_s_base_frame(tmp_path, encoding):
    log = _turtlebot(tmp_path / "e.mcap", encoding, child="")
    with open_log(log) as r:
        assert r.laser_to_base() == pytest.approx((0.6, 0.0, 0.0), abs=1e-12) and r.base_frame == "base_link"
    with open_log(log, base_frame="base_footprint") as r:
        assert r.laser_to_base() == pytest.approx((0.1, 0.0, 0.0), abs=1e-12)


def test_a_child_frame_the_tf_does_not_link_falls_back_to_the_config_s_warned(tmp_path):
    log = _turtlebot(tmp_path / "u.mcap", "cdr", child="chassis")
    with open_log(log) as r:
        assert r.laser_to_base() == pytest.approx((0.6, 0.0, 0.0), abs=1e-12) and r.base_frame == "base_link"
        (w,) = r.stats.warnings
        assert "'chassis' (its child_frame_id)" in w and "base_link→laser" in w


def test_without_any_tf_for_the_laser_the_odometry_s_frame_is_named(tmp_path):
    log = _turtlebot(tmp_path / "n.mcap", "cdr", tf=(("base_footprint", "imu", 0.2),))
    with open_log(log) as r:
        assert r.laser_to_base() is None and r.base_frame == "base_footprint"


@pytest.mark.parametrize("child", ["", "b", "base_footprint", "abc", "/robot1/base_footprint_long_name"])
@pytest.mark.parametrize("frame_id", ["", "odom", "od"])
def test_child_frame_decoding_matches_rosbags(child, frame_id):
    """The hand decoder against rosbags' deserializer, over string lengths that move every alignment."""
    o = OdomSample(12.5, 1.0, -2.0, 0.3)
    for enc, decode, store, deserialize in (
        ("cdr", odometry_frame_cdr, Stores.ROS2_HUMBLE, "deserialize_cdr"),
        ("ros1", odometry_frame_ros1, Stores.ROS1_NOETIC, "deserialize_ros1"),
    ):
        raw = serializer(enc).odometry(o, frame_id, child)
        want = getattr(get_typestore(store), deserialize)(raw, "nav_msgs/msg/Odometry").child_frame_id
        assert decode(raw) == want == child


def test_a_run_records_the_frame_and_the_results_mcap_moves_it(tmp_path):
    """summary.json says the robot's frame; the results MCAP's odom → base names it (not base_link,
    which would give base_link a second parent beside the log's base_footprint → base_link)."""
    scans = [
        RawScan(100.0 + i, -1.5, 0.01, np.full(301, 3.0, np.float32), 0.05, 20.0, "laser") for i in range(5)
    ]
    odoms = [OdomSample(100.0 + i, 0.1 * i, 0.0, 0.0) for i in range(5)]
    log = _turtlebot(tmp_path / "tb.mcap", "cdr", scans=scans, odoms=odoms)
    res = CliRunner().invoke(
        cli, ["run", str(log), "--out", str(tmp_path / "o"), "-q", "--mcap-out", str(tmp_path / "r.mcap")]
    )
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["input"]["base_frame"] == "base_footprint"
    info = CliRunner().invoke(cli, ["info", str(log)])
    assert "x=0.100 m y=0.000 m yaw=0.000 rad (from tf base_footprint→laser)" in info.output
    assert summary["input"]["laser_to_base"] == pytest.approx([0.1, 0.0, 0.0], abs=1e-9)
    with open(tmp_path / "r.mcap", "rb") as f:
        frames = {
            (m["parent_frame_id"], m["child_frame_id"])
            for _, c, msg in make_reader(f).iter_messages(topics=["/cornerslam/odom_tf"])
            for m in [json.loads(msg.data)]
        }
    assert frames == {("odom", "base_footprint")}


def test_tf_odometry_moving_the_frame_base_link_rides_on_is_taken_as_the_robot_s(tmp_path):
    """nav2's tree with odometry on /tf: odom→base_footprint, base_footprint→base_link on /tf_static.
    base_link rides on the frame the odometry moves: that frame is the robot's (before: exit 2 after
    reading the whole log, "--set input.base_frame=base_footprint")."""
    odoms = make_odoms(8)
    log = _turtlebot(tmp_path / "tf.mcap", "cdr", odoms=odoms, on_tf=("base_footprint",))
    with open_log(log) as r:
        assert r.laser_to_base() == pytest.approx((0.1, 0.0, 0.0), abs=1e-12)
        assert r.base_frame == "base_footprint" and r.odom_on_tf
        got = [m for m in r.messages() if isinstance(m, OdomSample)]
        assert r.info().odom_source == "tf odom→base_footprint"
    np.testing.assert_allclose([(o.stamp, o.x, o.y) for o in got], [(o.stamp, o.x, o.y) for o in odoms])
    # without the laser mount looked up first (input.laser.from_tf=false), the odometry is read as well
    with open_log(log) as r:
        assert sum(isinstance(m, OdomSample) for m in r.messages()) == len(odoms)


@pytest.mark.parametrize(
    "on_tf, tf",
    [
        (("robot1/base_link", "robot2/base_link"), (("robot1/base_link", "laser", 0.1),)),  # two robots
        (("chassis",), (("base_footprint", "base_link", -0.5), ("base_link", "laser", 0.6))),  # unlinked
    ],
    ids=["two_children", "base_frame_not_on_it"],
)
def test_tf_odometry_whose_robot_frame_is_not_clear_is_refused_as_before(tmp_path, on_tf, tf):
    log = _turtlebot(tmp_path / "tf.mcap", "cdr", on_tf=on_tf, tf=tf)
    with open_log(log) as r:
        with pytest.raises(LogError, match="has no odom→base_link transform"):
            list(r.messages())


def _with_first_odometry(log, tmp_path, child: str):
    """The TurtleBot log again, its first Odometry message's child_frame_id ``child``."""
    ros, odoms = serializer("cdr"), make_odoms(8)
    with open(log, "rb") as f:
        msgs = [(c.topic, s.name, m.log_time, m.data) for s, c, m in make_reader(f).iter_messages()]
    first = next(i for i, m in enumerate(msgs) if m[0] == "/odom")
    msgs[first] = (*msgs[first][:3], ros.odometry(odoms[0], "odom", child))
    return write_messages_mcap(tmp_path / f"first-{child or 'empty'}.mcap", msgs)


@pytest.mark.parametrize("child", ["", "odom"])
def test_the_first_child_frame_that_names_a_robot_frame_is_taken(tmp_path, child):
    """An empty child_frame_id in the first message, or odom itself (odom→odom is no robot): the next
    messages' base_footprint (review: the first message alone decided, silently base_link's mount)."""
    log = _with_first_odometry(_turtlebot(tmp_path / "tb.mcap", "cdr"), tmp_path, child)
    with open_log(log) as r:
        assert (
            r.laser_to_base() == pytest.approx((0.1, 0.0, 0.0), abs=1e-12)
            and r.base_frame == "base_footprint"
        )


def test_a_base_frame_the_user_names_is_the_robot_s_whatever_the_odometry_says(tmp_path):
    """input.base_frame set to another frame than the default base_link corrects a wrong child_frame_id."""
    log = _turtlebot(
        tmp_path / "tb.mcap", "cdr", tf=(("base_footprint", "chassis", -0.5), ("chassis", "laser", 0.6))
    )
    with open_log(log, base_frame="chassis") as r:
        assert r.laser_to_base() == pytest.approx((0.6, 0.0, 0.0), abs=1e-12) and r.base_frame == "chassis"
    with open_log(log) as r:  # left at base_link: the odometry's frame
        assert (
            r.laser_to_base() == pytest.approx((0.1, 0.0, 0.0), abs=1e-12)
            and r.base_frame == "base_footprint"
        )


def test_tf_odometry_found_after_many_other_tf_messages(tmp_path):
    """250 /tf messages of a wheel before the first odom→base_footprint (review: the frame was looked for
    in the first 200 messages of every tf topic, so the run was refused)."""
    ros, odoms = serializer("cdr"), make_odoms(8)
    log = _turtlebot(tmp_path / "tb.mcap", "cdr", odoms=odoms, on_tf=("base_footprint",))
    with open(log, "rb") as f:
        msgs = [(c.topic, s.name, m.log_time, m.data) for s, c, m in make_reader(f).iter_messages()]
    t0 = msgs[0][2]
    wheel = [
        (
            "/tf",
            "tf2_msgs/msg/TFMessage",
            t0 + i,
            ros.tf((t0 + i) * 1e-9, "base_link", "wheel", 0.1, 0.2, 0.0),
        )
        for i in range(1, 251)
    ]
    late = write_messages_mcap(tmp_path / "late.mcap", sorted(msgs + wheel, key=lambda m: m[2]))
    with open_log(late) as r:
        assert (
            r.laser_to_base() == pytest.approx((0.1, 0.0, 0.0), abs=1e-12)
            and r.base_frame == "base_footprint"
        )
        assert sum(isinstance(m, OdomSample) for m in r.messages()) == len(odoms)


def test_a_tf_through_an_empty_frame_name_links_nothing(tmp_path):
    """base_footprint→"" and ""→laser: tf2 refuses a frame "", so no mount comes from them (review: the
    chain went through the empty name and gave x = 0.5)."""
    log = _turtlebot(tmp_path / "e.mcap", "cdr", tf=(("base_footprint", "", 0.2), ("", "laser", 0.3)))
    with open_log(log) as r:
        assert r.laser_to_base() is None


def test_odometry_giving_the_poses_of_two_frames_is_warned(tmp_path):
    """Two publishers on /odom (the wheels' base_link, an EKF's base_footprint): the odometry jumps
    between two estimates; the read says so, naming both and how many messages each (review)."""
    ros, odoms = serializer("cdr"), make_odoms(8)
    log = _turtlebot(tmp_path / "tb.mcap", "cdr", odoms=odoms)
    with open(log, "rb") as f:
        msgs = [(c.topic, s.name, m.log_time, m.data) for s, c, m in make_reader(f).iter_messages()]
    odom = [i for i, m in enumerate(msgs) if m[0] == "/odom"]
    for j in range(0, len(odom), 3):  # every third message from the other publisher
        msgs[odom[j]] = (*msgs[odom[j]][:3], ros.odometry(odoms[j], "odom", "/base_link"))
    log = write_messages_mcap(tmp_path / "two.mcap", msgs)
    with open_log(log) as r:
        list(r.messages())
        (w,) = [w for w in r.stats.warnings if "gives the poses of 2 frames" in w]
        assert "'base_footprint' in 5 messages, 'base_link' in 3 messages" in w and "--odom-topic" in w
    with open_log(_turtlebot(tmp_path / "one.mcap", "cdr")) as r:
        list(r.messages())
        assert not any("frames" in w for w in r.stats.warnings)


def test_a_results_mcap_beside_a_log_whose_tf_already_has_map_to_odom_is_warned(tmp_path):
    """A log recorded with a localiser running (amcl, slam_toolbox): its /tf has map → odom, and the results
    MCAP's own map → odom gives the odom frame a second parent when both files are open in Foxglove —
    said (it was not); without --mcap-out nothing is said."""
    scans = [
        RawScan(100.0 + i, -1.5, 0.01, np.full(301, 3.0, np.float32), 0.05, 20.0, "laser") for i in range(5)
    ]
    odoms = [OdomSample(100.0 + i, 0.1 * i, 0.0, 0.0) for i in range(5)]
    tf = (("map", "odom", 0.3), ("base_footprint", "base_link", -0.5), ("base_link", "laser", 0.6))
    log = _turtlebot(tmp_path / "tb.mcap", "cdr", scans=scans, odoms=odoms, tf=tf)
    want = "its tf already gives 'odom' a parent (map → odom), and the results MCAP gives it its own"
    res = CliRunner().invoke(
        cli, ["run", str(log), "--out", str(tmp_path / "o"), "--mcap-out", str(tmp_path / "r.mcap")]
    )
    assert res.exit_code == 0 and want in res.output
    assert any(want in w for w in json.loads((tmp_path / "o" / "summary.json").read_text())["warnings"])
    res = CliRunner().invoke(cli, ["run", str(log), "--out", str(tmp_path / "p")])
    assert res.exit_code == 0 and "already gives" not in res.output
    plain = _turtlebot(tmp_path / "plain.mcap", "cdr", scans=scans, odoms=odoms)
    res = CliRunner().invoke(
        cli, ["run", str(plain), "--out", str(tmp_path / "q"), "--mcap-out", str(tmp_path / "s.mcap")]
    )
    assert res.exit_code == 0 and "already gives" not in res.output
    # the usual case: odometry on /tf too, a localiser's map → odom on /tf from after the first scan
    ros, tf = serializer("cdr"), "tf2_msgs/msg/TFMessage"
    odoms8 = [OdomSample(100.0 + 0.5 * i, 0.05 * i, 0.0, 0.0) for i in range(9)]
    mount = (("base_footprint", "base_link", -0.5), ("base_link", "laser", 0.6))
    msgs = [("/tf_static", tf, int(99.9e9), ros.tf(99.9, p, c, x, 0.0, 0.0)) for p, c, x in mount]
    msgs += [("/scan", "sensor_msgs/msg/LaserScan", int(s.stamp * 1e9), ros.laserscan(s)) for s in scans]
    for o in odoms8:
        msgs.append(
            ("/tf", tf, int(o.stamp * 1e9), ros.tf(o.stamp, "odom", "base_footprint", o.x, o.y, o.theta))
        )
    for t in (102.01, 103.01):  # (after the first scan and the first odometry on /tf)
        msgs.append(("/tf", tf, int(t * 1e9), ros.tf(t, "map", "odom", 0.2, 0.0, 0.0)))
    late = write_messages_mcap(tmp_path / "amcl.mcap", sorted(msgs, key=lambda m: m[2]), encoding="cdr")
    res = CliRunner().invoke(
        cli, ["run", str(late), "--out", str(tmp_path / "r"), "--mcap-out", str(tmp_path / "t.mcap")]
    )
    assert res.exit_code == 0 and want in res.output, res.output


def _yaw(q: dict) -> float:
    return 2.0 * np.arctan2(q["z"], q["w"])


def test_after_an_odometry_jump_the_results_map_to_odom_holds_the_log_s_own_odometry(tmp_path):
    """A reset of the odometry by (−5, +3) m mid-log: the run re-anchors it (trajectory.csv's odom_* go on
    from where they were), but the input log's odom → base_link is the raw one — so the results MCAP's
    map → odom must be the corrected pose ∘ the raw odometry⁻¹ for the two files to overlay (it was
    built from the re-anchored odometry: 5.8 m off after the jump); and its own odom → base_link is the
    raw odometry too."""
    from cornerslam_cli.geometry import compose

    scans = [
        RawScan(100.0 + i, -1.5, 0.01, np.full(301, 3.0, np.float32), 0.05, 20.0, "laser") for i in range(8)
    ]

    def logged(t):  # 10 Hz odometry, reset by (−5, +3) m at 103.55 s
        k = round((t - 100.0) * 10)
        return (0.01 * k, 0.0, 0.002 * k) if t < 103.55 else (0.01 * k - 5.0, 3.0, 0.002 * k)

    odoms = [OdomSample(100.0 + 0.1 * k, *logged(100.0 + 0.1 * k)) for k in range(75)]
    raw = [logged(100.0 + i) for i in range(8)]
    log = _turtlebot(tmp_path / "jump.mcap", "cdr", scans=scans, odoms=odoms)
    res = CliRunner().invoke(
        cli, ["run", str(log), "--out", str(tmp_path / "o"), "--mcap-out", str(tmp_path / "r.mcap")]
    )
    assert res.exit_code == 0 and "odometry jumped by" in res.output, res.output
    got: dict[str, dict[int, list]] = {
        "/cornerslam/tf": {},
        "/cornerslam/pose": {},
        "/cornerslam/odom_tf": {},
    }
    with open(tmp_path / "r.mcap", "rb") as f:
        for _, channel, msg in make_reader(f).iter_messages(topics=list(got)):
            m = json.loads(msg.data)
            if channel.topic == "/cornerslam/pose":
                p, q = m["pose"]["position"], m["pose"]["orientation"]
            else:
                p, q = m["translation"], m["rotation"]
            got[channel.topic][msg.log_time] = [p["x"], p["y"], _yaw(q)]
    stamps = sorted(got["/cornerslam/pose"])
    assert len(stamps) == 8
    for k, ns in enumerate(stamps):
        np.testing.assert_allclose(got["/cornerslam/odom_tf"][ns], raw[k], atol=1e-9)
        overlay = compose(np.array(got["/cornerslam/tf"][ns]), np.array(raw[k]))
        np.testing.assert_allclose(overlay, got["/cornerslam/pose"][ns], atol=1e-9)
