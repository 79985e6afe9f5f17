"""Output tables: write/read round trips and the atomic staged output directory."""

import numpy as np
import pytest

from cornerslam_cli.errors import LogError
from cornerslam_cli.report.outdir import MARKER, StagedDir, mark_output
from cornerslam_cli.report.tables import CsvTable, read_csv, read_tum, write_tum


def test_tum_round_trip_keeps_yaw(tmp_path):
    t = np.array([1.5, 2.5, 3.5])
    poses = np.array([[0.0, 1.0, 3.0], [1.0, 2.0, -3.0], [2.0, -1.0, 0.25]])
    write_tum(tmp_path / "t.tum", t, poses)
    t2, p2 = read_tum(tmp_path / "t.tum")
    assert t2 == pytest.approx(t)
    assert p2 == pytest.approx(poses, abs=1e-8)
    assert len((tmp_path / "t.tum").read_text().splitlines()[0].split()) == 8


def test_read_tum_rejects_bad_lines(tmp_path):
    p = tmp_path / "bad.tum"
    p.write_text("1 2 3\n")
    with pytest.raises(LogError, match="line 1 has 3 values"):
        read_tum(p)
    with pytest.raises(LogError, match="does not exist"):
        read_tum(tmp_path / "none.tum")


def test_csv_table_round_trip(tmp_path):
    tab = CsvTable(tmp_path / "x.csv", ["step", "a", "b"])
    tab.row(0, 1.25, float("nan"))
    tab.rows(np.array([[1.0, 2.0], [3.0, 4.0]]), lead=(7,))
    tab.close()
    cols = read_csv(tmp_path / "x.csv")
    assert list(cols) == ["step", "a", "b"]
    assert cols["step"].tolist() == [0, 7, 7]
    assert np.isnan(cols["b"][0]) and cols["b"][2] == 4.0


def test_staged_dir_replaces_only_on_commit(tmp_path):
    target = tmp_path / "out"
    target.mkdir()
    (target / "old.txt").write_text("previous run")
    mark_output(target, "run")  # a previous cornerslam run: the only kind of directory replaced
    with pytest.raises(RuntimeError):
        with StagedDir(target) as st:
            (st.path / "half.csv").write_text("step\n")
            raise RuntimeError("killed mid-run")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no staging directory left
    assert (target / "old.txt").read_text() == "previous run"
    with StagedDir(target) as st:
        (st.path / "new.csv").write_text("step\n")
        st.commit()
    assert sorted(p.name for p in target.iterdir()) == [MARKER, "new.csv"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
