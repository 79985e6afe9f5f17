"""Shared helpers of the feature-extractor and simulator tests (not a conftest: plain imports)."""

from __future__ import annotations

import math

import numpy as np
from scipy.stats import chi2

from cornerslam_cli import simworld as sw
from cornerslam_cli.features import CornersConfig, LinesConfig, SensorConfig, sigma_range

#: a 1,081-beam 270° Hokuyo
HOKUYO = np.linspace(-3 * np.pi / 4, 3 * np.pi / 4, 1081)
#: a precise sensor's noise model (about a UTM-30LX): σρ = 1 cm, σθ = 0.05°
PRECISE = SensorConfig(model="linear", a=0.01, b=0.0, sigma_theta=math.radians(0.05))
DEFAULTS = (LinesConfig(), CornersConfig())
#: the Hokuyo URG-04LX preset (configs/lasers/hokuyo_urg04lx.yaml): σρ = 1 cm to 1 m, 1 % beyond; σθ = π/1024
URG04LX = SensorConfig(model="piecewise", sigma_r_near=0.01, near_range=1.0, sigma_r_rel=0.01)
#: its beam spacing, 240° over 682 beams
URG04LX_STEP = math.radians(240.0 / 681)


def wall_bearings(r: float, alpha: float, u0: float, u1: float, step: float = URG04LX_STEP) -> np.ndarray:
    """Bearings on a grid of ``step`` whose beams hit the line (r, α) between the along-line coordinates
    u0 < u1 (metres from its foot point, positive counter-clockwise)."""
    b0, b1 = alpha + math.atan2(u0, r), alpha + math.atan2(u1, r)
    return np.arange(math.ceil(b0 / step), math.floor(b1 / step) + 1) * step


def noisy_ranges(r: float, alpha: float, bearings: np.ndarray, sensor: SensorConfig, rng) -> np.ndarray:
    """Ranges measured along ``bearings`` to the line (r, α): each beam leaves at its bearing plus
    N(0, σθ²) and its range gets N(0, σρ(ρ)²) (the sensor model of eq 1, as ``simworld.simulate_scan``)."""
    true = bearings + rng.normal(0.0, sensor.sigma_theta, bearings.shape)
    rho = r / np.cos(true - alpha)
    return rho + rng.normal(0.0, 1.0, rho.shape) * sigma_range(rho, sensor)


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


def beam_jacobian(f, rho: np.ndarray, theta: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central differences of f(ρ, θ) (a vector) in every beam's range and bearing: (m, 2n), columns
    ∂/∂ρ_0, ∂/∂θ_0, ∂/∂ρ_1, … (the order of :func:`beam_covariance`)."""
    cols = []
    for i in range(len(rho)):
        step = np.zeros(len(rho))
        step[i] = h
        cols.append((np.asarray(f(rho + step, theta)) - np.asarray(f(rho - step, theta))) / (2 * h))
        cols.append((np.asarray(f(rho, theta + step)) - np.asarray(f(rho, theta - step))) / (2 * h))
    return np.column_stack(cols)


def beam_covariance(var_rho: np.ndarray, var_theta) -> np.ndarray:
    """diag(σρ_0², σθ_0², σρ_1², …) (2n, 2n) of independent beams."""
    return np.diag(np.column_stack((var_rho, np.broadcast_to(var_theta, np.shape(var_rho)))).ravel())
