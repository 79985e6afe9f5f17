"""Feature extraction: line segments (paper Algorithm 1) and natural corners (Algorithm 2) of one scan.

    segments, corners = extract(scan, config.sensor, config.lines, config.corners)

``sensor.py`` holds the noise model (eq 1), ``lines.py`` the split-and-merge and the line fit with its
covariance (eq 2–8), ``corners.py`` the two corner types and their covariance (eq 9–13).
"""

from __future__ import annotations

import numpy as np

from ..types import Corners, Scan, Segments
from ..workers import signals_deferred
from .corners import extract_corners
from .lines import extract_segments, fit_lines
from .params import CornersConfig, LinesConfig, SensorConfig
from .sensor import sigma_bearing, sigma_range

__all__ = [
    "extract",
    "load_kernels",
    "extract_segments",
    "extract_corners",
    "fit_lines",
    "sigma_range",
    "sigma_bearing",
    "SensorConfig",
    "LinesConfig",
    "CornersConfig",
]


def load_kernels(sensor: SensorConfig, lines: LinesConfig) -> None:
    """Load (on a machine's first run: compile, 20–60 s) the Numba kernels of ``extract`` for this
    configuration now, so that the first timed extraction of a run does not pay it (~0.5 s from the
    cache): one extraction of a synthetic room corner, its segments and its corners.

    SIGINT and SIGTERM wait until the kernels are loaded: arriving inside Numba's compiler they break
    it half-way (an internal error, or noise on stderr) instead of stopping the run cleanly.
    """
    angles = np.linspace(-1.0, 1.4, 121)  # walls x = 2 and y = 1.5, meeting in the field of view
    ranges = np.minimum(2.0 / np.maximum(np.cos(angles), 1e-3), 1.5 / np.maximum(np.sin(angles), 1e-3))
    scan = Scan(
        0.0, ranges, angles, np.arange(121, dtype=np.int64), 121, 0.01, 10.0, float(angles[1] - angles[0])
    )
    with signals_deferred(), np.errstate(all="ignore"):
        segments, jac_ends = extract_segments(scan, sensor, lines)
        extract_corners(scan, segments, jac_ends, sensor, CornersConfig())


def extract(
    scan: Scan, sensor: SensorConfig, lines: LinesConfig, corners: CornersConfig
) -> tuple[Segments, Corners]:
    """Line segments and natural corners of one scan, both in the sensor frame.

    Degenerate input (no beams, one beam, all points at one spot, absurd ranges) gives empty results,
    never an exception; every returned number is finite and every covariance symmetric positive definite.
    """
    with np.errstate(all="ignore"):
        segments, jac_ends = extract_segments(scan, sensor, lines)
        return segments, extract_corners(scan, segments, jac_ends, sensor, corners)
