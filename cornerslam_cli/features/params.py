"""Config sections of the feature extractor (NOTES §1–3).

Defaults suit a 1,081-beam 270° Hokuyo (0.25°), a 682-beam URG-04LX (0.35°) and a 180-beam SICK (1°):
every length threshold is in metres and the angle-split window is a chord length, not a beam count.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal


def _check(cond: bool, msg: str) -> None:
    if not cond:
        raise ValueError(msg)


@dataclass(frozen=True)
class SensorConfig:
    """Range/bearing noise model (paper eq 1, 33, 34); see ``features.sensor``.

    piecewise: σρ = sigma_r_near for ρ <= near_range, else sigma_r_rel·ρ (paper's Hokuyo model).
    linear:    σρ = a + b·ρ.
    sigma_theta: bearing standard deviation σθ, radians.
    """

    model: Literal["piecewise", "linear"] = "piecewise"
    sigma_r_near: float = 0.03
    near_range: float = 1.0
    sigma_r_rel: float = 0.03
    a: float = 0.01
    b: float = 0.005
    sigma_theta: float = math.pi / 1024

    def __post_init__(self):
        _check(
            self.model in ("piecewise", "linear"),
            f"sensor.model must be piecewise or linear, got {self.model!r}",
        )
        for name in ("sigma_r_near", "near_range", "sigma_r_rel", "a", "b", "sigma_theta"):
            v = getattr(self, name)
            _check(math.isfinite(v) and v >= 0.0, f"sensor.{name} must be finite and >= 0, got {v}")


@dataclass(frozen=True)
class LinesConfig:
    """Split-and-merge line extraction (Algorithm 1); see ``features.lines``."""

    # 1. adaptive breakpoint (Borges & Aldon 2004): split when the gap between consecutive points exceeds
    #    d_max = ρ·sin Δφ / sin(λ − Δφ) + breakpoint_sigma   (breakpoint_sigma plays B&A's 3σ_r, added as is)
    breakpoint_lambda: float = math.radians(10.0)  # λ, radians
    breakpoint_sigma: float = 0.03  # metres
    max_missing_beams: int = 3  # more dropped (no-return) beams than this between two points break; 0 = off
    # 2. angle split: angle between the chords (p_i−k, p_i) and (p_i, p_i+k), k beams chosen per point so a
    #    chord is max(angle_split_chord, angle_split_sigmas·σ) long, σ the beam's noise (the paper's k = 1
    #    is noise-dominated on dense scans)
    angle_split_max: float = math.radians(30.0)  # a_max, radians
    angle_split_chord: float = 0.1  # metres
    angle_split_sigmas: float = 20.0
    # 3. distance split (split-and-merge)
    split_distance: float = 0.05  # l_max, metres
    # 4. merge of adjacent segments
    merge_angle: float = math.radians(3.0)  # a_mergeMax, radians
    merge_gap: float = 0.2  # d_mergeMax, metres
    # filters
    min_points: int = 6
    min_length: float = 0.3  # metres

    def __post_init__(self):
        _check(0.0 < self.breakpoint_lambda < math.pi / 2, "lines.breakpoint_lambda must be in (0, pi/2)")
        _check(self.breakpoint_sigma >= 0.0, "lines.breakpoint_sigma must be >= 0")
        _check(self.max_missing_beams >= 0, "lines.max_missing_beams must be >= 0")
        _check(0.0 < self.angle_split_max <= math.pi, "lines.angle_split_max must be in (0, pi]")
        _check(self.angle_split_chord > 0.0, "lines.angle_split_chord must be > 0")
        _check(self.angle_split_sigmas >= 0.0, "lines.angle_split_sigmas must be >= 0")
        _check(self.split_distance > 0.0, "lines.split_distance must be > 0")
        _check(0.0 <= self.merge_angle <= math.pi / 2, "lines.merge_angle must be in [0, pi/2]")
        _check(self.merge_gap >= 0.0, "lines.merge_gap must be >= 0")
        _check(self.min_points >= 2, "lines.min_points must be >= 2")
        _check(self.min_length >= 0.0, "lines.min_length must be >= 0")


@dataclass(frozen=True)
class CornersConfig:
    """Natural corner extraction (Algorithm 2); see ``features.corners``."""

    d_min: float = 0.3  # type I: segment ends closer than this may form a corner; type II: depth jump, metres
    dp_max: float = 0.2  # intersection within this distance of both segments, metres
    min_angle: float = math.radians(30.0)  # lines closer to parallel than this do not make corners, radians
    endpoints: bool = True  # type II corners at depth jumps
    drop_occluded: bool = True  # drop corners the scan shows hidden (far side of a jump, behind a surface)
    free_space_check: bool = True  # drop type I intersections reached through space the scan saw through
    occlusion_margin: float = 0.03  # margin of both checks against the measured range, + 3σρ, metres
    endpoint_max_gap: float = 0.2  # type II: drop ends whose next beam would hit the line farther away, m
    endpoint_phi: float = math.pi / 2  # φ given to type II corners (the end line meets its normal), radians
    endpoint_phi_sigma: float = math.radians(10.0)  # prior σ of that φ (it is not measured), radians
    duplicate_radius: float = 0.1  # corners closer than this are one corner: the most certain is kept, m
    # σ of how far a real corner is from an ideal point (rounded edges, skirting, segment-end bias), m:
    # added to the x and y variance of every corner the *filter* sees (pipeline.extract_frame); the
    # extractor's own covariance stays the propagated sensor noise that the Monte Carlo tests check
    model_sigma: float = 0.12

    def __post_init__(self):
        _check(self.d_min > 0.0, "corners.d_min must be > 0")
        _check(self.dp_max >= 0.0, "corners.dp_max must be >= 0")
        _check(0.0 < self.min_angle <= math.pi / 2, "corners.min_angle must be in (0, pi/2]")
        _check(self.occlusion_margin >= 0.0, "corners.occlusion_margin must be >= 0")
        _check(self.endpoint_max_gap > 0.0, "corners.endpoint_max_gap must be > 0")
        _check(0.0 <= self.endpoint_phi <= math.pi, "corners.endpoint_phi must be in [0, pi]")
        _check(self.endpoint_phi_sigma > 0.0, "corners.endpoint_phi_sigma must be > 0")
        _check(self.duplicate_radius >= 0.0, "corners.duplicate_radius must be >= 0")
        _check(self.model_sigma >= 0.0, "corners.model_sigma must be >= 0")
