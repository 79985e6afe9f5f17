"""Individual compatibility nearest neighbour, ICNN (paper §"Existing data association", O(mn)).

Each corner independently takes its individually compatible landmark of least D² (χ²(d, 1 − α) gate);
corners are *not* made exclusive (two corners may take the same landmark), as in the paper. The result
still reports the joint D² of the hypothesis and, in ``extra``, whether it is jointly compatible and
collision-free, so that ``compare`` can show how often ICNN's answer would fail JCBB's test.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..types import AssociationResult, Prediction
from .gating import build_result, chi2_gate, gate, joint_d2_of
from .params import AssociationConfig


class Icnn:
    """ICNN associator."""

    def __init__(self, cfg: AssociationConfig | None = None):
        self.cfg = cfg or AssociationConfig(method="icnn")

    def __call__(self, z: np.ndarray, C: np.ndarray, pred: Prediction) -> AssociationResult:
        t0 = time.perf_counter()
        g = gate(z, C, pred, self.cfg)
        nearest = g.nearest()
        pairs = [(i, int(k)) for i, k in enumerate(nearest) if k >= 0]
        joint = joint_d2_of(g, pairs) if pairs else 0.0
        landmarks = [k for _, k in pairs]
        extra = {
            "seconds": time.perf_counter() - t0,
            "jointly_compatible": bool(joint < chi2_gate(g.d * len(pairs), g.alpha)) if pairs else True,
            "collisions": len(landmarks) - len(set(landmarks)),
        }
        return build_result(g, pairs, joint if math.isfinite(joint) else np.nan, 0, False, extra)
