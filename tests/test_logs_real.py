"""The real logs shipped in ../shared/data/real open and yield their documented counts."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _log_fixtures import REAL, split

from cornerslam_cli.logs import open_log

pytestmark = pytest.mark.skipif(not REAL.is_dir(), reason="real logs not present (../shared/data/real)")


@pytest.mark.parametrize(
    "rel, fmt, n_scans, offset",
    [
        ("mines/exp1.mcap", "mcap", 756, (0.145, 0.0, 0.0)),
        ("mines/exp2.mcap", "mcap", 641, (0.145, 0.0, 0.0)),
        ("mines/exp4.mcap", "mcap", 577, (0.145, 0.0, 0.0)),
        ("mines/exp3.bag", "rosbag1", 525, None),
    ],
)
def test_mines(rel, fmt, n_scans, offset):
    with open_log(REAL / rel) as log:
        info = log.info()
        assert (info.format, info.scan_topic, info.odom_topic, info.odom_source) == (
            fmt, "/scan", "/odom", "nav_msgs/Odometry",
        )  # fmt: skip
        counts = {t.name: t.count for t in info.topics}
        assert counts["/scan"] == counts["/odom"] == n_scans
        assert info.duration > 0 and 9 < {t.name: t for t in info.topics}["/scan"].rate_hz < 11
        l2b = log.laser_to_base()
        assert l2b == (pytest.approx(offset, abs=1e-6) if offset else None)
        scans, odoms = split(log.messages())
        assert len(scans) == n_scans and len(odoms) == n_scans
        assert log.stats.decode_failed == 0 and log.stats.scans_skipped == 0
    s = scans[0]
    assert s.n_beams == 682 and s.frame_id == "laser"
    assert 0.3 < log.stats.beams_dropped / log.stats.beams < 0.7  # "about half the beams" are inf
    stamps = [m.stamp for m in scans]
    assert stamps == sorted(stamps) and stamps[0] > 1.2e9  # header stamps, epoch-shifted


def test_intel_noisy_odometry():
    path = REAL / "intel" / "intel-noisy-odom.log"
    with open_log(path) as log:
        info = log.info()
        assert (info.format, info.scan_topic, info.odom_topic, info.odom_source) == (
            "carmen", "FLASER", "ODOM", "ODOM lines",
        )  # fmt: skip
        assert log.laser_to_base() is None
        scans, odoms = split(log.messages())
    assert len(scans) == 910 and len(odoms) == 910
    # the noisy odometry of the ODOM lines (not gmapping's corrected poses of intel.gfs.log)
    assert (odoms[1].x, odoms[1].y, odoms[1].theta) == (0.107557, -0.037032, -0.572978)
    assert odoms[1].stamp == scans[1].stamp == 35.1051
    s = scans[0]
    assert s.n_beams == 180 and s.range_max == 81.83 and s.angle_increment == pytest.approx(math.pi / 180)
    assert s.angles[0] == pytest.approx(-math.pi / 2) and s.angles[-1] <= math.radians(89) + 1e-9
    assert np.all(s.ranges < 81.83)
    assert s.n_invalid == 15  # the 81.83 m no-returns of the first scan
