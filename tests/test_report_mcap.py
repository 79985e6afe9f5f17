"""Results as MCAP for Foxglove (report/mcap_out.py), read back with mcap's own reader."""

from __future__ import annotations

import csv
import json
from collections import defaultdict

import numpy as np
import pytest
from _strict_json import strict
from mcap.reader import make_reader
from test_report_plots import make_report_outputs

from cornerslam_cli.report.mcap_foxglove import SCHEMAS, TOPIC_SCHEMAS
from cornerslam_cli.report.mcap_out import TOPICS, stamp_to_ns, write_results_mcap
from cornerslam_cli.report.tables import read_csv


@pytest.fixture(scope="module")
def results(tmp_path_factory, sim_log):
    """(run dir, {topic: [(log_time, payload)]}, {topic: schema name}, {schema name: (encoding, schema)})."""
    run_dir, _ = make_report_outputs(tmp_path_factory, sim_log)
    path = write_results_mcap(run_dir, tmp_path_factory.mktemp("mcap") / "results.mcap")
    messages: dict[str, list] = defaultdict(list)
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        channels = {
            c.topic: (c.message_encoding, summary.schemas[c.schema_id].name)
            for c in summary.channels.values()
        }
        schemas = {s.name: (s.encoding, json.loads(s.data)) for s in summary.schemas.values()}
        for _schema, channel, message in reader.iter_messages(log_time_order=False):
            payload = json.loads(message.data, parse_constant=strict)  # what Foxglove accepts
            messages[channel.topic].append((message.log_time, payload))
    return run_dir, messages, channels, schemas


def validate(value, schema: dict, where: str = "$") -> None:
    """The subset of JSON Schema our schemas use: type, properties, required, items, minimum."""
    kind = schema.get("type")
    checks = {
        "object": lambda v: isinstance(v, dict),
        "array": lambda v: isinstance(v, list),
        "string": lambda v: isinstance(v, str),
        "boolean": lambda v: isinstance(v, bool),
        "integer": lambda v: isinstance(v, int) and not isinstance(v, bool),
        "number": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
    }
    if kind:
        assert checks[kind](value), f"{where}: expected {kind}, got {value!r:.60}"
    if "minimum" in schema:
        assert value >= schema["minimum"], where
    if kind == "object":
        missing = set(schema.get("required", ())) - set(value)
        assert not missing, f"{where}: missing required {sorted(missing)}"
        for k, sub in schema.get("properties", {}).items():
            if k in value:
                validate(value[k], sub, f"{where}.{k}")
    if kind == "array":
        for i, item in enumerate(value):
            validate(item, schema.get("items", {}), f"{where}[{i}]")


def yaw(q: dict) -> float:
    return 2 * np.arctan2(q["z"], q["w"])


def ns(t: dict) -> int:
    assert 0 <= t["nsec"] < 1_000_000_000
    return t["sec"] * 1_000_000_000 + t["nsec"]


def test_channels_and_schemas_are_the_foxglove_ones(results):
    _, _, channels, schemas = results
    said = [k for k in TOPICS if k != "scan"]  # (no scans given: that topic is not declared)
    assert channels == {TOPICS[k]: ("json", TOPIC_SCHEMAS[k]) for k in said}
    assert set(schemas) == {TOPIC_SCHEMAS[k] for k in said} and set(schemas) <= set(SCHEMAS)
    for name, (encoding, schema) in schemas.items():
        assert encoding == "jsonschema"
        assert name.startswith("foxglove.") and schema["title"] == name


def test_message_counts(results):
    run_dir, messages, _, _ = results
    steps = len(read_csv(run_dir / "trajectory.csv")["step"])
    landmarks = len(read_csv(run_dir / "map.csv")["id"])
    assert steps > 10 and landmarks > 5
    counts = {topic: len(m) for topic, m in messages.items()}
    assert counts == {
        TOPICS["pose"]: steps,
        TOPICS["odom_pose"]: steps,
        TOPICS["tf"]: steps,
        TOPICS["odom_tf"]: steps,  # the sim log has no tf odom → base_link: published from its odometry
        TOPICS["segments"]: steps,
        TOPICS["landmarks"]: landmarks,
        TOPICS["path"]: 1,
        TOPICS["odom_path"]: 1,
        TOPICS["ground_truth_path"]: 1,  # the sim log has ground truth
        TOPICS["grid"]: 1,  # the occupancy grid of map.pgm
    }


def test_the_grid_is_map_pgm_in_nav_msgs_values(results):
    """The occupancy grid (map.pgm) was not in the results MCAP (a new-user walkthrough): one
    foxglove.Grid, cell (0, 0) at map.yaml's origin, rows along +y, int8 100 / 0 / −1."""
    import base64

    from cornerslam_cli.report.occupancy import FREE, OCCUPIED, UNKNOWN, read_grid

    run_dir, messages, _, _ = results
    ((_, g),) = messages[TOPICS["grid"]]
    grid = read_grid(run_dir)
    rows, cols = grid.cells.shape
    assert (g["column_count"], g["row_stride"], g["cell_stride"]) == (cols, cols, 1)
    assert g["cell_size"] == {"x": grid.resolution, "y": grid.resolution}
    assert (g["pose"]["position"]["x"], g["pose"]["position"]["y"]) == pytest.approx(grid.origin)
    values = np.frombuffer(base64.b64decode(g["data"]), dtype=np.int8).reshape(rows, cols)
    for pixel, value in ((OCCUPIED, 100), (FREE, 0), (UNKNOWN, -1)):
        assert (values == value).sum() == (grid.cells == pixel).sum() > 0
    # row 0 is the lowest y: map.pgm's pixels upside down (the file is top row first)
    pgm = (run_dir / "map.pgm").read_bytes()
    pixels = np.frombuffer(pgm[len(pgm) - rows * cols :], dtype=np.uint8).reshape(rows, cols)[::-1]
    assert not np.array_equal(pixels, pixels[::-1])  # (a map that reads the same flipped tells nothing)
    np.testing.assert_array_equal(values == 100, pixels == OCCUPIED)
    np.testing.assert_array_equal(values == -1, pixels == UNKNOWN)


def test_every_payload_validates_against_its_embedded_schema(results):
    _, messages, channels, schemas = results
    for topic, msgs in messages.items():
        schema = schemas[channels[topic][1]][1]
        for i, (_, payload) in enumerate(msgs):
            validate(payload, schema, f"{topic}[{i}]")


def test_validator_rejects_a_missing_required_field(results):
    _, messages, _, schemas = results
    payload = json.loads(json.dumps(messages[TOPICS["pose"]][0][1]))
    del payload["pose"]["orientation"]["w"]
    with pytest.raises(AssertionError, match="missing required"):
        validate(payload, schemas["foxglove.PoseInFrame"][1])


def test_poses_carry_the_trajectory_stamps_and_values(results):
    run_dir, messages, _, _ = results
    traj = read_csv(run_dir / "trajectory.csv")
    with open(run_dir / "trajectory.csv", newline="") as f:
        stamps = [stamp_to_ns(r["stamp"]) for r in csv.DictReader(f)]
    np.testing.assert_allclose(np.array(stamps) / 1e9, traj["stamp"], atol=1e-6)
    poses = messages[TOPICS["pose"]]
    assert [t for t, _ in poses] == stamps
    assert [ns(p["timestamp"]) for _, p in poses] == stamps
    assert {p["frame_id"] for _, p in poses} == {"map"}
    got = np.array([[p["pose"]["position"]["x"], p["pose"]["position"]["y"], yaw(p["pose"]["orientation"])]
                    for _, p in poses])  # fmt: skip
    np.testing.assert_allclose(got[:, :2], np.column_stack((traj["x"], traj["y"])), atol=1e-9)
    np.testing.assert_allclose(np.angle(np.exp(1j * (got[:, 2] - traj["theta"]))), 0, atol=1e-9)
    path = messages[TOPICS["path"]][0][1]["poses"]
    np.testing.assert_allclose([p["position"]["x"] for p in path], traj["x"], atol=1e-9)


def test_map_to_odom_transform_puts_the_odometry_on_the_corrected_pose(results):
    run_dir, messages, _, _ = results
    traj = read_csv(run_dir / "trajectory.csv")
    tfs = messages[TOPICS["tf"]]
    assert {(m["parent_frame_id"], m["child_frame_id"]) for _, m in tfs} == {("map", "odom")}
    for i, (_, m) in enumerate(tfs):
        a = yaw(m["rotation"])
        c, s = np.cos(a), np.sin(a)
        ox, oy = traj["odom_x"][i], traj["odom_y"][i]
        x = m["translation"]["x"] + c * ox - s * oy
        y = m["translation"]["y"] + s * ox + c * oy
        np.testing.assert_allclose([x, y], [traj["x"][i], traj["y"][i]], atol=1e-9)
        assert np.angle(np.exp(1j * (a + traj["odom_theta"][i] - traj["theta"][i]))) == pytest.approx(
            0, abs=1e-9
        )


def test_landmarks_at_map_positions_from_their_first_step(results):
    run_dir, messages, _, _ = results
    lm = read_csv(run_dir / "map.csv")
    with open(run_dir / "trajectory.csv", newline="") as f:
        stamp_of_step = {int(r["step"]): stamp_to_ns(r["stamp"]) for r in csv.DictReader(f)}
    by_id = {}
    for t, update in messages[TOPICS["landmarks"]]:
        (entity,) = update["entities"]
        by_id[entity["id"]] = (t, entity)
    assert set(by_id) == {f"landmark/{int(i)}" for i in lm["id"]}
    for i, ident in enumerate(lm["id"]):
        t, entity = by_id[f"landmark/{int(ident)}"]
        assert t == stamp_of_step[int(lm["first_step"][i])] == ns(entity["timestamp"])
        (sphere,) = entity["spheres"]
        pos = sphere["pose"]["position"]
        assert (pos["x"], pos["y"]) == pytest.approx((lm["x"][i], lm["y"][i]), abs=1e-9)
        ellipse = entity["lines"][0]
        assert ellipse["type"] == 1 and len(ellipse["points"]) >= 8  # LINE_LOOP
        # the 3σ ellipse is centred on the landmark and no wider than 3·sqrt(trace)
        pts = np.array([[p["x"], p["y"]] for p in ellipse["points"]])
        np.testing.assert_allclose(pts.mean(axis=0), [lm["x"][i], lm["y"][i]], atol=1e-9)
        r = np.linalg.norm(pts - pts.mean(axis=0), axis=1).max()
        assert r <= 3 * np.sqrt(lm["var_x"][i] + lm["var_y"][i]) + 1e-9


def test_segments_per_step_match_lines_csv(results):
    run_dir, messages, _, _ = results
    lines = read_csv(run_dir / "lines.csv")
    got = []
    for _, update in messages[TOPICS["segments"]]:
        for entity in update["entities"]:
            step = int(entity["id"].split("/")[1])
            (line,) = entity["lines"]
            assert line["type"] == 2  # LINE_LIST
            pts = line["points"]
            got += [(step, a["x"], a["y"], b["x"], b["y"]) for a, b in zip(pts[::2], pts[1::2], strict=True)]
    want = np.column_stack((lines["step"], lines["x1"], lines["y1"], lines["x2"], lines["y2"]))
    np.testing.assert_allclose(np.array(sorted(got)), want[np.lexsort(want.T[::-1])], atol=1e-9)


def test_stamp_to_ns_is_exact():
    assert stamp_to_ns("1700000000.006000042") == 1_700_000_000_006_000_042
    assert stamp_to_ns("12") == 12_000_000_000
    assert stamp_to_ns("0.000000001") == 1


def test_info_describes_a_results_mcap_instead_of_refusing_it(results, tmp_path):
    """`info` on run --mcap-out's file listed its topics, then "laser not on tf …" and exit 2 "has no
    sensor_msgs/LaserScan topic" (a new-user walkthrough): it says what the file is, exit 0."""
    from click.testing import CliRunner

    from cornerslam_cli.cli import cli

    path = write_results_mcap(results[0], tmp_path / "results.mcap")
    res = CliRunner().invoke(cli, ["info", str(path)])
    assert res.exit_code == 0, res.output
    lines = res.stdout.splitlines()
    assert "topics:" in lines and "run would use:" not in lines and res.stderr == ""
    assert lines[-1].startswith("results:  written by `cornerslam run --mcap-out`")
    assert any(line.split()[0] == TOPICS["path"] for line in lines if line.startswith("  /"))
    asked = CliRunner().invoke(cli, ["info", str(path), "--scan-topic", "/nope"])  # judged as a log then
    assert asked.exit_code == 2 and "/nope" in asked.stderr
    # run (and compare) on it: said to be a run's results, not "has no sensor_msgs/LaserScan topic (record
    # the laser as …)" (a ROS-user probe)
    for command in ("run", "compare"):
        ran = CliRunner().invoke(cli, [command, str(path), "--out", str(tmp_path / command), "-q"])
        assert ran.exit_code == 2 and not (tmp_path / command).exists()
        said = "'results.mcap' is the results MCAP of a run (`cornerslam run --mcap-out`), not a log"
        assert said in ran.stderr
        assert "summary.json names as input.log" in ran.stderr


def test_an_unscored_runs_results_declare_no_ground_truth_topic(sim_log, tmp_path):
    """A run without ground truth declared /cornerslam/ground_truth_path with no message, an empty topic
    in Foxglove's list (a new-user walkthrough)."""
    import shutil

    from click.testing import CliRunner

    from cornerslam_cli.cli import cli

    log = tmp_path / "alone.mcap"  # (no alone.gt.tum beside it)
    shutil.copy(sim_log, log)
    args = ["run", str(log), "--out", str(tmp_path / "o"), "-q", "--max-scans", "30"]
    assert CliRunner().invoke(cli, [*args, "--mcap-out", str(tmp_path / "r.mcap")]).exit_code == 0
    with open(tmp_path / "r.mcap", "rb") as f:
        topics = {c.topic for c in make_reader(f).get_summary().channels.values()}
    assert TOPICS["path"] in topics and TOPICS["ground_truth_path"] not in topics


def test_results_play_beside_a_log_recorded_on_another_clock(sim_log, tmp_path):
    """A simulation recorded without use_sim_time: header stamps from the simulation's clock, log times
    the wall clock's. The results' log times were the stamps: a Foxglove timeline of both files spanned
    decades and never played them together. Now they follow the log's recorder clock (its median offset
    over the first scans), warned; the messages keep their stamps."""
    from _log_fixtures import rewrite_mcap
    from click.testing import CliRunner

    from cornerslam_cli.cli import cli

    ahead = 1_000_000 * 10**9  # ns: the recorder's clock ahead of the stamps
    log = rewrite_mcap(
        sim_log,
        tmp_path / "wallclock.mcap",
        lambda _, m: (m.log_time + ahead, m.publish_time + ahead, m.data),
    )
    out = tmp_path / "o"
    args = [
        "run",
        str(log),
        "--out",
        str(out),
        "-q",
        "--max-scans",
        "30",
        "--mcap-out",
        str(tmp_path / "r.mcap"),
    ]
    assert CliRunner().invoke(cli, args).exit_code == 0
    with open(tmp_path / "r.mcap", "rb") as f:
        poses = [(m.log_time, json.loads(m.data)["timestamp"]) for _, c, m in make_reader(f).iter_messages()
                 if c.topic == TOPICS["pose"]]  # fmt: skip
    with open(out / "trajectory.csv", newline="") as f:
        stamps = [stamp_to_ns(row["stamp"]) for row in csv.DictReader(f)]
    assert [ns(t) for _, t in poses] == stamps  # the messages' own stamps: the log's header stamps
    assert [t for t, _ in poses] == [s + ahead for s in stamps]
    warnings = json.loads((out / "summary.json").read_text())["warnings"]
    assert any("its recorder's clock is 1000000.0 s ahead of its scans' header stamps" in w for w in warnings)
    from cornerslam_cli.logs import open_log

    (note,) = open_log(log).info().notes  # info's start and duration are the recorder's: it says so
    assert note.startswith("its scans' header stamps are 1000000.0 s behind its record times")
    assert open_log(sim_log).info().notes == ()


def test_a_logs_tf_odometry_beside_its_odometry_topic_places_map_to_odom(sim_log, tmp_path):
    """A log with /odom and a different odom → base_link on /tf (an EKF's beside the wheels'): the
    results MCAP's map → odom is built on the tf's, so the log's own tf ∘ it is the corrected pose (a
    ROS-user probe: 0.57 m off), and the run's summary.json keeps the warning that the two differ (it was
    only on stderr: a review)."""
    import math

    from _log_fixtures import write_messages_mcap

    from cornerslam_cli.cli import cli
    from cornerslam_cli.geometry import compose
    from cornerslam_cli.logs.writers import RosSerializer

    ros = RosSerializer("cdr")
    msgs = []
    with open(sim_log, "rb") as f:
        for schema, channel, m in make_reader(f).iter_messages():
            msgs.append((channel.topic, schema.name, m.log_time, m.data))
            if channel.topic == "/odom":  # its pose ×1.05 on /tf: another estimate of the motion
                o = ros.store.deserialize_cdr(m.data, "nav_msgs/msg/Odometry")
                p, q = o.pose.pose.position, o.pose.pose.orientation
                t = m.log_time * 1e-9
                heading = 2 * math.atan2(q.z, q.w)
                msgs.append(("/tf", "tf2_msgs/msg/TFMessage", m.log_time,
                             ros.tf(t, "odom", "base_link", 1.05 * p.x, 1.05 * p.y, heading)))  # fmt: skip
    log = write_messages_mcap(tmp_path / "both.mcap", sorted(msgs, key=lambda x: x[2]))
    out, mc = tmp_path / "out", tmp_path / "res.mcap"
    from click.testing import CliRunner

    res = CliRunner().invoke(cli, ["run", str(log), "--out", str(out), "--mcap-out", str(mc), "-q"])
    assert res.exit_code == 0, res.output
    s = json.loads((out / "summary.json").read_text())
    assert s["input"]["odom_source"] == "nav_msgs/Odometry"
    assert any("the log's tf odom → base differs from the odometry the run used" in w for w in s["warnings"])
    tf_of = {}
    for t, _, _, data in msgs:
        if t == "/tf":
            tr = ros.store.deserialize_cdr(data, "tf2_msgs/msg/TFMessage").transforms[0]
            stamp = tr.header.stamp.sec * 10**9 + tr.header.stamp.nanosec
            q = tr.transform.rotation
            tf_of[stamp] = (tr.transform.translation.x, tr.transform.translation.y, 2 * math.atan2(q.z, q.w))
    keys = np.array(sorted(tf_of))
    got = defaultdict(dict)
    with open(mc, "rb") as f:
        for _, channel, m in make_reader(f).iter_messages(topics=["/cornerslam/tf", "/cornerslam/pose"]):
            d = json.loads(m.data)
            if channel.topic == "/cornerslam/tf":
                pose = (d["translation"]["x"], d["translation"]["y"], yaw(d["rotation"]))
            else:
                pose = (d["pose"]["position"]["x"], d["pose"]["position"]["y"], yaw(d["pose"]["orientation"]))
            got[ns(d["timestamp"])][channel.topic] = pose
    off = []
    for stamp, v in got.items():
        near = keys[np.abs(keys - stamp).argmin()]  # the tf sample at the scan (the log's 10 ms apart)
        placed = compose(np.array(v["/cornerslam/tf"]), np.array(tf_of[near]))
        off.append(np.hypot(*(placed[:2] - np.array(v["/cornerslam/pose"][:2]))))
    assert len(off) > 10 and max(off) < 0.02
