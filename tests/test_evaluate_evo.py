"""Our ATE (SE(2) alignment) against evo's APE with SE(3) Umeyama alignment, on the same TUM files.

With z = 0 and yaw-only rotations, evo's SE(3) alignment without scale is our SE(2) alignment, so the
translation RMSE must agree to rounding — for trajectories that fit their reference: for one that fits
badly (raw odometry) its best 3-D rotation may turn 180° about an axis in the plane, z flipped: the
trajectory mirrored within the plane, which no rigid motion in the plane gives (README, `evaluate`).
Skipped when evo is not installed (``pip install evo``).
"""

from __future__ import annotations

import numpy as np
import pytest

from cornerslam_cli.evaluate import ate
from cornerslam_cli.report.tables import read_tum, write_tum

evo_metrics = pytest.importorskip("evo.core.metrics")
from evo.core import sync  # noqa: E402
from evo.tools import file_interface  # noqa: E402


def evo_ate_rmse(est_path, gt_path) -> float:
    """What ``evo_ape tum GT EST --align`` reports as rmse."""
    ref = file_interface.read_tum_trajectory_file(gt_path)
    est = file_interface.read_tum_trajectory_file(est_path)
    ref, est = sync.associate_trajectories(ref, est, max_diff=1e-3)
    est.align(ref, correct_scale=False)
    ape = evo_metrics.APE(evo_metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    return float(ape.get_statistic(evo_metrics.StatisticsType.rmse))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_ate_matches_evo_ape_aligned(tmp_path, seed):
    rng = np.random.default_rng(seed)
    n = 200
    t = 1_700_000_000.0 + 0.1 * np.arange(n)
    # ground truth: a loop with turns; estimate: the same drifted, noisy, and in another frame
    s = np.linspace(0, 2 * np.pi, n)
    gt = np.column_stack((5 * np.cos(s) + 0.5 * s, 3 * np.sin(2 * s), s + 0.3 * np.sin(3 * s)))
    drift = np.cumsum(rng.normal(0, 0.02, (n, 3)), axis=0)
    noisy = gt + drift + rng.normal(0, 0.05, (n, 3))
    a = rng.uniform(-np.pi, np.pi)
    c, si = np.cos(a), np.sin(a)
    est = np.column_stack(
        (c * noisy[:, 0] - si * noisy[:, 1] + 7.0, si * noisy[:, 0] + c * noisy[:, 1] - 2.0, noisy[:, 2] + a)
    )
    gt_path, est_path = tmp_path / "gt.tum", tmp_path / "est.tum"
    write_tum(gt_path, t, gt)
    write_tum(est_path, t, est)

    ours = ate(*read_tum(est_path), *read_tum(gt_path))
    theirs = evo_ate_rmse(est_path, gt_path)
    assert ours.n == n
    assert ours.rmse > 0.05  # not trivially zero: the drift survives alignment
    assert ours.rmse == pytest.approx(theirs, rel=1e-6, abs=1e-9)
