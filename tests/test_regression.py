"""Regression on the shipped sample logs: `cornerslam run` against the figures in sample_logs/expected.json.

The figures are refreshed on purpose only (``python sample_logs/update_expected.py --accept "reason"``,
which records the reason in the file's history). The tolerances are fixed here, never in that file,
and this test reads each run's summary.json with its own code (nothing is shared with the update
script), so accepting new figures cannot loosen what is checked.

The runs are deterministic (single-threaded BLAS, no randomness; tests/test_faults.py checks runs are
byte-identical), so counts must match exactly: a change that moves one association decision fails
here and has to be accepted with a reason. The real logs are also run with scan matching off, so the
paper's odometry-driven filter is covered on real data.
"""

import json
import math
from pathlib import Path

import pytest
from click.testing import CliRunner

from cornerslam_cli.cli import cli

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "sample_logs"
REFERENCES = json.loads((SAMPLES / "expected.json").read_text())["runs"]

EXACT_COUNTS = ("steps", "landmarks", "matched_total", "scans_matched")
ATE_FACTOR, ATE_SLACK = 1.25, 0.005  # an estimate's ATE may grow to 1.25 × the reference + 5 mm
FINAL_XY, FINAL_THETA = 0.02, 0.005  # m, rad: with every count equal, only rounding moves the pose
ODOM_ATE_REL = 1e-9  # raw odometry is input: its ATE does not depend on the filter at all


def run(log: str, args: list[str], out: Path) -> dict:
    res = CliRunner().invoke(cli, ["run", str(SAMPLES / log), "--out", str(out), "-q", *args])
    assert res.exit_code == 0, res.output
    return json.loads((out / "summary.json").read_text())


def test_every_sample_log_has_a_reference_and_real_logs_one_without_scan_matching():
    logs = {p.name for p in SAMPLES.iterdir() if p.suffix in (".mcap", ".bag", ".clf", ".log", ".gz")}
    assert logs == {ref["log"] for ref in REFERENCES.values()}
    assert all(p.stat().st_size < 5_000_000 for p in SAMPLES.iterdir())
    for real in logs - {"sim_office.mcap"}:
        assert any(
            ref["log"] == real and "scan_match.enabled=false" in ref["args"] for ref in REFERENCES.values()
        ), real


@pytest.mark.parametrize("name", sorted(REFERENCES))
def test_sample_log_matches_its_reference(name, tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)  # the arguments name files relative to the repository (configs/mines.yaml)
    ref = REFERENCES[name]
    summary = run(ref["log"], ref["args"], tmp_path / "out")
    counts = summary["counts"]
    assert {k: counts.get(k) for k in EXACT_COUNTS} == {k: ref[k] for k in EXACT_COUNTS}
    (x, y, th), (rx, ry, rth) = summary["final_pose"], ref["final_pose"]
    assert math.hypot(x - rx, y - ry) <= FINAL_XY
    assert abs(math.remainder(th - rth, math.tau)) <= FINAL_THETA
    acc = summary["accuracy"] or {}
    assert ("ate" in acc) == (ref["ate_rmse"] is not None)
    if "ate" in acc:
        assert acc["ate"]["rmse"] <= ATE_FACTOR * ref["ate_rmse"] + ATE_SLACK
        assert acc["odom_ate"]["rmse"] == pytest.approx(ref["odom_ate_rmse"], rel=ODOM_ATE_REL)
    assert ("scan_odom_ate" in acc) == (ref["scan_odom_ate_rmse"] is not None)
    if "scan_odom_ate" in acc:
        assert acc["scan_odom_ate"]["rmse"] <= ATE_FACTOR * ref["scan_odom_ate_rmse"] + ATE_SLACK
