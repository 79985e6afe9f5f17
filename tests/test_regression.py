"""Regression on the shipped sample logs: `cornerslam run` against sample_logs/expected.json.

The references are refreshed on purpose only (sample_logs/update_expected.py); a change that moves
a figure beyond its tolerance fails here.
"""

import json
import math
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "sample_logs"
EXPECTED = json.loads((SAMPLES / "expected.json").read_text())
TOL = EXPECTED["tolerances"]
sys.path.insert(0, str(SAMPLES))
from update_expected import figures, run_sample  # noqa: E402


def test_every_sample_log_has_a_reference():
    logs = {p.name for p in SAMPLES.iterdir() if p.suffix in (".mcap", ".bag", ".clf", ".log", ".gz")}
    assert logs == set(EXPECTED["logs"])
    assert all(p.stat().st_size < 5_000_000 for p in SAMPLES.iterdir())


@pytest.mark.parametrize("name", sorted(EXPECTED["logs"]))
def test_sample_log_matches_its_reference(name, tmp_path):
    ref = EXPECTED["logs"][name]
    got = figures(run_sample(name, ref["args"], tmp_path / "out"))
    assert got["steps"] == ref["steps"]
    assert abs(got["landmarks"] - ref["landmarks"]) <= TOL["landmarks_rel"] * ref["landmarks"]
    (x, y, th), (rx, ry, rth) = got["final_pose"], ref["final_pose"]
    assert math.hypot(x - rx, y - ry) <= TOL["final_xy_m"]
    assert abs(math.remainder(th - rth, 2 * math.pi)) <= TOL["final_theta_rad"]
    if ref["ate_rmse"] is not None:
        assert got["ate_rmse"] <= ref["ate_rmse"] + TOL["ate_abs_m"]
        assert got["odom_ate_rmse"] == pytest.approx(ref["odom_ate_rmse"], rel=1e-6)
