"""Config sections of the feature extractor (NOTES §1–3).

Defaults suit a 1,081-beam 270° Hokuyo (0.25°), a 682-beam URG-04LX (0.35°) and a 180-beam SICK (1°):
every length threshold is in metres and the angle-split window is a chord length, not a beam count.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from ..ranges import check_ranges, num

HALF_PI = math.pi / 2


@dataclass(frozen=True)
class SensorConfig:
    """Range/bearing noise model (paper eq 1, 33, 34); see ``features.sensor``.

    piecewise: σρ = sigma_r_near for ρ <= near_range, else sigma_r_rel·ρ (paper's Hokuyo model).
    linear:    σρ = a + b·ρ.
    sigma_theta: bearing standard deviation σθ, radians.
    """

    model: Literal["piecewise", "linear"] = "piecewise"
    sigma_r_near: float = num(0.03, ge=0.0, le=10.0)  # metres
    near_range: float = num(1.0, ge=0.0, le=1000.0)  # metres
    sigma_r_rel: float = num(0.03, ge=0.0, le=1.0)  # share of the range
    a: float = num(0.01, ge=0.0, le=10.0)  # metres
    b: float = num(0.005, ge=0.0, le=1.0)  # share of the range
    sigma_theta: float = num(math.pi / 1024, ge=0.0, le=0.5)  # radians

    def __post_init__(self):
        check_ranges(self)
        if self.model not in ("piecewise", "linear"):
            raise ValueError(f"sensor.model must be piecewise or linear, got {self.model!r}")


@dataclass(frozen=True)
class LinesConfig:
    """Split-and-merge line extraction (Algorithm 1); see ``features.lines``."""

    # 1. adaptive breakpoint (Borges & Aldon 2004): split when the gap between consecutive points exceeds
    #    d_max = ρ·sin Δφ / sin(λ − Δφ) + breakpoint_sigma   (breakpoint_sigma plays B&A's 3σ_r, added as is)
    breakpoint_lambda: float = num(math.radians(10.0), gt=0.0, lt=HALF_PI)  # λ, radians
    breakpoint_sigma: float = num(0.03, ge=0.0, le=10.0)  # metres
    # more dropped (no-return) beams than this between two points break; 0 = off
    max_missing_beams: int = num(3, ge=0, le=100_000)
    # 2. angle split: angle between the chords (p_i−k, p_i) and (p_i, p_i+k), k beams chosen per point so a
    #    chord is max(angle_split_chord, angle_split_sigmas·σ) long, σ the beam's noise (the paper's k = 1
    #    is noise-dominated on dense scans)
    angle_split_max: float = num(math.radians(30.0), gt=0.0, le=math.pi)  # a_max, radians
    angle_split_chord: float = num(0.1, gt=0.0, le=100.0)  # metres
    angle_split_sigmas: float = num(20.0, ge=0.0, le=1000.0)
    # 3. distance split (split-and-merge)
    split_distance: float = num(0.05, gt=0.0, le=100.0)  # l_max, metres
    # 4. merge of adjacent segments
    merge_angle: float = num(math.radians(3.0), ge=0.0, le=HALF_PI)  # a_mergeMax, radians
    merge_gap: float = num(0.2, ge=0.0, le=100.0)  # d_mergeMax, metres
    # filters
    min_points: int = num(6, ge=2, le=100_000)
    min_length: float = num(0.3, ge=0.0, le=1000.0)  # metres

    def __post_init__(self):
        check_ranges(self)


@dataclass(frozen=True)
class CornersConfig:
    """Natural corner extraction (Algorithm 2); see ``features.corners``."""

    # type I: segment ends closer than this may form a corner; type II: depth jump, metres
    d_min: float = num(0.3, gt=0.0, le=100.0)
    dp_max: float = num(0.2, ge=0.0, le=100.0)  # intersection within this distance of both segments, metres
    # lines closer to parallel than this do not make corners, radians
    min_angle: float = num(math.radians(30.0), gt=0.0, le=HALF_PI)
    endpoints: bool = True  # type II corners at depth jumps
    drop_occluded: bool = True  # drop corners the scan shows hidden (far side of a jump, behind a surface)
    free_space_check: bool = True  # drop type I intersections reached through space the scan saw through
    # margin of both checks against the measured range, + 3σρ, metres
    occlusion_margin: float = num(0.03, ge=0.0, le=10.0)
    # type II: drop ends whose next beam would hit the line farther away, m
    endpoint_max_gap: float = num(0.2, gt=0.0, le=100.0)
    # φ given to type II corners (the end line meets its normal), radians
    endpoint_phi: float = num(HALF_PI, ge=0.0, le=math.pi)
    # prior σ of that φ (it is not measured), radians
    endpoint_phi_sigma: float = num(math.radians(10.0), gt=0.0, le=math.pi)
    # corners closer than this are one corner: the most certain is kept, m
    duplicate_radius: float = num(0.1, ge=0.0, le=100.0)
    # σ of how far a real corner is from an ideal point (rounded edges, skirting, segment-end bias), m:
    # added to the x and y variance of every corner the *filter* sees (pipeline.extract_frame); the
    # extractor's own covariance stays the propagated sensor noise that the Monte Carlo tests check
    model_sigma: float = num(0.12, ge=0.0, le=10.0)

    def __post_init__(self):
        check_ranges(self)
