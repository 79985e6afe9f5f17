"""``input.stamps: receive``: every scan and odometry sample taken at the time the recorder received it (a
ROS log's log time, a CARMEN line's logger timestamp) instead of its header stamp — for a log whose
drivers stamp on two clocks (the odometry on a microcontroller's, the laser on the host's) or not at
all, which a run refused (no scan met the odometry), saying how to get out of it only now."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from cornerslam_cli.cli import cli
from cornerslam_cli.logs import open_log
from cornerslam_cli.report.tables import read_csv

SAMPLES = Path(__file__).resolve().parents[1] / "sample_logs"
APART = 1000 * 10**9  # ns: the odometry's clock ahead of the recorder's


def restamped_odometry(src: Path, dst: Path, shift_ns: int) -> Path:
    """``src`` with each nav_msgs/Odometry header stamp moved by ``shift_ns``, every log time kept: the
    odometry stamped on another clock, received when it was."""
    from _log_fixtures import rewrite_mcap

    def change(schema, m):
        data = restamp(m.data, shift_ns) if schema.name == "nav_msgs/msg/Odometry" else m.data
        return m.log_time, m.publish_time, data

    return rewrite_mcap(src, dst, change)


def run(log: Path, out: Path, *more: str):
    return CliRunner().invoke(cli, ["run", str(log), "--out", str(out), "-q", "--max-scans", "60", *more])


def test_odometry_on_another_clock_runs_on_the_recorders_time(sim_log, tmp_path):
    log = restamped_odometry(sim_log, tmp_path / "two_clocks.mcap", APART)
    refused = run(log, tmp_path / "header")
    assert refused.exit_code == 2 and not (tmp_path / "header").exists()
    assert "--set input.stamps=receive" in refused.stderr, refused.stderr
    assert len(refused.stderr.strip().splitlines()) == 1, refused.stderr  # (a warning said it first: a probe)
    ran = run(log, tmp_path / "receive", "--set", "input.stamps=receive")
    assert ran.exit_code == 0, ran.output
    # the sim log's log times are its header stamps: the same run as on the log itself
    assert run(sim_log, tmp_path / "original").exit_code == 0
    mine, theirs = (
        read_csv(tmp_path / "receive" / "trajectory.csv"),
        read_csv(tmp_path / "original" / "trajectory.csv"),
    )
    assert len(mine["stamp"]) == len(theirs["stamp"]) > 10
    for column in ("stamp", "x", "y", "theta", "odom_x", "odom_y"):
        np.testing.assert_array_equal(mine[column], theirs[column], err_msg=column)


def test_the_reader_stamps_scans_and_odometry_at_their_log_times(tmp_path):
    """Each message taken at its log time, 0.25 s after its header stamp here; header stamps otherwise."""
    from _log_fixtures import odom_messages, scan_messages, write_messages_mcap

    late = 250_000_000
    msgs = [(topic, kind, t + late, data) for topic, kind, t, data in scan_messages(n=5) + odom_messages(n=8)]
    log = write_messages_mcap(tmp_path / "late.mcap", sorted(msgs, key=lambda m: m[2]))
    headers = [m.stamp for m in open_log(log).messages()]
    received = [m.stamp for m in open_log(log, stamps="receive").messages()]
    assert len(headers) == len(received) == 13
    np.testing.assert_allclose(np.array(received) - np.array(headers), 0.25, atol=1e-6)
    assert open_log(log, stamps="receive").record_offset() == 0  # (the outputs' stamps are the recorder's)
    assert abs(open_log(log).record_offset() - late) < 1000  # (the fixture rounds stamps to ns)


def test_a_carmen_log_is_read_on_its_logger_timestamps(tmp_path):
    """intel_cut.clf's logger timestamps are its timestamps: the same run; a log whose lines lack them is
    refused, naming the key."""
    clf = SAMPLES / "intel_cut.clf"
    lines = clf.read_text().splitlines()[:120]
    log = tmp_path / "cut.clf"
    log.write_text("\n".join(lines) + "\n")
    assert run(log, tmp_path / "h").exit_code == 0
    assert run(log, tmp_path / "r", "--set", "input.stamps=receive").exit_code == 0
    assert (tmp_path / "h" / "trajectory.csv").read_bytes() == (
        tmp_path / "r" / "trajectory.csv"
    ).read_bytes()
    moved = []
    for line in lines:  # the logger timestamps 5 s later: the run's stamps follow them
        f = line.split()
        if f and f[0] in ("ODOM", "FLASER"):
            f[-1] = f"{float(f[-1]) + 5:.6f}"
        moved.append(" ".join(f))
    (tmp_path / "later.clf").write_text("\n".join(moved) + "\n")
    assert run(tmp_path / "later.clf", tmp_path / "r5", "--set", "input.stamps=receive").exit_code == 0
    np.testing.assert_allclose(
        read_csv(tmp_path / "r5" / "trajectory.csv")["stamp"]
        - read_csv(tmp_path / "h" / "trajectory.csv")["stamp"],
        5.0,
        atol=1e-6,
    )
    cut = [" ".join(line.split()[:-2]) if line.startswith(("ODOM", "FLASER")) else line for line in lines]
    (tmp_path / "bare.clf").write_text("\n".join(cut) + "\n")
    res = run(tmp_path / "bare.clf", tmp_path / "b", "--set", "input.stamps=receive")
    assert res.exit_code == 2 and "input.stamps=receive reads the lines' logger timestamps" in res.stderr
    assert not (tmp_path / "b").exists()


def test_an_unknown_value_is_refused():
    res = CliRunner().invoke(cli, ["config", "--set", "input.stamps=recorder"])
    assert res.exit_code == 2 and "receive" in res.stderr


@pytest.mark.parametrize("value", ["header", "receive"])
def test_the_default_config_and_summary_say_which(sim_log, tmp_path, value):

    assert (
        run(sim_log, tmp_path / value, "--set", f"input.stamps={value}", "--max-scans", "20").exit_code == 0
    )
    summary = json.loads((tmp_path / value / "summary.json").read_text())
    assert summary["config"]["input"]["stamps"] == value


def test_transforms_of_one_message_keep_their_spacing_before_its_log_time(tmp_path):
    """Odometry from tf with three odom → base_link transforms a message (10 ms apart): with receive all
    took the message's one log time, two of three dropped as repeats (a review); each now keeps its
    spacing before it."""
    from _log_fixtures import scan_messages, write_messages_mcap
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    t = store.types

    def transform(ns: int, x: float):
        sec, nsec = divmod(ns, 10**9)
        header = t["std_msgs/msg/Header"](
            stamp=t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id="odom"
        )
        tr = t["geometry_msgs/msg/Transform"](
            translation=t["geometry_msgs/msg/Vector3"](x=x, y=0.0, z=0.0),
            rotation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        )
        return t["geometry_msgs/msg/TransformStamped"](
            header=header, child_frame_id="base_link", transform=tr
        )

    t0, late = 1_700_000_000 * 10**9, 500_000_000
    msgs = scan_messages(n=5)
    for k in range(6):
        stamps = [t0 + k * 100_000_000 + j * 10_000_000 for j in range(3)]
        tf = t["tf2_msgs/msg/TFMessage"](transforms=[transform(s, 0.01 * i) for i, s in enumerate(stamps)])
        data = bytes(store.serialize_cdr(tf, "tf2_msgs/msg/TFMessage"))
        msgs.append(("/tf", "tf2_msgs/msg/TFMessage", stamps[-1] + late, data))
    log = write_messages_mcap(tmp_path / "tf3.mcap", sorted(msgs, key=lambda m: m[2]))
    odometry = [m.stamp for m in open_log(log, stamps="receive").messages() if not hasattr(m, "ranges")]
    header = [m.stamp for m in open_log(log).messages() if not hasattr(m, "ranges")]
    assert len(odometry) == len(header) == 18
    np.testing.assert_allclose(np.array(odometry) - np.array(header), 0.5, atol=1e-6)


def test_the_way_out_is_offered_only_where_it_can_help(sim_log, tmp_path):
    """The hint to read the recorder's times was offered where they are apart too (and a CARMEN log
    without logger timestamps sent the user round in a circle); with receive, a refusal spoke of header
    stamps and offered no way back (a review)."""
    from _log_fixtures import rewrite_mcap

    def both(schema, m):  # the odometry on another clock in its header stamps and its log times alike
        if schema.name != "nav_msgs/msg/Odometry":
            return m.log_time, m.publish_time, m.data
        return m.log_time + APART, m.publish_time + APART, restamp(m.data, APART)

    log = rewrite_mcap(sim_log, tmp_path / "both.mcap", both)
    res = run(log, tmp_path / "o")
    assert res.exit_code == 2 and "s apart" in res.stderr and "input.stamps" not in res.stderr
    one_time = rewrite_mcap(sim_log, tmp_path / "one_time.mcap", lambda _, m: (10**18, 10**18, m.data))
    res = run(one_time, tmp_path / "o", "--set", "input.stamps=receive")
    assert res.exit_code == 2 and "the log times of the other" in res.stderr, res.stderr
    assert "check that the recorder stamped each message" in res.stderr
    assert res.stderr.rstrip().endswith("or read the messages' header stamps: --set input.stamps=header)")
    # CARMEN without logger timestamps, its odometry on another clock: no hint to read them
    lines = (SAMPLES / "intel_cut.clf").read_text().splitlines()[:120]
    bare = []
    for line in lines:
        f = line.split()
        if f and f[0] in ("ODOM", "FLASER"):
            f = f[:-2]
            if f[0] == "ODOM":
                f[-1] = f"{float(f[-1]) + 5000:.6f}"
        bare.append(" ".join(f))
    (tmp_path / "bare.clf").write_text("\n".join(bare) + "\n")
    res = run(tmp_path / "bare.clf", tmp_path / "o")
    assert res.exit_code == 2 and "input.stamps" not in res.stderr, res.stderr


def restamp(data: bytes, shift_ns: int) -> bytes:
    """A CDR message whose first field is a std_msgs/Header (nav_msgs/Odometry) with its stamp moved by
    ``shift_ns``: the stamp's sec (int32) and nanosec (uint32) follow the 4-byte encapsulation header, so
    they are rewritten in place (rosbags' deserialize and serialize took 25 ms a message: 2 min a test)."""
    little = data[1] == 1  # CDR_LE (0x0001) or CDR_BE (0x0000)
    fmt = "<iI" if little else ">iI"
    sec, nanosec = struct.unpack_from(fmt, data, 4)
    total = sec * 10**9 + nanosec + shift_ns
    return data[:4] + struct.pack(fmt, *divmod(total, 10**9)) + data[12:]


def test_restamp_moves_the_header_stamp_as_rosbags_reads_it():
    from rosbags.typesys import Stores, get_typestore

    from cornerslam_cli.logs.writers import RosSerializer
    from cornerslam_cli.types import OdomSample

    store = get_typestore(Stores.ROS2_HUMBLE)
    data = RosSerializer("cdr").odometry(OdomSample(1_700_000_000.25, 1.0, 2.0, 0.5), "odom", "base_link")
    msg = store.deserialize_cdr(restamp(data, APART + 900_000_000), "nav_msgs/msg/Odometry")
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1_700_001_001, 150_000_000)
    assert msg.header.frame_id == "odom" and msg.child_frame_id == "base_link"
    assert msg.pose.pose.position.x == 1.0 and msg.pose.pose.position.y == 2.0


def test_a_carmen_tag_not_read_may_lack_logger_timestamps(tmp_path):
    """RLASER lines without logger timestamps beside the FLASER lines read: receive was refused for them."""
    lines = (SAMPLES / "intel_cut.clf").read_text().splitlines()[:120]
    extra = [" ".join(["RLASER", *line.split()[1:-2]]) for line in lines if line.startswith("FLASER")][:3]
    (tmp_path / "rear.clf").write_text("\n".join([*lines, *extra]) + "\n")
    res = run(tmp_path / "rear.clf", tmp_path / "o", "--set", "input.stamps=receive")
    assert res.exit_code == 0, res.output


def test_a_misspelt_value_in_code_is_refused(tmp_path):
    with pytest.raises(ValueError, match="stamps must be one of header, receive, not 'recieve'"):
        open_log(SAMPLES / "intel_cut.clf", stamps="recieve")


def test_a_carmen_log_read_on_its_logger_timestamps_already_is_offered_no_switch(tmp_path):
    """Timestamps that stand still (a converter's 0) are read on the logger timestamps already: offering
    input.stamps=receive there would change nothing."""
    out = []
    for line in (SAMPLES / "intel_cut.clf").read_text().splitlines()[:120]:
        f = line.split()
        if f and f[0] in ("ODOM", "FLASER"):
            f[-3] = "0.000000"  # the timestamp; the logger timestamp (last) moves
        out.append(" ".join(f))
    (tmp_path / "still.clf").write_text("\n".join(out) + "\n")
    reader = open_log(tmp_path / "still.clf")
    assert reader.stamps_name == "logger timestamps" and reader.stamps_way_out() == ""
    assert open_log(SAMPLES / "intel_cut.clf").stamps_way_out().endswith("--set input.stamps=receive")
    assert (
        open_log(SAMPLES / "intel_cut.clf", stamps="receive").stamps_way_out().endswith("input.stamps=header")
    )


def test_a_ground_truth_a_receive_run_does_not_meet_is_said_to_be_on_the_other_clock(sim_log, tmp_path):
    """Every message logged 1000 s after its header stamp (a recorder on another clock): a receive run
    is stamped on the recorder's clock, which the ground truth (on the header clock) does not overlap —
    the warning says which clock the run is on; a header run is scored."""
    from _log_fixtures import rewrite_mcap

    log = rewrite_mcap(
        sim_log, tmp_path / "late.mcap", lambda schema, m: (m.log_time + APART, m.publish_time, m.data)
    )
    gt = sim_log.with_suffix(".gt.tum")
    (tmp_path / "late.gt.tum").write_bytes(gt.read_bytes())
    assert run(log, tmp_path / "h").exit_code == 0
    assert json.loads((tmp_path / "h" / "summary.json").read_text())["accuracy"]["ate"]["n"] > 10
    res = run(log, tmp_path / "r", "--set", "input.stamps=receive")
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert "ate" not in (summary.get("accuracy") or {})
    (warning,) = [w for w in summary["warnings"] if "does not overlap" in w]
    assert "the run is stamped on the recorder's clock (input.stamps=receive)" in warning, warning
    # only where the two do not overlap: a ground truth of one pose is not put down to the clocks (a review)
    (tmp_path / "late.gt.tum").write_text(gt.read_text().splitlines()[0] + "\n")
    assert run(log, tmp_path / "one", "--set", "input.stamps=receive").exit_code == 0
    warnings = json.loads((tmp_path / "one" / "summary.json").read_text())["warnings"]
    (warning,) = [w for w in warnings if "single pose" in w]
    assert "recorder's clock" not in warning, warning


def test_info_notes_odometry_on_another_clock_with_the_way_out(sim_log, tmp_path):
    """Odometry header stamps two hours ahead of the scans': info said nothing, run refused the log (a
    ROS-user probe). A note names the two clocks and input.stamps=receive; none under it, nor on the log."""
    log = restamped_odometry(sim_log, tmp_path / "two_clocks.mcap", 7200 * 10**9)
    notes = open_log(log).info().notes
    assert any(
        n.startswith("its odometry's header stamps are about 7200 s ahead of its scans': two clocks")
        and "--set input.stamps=receive" in n
        for n in notes
    ), notes
    assert not any("odometry's header stamps" in n for n in open_log(log, stamps="receive").info().notes)
    assert not any("odometry's header stamps" in n for n in open_log(sim_log).info().notes)
