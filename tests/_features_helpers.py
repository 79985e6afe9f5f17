"""Shared helpers of the feature-extractor and simulator tests (not a conftest: plain imports)."""

from __future__ import annotations

import math

import numpy as np
from scipy.stats import chi2

from cornerslam_cli import simworld as sw
from cornerslam_cli.features import CornersConfig, LinesConfig, SensorConfig

#: a 1,081-beam 270° Hokuyo
HOKUYO = np.linspace(-3 * np.pi / 4, 3 * np.pi / 4, 1081)
#: a precise sensor's noise model (about a UTM-30LX): σρ = 1 cm, σθ = 0.05°
PRECISE = SensorConfig(model="linear", a=0.01, b=0.0, sigma_theta=math.radians(0.05))
DEFAULTS = (LinesConfig(), CornersConfig())


def to_world(xy: np.ndarray, pose) -> np.ndarray:
    """(k, 2) sensor-frame points to the world frame."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return xy @ np.array([[c, s], [-s, c]]) + np.asarray(pose[:2])


def clutter_room() -> sw.World:
    """8 × 6 m room with a door, two boxes, a rotated crate and a pillar."""
    return sw.make_world(
        [
            sw.room(0, 0, 8, 6, doors={"N": [(2.0, 1.0)]}),
            sw.rectangle(5.0, 2.0, 1.0, 0.6),
            sw.rectangle(2.5, 4.5, 0.8, 0.5),
            sw.rectangle(6.5, 4.5, 0.7, 0.7, math.radians(30.0)),
            sw.rectangle(1.2, 1.2, 0.4, 0.4),
        ],
        "clutter_room",
    )


def nees_band(n: int, dim: int) -> tuple[float, float]:
    """95 % band of the mean NEES over n draws of a dim-dimensional Gaussian."""
    lo, hi = chi2.ppf([0.025, 0.975], n * dim) / n
    return float(lo), float(hi)


def mean_nees(err: np.ndarray, cov: np.ndarray) -> float:
    """Mean of eᵀC⁻¹e over draws; err (n, d), cov (n, d, d)."""
    return float(np.mean(np.einsum("ni,ni->n", err, np.linalg.solve(cov, err[..., None])[..., 0])))
