"""Data passed between pipeline stages: frozen dataclasses of numpy arrays.

Frames: *sensor* is the laser frame of one scan, *base* the robot frame (odometry child frame),
*map* the SLAM world frame. Angles in radians, lengths in metres, stamps in seconds (float, epoch).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np


@dataclass(frozen=True)
class Scan:
    """One laser scan, valid beams only, in increasing bearing order.

    ranges : (k,) float64, metres, valid beams only (finite and within [range_min, range_max])
    angles : (k,) float64, radians, sensor frame, bearing of each valid beam
    beam_index : (k,) int64, index of each valid beam in the original message (gaps = dropped beams):
        increasing, or decreasing where the message's beams run clockwise (a negative angle_increment,
        a laser mounted upside down: :meth:`mirrored`), so that it still gives each beam's time
    n_beams : beams in the original message; n_invalid = n_beams - k were dropped.
    time_increment : seconds between two beams of the message (its own field; 0 = not given), beam i
    at ``stamp + i · time_increment`` (logs/deskew.py)
    """

    stamp: float
    ranges: np.ndarray
    angles: np.ndarray
    beam_index: np.ndarray
    n_beams: int
    range_min: float
    range_max: float
    angle_increment: float
    frame_id: str = ""
    time_increment: float = 0.0

    @property
    def n_invalid(self) -> int:
        return self.n_beams - len(self.ranges)

    def points(self) -> np.ndarray:
        """(k, 2) Cartesian points in the sensor frame."""
        return np.column_stack((self.ranges * np.cos(self.angles), self.ranges * np.sin(self.angles)))

    def reversed(self) -> Scan:
        """The same beams in the opposite order (``angles`` as they are): a scan whose bearings were
        decreasing made increasing. ``beam_index`` goes with the beams, so their times stay."""
        return replace(
            self, ranges=self.ranges[::-1].copy(), angles=self.angles[::-1].copy(),
            beam_index=self.beam_index[::-1].copy(),
        )  # fmt: skip

    def mirrored(self) -> Scan:
        """The scan as an upright laser at the same place would see it, of a laser mounted upside down
        (its z axis down, roll π: a beam at bearing φ looks at −φ of the base's plane); bearings
        still increasing."""
        return replace(self, angles=-self.angles).reversed()


@dataclass(frozen=True)
class OdomSample:
    """One odometry pose of the base in the odometry frame."""

    stamp: float
    x: float
    y: float
    theta: float
    jumped: bool = False  # re-anchored across an odometry jump (logs/sync.py reanchor_odometry)


@dataclass(frozen=True)
class Segments:
    """Line segments of one scan (paper Algorithm 1), Hessian normal form x·cos α + y·sin α = r.

    r : (k,) metres, r >= 0;  alpha : (k,) radians in (-pi, pi]
    cov : (k, 2, 2) covariance of (r, alpha)
    p1, p2 : (k, 2) end points (first / last point projected onto the line), sensor frame
    n_points : (k,) points used in the fit;  first, last : (k,) indices into the scan's valid beams
    """

    r: np.ndarray
    alpha: np.ndarray
    cov: np.ndarray
    p1: np.ndarray
    p2: np.ndarray
    n_points: np.ndarray
    first: np.ndarray
    last: np.ndarray

    def __len__(self) -> int:
        return len(self.r)

    @staticmethod
    def empty() -> Segments:
        z = np.zeros(0)
        zi = np.zeros(0, dtype=np.int64)
        return Segments(z, z, np.zeros((0, 2, 2)), np.zeros((0, 2)), np.zeros((0, 2)), zi, zi, zi)


@dataclass(frozen=True)
class Corners:
    """Natural corners of one scan (paper Algorithm 2).

    z : (m, 3) measurement (x, y, phi): position in metres in the frame named by the producer
        (sensor frame from the extractor, base frame after the pipeline applies laser2base),
        phi the pose-invariant angle between the two lines, radians
    cov : (m, 3, 3) covariance of z
    kind : (m,) int8, 1 = line intersection (type I), 2 = segment end point (type II)
    segs : (m, 2) int64 indices of the segments that made the corner (-1 where none)
    """

    z: np.ndarray
    cov: np.ndarray
    kind: np.ndarray
    segs: np.ndarray

    def __len__(self) -> int:
        return len(self.z)

    @staticmethod
    def empty() -> Corners:
        return Corners(
            np.zeros((0, 3)),
            np.zeros((0, 3, 3)),
            np.zeros(0, dtype=np.int8),
            np.zeros((0, 2), dtype=np.int64),
        )


@dataclass(frozen=True)
class Prediction:
    """Predicted observations of all n landmarks from the predicted robot pose (NOTES §4).

    h : (n, 3) predicted measurement h_k = [R(θ)ᵀ(m_k,xy − p); m_k,φ], base frame
    H_r : (n, 3, 3) Jacobian of h_k w.r.t. the robot pose (x, y, θ)
    H_l : (n, 3, 3) Jacobian of h_k w.r.t. landmark k (x, y, φ)
    P : (3 + 3n, 3 + 3n) state covariance (read only; shared with the filter, do not modify)

    The innovation covariance of a pairing (i ↔ k) is S = hph(k, k) + C_i; the cross covariance
    between two pairings (i ↔ k), (j ↔ l) is hph(k, l): measurements are independent.
    """

    h: np.ndarray
    H_r: np.ndarray
    H_l: np.ndarray
    P: np.ndarray

    def __len__(self) -> int:
        return len(self.h)

    def hph_diag(self) -> np.ndarray:
        """(n, 3, 3) H_k P H_kᵀ for every landmark, O(n)."""
        return self.hph_blocks(np.arange(len(self)), None)

    def hph_blocks(
        self, I: np.ndarray, J: np.ndarray | None = None, factors: tuple | None = None
    ) -> np.ndarray:
        """Blocks H_i P H_jᵀ for landmark index arrays I (a,) and J (b,).

        Returns (a, b, 3, 3); with J None, the diagonal blocks (a, 3, 3) for i = j. ``factors``:
        :meth:`row_factors` (I), computed once when the same I meets many J.
        Costs O(a·b) 3×3 products plus O((a + b)·N) to gather the rows of P.
        """
        I = np.asarray(I, dtype=np.int64)
        P = self.P
        ri = 3 + 3 * I[:, None] + np.arange(3)  # (a, 3) state rows of landmarks I
        # A_i = [H_r,i  H_l,i] restricted to the columns of the robot and landmark i
        if J is None:
            Prr = P[:3, :3]
            Prl = P[:3][:, ri].transpose(1, 0, 2)  # (a, 3, 3) P_r,li
            Pll = P[ri[:, :, None], ri[:, None, :]]  # (a, 3, 3) P_li,li
            Hr, Hl = self.H_r[I], self.H_l[I]
            out = Hr @ Prr @ Hr.transpose(0, 2, 1)
            cross = Hr @ Prl @ Hl.transpose(0, 2, 1)
            out = out + cross + cross.transpose(0, 2, 1) + Hl @ Pll @ Hl.transpose(0, 2, 1)
            return out
        J = np.asarray(J, dtype=np.int64)
        rj = 3 + 3 * J[:, None] + np.arange(3)
        ri, Hri, Hli, HriPrr, HliPlir = factors if factors is not None else self.row_factors(I)
        Hrj, Hlj = self.H_r[J], self.H_l[J]
        Pr_lj = P[:3][:, rj].transpose(1, 0, 2)  # (b, 3, 3)
        Pli_lj = P[ri[:, None, :, None], rj[None, :, None, :]]  # (a, b, 3, 3)
        out = HriPrr[:, None] @ Hrj.transpose(0, 2, 1)[None]
        out = out + Hri[:, None] @ (Pr_lj @ Hlj.transpose(0, 2, 1))[None]
        out = out + HliPlir[:, None] @ Hrj.transpose(0, 2, 1)[None]
        out = out + Hli[:, None] @ Pli_lj @ Hlj.transpose(0, 2, 1)[None]
        return out

    def row_factors(self, I: np.ndarray) -> tuple[np.ndarray, ...]:
        """The parts of :meth:`hph_blocks` (I, J) that depend on I only — its state rows, H_r,i, H_l,i,
        H_r,i P_rr and H_l,i P_li,r — to pass back as ``factors`` for many J."""
        I = np.asarray(I, dtype=np.int64)
        P = self.P
        ri = 3 + 3 * I[:, None] + np.arange(3)
        Hri, Hli = self.H_r[I], self.H_l[I]
        return ri, Hri, Hli, Hri @ P[:3, :3], Hli @ P[ri][:, :, :3]


@dataclass(frozen=True)
class AssociationResult:
    """What an associator decided for the m corners of one step, with its diagnostics.

    pairs : (m,) int64, landmark index matched to each corner, -1 = unmatched (new or spurious)
    d2 : (m,) individual Mahalanobis D² of each chosen pair (nan where unmatched)
    n_candidates : (m,) individually compatible landmarks per corner
    joint_d2 : joint Mahalanobis D² of the whole hypothesis (0 when empty)
    nodes : search nodes expanded (ICNN: 0)
    budget_hit : the optional node/time budget stopped the search early
    """

    pairs: np.ndarray
    d2: np.ndarray
    n_candidates: np.ndarray
    joint_d2: float = 0.0
    nodes: int = 0
    budget_hit: bool = False
    extra: dict = field(default_factory=dict)

    @property
    def n_matched(self) -> int:
        return int(np.count_nonzero(self.pairs >= 0))
