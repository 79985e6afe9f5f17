"""Config section of data association (NOTES §4)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from ..ranges import check_ranges, num

MAX_NODES = 10**12  # search nodes: far beyond any budget that finishes
MAX_SECONDS = 1e6


@dataclass(frozen=True)
class JcbbConfig:
    """Optional search budget of JCBB (Neira & Tardós 2001); the best hypothesis so far is returned."""

    max_nodes: int = num(0, ge=0, le=MAX_NODES)  # 0 = no budget
    max_seconds: float = num(0.0, ge=0.0, le=MAX_SECONDS)  # 0 = no budget
    # prefix: Neira & Tardós, every partial hypothesis must pass χ²(d·|H|) (result depends on visiting
    # order); exact: prune only what no extension can make compatible (the true optimum, more nodes)
    joint_gate: Literal["prefix", "exact"] = "prefix"
    # True: also search branches that can only *tie* the best count, for a smaller joint D² (the exact
    # "most pairings, then least D²" optimum); False: prune them (pairings(H) + remaining ≤ pairings(best),
    # Neira & Tardós) — much faster when nearly every corner matches. Also used by PCA.
    explore_ties: bool = True

    def __post_init__(self):
        check_ranges(self)
        if self.joint_gate not in ("prefix", "exact"):
            raise ValueError(f"jcbb.joint_gate must be 'prefix' or 'exact', got {self.joint_gate!r}")


@dataclass(frozen=True)
class PcaConfig:
    """Partial compatibility (paper Algorithms 3–5).

    ``grouping``: ``scan`` = consecutive corners in bearing order (the paper); ``spatial`` = each group
    is a seed corner (least bearing left) and its p − 1 nearest remaining corners.
    The budget bounds the whole call (per-group JCBB plus the combination); 0 = none.
    """

    group_size: int = num(3, ge=1, le=1000)  # p
    grouping: Literal["scan", "spatial"] = "scan"
    max_nodes: int = num(0, ge=0, le=MAX_NODES)
    max_seconds: float = num(0.0, ge=0.0, le=MAX_SECONDS)

    def __post_init__(self):
        check_ranges(self)
        if self.grouping not in ("scan", "spatial"):
            raise ValueError(f"pca.grouping must be 'scan' or 'spatial', got {self.grouping!r}")


@dataclass(frozen=True)
class AssociationConfig:
    method: str = "pca"  # a name in association.ASSOCIATORS
    alpha: float = num(0.05, gt=0.0, lt=1.0)  # gates at χ²(d·k, 1 − alpha), d = 3 (2 without phi)
    # metres; pairs farther apart are never paired, whatever the covariance says; 0 = off. A robot
    # covariance grown to metres otherwise lets one corner "close a loop" metres away (docs/tuning.md)
    euclidean_gate: float = num(0.5, ge=0.0, le=1000.0)
    use_phi: bool = True  # the corner angle is part of the measurement
    jcbb: JcbbConfig = field(default_factory=JcbbConfig)
    pca: PcaConfig = field(default_factory=PcaConfig)

    def __post_init__(self):
        check_ranges(self)
