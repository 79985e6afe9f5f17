"""Data association (paper Algorithms 3–5, NOTES §4): which landmark, if any, each corner observes.

Every associator is a callable ``assoc(z, C, pred) -> AssociationResult``:

    z : (m, 3) corners (x, y, φ), base frame, metres / radians
    C : (m, 3, 3) their covariances
    pred : :class:`~cornerslam_cli.types.Prediction` of the n landmarks

``ASSOCIATORS`` maps config/CLI names to classes; ``make_associator(cfg)`` builds the configured one,
``associator_class(name)`` checks a name without building one.
m = 0 or n = 0 gives an all-unmatched result, never an error.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ..errors import ConfigError, did_you_mean
from ..types import AssociationResult, Prediction
from .icnn import Icnn
from .jcbb import Jcbb
from .params import AssociationConfig
from .pca import Pca, load_kernels


class Associator(Protocol):
    def __call__(self, z: np.ndarray, C: np.ndarray, pred: Prediction) -> AssociationResult: ...


ASSOCIATORS: dict[str, type] = {"icnn": Icnn, "jcbb": Jcbb, "pca": Pca}


def associator_class(method: str) -> type:
    """The class ``ASSOCIATORS`` names ``method``; ConfigError with the closest name for an unknown one."""
    cls = ASSOCIATORS.get(method)
    if cls is None:
        names = ", ".join(ASSOCIATORS)
        dym = did_you_mean(method.lower(), ASSOCIATORS, cutoff=0.3)  # ('PCA': 'pca')
        hint = f"{dym} Choices: {names}" if dym else f"choose one of: {names}"
        raise ConfigError(f"unknown associator '{method}'", hint)
    return cls


def make_associator(cfg: AssociationConfig) -> Associator:
    """The associator named by ``cfg.method``, configured by ``cfg``; ConfigError for an unknown name."""
    return associator_class(cfg.method)(cfg)


__all__ = [
    "ASSOCIATORS",
    "AssociationConfig",
    "Associator",
    "Icnn",
    "Jcbb",
    "Pca",
    "associator_class",
    "load_kernels",
    "make_associator",
]
