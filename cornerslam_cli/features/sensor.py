"""Laser noise model (paper eq 1, 33, 34): each beam ρ_i ~ N(ρ, σρ(ρ)²), θ_i ~ N(θ, σθ²), independent."""

from __future__ import annotations

import numpy as np

from .params import SensorConfig

#: added to covariance diagonals (m², rad²) so they stay positive definite when the sensor model is noiseless
COV_FLOOR = 1e-12


def kernel_model(sensor: SensorConfig) -> tuple:
    """The noise model as the compiled kernels take it: (linear, a, b, near_range, sigma_r_near,
    sigma_r_rel, sigma_theta)."""
    return (sensor.model == "linear", sensor.a, sensor.b, sensor.near_range, sensor.sigma_r_near,
            sensor.sigma_r_rel, sensor.sigma_theta)  # fmt: skip


def sigma_range(rho: np.ndarray, sensor: SensorConfig) -> np.ndarray:
    """σρ(ρ) in metres for ranges ``rho`` (any shape, metres).

    piecewise (paper, Hokuyo data sheet): σρ = sigma_r_near for ρ <= near_range, sigma_r_rel·ρ beyond.
    linear: σρ = a + b·ρ.
    """
    rho = np.asarray(rho, dtype=float)
    if sensor.model == "linear":
        return sensor.a + sensor.b * rho
    return np.where(rho <= sensor.near_range, sensor.sigma_r_near, sensor.sigma_r_rel * rho)


def sigma_bearing(rho: np.ndarray, sensor: SensorConfig) -> np.ndarray:
    """σθ in radians, broadcast to the shape of ``rho`` (constant in both models)."""
    return np.full(np.shape(rho), sensor.sigma_theta)


def beam_variances(rho: np.ndarray, sensor: SensorConfig) -> tuple[np.ndarray, np.ndarray]:
    """(σρ², σθ²) per beam, each shaped like ``rho``."""
    return sigma_range(rho, sensor) ** 2, sigma_bearing(rho, sensor) ** 2
