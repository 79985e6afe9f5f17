"""Config section of data association (NOTES §4)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal


@dataclass(frozen=True)
class JcbbConfig:
    max_nodes: int = 0  # 0 = no budget
    max_seconds: float = 0.0  # 0 = no budget


@dataclass(frozen=True)
class PcaConfig:
    group_size: int = 3  # p
    grouping: Literal["scan", "spatial"] = "scan"


@dataclass(frozen=True)
class AssociationConfig:
    method: str = "pca"  # a name in association.ASSOCIATORS
    alpha: float = 0.05  # gates at χ²(3·k, 1 − alpha)
    euclidean_gate: float = 0.0  # metres; 0 = off
    use_phi: bool = True  # the corner angle is part of the measurement
    jcbb: JcbbConfig = field(default_factory=JcbbConfig)
    pca: PcaConfig = field(default_factory=PcaConfig)
