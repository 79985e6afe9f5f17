"""sample_logs/update_expected.py: shows what moved, writes only with --accept and a reason, keeps history.

The sample runs are replaced by summaries built from the stored figures (the real runs are
tests/test_regression.py's business), so these tests take milliseconds.
"""

import importlib.util
import json
import shutil
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "sample_logs" / "update_expected.py"


@pytest.fixture
def script(tmp_path, monkeypatch):
    """The script as a module, its expected.json a copy in tmp_path."""
    spec = importlib.util.spec_from_file_location("update_expected", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    shutil.copy(SCRIPT.with_name("expected.json"), tmp_path / "expected.json")
    monkeypatch.setattr(module, "EXPECTED", tmp_path / "expected.json")
    return module


def fake_runs(stored: dict, moved: dict | None = None):
    """A stand-in for `cornerslam run`: the summary a run with the stored figures would write, with
    ``moved`` = {reference name: {count: new value}} changed."""
    by_args = {(ref["log"], tuple(ref["args"])): name for name, ref in stored.items()}

    def run(log: str, args: list[str], out: Path) -> dict:
        name = by_args[(log, tuple(args))]
        ref = {**stored[name], **(moved or {}).get(name, {})}
        counts = {k: ref[k] for k in ("steps", "landmarks", "matched_total", "scans_matched")}
        counts = {k: v for k, v in counts.items() if v is not None}  # no scans_matched without matching
        acc = {k: {"rmse": ref[f"{k}_rmse"]} for k in ("ate", "odom_ate", "scan_odom_ate")}
        acc = {k: v for k, v in acc.items() if v["rmse"] is not None}
        return {"counts": counts, "final_pose": ref["final_pose"], "accuracy": acc or None}

    return run


def test_unchanged_figures_report_nothing_and_write_nothing(script, capsys):
    before = script.EXPECTED.read_bytes()
    stored = json.loads(before)["runs"]
    assert script.main([], run=fake_runs(stored)) == 0
    assert "no figure moved" in capsys.readouterr().out
    assert script.EXPECTED.read_bytes() == before


def test_without_accept_a_moved_figure_is_shown_and_not_written(script, capsys):
    before = script.EXPECTED.read_bytes()
    stored = json.loads(before)["runs"]
    moved = {"sim_office.mcap": {"landmarks": stored["sim_office.mcap"]["landmarks"] + 1}}
    assert script.main([], run=fake_runs(stored, moved)) == 1
    out = capsys.readouterr()
    n = stored["sim_office.mcap"]["landmarks"]
    assert out.out.strip() == f"sim_office.mcap: landmarks {n} -> {n + 1}"
    assert "--accept" in out.err
    assert script.EXPECTED.read_bytes() == before


def test_accept_writes_the_figures_and_records_the_reason(script, capsys):
    old = json.loads(script.EXPECTED.read_text())
    moved = {"intel_cut.clf": {"matched_total": 7, "final_pose": [1.0, 2.0, 0.5]}}
    assert script.main(["--accept", "  fewer matches: test  "], run=fake_runs(old["runs"], moved)) == 0
    new = json.loads(script.EXPECTED.read_text())
    assert set(new) == {"runs", "history"}  # figures and history only: no tolerances
    assert new["runs"]["intel_cut.clf"]["matched_total"] == 7
    assert new["runs"]["intel_cut.clf"]["final_pose"] == [1.0, 2.0, 0.5]
    assert {k: v for k, v in new["runs"].items() if k != "intel_cut.clf"} == {
        k: v for k, v in old["runs"].items() if k != "intel_cut.clf"
    }
    assert new["history"][:-1] == old["history"]
    entry = new["history"][-1]
    assert entry["reason"] == "fewer matches: test" and entry["commit"] and entry["date"]
    was = old["runs"]["intel_cut.clf"]["matched_total"]
    x, y, th = old["runs"]["intel_cut.clf"]["final_pose"]
    assert entry["changes"] == [
        f"intel_cut.clf: matched_total {was} -> 7",
        f"intel_cut.clf: final_pose [{x:.6g}, {y:.6g}, {th:.6g}] -> [1, 2, 0.5]",
    ]
    assert entry["changes"] == capsys.readouterr().out.splitlines()[:-1]


@pytest.mark.parametrize("reason", ["", "   "])
def test_accept_needs_a_reason(script, reason):
    before = script.EXPECTED.read_bytes()
    with pytest.raises(SystemExit) as exc:
        script.main(["--accept", reason], run=fake_runs(json.loads(before)["runs"]))
    assert exc.value.code == 2
    assert script.EXPECTED.read_bytes() == before


def test_rounding_level_differences_are_not_moves(script, capsys):
    """Another machine's last bits (the ATE 0.0296836 printed twice as 'moved', exit 1: found by a
    README probe) are not a move; a change in the 6th significant digit is."""
    stored = json.loads(script.EXPECTED.read_bytes())["runs"]
    ate = stored["sim_office.mcap"]["ate_rmse"]
    pose = stored["sim_office.mcap"]["final_pose"]
    nudged = {"sim_office.mcap": {"ate_rmse": ate * (1 + 1e-9), "final_pose": [v + 1e-12 for v in pose]}}
    assert script.main([], run=fake_runs(stored, nudged)) == 0
    assert "no figure moved" in capsys.readouterr().out
    moved = {"sim_office.mcap": {"ate_rmse": ate * (1 + 1e-5)}}
    assert script.main([], run=fake_runs(stored, moved)) == 1
    assert capsys.readouterr().out.strip().startswith("sim_office.mcap: ate_rmse")
