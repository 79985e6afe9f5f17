"""The results MCAP in ROS 2 messages (``--mcap-profile ros2``, report/mcap_ros2.py),
read back with rosbags' own rosbag2 reader and decoded with types built from the file's embedded
definitions alone; every value checked against the Foxglove profile's file of the same run and the run's
tables."""

from __future__ import annotations

import base64
import json
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from mcap.reader import make_reader
from test_report_plots import make_report_outputs

from cornerslam_cli.cli import cli
from cornerslam_cli.logs.mcap import RESULTS_MCAP_LIBRARY, header_fields
from cornerslam_cli.report.mcap_items import PROFILES
from cornerslam_cli.report.mcap_out import (
    ROS2_LAST_SECOND,
    TOPICS,
    StampRangeError,
    check_stamps,
    stamp_to_ns,
    write_results_mcap,
)
from cornerslam_cli.report.mcap_ros2 import LATCHED, ROS_TOPICS, SCAN_FRAME, TYPES
from cornerslam_cli.report.occupancy import read_grid
from cornerslam_cli.report.tables import read_csv


def read_ros2(path: Path) -> tuple[dict, dict, dict]:
    """({topic: [(log time, message)]}, {topic: (type, durability name)}, {type: definition text}) through
    rosbags' rosbag2 MCAP reader, each message decoded with the types its channel's definition declares."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    messages: dict[str, list] = defaultdict(list)
    with Reader(path) as reader:
        store = get_typestore(Stores.EMPTY)  # nothing but what the file says
        for c in reader.connections:
            store.register(get_types_from_msg(c.msgdef.data, c.msgtype))
        channels = {
            c.topic: (c.msgtype, c.ext.offered_qos_profiles[0].durability.name) for c in reader.connections
        }
        defs = {c.msgtype: c.msgdef.data for c in reader.connections}
        for c, t, raw in reader.messages():
            messages[c.topic].append((t, store.deserialize_cdr(raw, c.msgtype)))
    return messages, channels, defs


def read_foxglove(path: Path) -> dict[str, list]:
    out: dict[str, list] = defaultdict(list)
    with open(path, "rb") as f:
        for _, channel, m in make_reader(f).iter_messages(log_time_order=False):
            out[channel.topic].append((m.log_time, json.loads(m.data)))
    return out


def stamp(header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def xyyaw(pose) -> tuple[float, float, float]:
    q = pose.orientation
    return pose.position.x, pose.position.y, 2 * np.arctan2(q.z, q.w)


@pytest.fixture(scope="module")
def files(tmp_path_factory, sim_log):
    """(run dir, {profile: path}) for one run, written in every profile."""
    run_dir, _ = make_report_outputs(tmp_path_factory, sim_log)
    where = tmp_path_factory.mktemp("ros2")
    paths = {p: write_results_mcap(run_dir, where / f"{p}.mcap", profile=p) for p in PROFILES}
    return run_dir, paths


@pytest.fixture(scope="module")
def ros2(files):
    return read_ros2(files[1]["ros2"])


def test_header_channels_qos_and_metadata_are_the_ros2_profiles(files, ros2):
    _, paths = files
    assert header_fields(paths["ros2"]) == ("ros2", RESULTS_MCAP_LIBRARY)
    assert header_fields(paths["foxglove"]) == ("", RESULTS_MCAP_LIBRARY)
    _, channels, _ = ros2
    said = [k for k in TOPICS if k != "scan"]  # (no scans given: not declared)
    expected = {ROS_TOPICS[k]: (TYPES[k], "TRANSIENT_LOCAL" if k in LATCHED else "VOLATILE") for k in said}
    assert channels == expected and "/tf" in channels and TOPICS["tf"] not in channels
    with open(paths["ros2"], "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}
        assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
        records = {m.name: m.metadata for m in reader.iter_metadata()}
    # rosbag2 (Jazzy on) reads numeric QoS when the rosbag2 record's serialized_metadata is empty
    assert records["rosbag2"] == {"serialized_metadata": ""}
    assert records["cornerslam"]["assoc"] == "pca"


def test_the_same_messages_at_the_same_times_as_the_foxglove_profile(files, ros2):
    _, paths = files
    fox = read_foxglove(paths["foxglove"])
    messages, _, _ = ros2
    by_key = {k: [t for t, _ in fox[TOPICS[k]]] for k in TOPICS if TOPICS[k] in fox}
    assert [t for t, _ in messages["/tf"]] == sorted(by_key["tf"] + by_key["odom_tf"])
    for key, times in by_key.items():
        if key not in ("tf", "odom_tf"):
            assert [t for t, _ in messages[ROS_TOPICS[key]]] == times, key


def test_poses_paths_and_transforms_are_the_runs(files, ros2):
    run_dir, paths = files
    messages, _, _ = ros2
    fox = read_foxglove(paths["foxglove"])
    traj = read_csv(run_dir / "trajectory.csv")
    with open(run_dir / "trajectory.csv") as f:
        stamps = [stamp_to_ns(line.split(",")[1]) for line in f.read().splitlines()[1:]]
    assert next(iter(open(run_dir / "trajectory.csv"))).split(",")[1] == "stamp"
    poses = messages[TOPICS["pose"]]
    assert [stamp(m.header) for _, m in poses] == stamps and {m.header.frame_id for _, m in poses} == {"map"}
    got = np.array([xyyaw(m.pose) for _, m in poses])
    np.testing.assert_allclose(got[:, :2], np.column_stack((traj["x"], traj["y"])), atol=1e-12)
    np.testing.assert_allclose(np.angle(np.exp(1j * (got[:, 2] - traj["theta"]))), 0, atol=1e-9)
    ((_, path),) = messages[TOPICS["path"]]
    assert [stamp(p.header) for p in path.poses] == stamps  # each pose at its step's stamp
    np.testing.assert_array_equal(np.array([xyyaw(p.pose) for p in path.poses]), got)
    ((_, fox_path),) = fox[TOPICS["odom_path"]]
    ((_, odom_path),) = messages[TOPICS["odom_path"]]
    fox_xy = [(p["position"]["x"], p["position"]["y"]) for p in fox_path["poses"]]
    assert [(p.pose.position.x, p.pose.position.y) for p in odom_path.poses] == fox_xy
    # /tf: map → odom and odom → base, the values of the Foxglove profile's two transform topics
    fox_tf = {
        (t["parent_frame_id"], t["child_frame_id"], t["timestamp"]["sec"] * 10**9 + t["timestamp"]["nsec"])
        for key in ("tf", "odom_tf")
        for _, t in fox[TOPICS[key]]
    }
    ros_tf = set()
    for _, m in messages["/tf"]:
        (t,) = m.transforms
        ros_tf.add((t.header.frame_id, t.child_frame_id, stamp(t.header)))
    assert ros_tf == fox_tf and {p for p, _, _ in ros_tf} == {"map", "odom"}
    fox_first = fox[TOPICS["tf"]][0][1]
    first = next(m.transforms[0] for _, m in messages["/tf"] if m.transforms[0].header.frame_id == "map")
    assert (first.transform.translation.x, first.transform.rotation.z) == (
        fox_first["translation"]["x"], fox_first["rotation"]["z"],
    )  # fmt: skip


def test_landmarks_are_markers_at_map_csv_and_segments_are_lines_csv(files, ros2):
    run_dir, _ = files
    messages, _, _ = ros2
    lm = read_csv(run_dir / "map.csv")
    markers = [mk for _, m in messages[TOPICS["landmarks"]] for mk in m.markers]
    spheres = {mk.id: mk for mk in markers if mk.ns == "landmarks"}
    ellipses = {mk.id: mk for mk in markers if mk.ns == "landmark_ellipses"}
    arrows = {mk.id: mk for mk in markers if mk.ns == "landmark_directions"}
    ids = [int(i) for i in lm["id"]]
    assert sorted(spheres) == sorted(ellipses) == sorted(arrows) == sorted(ids) and len(markers) == 3 * len(
        ids
    )
    for i, x, y, phi in zip(ids, lm["x"], lm["y"], lm["phi"], strict=True):
        s, e, a = spheres[i], ellipses[i], arrows[i]
        assert (s.type, e.type, a.type) == (2, 4, 0)  # SPHERE, LINE_STRIP, ARROW
        assert (s.pose.position.x, s.pose.position.y) == (x, y)
        ring = np.array([(p.x, p.y) for p in e.points])
        assert len(ring) == 25 and np.array_equal(ring[0], ring[-1])  # closed
        tail, tip = a.points
        assert (tail.x, tail.y) == (x, y)
        assert np.arctan2(tip.y - y, tip.x - x) == pytest.approx(np.angle(np.exp(1j * phi)), abs=1e-9)
    lines = read_csv(run_dir / "lines.csv")
    segs = [mk for _, m in messages[TOPICS["segments"]] for mk in m.markers]
    assert {mk.type for mk in segs} == {5} and {mk.ns for mk in segs} == {"segments"}  # LINE_LIST
    assert sum(len(mk.points) for mk in segs) == 2 * len(lines["step"])
    step = int(lines["step"][0])
    (first,) = [mk for mk in segs if mk.id == step]
    mine = lines["step"] == step
    np.testing.assert_array_equal(
        np.array([(p.x, p.y) for p in first.points]).reshape(-1, 4),
        np.column_stack([lines[k][mine] for k in ("x1", "y1", "x2", "y2")]),
    )


def test_the_grid_is_the_foxglove_profiles(files, ros2):
    run_dir, paths = files
    messages, _, _ = ros2
    ((_, g),) = messages[TOPICS["grid"]]
    ((_, fg),) = read_foxglove(paths["foxglove"])[TOPICS["grid"]]
    grid = read_grid(run_dir)
    assert (g.info.height, g.info.width) == grid.cells.shape and g.info.resolution == np.float32(
        grid.resolution
    )
    assert (g.info.origin.position.x, g.info.origin.position.y) == grid.origin
    np.testing.assert_array_equal(g.data, np.frombuffer(base64.b64decode(fg["data"]), dtype=np.int8))
    assert set(np.unique(g.data)) == {-1, 0, 100}


def test_one_profile_serves_every_distribution_the_layouts_are_the_same():
    """A player publishes the bytes as recorded: the types' fields (constants aside) must be the same in
    every ROS 2 distribution rosbags knows from Humble on, or one profile would not do."""
    import re

    from rosbags.typesys import Stores, get_typestore

    def fields(store: Stores, name: str) -> list[str]:
        text, _ = get_typestore(store).generate_msgdef(name, ros_version=2)
        return [line for line in text.splitlines() if not re.match(r"^\s*\w+\s+[A-Z_0-9]+\s*=", line)]

    stores = [
        Stores.ROS2_HUMBLE,
        Stores.ROS2_IRON,
        Stores.ROS2_JAZZY,
        Stores.ROS2_KILTED,
        Stores.ROS2_LYRICAL,
    ]
    for name in set(TYPES.values()):
        layouts = [fields(s, name) for s in stores]
        assert all(layout == layouts[0] for layout in layouts), name
    assert any("ARROW_STRIP" in line for line in get_typestore(Stores.ROS2_JAZZY).generate_msgdef(
        TYPES["landmarks"], ros_version=2)[0].splitlines())  # (what does differ: a constant)  # fmt: skip


def test_run_writes_scans_as_float32_clouds_in_a_frame_at_their_origin(sim_log, tmp_path):
    """`run --mcap-profile ros2`: the scans as PointCloud2 x, y, z float32 (RViz draws no other position
    type: a review found float64 clouds undrawn) in ``cornerslam_scan_origin``, which one /tf_static
    message puts where the Foxglove profile's cloud pose is; `info` says what the file is; run refuses it."""
    base = ["run", str(sim_log), "-q", "--max-scans", "30"]
    for profile in PROFILES:
        args = [*base, "--out", str(tmp_path / profile), "--mcap-out", str(tmp_path / f"{profile}.mcap")]
        res = CliRunner().invoke(cli, [*args, "--mcap-profile", profile])
        assert res.exit_code == 0, res.output
    messages, channels, _ = read_ros2(tmp_path / "ros2.mcap")
    fox = read_foxglove(tmp_path / "foxglove.mcap")[TOPICS["scan"]]
    clouds = messages[TOPICS["scan"]]
    assert len(clouds) == len(fox) == 30
    for (_, c), (_, f) in zip(clouds, fox, strict=True):
        assert [(fl.name, fl.offset, fl.datatype) for fl in c.fields] == [
            ("x", 0, 7),
            ("y", 4, 7),
            ("z", 8, 7),
        ]
        assert (c.point_step, c.row_step, c.header.frame_id) == (12, 12 * c.width, SCAN_FRAME)
        xyz = np.frombuffer(c.data.tobytes(), dtype="<f4").reshape(-1, 3)
        xy32 = np.frombuffer(base64.b64decode(f["data"]), dtype="<f4").reshape(-1, 2)
        assert c.width == len(xy32) > 0 and not xyz[:, 2].any()
        np.testing.assert_array_equal(xyz[:, :2], xy32)
    assert channels["/tf_static"] == ("tf2_msgs/msg/TFMessage", "TRANSIENT_LOCAL")
    ((_, static),) = messages["/tf_static"]
    (t,) = static.transforms
    pose = fox[0][1]["pose"]
    assert (t.header.frame_id, t.child_frame_id) == ("map", SCAN_FRAME)
    assert (t.transform.translation.x, t.transform.translation.y) == (
        pose["position"]["x"],
        pose["position"]["y"],
    )
    assert t.transform.rotation.w == 1.0
    said = CliRunner().invoke(cli, ["info", str(tmp_path / "ros2.mcap")])
    assert said.exit_code == 0 and "`ros2 bag play -i LOG -i FILE`" in said.stdout.splitlines()[-1]
    refused = CliRunner().invoke(
        cli, ["run", str(tmp_path / "ros2.mcap"), "--out", str(tmp_path / "x"), "-q"]
    )
    assert refused.exit_code == 2 and "is the results MCAP of a run" in refused.stderr


def shifted_carmen(tmp_path: Path, seconds: float) -> Path:
    """The first 60 lines of sample_logs/intel_cut.clf with every stamp moved by ``seconds``."""
    src = Path(__file__).parents[1] / "sample_logs" / "intel_cut.clf"
    out = []
    for line in src.read_text().splitlines()[:60]:
        f = line.split()
        if f and f[0] in ("ODOM", "FLASER"):
            at = 7 if f[0] == "ODOM" else 2 + int(f[1]) + 6  # ipc_timestamp, then logger_timestamp two on
            f[at], f[at + 2] = (f"{float(f[i]) + seconds:.6f}" for i in (at, at + 2))
        out.append(" ".join(f))
    path = tmp_path / f"shifted{seconds:+.0f}.clf"
    path.write_text("\n".join(out) + "\n")
    return path


@pytest.mark.parametrize(
    ("seconds", "profile", "said"),
    [
        (2.2e9, "ros2", "past ROS 2's int32 seconds (2038-01-19) (write it with --mcap-profile foxglove)"),
        (
            -100.0,
            "ros2",
            "begin before 1970 (-67.093 s): MCAP's times are unsigned (run it without --mcap-out)",
        ),
        (-100.0, "foxglove", "begin before 1970"),
    ],
)
def test_stamps_a_results_mcap_cannot_hold_are_refused_and_nothing_is_written(
    tmp_path, seconds, profile, said
):
    """A log stamped past 2038 crashed the ROS 2 encoding (int32 seconds) and one stamped before 1970 both
    (MCAP's unsigned times), exit 1 (a review): now exit 2 naming the file and what to do, no output."""
    log, out = shifted_carmen(tmp_path, seconds), tmp_path / "o"
    args = ["run", str(log), "--out", str(out), "-q", "--mcap-out", str(tmp_path / "r.mcap")]
    res = CliRunner().invoke(cli, [*args, "--mcap-profile", profile])
    assert res.exit_code == 2, res.output
    assert res.stderr.startswith(
        f"error: --mcap-out '{tmp_path / 'r.mcap'}' cannot be written: the log's stamps"
    )
    assert said in res.stderr and not out.exists() and not (tmp_path / "r.mcap").exists()
    if seconds > 0:  # the Foxglove profile holds them
        res = CliRunner().invoke(cli, [*args, "--mcap-profile", "foxglove"])
        assert res.exit_code == 0 and (tmp_path / "r.mcap").exists(), res.output


def test_check_stamps_at_the_boundaries():
    last = ROS2_LAST_SECOND * 10**9 + 999_999_999
    check_stamps(0, last, 0, "ros2")
    check_stamps(0, last + 1, 0, "foxglove")
    with pytest.raises(StampRangeError, match="int32 seconds"):
        check_stamps(0, last + 1, 0, "ros2")
    with pytest.raises(StampRangeError, match="before 1970"):
        check_stamps(10**9, 2 * 10**9, -2 * 10**9, "foxglove")  # log times behind the stamps, below 0


def test_a_profile_without_mcap_out_or_unknown_is_refused_before_any_work(sim_log, tmp_path):
    out = tmp_path / "o"
    for profile in PROFILES:  # (the default given too: it would write nothing)
        res = CliRunner().invoke(cli, ["run", str(sim_log), "--out", str(out), "--mcap-profile", profile])
        assert res.exit_code == 2 and "give --mcap-out FILE" in res.stderr and not out.exists()
    res = CliRunner().invoke(
        cli,
        [
            "run",
            str(sim_log),
            "--out",
            str(out),
            "--mcap-out",
            str(tmp_path / "r.mcap"),
            "--mcap-profile",
            "ros1",
        ],
    )
    assert res.exit_code == 2 and "'ros1' is not one of 'foxglove', 'ros2'" in res.stderr and not out.exists()
    with pytest.raises(ValueError, match="unknown results MCAP profile 'x'"):
        write_results_mcap(tmp_path, tmp_path / "r.mcap", profile="x")
