"""Logs of several robots, or of one robot recorded with more than it needs: each robot's topics in its
namespace (/robot1/scan, /robot1/odom, /robot1/tf, /robot1/tf_static) and its frames named as the others'.
The mount and the odometry of the scans' robot are read, not the first robot's (a hostile-user probe
found the other robot's tf_static mount taken without a word: a wrong map, every line saying right)."""

from __future__ import annotations

import dataclasses
import logging
import math

import numpy as np
import pytest
from _log_fixtures import make_odoms, make_scans, write_messages_mcap

from cornerslam_cli.logs import open_log
from cornerslam_cli.logs.ros import is_static, namespace, of_robot
from cornerslam_cli.logs.writers import RosSerializer

ROS = RosSerializer("cdr")
T0 = 1_700_000_000.0
YAWS = {"/robot1": 0.0, "/robot2": math.pi / 2}  # each robot's laser mount


def scans(topic: str) -> list:
    return [(topic, "sensor_msgs/msg/LaserScan", int(s.stamp * 1e9), ROS.laserscan(s)) for s in make_scans(5)]


def odometry(topic: str) -> list:
    return [(topic, "nav_msgs/msg/Odometry", int(o.stamp * 1e9), ROS.odometry(o, "odom", "base_link"))
            for o in make_odoms(6)]  # fmt: skip


def tf(topic: str, parent: str, child: str, yaw: float, t: float = T0) -> tuple:
    return (topic, "tf2_msgs/msg/TFMessage", int(t * 1e9), ROS.tf(t, parent, child, 0.2, 0.0, yaw))


def tf_odometry(topic: str) -> list:
    return [tf(topic, "odom", "base_link", 0.03 * i, T0 + 0.1 * i) for i in range(6)]


def write(path, messages):
    return write_messages_mcap(path, sorted(messages, key=lambda m: m[2]))


def two_robots(tmp_path, odom=odometry):
    msgs = []
    for ns, yaw in YAWS.items():
        msgs += scans(f"{ns}/scan") + odom(f"{ns}/{'odom' if odom is odometry else 'tf'}")
        msgs.append(tf(f"{ns}/tf_static", "base_link", "laser", yaw))
    return write(tmp_path / "two.mcap", msgs)


def test_names():
    assert namespace("/robot1/scan") == "/robot1" and namespace("/scan") == ""
    assert is_static("/tf_static") and is_static("/robot1/tf_static") and not is_static("/robot1/tf")
    tfs = ["/robot1/tf", "/robot2/tf", "/tf"]
    assert of_robot(tfs, "/robot2/scan") == ["/robot2/tf", "/tf"]
    assert of_robot(tfs, "/a/robot2/scan") == ["/tf"]  # (a namespace above the scans' one)
    assert of_robot(["/robot1/tf"], "/scan") == ["/robot1/tf"]  # none of the scans' robot: all
    assert of_robot(tfs, "") == tfs


@pytest.mark.parametrize("robot", ["/robot1", "/robot2"])
def test_the_scans_robot_gives_the_mount_and_the_odometry(tmp_path, robot):
    log = open_log(two_robots(tmp_path), scan_topic=f"{robot}/scan")
    assert log.odom_topic == f"{robot}/odom"
    assert log.info().notes == (
        f"2 Odometry topics: {robot}/odom taken (the scans' namespace), not "
        f"{'/robot2' if robot == '/robot1' else '/robot1'}/odom",
    )
    x, _, yaw = log.laser_to_base()
    assert (x, yaw) == pytest.approx((0.2, YAWS[robot]))
    assert not log.stats.warnings


def test_info_on_two_robots_says_the_scan_topic_chooses_the_odometry_too(tmp_path):
    """info on two robots' log, no topic chosen: exit 2 (run would refuse), and the odometry line names
    --scan-topic besides --odom-topic (a probe: only --odom-topic, though the scans' namespace chooses)."""
    from click.testing import CliRunner

    from cornerslam_cli.cli import cli

    res = CliRunner().invoke(cli, ["info", str(two_robots(tmp_path))])
    assert res.exit_code == 2 and "choose one with --scan-topic" in res.stderr
    want = "  odometry  - (2 nav_msgs/Odometry topics: choose one with --odom-topic, or --scan-topic: "
    assert any(line.startswith(want) for line in res.stdout.splitlines()), res.stdout
    res = CliRunner().invoke(cli, ["info", str(tmp_path / "two.mcap"), "--scan-topic", "/robot2/scan"])
    assert res.exit_code == 0 and "  odometry  /robot2/odom (nav_msgs/Odometry)" in res.stdout


def test_the_scans_robot_gives_the_tf_odometry(tmp_path):
    log = open_log(two_robots(tmp_path, odom=tf_odometry), scan_topic="/robot2/scan")
    assert log.odom_topic == "/robot2/tf"
    assert log.laser_to_base()[2] == pytest.approx(YAWS["/robot2"])
    odoms = [m for m in log.messages() if not hasattr(m, "ranges")]
    assert odoms and odoms[-1].theta == pytest.approx(0.15)


def test_two_tf_topics_that_disagree_on_a_mount_are_warned_of(tmp_path, caplog):
    """Scans outside every robot's namespace: the tf topics cannot be told apart — the first read is
    used, and the disagreement said."""
    msgs = scans("/scan") + odometry("/odom")
    msgs += [tf(f"{ns}/tf_static", "base_link", "laser", yaw) for ns, yaw in YAWS.items()]
    with caplog.at_level(logging.WARNING, logger="cornerslam.logs"):
        log = open_log(write(tmp_path / "one.mcap", msgs))
        assert log.laser_to_base() is not None
    assert (
        "tf topics '/robot1/tf_static' and '/robot2/tf_static' both give base_link→laser, and differently"
        in (caplog.text)
    )


def test_an_odometry_topic_never_published_gives_way_to_tf_odometry(tmp_path):
    """/odom declared with no message beside tf odometry was refused ("has no messages") with a hint that
    led nowhere; now the tf odometry is read, noted."""
    msgs = scans("/scan") + tf_odometry("/tf") + [tf("/tf_static", "base_link", "laser", 0.0)]
    path = write_with_empty(tmp_path / "empty_odom.mcap", msgs, "/odom")
    log = open_log(path)
    assert log.odom_topic == "/tf"
    assert log.info().notes == ("/odom has no messages: tf odometry taken",)
    log.check()
    assert sum(1 for m in log.messages() if not hasattr(m, "ranges")) == 6


def test_info_does_not_say_the_mount_is_missing_when_it_did_not_look(tmp_path):
    """With two Odometry topics to choose from (neither /odom, nor in the scans' namespace), info listed
    'laser not on tf: from the config's input.laser' though /tf_static holds it: it had not looked."""
    from click.testing import CliRunner

    from cornerslam_cli.cli import cli

    msgs = scans("/scan") + odometry("/wheels/odom") + odometry("/ekf/odom")
    log = write(tmp_path / "two_odom.mcap", [*msgs, tf("/tf_static", "base_link", "laser", 0.0)])
    res = CliRunner().invoke(cli, ["info", str(log)])
    assert res.exit_code == 2 and "2 Odometry topics" in res.output
    assert "  laser     - (not looked up: the problem below comes first)" in res.output.splitlines()
    assert "not on tf" not in res.output
    res = CliRunner().invoke(cli, ["info", str(log), "--odom-topic", "/ekf/odom"])
    assert res.exit_code == 0 and "laser     x=0.200 m y=0.000 m yaw=0.000 rad (from tf" in res.output


def test_one_storage_file_of_a_split_bag_is_read_with_a_warning(tmp_path, caplog):
    """`ros2 bag record --max-bag-size` splits a bag into storage files; one given alone ran on its part of
    the recording, exit 0, with nothing to say the output covers half of it."""
    import shutil

    import yaml
    from _log_fixtures import write_log

    bag = write_log("rosbag2-sqlite3", tmp_path)
    (first,) = bag.glob("*.db3")
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())
    assert open_log(first).stats.warnings == []  # one file: the whole bag
    shutil.copy(first, bag / "second.db3")
    meta["rosbag2_bagfile_information"]["relative_file_paths"] = [first.name, "second.db3"]
    (bag / "metadata.yaml").write_text(yaml.safe_dump(meta))
    with caplog.at_level(logging.WARNING, logger="cornerslam.logs"):
        assert open_log(first).stats.warnings == [
            f"{first.name} is one of the 2 storage files of the ROS 2 bag '{bag.name}': only its messages "
            "are read (give the bag's directory to read them all)"
        ]
    assert "only its messages are read" in caplog.text


def test_a_namespaced_robots_static_tf_links_its_tf_odometry_to_the_mount(tmp_path):
    """nav2 in a namespace: odom→base_footprint on /robot1/tf, base_footprint→base_link and the mount on
    /robot1/tf_static. The robot's frame is found through its own tf_static (a namespaced tf_static is
    static too): its odometry is read and the mount chained from base_footprint."""
    msgs = scans("/robot1/scan") + [
        tf("/robot1/tf", "odom", "base_footprint", 0.03 * i, T0 + 0.1 * i) for i in range(6)
    ]
    msgs += [
        tf("/robot1/tf_static", "base_footprint", "base_link", 0.0),
        tf("/robot1/tf_static", "base_link", "laser", 0.5),
    ]
    msgs += scans("/robot2/scan") + [
        tf("/robot2/tf", "odom", "base_link", 0.0, T0 + 0.1 * i) for i in range(6)
    ]
    log = open_log(write(tmp_path / "nav2.mcap", msgs), scan_topic="/robot1/scan")
    assert log.odom_topic == "/robot1/tf"
    x, _, yaw = log.laser_to_base()
    assert log.base_frame == "base_footprint" and (x, yaw) == pytest.approx((0.4, 0.5))  # 0.2 + 0.2 along x
    odoms = [m for m in log.messages() if not hasattr(m, "ranges")]
    assert len(odoms) == 6 and odoms[-1].theta == pytest.approx(0.15)


def test_the_second_parent_check_reads_the_scans_robots_tf_only(tmp_path):
    """--mcap-out's check for a parent of 'odom' already on tf: another robot's localiser (map → odom on
    /robot2/tf) is not this robot's."""
    msgs = (
        scans("/robot1/scan")
        + odometry("/robot1/odom")
        + [tf("/robot1/tf_static", "base_link", "laser", 0.0)]
    )
    msgs += (
        scans("/robot2/scan") + odometry("/robot2/odom") + [tf("/robot2/tf", "map", "odom", 0.0, T0 + 0.3)]
    )
    path = write(tmp_path / "loc.mcap", msgs)
    assert open_log(path, scan_topic="/robot1/scan").parent_on_tf("odom") is None
    assert open_log(path, scan_topic="/robot2/scan").parent_on_tf("odom") == "map"


def write_with_empty(path, messages, empty: str):
    """An MCAP of ``messages`` with the Odometry topic ``empty`` declared and never published."""
    from mcap.writer import Writer

    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="test")
        sid = w.register_schema(
            "nav_msgs/msg/Odometry", "ros2msg", ROS.msgdef("nav_msgs/msg/Odometry").encode()
        )
        w.register_channel(empty, "cdr", sid)
        chans = {}
        for topic, typename, t, data in sorted(messages, key=lambda m: m[2]):
            if topic not in chans:
                s = w.register_schema(typename, "ros2msg", ROS.msgdef(typename).encode())
                chans[topic] = w.register_channel(topic, "cdr", s)
            w.add_message(chans[topic], t, data, t)
        w.finish()
    return path


@pytest.mark.parametrize(
    ("name", "messages", "scan", "want"),
    [
        # the nearest namespace of several (/robot1/front/scan: /robot1/odom, not /odom nor /robot2/odom)
        (
            "nested",
            scans("/robot1/front/scan")
            + odometry("/robot1/odom")
            + odometry("/robot2/odom")
            + odometry("/odom"),
            "/robot1/front/scan",
            "/robot1/odom",
        ),
        # a robot's own odometry below its namespace (a namespaced TurtleBot 2; ros2_control's topic)
        (
            "tb2",
            scans("/robot1/scan")
            + odometry("/robot1/mobile_base/odom")
            + [tf("/tf", "base_link", "laser", 0)],
            "/robot1/scan",
            "/robot1/mobile_base/odom",
        ),
        (
            "sensor_ns",
            scans("/front/scan") + odometry("/mobile_base/odom"),
            "/front/scan",
            "/mobile_base/odom",
        ),
        (
            "controllers",
            [
                m
                for r in ("/robot1", "/robot2")
                for m in scans(f"{r}/scan") + odometry(f"{r}/diff_drive_controller/odom")
            ],
            "/robot1/scan",
            "/robot1/diff_drive_controller/odom",
        ),
        # scans in a sensor namespace with /odom and a filtered one at the root: /odom, as at the root
        (
            "filtered",
            scans("/laser/scan") + odometry("/odom") + odometry("/odom_filtered"),
            "/laser/scan",
            "/odom",
        ),
        # the only Odometry, outside the scans' namespace and no other robot's scans there: taken
        ("outside", scans("/robot1/scan") + odometry("/robot2/odom"), "/robot1/scan", "/robot2/odom"),
    ],
)
def test_the_odometry_of_scans_in_a_namespace(tmp_path, name, messages, scan, want):
    """A review's cases: sub-namespaces and sensor namespaces are the robot's own; only another robot's
    (a namespace with its own LaserScan) is set aside; several at the root level: /odom."""
    log = open_log(write(tmp_path / f"{name}.mcap", messages), scan_topic=scan)
    assert log.odom_topic == want
    log.check()
    assert not log.stats.warnings


def test_another_robots_odometry_is_set_aside(tmp_path):
    """Two robots: robot1's Odometry declared and empty, its tf odometry there — robot2's live Odometry is
    not taken (an empty /robot1/odom had let it in without a word); with no tf odometry of its own either,
    the only Odometry there is, another robot's, is taken with a warning."""
    two = scans("/robot1/scan") + scans("/robot2/scan") + odometry("/robot2/odom")
    log = open_log(write_with_empty(tmp_path / "a.mcap", two + tf_odometry("/robot1/tf"), "/robot1/odom"),
                   scan_topic="/robot1/scan")  # fmt: skip
    assert log.odom_topic == "/robot1/tf"
    assert log.info().notes == ("/robot1/odom has no messages: tf odometry taken",)
    log = open_log(write(tmp_path / "b.mcap", two), scan_topic="/robot1/scan")
    assert log.odom_topic == "/robot2/odom"
    assert log.stats.warnings == [
        "log 'b.mcap': odometry '/robot2/odom' taken, the only one, though another robot's scans are in its "
        "namespace (choose another with --odom-topic)"
    ]


def test_a_scan_topic_not_found_does_not_call_the_robots_odometry_another_robots(tmp_path):
    """`info --scan-topic scan` on a log of /robot1/* alone: a warning that '/robot1/odom' was another
    robot's came before the error naming '/robot1/scan' (no scan topic chosen, every namespace looked
    like another robot's; a ROS-user probe)."""
    from cornerslam_cli.errors import LogError

    log = open_log(
        write(tmp_path / "ns.mcap", scans("/robot1/scan") + odometry("/robot1/odom")), scan_topic="scan"
    )
    assert log.stats.warnings == []
    with pytest.raises(LogError, match="/robot1/scan"):
        log.check()


def test_an_empty_odometry_topic_is_named_when_tf_has_no_odometry_either(tmp_path):
    """/odom declared and empty, /tf with the mount and a localiser's map → odom only: the error was of the
    tf alone, though the Odometry topic is why tf was read."""
    from cornerslam_cli.errors import LogError

    msgs = scans("/scan") + [tf("/tf", "base_link", "laser", 0.0), tf("/tf", "map", "odom", 0.0, T0 + 0.3)]
    log = open_log(write_with_empty(tmp_path / "e.mcap", msgs, "/odom"))
    with pytest.raises(
        LogError, match=r"has no odom→base_link transform .*; /odom has no messages: tf odometry"
    ):
        list(log.messages())


def test_a_scan_topic_of_another_type_in_a_log_with_no_laserscan(tmp_path):
    """--scan-topic naming a PointCloud2 in a log with no LaserScan: the hint said "choose a LaserScan
    topic with --scan-topic (none)"."""
    from cornerslam_cli.errors import LogError

    log = write(
        tmp_path / "cloud.mcap",
        odometry("/odom") + [("/points", "nav_msgs/msg/Odometry", int(T0 * 1e9), b"")],
    )
    with pytest.raises(LogError) as err:
        open_log(log, scan_topic="/odom").check()
    assert err.value.hint == "it has no LaserScan topic: cornerslam reads the laser as sensor_msgs/LaserScan"


def test_did_you_mean_names_topics_of_the_wanted_type_every_equal_one(tmp_path):
    """--scan-topic /scan: an Odometry topic /scans is no suggestion (it led to a second exit 2), and two
    robots' scans are both named, not the first found."""
    from cornerslam_cli.errors import LogError

    def hint(messages, **kw) -> str:
        with pytest.raises(LogError) as err:
            open_log(write(tmp_path / "h.mcap", messages), **kw).check()
        return err.value.hint

    assert "did you mean" not in hint(scans("/base_scan") + odometry("/scans"), scan_topic="/scan")
    two = scans("/robot1/scan") + scans("/robot2/scan") + odometry("/odom")
    assert "did you mean '/robot1/scan' or '/robot2/scan'?" in hint(two, scan_topic="scan")
    assert "did you mean '/odom'?" in hint(scans("/scan") + odometry("/odom"), odom_topic="odm")


def test_scans_of_two_frames_on_one_topic_are_warned_of(tmp_path):
    """Two lasers published on /scan (or a driver restarted with another frame_id): every scan is placed
    with the first frame's mount — a probe's second laser, upside down, gave 10× the error with no word."""
    from dataclasses import replace

    raw = [replace(s, frame_id="laser_b") if i % 2 else s for i, s in enumerate(make_scans(6))]
    msgs = [("/scan", "sensor_msgs/msg/LaserScan", int(s.stamp * 1e9), ROS.laserscan(s)) for s in raw]
    log = open_log(write(tmp_path / "two.mcap", msgs + odometry("/odom")))
    assert len([m for m in log.messages() if hasattr(m, "ranges")]) == 6
    assert log.stats.warnings == [
        "two.mcap: scans on '/scan' come from frame 'laser_b' besides 'laser' (two lasers on one topic, or a "
        "driver restarted with another frame_id): every scan is placed with the mount of 'laser'"
    ]
    one = open_log(write(tmp_path / "one.mcap", scans("/scan") + odometry("/odom")))
    list(one.messages())
    assert not one.stats.warnings


@pytest.mark.parametrize(("yaw_b", "scan_frame"), [(0.0, ""), (1.5, ""), (1.5, "laser_b"), (1.5, "nolaser")])
def test_a_second_laser_on_the_scan_topic_mounted_elsewhere_is_left_out(tmp_path, yaw_b, scan_frame):
    """Two lasers on /scan whose frames the tf mounts apart: every scan placed with the first's mount made
    a map of both a mess (a ROS-user probe: ATE 3.4 m against 0.03, exit 0). The second's scans are left
    out, said with their count and the key that chooses (input.scan_frame); a frame the tf mounts as the
    first is the same laser renamed, kept; input.scan_frame naming no scan's frame is refused."""
    from dataclasses import replace

    from cornerslam_cli.errors import LogError

    raw = [replace(s, frame_id="laser_b") if i % 2 else s for i, s in enumerate(make_scans(6))]
    msgs = [("/scan", "sensor_msgs/msg/LaserScan", int(s.stamp * 1e9), ROS.laserscan(s)) for s in raw]
    msgs += [tf("/tf_static", "base_link", "laser", 0.0), tf("/tf_static", "base_link", "laser_b", yaw_b)]
    log = open_log(write(tmp_path / "two.mcap", msgs + odometry("/odom")), scan_frame=scan_frame)
    if scan_frame == "nolaser":
        with pytest.raises(LogError) as err:
            log.laser_to_base()
        assert (
            "no scan on '/scan' has frame_id 'nolaser' (input.scan_frame; its scans': 'laser', 'laser_b')"
            in (str(err.value))
        )
        return
    mount = log.laser_to_base()
    assert mount == pytest.approx((0.2, 0.0, yaw_b if scan_frame else 0.0))
    frames = [m.frame_id for m in log.messages() if hasattr(m, "ranges")]
    if yaw_b == 0.0:  # mounted alike: one laser, renamed
        assert frames == ["laser", "laser_b"] * 3
        assert "(the tf mounts both alike: one laser renamed)" in log.stats.warnings[0]
        return
    used, other = ("laser_b", "laser") if scan_frame else ("laser", "laser_b")
    assert frames == [used] * 3
    why = "input.scan_frame chose it" if scan_frame else "another laser: the tf mounts it elsewhere"
    assert log.stats.warnings == [
        f"two.mcap: 3 scans on '/scan' of frame '{other}' left out, only those of '{used}' used ({why}): "
        f"--set input.scan_frame={other} to map with that laser's instead"
    ]


@pytest.mark.parametrize("shared", [False, True])
def test_tf_odometry_in_a_robots_prefixed_frames_is_found(tmp_path, shared):
    """robot2/odom → robot2/base_link on /robot2/tf, or both robots' prefixed frames on one /tf: refused
    with the default input.odom_frame/base_frame (a probe), though the same prefixed frames were found
    for nav_msgs/Odometry. The scans' robot's prefixed frames are taken, the mount chained from them,
    and the odometry read, as with the frames set by hand."""
    msgs = []
    for ns, yaw in YAWS.items():
        r = ns.strip("/")
        topic = "/tf" if shared else f"{ns}/tf"
        laser = [dataclasses.replace(s, frame_id=f"{r}/laser") for s in make_scans(5)]
        msgs += [
            (f"{ns}/scan", "sensor_msgs/msg/LaserScan", int(s.stamp * 1e9), ROS.laserscan(s)) for s in laser
        ]
        msgs += [
            tf(topic, f"{r}/odom", f"{r}/base_link", 0.03 * i * (r == "robot2"), T0 + 0.1 * i)
            for i in range(6)
        ]
        msgs.append(tf(f"{ns}/tf_static", f"{r}/base_link", f"{r}/laser", yaw))
    path = write(tmp_path / "prefixed.mcap", msgs)
    log = open_log(path, scan_topic="/robot2/scan")
    x, _, yaw = log.laser_to_base()
    assert (x, yaw) == pytest.approx((0.2, YAWS["/robot2"]))
    assert (log.odom_frame, log.base_frame) == ("robot2/odom", "robot2/base_link")
    odoms = [m for m in log.messages() if not hasattr(m, "ranges")]
    assert len(odoms) == 6 and odoms[-1].theta == pytest.approx(0.15)  # robot2's, not robot1's (still)
    by_hand = open_log(
        path, scan_topic="/robot2/scan", odom_frame="robot2/odom", base_frame="robot2/base_link"
    )
    assert [o.theta for o in by_hand.messages() if not hasattr(o, "ranges")] == [o.theta for o in odoms]


def test_a_laser_renamed_mid_log_whose_mount_comes_later_on_tf_is_kept(tmp_path):
    """The tf read for the mount stops once the first laser is linked: a renamed laser whose mount comes
    later on /tf was taken for another laser and half the log left out (a review). A frame not on the tf
    read is unknown, kept (warned); extract leaves out what run leaves out, so '#N' is one scan."""
    from dataclasses import replace

    from cornerslam_cli.config import load_config
    from cornerslam_cli.extract import extract_step

    raw = [replace(s, frame_id="laser_b") if i >= 3 else s for i, s in enumerate(make_scans(6))]
    msgs = [("/scan", "sensor_msgs/msg/LaserScan", int(s.stamp * 1e9), ROS.laserscan(s)) for s in raw]
    msgs += tf_odometry("/tf") + [
        tf("/tf", "base_link", "laser", 0.0, T0),
        tf("/tf", "base_link", "laser_b", 0.0, T0 + 0.45),
    ]
    log = open_log(write(tmp_path / "renamed.mcap", msgs))
    log.laser_to_base()
    assert [m.frame_id for m in log.messages() if hasattr(m, "ranges")] == ["laser"] * 3 + ["laser_b"] * 3
    assert "two lasers on one topic, or a driver restarted with another frame_id" in log.stats.warnings[0]
    # two lasers alternating, mounted apart on /tf_static: extract's '#1' is run's second scan of 'laser'
    raw = [replace(s, frame_id="laser_b") if i % 2 else s for i, s in enumerate(make_scans(6))]
    msgs = [("/scan", "sensor_msgs/msg/LaserScan", int(s.stamp * 1e9), ROS.laserscan(s)) for s in raw]
    msgs += odometry("/odom") + [
        tf("/tf_static", "base_link", "laser", 0.0),
        tf("/tf_static", "base_link", "laser_b", 1.5),
    ]
    apart = write(tmp_path / "apart.mcap", msgs)
    n, scan, _, _ = extract_step(apart, 1, load_config(None, []))
    assert (n, scan.stamp, scan.frame_id) == (1, raw[2].stamp, "laser")


def test_the_tfs_odometry_poses_are_read_beside_an_odometry_topic(tmp_path):
    """A log with /odom and an odom → base_link on /tf (an EKF's, beside the wheels'): the results MCAP's
    map → odom is built on the tf's poses (a ROS-user probe: on /odom's, the robot was drawn 0.6 m off its
    corrected pose by a viewer chaining the log's tf). The reader gives them in stamp order, the robot's
    only (another robot's tf and static transforms left out)."""
    msgs = (
        scans("/scan")
        + odometry("/odom")
        + tf_odometry("/tf")[::-1]
        + [tf("/tf_static", "base_link", "laser", 0.0)]
    )
    msgs += [tf("/robot2/tf", "odom", "base_link", 1.0, T0 + 0.05)]  # another robot's: not read
    log = open_log(write(tmp_path / "both.mcap", msgs))
    assert log.info().odom_source == "nav_msgs/Odometry"
    stamps, poses = log.tf_odometry_poses()
    assert stamps == pytest.approx([T0 + 0.1 * i for i in range(6)])
    assert poses == pytest.approx(np.array([[0.2, 0.0, 0.03 * i] for i in range(6)]))
    alone = open_log(write(tmp_path / "odom.mcap", scans("/scan") + odometry("/odom")))
    assert alone.tf_odometry_poses() is None


def test_map_to_odom_is_built_on_the_logs_tf_odometry_inside_its_span(caplog):
    """report.mcap_out.on_logged_tf: inside the tf's span the run's odometry poses are replaced by the tf's,
    interpolated (hand-computed), outside kept; warned when they differ by more than TF_DIFFERS."""
    from cornerslam_cli.report.mcap_out import TF_DIFFERS, on_logged_tf

    odom = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.1], [2.0, 0.0, 0.2], [3.0, 0.0, 0.3]])
    stamps = np.array([0.0, 1.0, 2.0, 3.0])
    tf_stamps, tf_poses = np.array([0.5, 2.5]), np.array([[0.5, 1.0, 0.0], [2.5, 1.0, 0.4]])
    with caplog.at_level(logging.WARNING, logger="cornerslam"):
        out = on_logged_tf(odom, stamps, tf_stamps, tf_poses)
    assert out == pytest.approx(
        np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 0.1], [2.0, 1.0, 0.3], [3.0, 0.0, 0.3]])
    )
    assert "differs from the odometry the run used by up to 1.00 m" in caplog.text
    caplog.clear()
    near = tf_poses - [0.0, 1.0 - TF_DIFFERS / 2, 0.0]
    with caplog.at_level(logging.WARNING, logger="cornerslam"):
        on_logged_tf(odom, stamps, tf_stamps, near)
    assert not caplog.text
