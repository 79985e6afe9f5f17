"""Config section of data association (NOTES §4)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal


@dataclass(frozen=True)
class JcbbConfig:
    """Optional search budget of JCBB (Neira & Tardós 2001); the best hypothesis so far is returned."""

    max_nodes: int = 0  # 0 = no budget
    max_seconds: float = 0.0  # 0 = no budget
    # prefix: Neira & Tardós, every partial hypothesis must pass χ²(d·|H|) (result depends on visiting
    # order); exact: prune only what no extension can make compatible (the true optimum, more nodes)
    joint_gate: Literal["prefix", "exact"] = "prefix"
    # True: also search branches that can only *tie* the best count, for a smaller joint D² (the exact
    # "most pairings, then least D²" optimum); False: prune them (pairings(H) + remaining ≤ pairings(best),
    # Neira & Tardós) — much faster when nearly every corner matches. Also used by PCA.
    explore_ties: bool = True

    def __post_init__(self):
        if self.max_nodes < 0 or self.max_seconds < 0:
            raise ValueError("jcbb budget must be >= 0 (0 = no budget)")
        if self.joint_gate not in ("prefix", "exact"):
            raise ValueError(f"jcbb.joint_gate must be 'prefix' or 'exact', got {self.joint_gate!r}")


@dataclass(frozen=True)
class PcaConfig:
    """Partial compatibility (paper Algorithms 3–5).

    ``grouping``: ``scan`` = consecutive corners in bearing order (the paper); ``spatial`` = each group
    is a seed corner (least bearing left) and its p − 1 nearest remaining corners.
    The budget bounds the whole call (per-group JCBB plus the combination); 0 = none.
    """

    group_size: int = 3  # p
    grouping: Literal["scan", "spatial"] = "scan"
    max_nodes: int = 0
    max_seconds: float = 0.0

    def __post_init__(self):
        if self.group_size < 1:
            raise ValueError(f"pca.group_size must be >= 1, got {self.group_size}")
        if self.grouping not in ("scan", "spatial"):
            raise ValueError(f"pca.grouping must be 'scan' or 'spatial', got {self.grouping!r}")
        if self.max_nodes < 0 or self.max_seconds < 0:
            raise ValueError("pca budget must be >= 0 (0 = no budget)")


@dataclass(frozen=True)
class AssociationConfig:
    method: str = "pca"  # a name in association.ASSOCIATORS
    alpha: float = 0.05  # gates at χ²(d·k, 1 − alpha), d = 3 (2 without phi)
    # metres; pairs farther apart are never paired, whatever the covariance says; 0 = off. A robot
    # covariance grown to metres otherwise lets one corner "close a loop" metres away (docs/tuning.md)
    euclidean_gate: float = 0.5
    use_phi: bool = True  # the corner angle is part of the measurement
    jcbb: JcbbConfig = field(default_factory=JcbbConfig)
    pca: PcaConfig = field(default_factory=PcaConfig)

    def __post_init__(self):
        if not 0.0 < self.alpha < 1.0:
            raise ValueError(f"association.alpha must be in (0, 1), got {self.alpha}")
        if self.euclidean_gate < 0:
            raise ValueError(f"association.euclidean_gate must be >= 0, got {self.euclidean_gate}")
