"""Odometry whose pose never moves (a base driver that fills only the twist; an odom→base_link tf left
at identity) is warned about: the run took the robot as standing still, with no word of it (a ROS-user
probe: 3.7 m ATE against 0.04); so is a long run of steps with no valid beam."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from cornerslam_cli.cli import cli


def with_still_odometry(src: Path, dest: Path, heading: bool = False) -> Path:
    """``src`` (an MCAP of nav_msgs/Odometry on /odom) with every odometry pose at the origin, its twist
    kept (a driver that fills only the twist); with ``heading`` its orientation kept (an IMU's yaw)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    with open(src, "rb") as f, open(dest, "wb") as g:
        w = Writer(g)
        w.start(profile="ros2", library="test")
        schemas, channels = {}, {}
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=True):
            if schema.id not in schemas:
                schemas[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = w.register_channel(
                    channel.topic, channel.message_encoding, schemas[schema.id]
                )
            data = message.data
            if channel.topic == "/odom":
                msg = ts.deserialize_cdr(data, "nav_msgs/msg/Odometry")
                p = msg.pose.pose
                p.position.x = p.position.y = p.position.z = 0.0
                if not heading:
                    p.orientation.x = p.orientation.y = p.orientation.z = 0.0
                    p.orientation.w = 1.0
                data = bytes(ts.serialize_cdr(msg, "nav_msgs/msg/Odometry"))
            w.add_message(channels[channel.id], message.log_time, data, message.publish_time)
        w.finish()
    return dest


def warnings_of(out: Path) -> list[str]:
    return json.loads((out / "summary.json").read_text())["warnings"]


@pytest.mark.parametrize("moved", [True, False])
def test_odometry_that_never_moves_is_warned_of_when_the_scans_moved(sim_log, tmp_path, moved):
    log = with_still_odometry(sim_log, tmp_path / "still.mcap")
    out = tmp_path / "run"
    args = ["run", str(log), "--out", str(out), "-q"] + ([] if moved else ["--max-scans", "2"])
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 0, res.output
    said = [w for w in warnings_of(out) if "never moves over the run" in w]
    if moved:  # the scans went metres: said, with how far, and what to check
        assert len(said) == 1, warnings_of(out)
        assert (
            "odometry's position (/odom, nav_msgs/Odometry) never moves over the run, while its scans"
            in said[0]
        )
        assert "fills only the twist" in said[0]
    else:  # two scans, hardly apart: a robot standing still has odometry that does not move
        assert not said


def test_a_still_position_with_a_moving_heading_is_warned_of_but_not_without_scan_matching(sim_log, tmp_path):
    """A review: an odometry whose heading moves (an IMU's yaw) while its position stays at 0 is the same
    failure, and was not warned of; with scan matching off nothing tells a parked robot from a still
    odometry, and the warning (which spoke of scan matches) was given."""
    log = with_still_odometry(sim_log, tmp_path / "yaw.mcap", heading=True)
    for sets, warned in (([], True), (["--set", "scan_match.enabled=false"], False)):
        out = tmp_path / f"run{len(sets)}"
        assert CliRunner().invoke(cli, ["run", str(log), "--out", str(out), "-q", *sets]).exit_code == 0
        assert any("never moves over the run" in w for w in warnings_of(out)) == warned


def test_moving_odometry_is_not_warned_of(sim_log, tmp_path):
    out = tmp_path / "run"
    assert CliRunner().invoke(cli, ["run", str(sim_log), "--out", str(out), "-q"]).exit_code == 0
    assert not [w for w in warnings_of(out) if "never moves" in w]


def test_a_long_run_of_blind_steps_is_warned_of():
    """20 scans in a row with no valid beam (a covered laser, a driver writing NaN) went unsaid but for
    beams_invalid (a ROS-user probe): the longest such run of steps, BLIND_STEPS or more, is warned of
    with its stamps; a shorter one, or a log blind throughout (refused by the run), is not."""
    from types import SimpleNamespace

    from cornerslam_cli.report.summary import BLIND_STEPS, Totals, warn_blind

    def totals(points):
        t = Totals()
        zero = dict.fromkeys(("t_extract", "t_predict", "t_match", "t_update", "t_scan_match", "t_loop"), 0)
        for k, n in enumerate(points):
            t.add(SimpleNamespace(stamp=100.0 + 0.5 * k, n_points=n, budget_hit=0, n_matched=0, **zero))
        return t

    said = []
    stats = SimpleNamespace(warn=lambda fmt, *a: said.append(fmt % a))
    src = SimpleNamespace(path=Path("b.mcap"), scan_odometry=None, reader=SimpleNamespace(stats=stats))
    blind = [100] * 5 + [0] * 3 + [100] * 4 + [0] * BLIND_STEPS + [100] * 6  # two runs: 3 and BLIND_STEPS
    warn_blind(src, totals(blind))
    assert said == [
        f"log 'b.mcap': {BLIND_STEPS} steps in a row had no valid beam (106.000 to 110.500 s, 4.5 s): the "
        "robot went on its odometry alone there (a laser covered or blinded? a driver writing NaN or inf?)"
    ]
    said.clear()
    warn_blind(src, totals([100] * 5 + [0] * (BLIND_STEPS - 1) + [100]))
    warn_blind(src, totals([0] * 30))
    assert not said
    src.scan_odometry = object()  # on the scans alone (input.odometry=scans) there is no odometry to go on
    warn_blind(src, totals(blind))
    assert said and "the robot went on its last motion (input.odometry=scans) there" in said[0]
