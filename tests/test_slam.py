"""The filter's motion input and its noise (slam.py ``Slam.motion``) and the run writer's rows by
column name (report/run_writer.py)."""

from __future__ import annotations

import numpy as np
import pytest

from cornerslam_cli.config import load_config
from cornerslam_cli.frontend import Frame
from cornerslam_cli.report.run_writer import timing_row, trajectory_row
from cornerslam_cli.report.tables import MAP_COLUMNS, TIMING_COLUMNS, TRAJECTORY_COLUMNS, CsvTable, read_csv
from cornerslam_cli.slam import Slam
from cornerslam_cli.types import Segments

CFG = load_config(None, ["input.odom_jump.sigma_xy=0.7", "input.odom_jump.sigma_theta=0.3"])
NO_SEGMENTS = Segments(*(np.zeros((0,) + s) for s in ((), (), (2, 2), (2,), (2,), (), (), ())))


def frame(odom, motion=None, **kw) -> Frame:
    return Frame(0.0, np.array(odom, float), 0, NO_SEGMENTS, np.zeros((0, 3)), np.zeros((0, 3, 3)), 0.0,
                 motion=None if motion is None else np.array(motion, float), **kw)  # fmt: skip


def test_the_first_frame_has_nothing_to_predict_then_odometry_with_the_filter_noise():
    slam = Slam.from_config(CFG, (0.0, 0.0, 0.0))
    m = slam.motion(frame([1.0, 2.0, 0.1]))
    assert m.prev is None and m.cur == pytest.approx([1.0, 2.0, 0.1])
    slam.step(frame([1.0, 2.0, 0.1]))
    m = slam.motion(frame([1.5, 2.0, 0.1]))
    assert m.prev == pytest.approx([1.0, 2.0, 0.1]) and m.cur == pytest.approx([1.5, 2.0, 0.1])
    assert (m.cov, m.inflate) == (None, None)  # the filter's own ekf.alpha*


def test_a_fused_increment_brings_its_covariance_and_no_inflation_across_a_jump():
    slam = Slam.from_config(CFG, (0.0, 0.0, 0.0))
    slam.step(frame([0.0, 0.0, 0.0], motion=[0.0, 0.0, 0.0], scan_matched=True))
    cov = np.diag([1e-4, 4e-4, 1e-5])
    m = slam.motion(
        frame([9.0, 0.0, 0.0], motion=[0.2, 0.0, 0.0], motion_cov=cov, scan_matched=True, odom_jump=True)
    )
    assert m.cur == pytest.approx([0.2, 0.0, 0.0])  # the fused chain, not odometry
    assert m.cov is cov
    assert m.inflate is None  # the scans told the motion across the jump


def test_an_odometry_jump_without_scan_matching_inflates_the_robot_covariance():
    slam = Slam.from_config(CFG, (0.0, 0.0, 0.0))
    slam.step(frame([0.0, 0.0, 0.0]))
    before = slam.ekf.P[:3, :3].copy()
    m = slam.motion(frame([0.0, 0.0, 0.0], odom_jump=True))
    assert m.inflate == (0.7, 0.3) and m.cov is None
    slam.step(frame([0.0, 0.0, 0.0], odom_jump=True))  # no motion: the prediction adds only its floor
    added = np.diag(slam.ekf.P[:3, :3] - before)
    assert added == pytest.approx([0.49, 0.49, 0.09], abs=0.01)


def test_rows_are_written_by_column_name(tmp_path):
    """Each table row is a dict over exactly its columns: a missing or an extra name is an error, and
    the values land under their names whatever order the dict has."""
    slam = Slam.from_config(CFG, (0.0, 0.0, 0.0))
    r = slam.step(frame([1.0, 2.0, 0.5], motion=[1.1, 2.1, 0.6], scan_matched=True))
    row = trajectory_row(r)
    assert list(row) == TRAJECTORY_COLUMNS and set(timing_row(r)) == set(TIMING_COLUMNS)
    assert (row["odom_x"], row["odom_theta"], row["scan_odom_y"]) == (1.0, 0.5, 2.1)
    with CsvTable(tmp_path / "t.csv", MAP_COLUMNS) as t:
        t.write(dict(reversed({name: i for i, name in enumerate(MAP_COLUMNS)}.items())))
        with pytest.raises(ValueError, match="not the columns"):
            t.write({name: 0 for name in MAP_COLUMNS[1:]})
        with pytest.raises(ValueError, match="not the columns"):
            t.write({**{name: 0 for name in MAP_COLUMNS}, "extra": 1})
    got = read_csv(tmp_path / "t.csv")
    assert [got[name][0] for name in MAP_COLUMNS] == list(range(len(MAP_COLUMNS)))
