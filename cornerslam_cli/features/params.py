"""Config sections of the feature extractor (NOTES §1–3)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal


@dataclass(frozen=True)
class SensorConfig:
    """Range/bearing noise model (paper eq 1, 33, 34).

    piecewise: σρ = sigma_r_near for ρ <= near_range, else sigma_r_rel·ρ (paper's Hokuyo model).
    linear:    σρ = a + b·ρ.
    """

    model: Literal["piecewise", "linear"] = "piecewise"
    sigma_r_near: float = 0.03
    near_range: float = 1.0
    sigma_r_rel: float = 0.03
    a: float = 0.01
    b: float = 0.005
    sigma_theta: float = math.pi / 1024


@dataclass(frozen=True)
class LinesConfig:
    """Split-and-merge line extraction (Algorithm 1)."""

    breakpoint_lambda: float = math.radians(10.0)  # Borges & Aldon adaptive breakpoint angle λ
    breakpoint_sigma: float = 0.03  # added to the adaptive gap, metres
    angle_split_max: float = math.radians(30.0)  # a_max
    split_distance: float = 0.05  # l_max, metres
    merge_angle: float = math.radians(3.0)  # a_mergeMax
    merge_gap: float = 0.2  # d_mergeMax, metres
    min_points: int = 6
    min_length: float = 0.3


@dataclass(frozen=True)
class CornersConfig:
    """Natural corner extraction (Algorithm 2)."""

    d_min: float = 0.3  # type I: segment ends closer than this may form a corner, metres
    dp_max: float = 0.2  # intersection within this distance of both segments, metres
    min_angle: float = math.radians(30.0)  # lines closer to parallel do not make corners
    endpoints: bool = True  # type II corners at depth jumps
    drop_occluded: bool = True  # drop end points on the farther side of a jump
