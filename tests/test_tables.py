"""Output tables: write/read round trips, the atomic staged output directory, README's column lists."""

import re
from pathlib import Path

import numpy as np
import pytest

from cornerslam_cli.errors import LogError, OutputError
from cornerslam_cli.report.outdir import StagedDir
from cornerslam_cli.report.ownership import MARKER, mark_output
from cornerslam_cli.report.tables import (
    LINES_COLUMNS,
    LOOP_COLUMNS,
    MAP_COLUMNS,
    TIMING_COLUMNS,
    TRAJECTORY_COLUMNS,
    CsvTable,
    read_csv,
    read_tum,
    write_tum,
)


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


def test_a_staged_dir_not_committed_takes_away_the_directories_it_made(tmp_path):
    """An interrupted `compare --out new/deep/c` left new/deep/ behind, empty: the directories above the
    target that the output made go with it, deepest first, but not one another file has come into."""
    with pytest.raises(RuntimeError):
        with StagedDir(tmp_path / "new" / "deep" / "out"):
            raise RuntimeError("interrupted")
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(RuntimeError):
        with StagedDir(tmp_path / "new" / "deep" / "out"):
            (tmp_path / "new" / "mine.txt").write_text("a user's file")
            raise RuntimeError("interrupted")
    assert sorted(p.name for p in (tmp_path / "new").iterdir()) == ["mine.txt"]
    with pytest.raises(OutputError):  # refused while staging (a name too long): the same
        StagedDir(tmp_path / "other" / "deep" / ("x" * 300))
    assert not (tmp_path / "other").exists()
    # a staged file's: `run --out a/out --mcap-out b/c/r.mcap` interrupted left b/c/ (noted since 2026-12-05)
    (tmp_path / "new" / "mine.txt").unlink()
    (tmp_path / "new").rmdir()
    with pytest.raises(RuntimeError):
        with StagedDir(tmp_path / "new" / "out") as st:
            st.stage_file(tmp_path / "b" / "c" / "r.mcap").write_text("partial")
            st.stage_file(tmp_path / "new" / "n" / "r2.mcap")  # (beside the output's own new directory)
            raise RuntimeError("interrupted")
    assert list(tmp_path.iterdir()) == []


def test_write_json_is_strict_json(tmp_path):
    """NaN and ±inf (Python floats, numpy scalars, inside arrays) are written as null: every JSON
    reader accepts the file, Python's own with NaN refused too."""
    from _strict_json import strict_load

    from cornerslam_cli.report.tables import json_text, write_json

    data = {
        "a": float("nan"),
        "b": [1.5, float("inf"), -float("inf")],
        "c": {"d": np.float32("nan"), "e": np.float64(2.5), "f": np.int64(3), "g": np.bool_(True)},
        "h": np.array([[1.0, np.nan], [np.inf, 4.0]]),
        "i": (np.float64(-np.inf), 7),
    }
    write_json(tmp_path / "s.json", data)
    assert strict_load(tmp_path / "s.json") == {
        "a": None,
        "b": [1.5, None, None],
        "c": {"d": None, "e": 2.5, "f": 3, "g": True},
        "h": [[1.0, None], [None, 4.0]],
        "i": [None, 7],
    }
    assert json_text({"x": 0.1, "y": [1, 2]}) == '{"x": 0.1, "y": [1, 2]}'  # finite values unchanged


def test_read_tum_sorts_drops_repeats_and_refuses_two_poses_at_one_stamp(tmp_path):
    lines = ["3 3 0 0 0 0 0 1", "1 1 0 0 0 0 0 1", "2 2 0 0 0 0 0 1", "2 2 0 0 0 0 0 1"]
    p = tmp_path / "t.tum"
    p.write_text("\n".join(lines) + "\n")
    notes: list[str] = []
    t, poses = read_tum(p, "ground truth", notes.append)
    assert t.tolist() == [1, 2, 3] and poses[:, 0].tolist() == [1, 2, 3]
    assert len(notes) == 2 and "line 2 at 1.000000 s comes after line 1 at 3.000000 s" in notes[0]
    assert "repeats 1 line(s) (first: line 4): dropped" in notes[1]
    p.write_text("\n".join([*lines, "2 2.5 0 0 0 0 0 1"]) + "\n")
    with pytest.raises(LogError, match=r"two different poses at stamp 2\.0+ \(lines 4 and 5\)"):
        read_tum(p, "ground truth", notes.append)


def test_a_huge_binary_file_is_refused_on_its_first_bytes(tmp_path):
    """A 256 MiB bag given as ground truth is refused after reading 64 KiB, not loaded whole."""
    import tracemalloc

    p = tmp_path / "huge.bag"
    with open(p, "wb") as f:
        f.write(b"#ROSBAG V2.0\n\x00\x01")
        f.truncate(256 << 20)  # sparse: no disk used
    tracemalloc.start()
    try:
        with pytest.raises(LogError, match="huge.bag' is a binary file"):
            read_tum(p, "ground truth")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 1 << 20, peak


@pytest.mark.parametrize(
    "name, columns",
    [
        ("trajectory.csv", TRAJECTORY_COLUMNS),
        ("map.csv", MAP_COLUMNS),
        ("loops.csv", LOOP_COLUMNS),
        ("lines.csv", LINES_COLUMNS),
        ("timing.csv", TIMING_COLUMNS),
    ],
)
def test_readme_names_every_column_of_each_table_in_order(name, columns):
    """README's file table gives each CSV's columns as backquoted comma lists (the first ones, then the
    appended ones): by first mention, in their order, they are the columns the run writes."""
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    row = next(line for line in readme.splitlines() if line.startswith(f"| `{name}` |"))
    named = [c for span in re.findall(r"`([^`]*)`", row) for c in span.split(",")]
    assert list(dict.fromkeys(c for c in named if c in columns)) == columns


def test_read_tum_refuses_quaternions_written_w_first_but_reads_an_upside_down_body(tmp_path):
    """A planar trajectory written stamp x y z qw qx qy qz read as rolled ~180° with a constant yaw (a
    hostile-user probe): refused, naming the order. A body upside down (z down: qz = qw = 0), driving
    mostly one way, looks alike at a glance (a review) and is read as it is, its yaw right."""
    yaw = np.linspace(-0.15, 0.15, 40)
    rows = [(t, 0.1 * t, 0.0, 0.0, np.sin(a / 2), np.cos(a / 2)) for t, a in enumerate(yaw)]
    w_first = tmp_path / "w.tum"
    w_first.write_text("".join(f"{t} {x} {y} {z} {w} 0 0 {qz}\n" for t, x, y, z, qz, w in rows))
    with pytest.raises(LogError, match=r"out of the plane .* written with qw first\?"):
        read_tum(w_first, "ground truth")
    flipped = tmp_path / "z_down.tum"  # rotated π about x, then by yaw about the world's z
    flipped.write_text("".join(f"{t} {x} {y} {z} {w} {qz} 0 0\n" for t, x, y, z, qz, w in rows))
    _, poses = read_tum(flipped, "ground truth")
    assert np.allclose(np.abs(poses[:, 2]), np.abs(yaw), atol=1e-9)
