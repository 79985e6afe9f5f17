"""results.py: RunSummary / Accuracy, their JSON form (summary.json) and how consumers read them."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import platform
import re
from pathlib import Path

import pytest
from _results_helpers import NO_REL, REL, ate, make_summary
from click.testing import CliRunner

from cornerslam_cli.cli import cli
from cornerslam_cli.config import load_config
from cornerslam_cli.errors import ResultsError
from cornerslam_cli.evaluate import evaluate_files
from cornerslam_cli.report.tables import read_csv, write_json
from cornerslam_cli.report.text import summary_lines
from cornerslam_cli.results import Accuracy, Ate, RelationError, RunSummary

FULL_ACCURACY = Accuracy(
    ground_truth="gt.tum",
    ate=ate(0.0123),
    odom_ate=Ate(n=2, rmse=1.5, mean=1.25, max=2.0, rot_rmse=0.125),
    rpe_step_rmse=0.01,
    rpe_step_rot_rmse=0.002,
    rpe_per_m=0.03,
    scan_odom_ate=ate(0.08),
    relations_file="x.relations",
    relations=REL,
    odom_relations=NO_REL,
    scan_odom_relations=REL,
)


@pytest.mark.parametrize("accuracy", [None, FULL_ACCURACY, Accuracy(relations_file="r", relations=NO_REL)])
def test_run_summary_round_trip(accuracy):
    s = make_summary(accuracy=accuracy, scans_matched=499, scans_match_retried=3, scans_match_fallback=1)
    data = json.loads(json.dumps(s.to_json()))  # through JSON text: tuples become lists
    back = RunSummary.from_json(data)
    assert back == dataclasses.replace(s, out_dir=None)  # out_dir is not part of summary.json
    assert back.to_json() == data
    assert "out_dir" not in data


def test_optional_fields_are_left_out_and_null_floats_read_as_nan():
    s = make_summary(t_scan_match=None, accuracy=Accuracy(ate=Ate(n=1, rmse=math.nan, mean=0.0, max=0.0)))
    data = s.to_json()
    assert "t_scan_match" not in data["timing"] and "scans_matched" not in data["counts"]
    assert data["accuracy"] == {"ate": {"n": 1, "rmse": math.nan, "mean": 0.0, "max": 0.0}}
    data["accuracy"]["ate"]["rmse"] = None  # what strict JSON writes for NaN
    back = RunSummary.from_json(data)
    assert math.isnan(back.accuracy.ate.rmse) and back.accuracy.ate.rot_rmse is None
    assert back.timing.t_scan_match is None and back.counts.scans_matched is None
    assert NO_REL.to_json() == {"n": 0, "n_total": 4}


def test_a_misspelt_or_written_field_fails_loudly():
    s = make_summary(accuracy=FULL_ACCURACY)
    with pytest.raises(AttributeError):
        s.counts.matches  # noqa: B018 — the field is matched_total
    with pytest.raises(AttributeError):
        s.get("accuracy")  # not a dict: no silent default
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.counts.steps = 1
    with pytest.raises(TypeError):
        s["counts"]  # noqa: B018
    with pytest.raises(AttributeError):  # a printer handed the old dict form
        summary_lines(s.to_json())


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d: d["counts"].pop("steps"), "RunSummary.counts has no 'steps'"),
        (lambda d: d["timing"].update(t_new=1.0), "RunSummary.timing has the unknown key 't_new'"),
        (lambda d: d["counts"].update(steps="500"), "RunSummary.counts.steps is str, not int"),
        (lambda d: d["counts"].update(steps=True), "RunSummary.counts.steps is bool, not int"),
        (lambda d: d.update(input=None), "RunSummary.input is null"),
        (lambda d: d.update(final_pose={}), "RunSummary.final_pose is dict, not tuple"),
        (lambda d: d.update(final_pose=[1.0, "2", 0.0]), "RunSummary.final_pose[1] is str, not float"),
        (lambda d: d.update(warnings=[3]), "RunSummary.warnings[0] is int, not str"),
        (lambda d: d["accuracy"]["relations"].update(n=None), "RunSummary.accuracy.relations.n is null"),
        (lambda d: d.update(accuracy=[]), "RunSummary.accuracy is list, not an object"),
    ],
)
def test_from_json_names_the_key_it_cannot_read(edit, message):
    data = make_summary(accuracy=FULL_ACCURACY).to_json()
    edit(data)
    with pytest.raises(ResultsError, match="^" + re.escape(message)):
        RunSummary.from_json(data)


def test_read_names_the_file_it_cannot_read(tmp_path):
    with pytest.raises(ResultsError, match="cannot read the run summary .*summary.json"):
        RunSummary.read(tmp_path)
    (tmp_path / "summary.json").write_text('{"mode": "slam"}')
    with pytest.raises(ResultsError, match=r"summary.json': summary has no 'cornerslam_version'"):
        RunSummary.read(tmp_path)


# summary.json's layout as INTERFACE.md and every earlier version wrote it: keys in this order
SUMMARY_KEYS = [
    "cornerslam_version", "mode", "input", "assoc", "counts", "timing", "final_pose", "warnings",
    "accuracy", "hashes", "config", "versions", "odometry_model",  # odometry_model appended (issue 15)
    "consistency",  # appended (issue 17): map consistency without ground truth
]  # fmt: skip
INPUT_KEYS = [
    "log",
    "format",
    "scan_topic",
    "odom_topic",
    "odom_source",
    "laser_to_base",
    "laser_to_base_source",
    "odom_on_tf",  # appended (issue 17): the log's tf carries odom → base
    "beam_times",  # appended: where the deskewing's beam times came from
    "beam_time",
    "laser_upside_down",  # appended: the laser's z axis down, its scans mirrored
    "laser_upside_down_source",  # appended: where laser_upside_down came from (tf or config)
    "base_frame",  # appended: the robot's frame (the odometry's child_frame_id, else input.base_frame)
    "odom_frame",  # appended: the odometry's frame (the odometry's frame_id, else input.odom_frame)
]
COUNT_KEYS = [
    "steps", "landmarks", "matched_total", "beams_total", "beams_invalid", "scans_bad_geometry",
    "scans_size_mismatch", "messages_failed", "scans_in", "scans_out", "before_first_odom",
    "after_last_odom", "odom_gap", "scan_time_backwards", "odom_time_backwards", "keyframes_skipped",
    "odom_jumps", "scans_skipped", "budget_hits", "scans_matched", "scans_match_retried",
    "scans_match_fallback", "scans_match_rejected",  # scans_match_rejected appended (issue 15)
    "submaps", "loops_accepted", "loops_rejected",  # appended (issue 16): the two-level SLAM's
]  # fmt: skip
TIMING_KEYS = [
    "t_extract", "t_predict", "t_match", "t_update", "t_scan_match", "t_total", "t_match_max", "wall_time",
    "scans_per_second", "t_grid",  # t_grid appended (issue 17): the occupancy grid
    "t_loop",  # appended (issue 16): loop closing and the pose graph
]  # fmt: skip
ACCURACY_KEYS = [
    "ground_truth", "ate", "odom_ate", "rpe_step_rmse", "rpe_step_rot_rmse", "rpe_per_m", "scan_odom_ate",
    "online_ate",  # appended (issue 16): the causal estimate beside the smoothed one
]  # fmt: skip
ATE_KEYS = ["n", "rmse", "mean", "max", "rot_rmse"]


@pytest.fixture(scope="module")
def sim_run(sim_log, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("results") / "run"
    res = CliRunner().invoke(cli, ["run", str(sim_log), "--out", str(out), "-q"])
    assert res.exit_code == 0, res.output
    return out


def test_summary_json_of_a_simulated_run_has_the_layout_and_values_it_always_had(sim_run, sim_log):
    s = json.loads((sim_run / "summary.json").read_text())
    assert list(s) == SUMMARY_KEYS
    assert list(s["input"]) == INPUT_KEYS and list(s["counts"]) == COUNT_KEYS
    assert list(s["timing"]) == TIMING_KEYS and list(s["accuracy"]) == ACCURACY_KEYS
    assert list(s["accuracy"]["ate"]) == ATE_KEYS
    assert list(s["hashes"]) == ["input", "config", "version", "ground_truth", "code"]  # appended, in turn
    assert s["mode"] == "slam" and s["assoc"] == "pca" and s["warnings"] == []
    assert s["input"]["log"] == str(sim_log) and s["input"]["format"] == "mcap"
    assert s["input"]["laser_to_base"] == [0.1, 0.0, 0.0] and s["input"]["laser_to_base_source"] == "tf"
    traj, timing, lm = (read_csv(sim_run / f"{n}.csv") for n in ("trajectory", "timing", "map"))
    c = s["counts"]
    assert c["steps"] == len(traj["step"]) == c["scans_in"] == c["scans_matched"] + 1
    assert c["landmarks"] == len(lm["id"]) and c["matched_total"] == timing["n_matched"].sum()
    assert c["scans_skipped"] == c["keyframes_skipped"] == c["budget_hits"] == c["scans_match_fallback"] == 0
    assert c["scans_match_rejected"] == 0
    m = s["odometry_model"]
    froms = ["scale_error_from_keyframe", "heading_drift_from_keyframe"]  # appended, left out when never
    assert list(m) == [
        "odom_noise_scale", "match_noise_scale", "odom_scale_error", "heading_drift_per_m",
        "heading_drift_along_path", *(k for k in froms if k in m),
    ]  # fmt: skip
    for term, key in zip(("odom_scale_error", "heading_drift_per_m"), froms, strict=True):
        assert m[term] == 0.0 or 1 <= m[key] < c["steps"]  # the term used now was first taken at that step
    assert m["heading_drift_along_path"] in (True, False)
    assert 0 < m["odom_noise_scale"] <= 100 and 1 <= m["match_noise_scale"] <= 1e4
    assert c["beams_total"] == 541 * c["scans_in"] > c["beams_invalid"] > 0  # the fixture's 541 beams a scan
    assert c["messages_failed"] == c["scans_size_mismatch"] == c["scans_bad_geometry"] == 0
    t, rounding = s["timing"], 1e-9 * c["steps"]  # timing.csv has 9 decimals
    for name in ("t_extract", "t_predict", "t_match", "t_update", "t_scan_match"):
        assert t[name] == pytest.approx(timing[name].sum(), abs=rounding)
    # the steps' loop closing is in t_total; t_loop also holds the last submap's, closed after the last step
    steps_loop = timing["t_loop"].sum()
    assert t["t_total"] == pytest.approx(sum(t[n] for n in TIMING_KEYS[:5]) + steps_loop, rel=1e-6)
    assert t["t_loop"] >= steps_loop - rounding
    assert (
        t["t_match_max"] == pytest.approx(timing["t_match"].max(), abs=1e-9) and t["wall_time"] > t["t_total"]
    )
    assert s["final_pose"] == pytest.approx([traj["x"][-1], traj["y"][-1], traj["theta"][-1]], abs=1e-9)
    scored = evaluate_files(sim_run, sim_log.with_suffix(".gt.tum"))
    assert s["accuracy"]["ground_truth"] == str(sim_log.with_suffix(".gt.tum"))
    assert s["accuracy"]["ate"]["rmse"] == pytest.approx(scored.ate.rmse, rel=1e-6)
    assert s["accuracy"]["ate"]["n"] == c["steps"] and 0 < s["accuracy"]["ate"]["rmse"] < 0.1
    assert s["accuracy"]["odom_ate"]["rmse"] > 5 * s["accuracy"]["ate"]["rmse"]
    named = hashlib.sha256(sim_log.name.encode() + sim_log.read_bytes())  # the file's name, then its bytes
    assert s["hashes"]["input"] == named.hexdigest()
    assert s["hashes"]["version"] == s["cornerslam_version"]
    assert s["config"] == load_config(None).to_dict()
    assert s["versions"]["python"] == platform.python_version()


def test_summary_json_is_the_run_summary_serialised(sim_run, tmp_path):
    """Read and written again, a real summary.json is byte for byte the same file."""
    s = RunSummary.read(sim_run)
    write_json(tmp_path / "again.json", s.to_json())
    assert (tmp_path / "again.json").read_bytes() == (sim_run / "summary.json").read_bytes()
    assert isinstance(s.accuracy.ate, Ate) and isinstance(s.accuracy, Accuracy)
    assert s.accuracy.relations is None and not isinstance(s.accuracy.relations, RelationError)


def test_a_report_of_a_run_directory_from_an_older_layout_names_the_missing_key(sim_run, tmp_path):
    import shutil

    from cornerslam_cli.report.html import write_report

    old = tmp_path / "old"
    shutil.copytree(sim_run, old)
    data = json.loads((old / "summary.json").read_text())
    del data["counts"]["odom_jumps"]  # a count an earlier version did not write
    (old / "summary.json").write_text(json.dumps(data))
    with pytest.raises(
        ResultsError, match=r"old/summary.json': summary.counts has no 'odom_jumps' \(.*run it again"
    ):
        write_report(old)
    assert not (old / "report.html").exists()
