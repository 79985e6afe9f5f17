"""The filter of a run: corner EKF-SLAM over the front end's frames (frontend.py).

:class:`Slam` holds the EKF (filter/), the associator (association/) and the landmark bookkeeping;
:meth:`Slam.step` is one step of the paper's loop (Fig 1): predict with the frame's motion input,
associate, update, augment, each stage timed for ``timing.csv``. It is given only the config sections
it uses (:meth:`Slam.from_config` picks them out of a run's config).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from .association import make_associator
from .association.params import AssociationConfig
from .filter import Ekf
from .filter.models import increment_noise
from .filter.params import EkfConfig
from .frontend import Frame
from .geometry import compose, matrix_from_pose, relative, transform_points
from .graph.submap import propagate
from .logs.params import OdomJumpConfig
from .types import Segments

if TYPE_CHECKING:
    from .config import Config


def segments_to_map(segments: Segments, sensor2map: np.ndarray) -> np.ndarray:
    """(k, 4) segment end points x1, y1, x2, y2 in the map frame."""
    R, t = sensor2map[:2, :2], sensor2map[:2, 2]
    return np.hstack((segments.p1 @ R.T + t, segments.p2 @ R.T + t))


@dataclass
class StepRecord:
    """What one step produced (one row of trajectory.csv and timing.csv)."""

    step: int
    stamp: float
    pose: np.ndarray
    pose_var: np.ndarray
    odom: np.ndarray
    motion: np.ndarray  # the filter's motion input: scan-matched odometry, or odom
    n_points: int
    n_lines: int
    n_corners: int
    n_candidates: int
    n_matched: int
    n_new: int
    n_landmarks: int
    t_extract: float
    t_predict: float
    t_match: float
    t_update: float
    segments_map: np.ndarray
    nodes: int = 0
    budget_hit: bool = False
    t_scan_match: float = 0.0
    scan_fit: float = float("nan")
    cov_xy: float = 0.0  # the robot's x-y covariance (pose_var holds the diagonal)
    t_loop: float = 0.0  # closing a submap: loop detection and the pose graph's optimisation (hierarchy.py)
    submap: int = 0  # the local map the step was filtered in (0 without submaps)

    @property
    def t_total(self) -> float:
        return (
            self.t_extract + self.t_scan_match + self.t_predict + self.t_match + self.t_update + self.t_loop
        )


@dataclass(frozen=True)
class Motion:
    """The filter's motion input into one frame and its noise: the increment ``prev`` → ``cur``
    (keyframe poses; ``prev`` None at the first frame: nothing to predict), its covariance ``cov`` in
    the frame of ``prev`` (None: the filter's odometry noise model, ``ekf.alpha*``) and ``inflate`` =
    (σ_xy, σ_θ) added to the robot's covariance after it, or None."""

    prev: np.ndarray | None
    cur: np.ndarray
    cov: np.ndarray | None = None
    inflate: tuple[float, float] | None = None


class Slam:
    """Corner EKF-SLAM state across steps: the filter, the associator, landmark bookkeeping."""

    def __init__(
        self,
        ekf: EkfConfig,
        association: AssociationConfig,
        odom_jump: OdomJumpConfig,
        laser2base: tuple[float, float, float],
    ):
        self.odom_jump = odom_jump  # the robot uncertainty added across an odometry jump
        self.laser2base = laser2base
        self.ekf = Ekf(ekf)
        self.associate = make_associator(association)
        self.first_step = np.zeros(0, dtype=np.int64)  # per landmark id, kept in step with the filter's ids
        self.last_step = np.zeros(0, dtype=np.int64)
        self.prev_motion: np.ndarray | None = None  # the previous frame's motion input
        self.step_cov = np.zeros((3, 3))  # the last step's motion noise (step_noise)
        self.n_steps = 0

    @classmethod
    def from_config(cls, cfg: Config, laser2base: tuple[float, float, float]) -> Slam:
        """The filter with the sections of a run's config that it uses."""
        return cls(cfg.ekf, cfg.association, cfg.input.odom_jump, laser2base)

    def new_map(self) -> None:
        """Start a new local map (a submap, hierarchy.py): the filter restarts empty at the origin of
        its frame — the robot's current pose — with zero uncertainty; the step count and the motion
        input go on, so the next prediction is the motion since the last step."""
        cfg = self.ekf.cfg
        self.ekf = Ekf.from_state(cfg, np.zeros(3), np.zeros((3, 3)))
        self.first_step = np.zeros(0, dtype=np.int64)
        self.last_step = np.zeros(0, dtype=np.int64)

    def motion(self, frame: Frame) -> Motion:
        """The motion input into ``frame`` and its noise.

        The input is the pose chain the front end fused from odometry and scan matches, with the
        covariance of each increment (motion/fusion.py), when it has one; else the odometry with the
        filter's own noise model. An odometry increment across a jump was re-anchored (logs/sync.py),
        so unless a scan match measured it the motion over it is unknown: the robot's covariance is
        inflated by ``input.odom_jump.sigma_*``.
        """
        cur = frame.odom if frame.motion is None else frame.motion
        jump = frame.odom_jump and not frame.scan_matched
        inflate = (self.odom_jump.sigma_xy, self.odom_jump.sigma_theta) if jump else None
        return Motion(self.prev_motion, cur, frame.motion_cov, inflate)

    def step_noise(self, m: Motion) -> np.ndarray:
        """The covariance (3, 3) of motion ``m``'s increment in the frame it starts from, as the
        filter's prediction took it (its own, else the odometry noise model; a jump's inflation added);
        zero at the first frame. The pose graph's keyframe factors (hierarchy.py) carry it."""
        if m.prev is None:
            return np.zeros((3, 3))
        cfg = self.ekf.cfg
        if m.cov is not None:
            cov = np.array(m.cov, dtype=float)
        else:
            inc = relative(m.prev, m.cur)
            cov = increment_noise(
                inc,
                cfg.alphas,
                cfg.min_sigma_xy,
                cfg.min_sigma_theta,
                cfg.pure_rotation_eps,
                cfg.reverse_motion,
            )
        if m.inflate is not None:
            cov += np.diag([m.inflate[0] ** 2, m.inflate[0] ** 2, m.inflate[1] ** 2])
        return cov

    def step(self, frame: Frame) -> StepRecord:
        """One step of the paper's loop on an extracted frame: predict, associate, update, augment."""
        k = self.n_steps
        z, C = frame.z, frame.C
        t1 = time.perf_counter()
        m = self.motion(frame)
        if m.prev is not None:
            self.ekf.predict(m.prev, m.cur, m.cov)  # eq 19-22, O(N)
            if m.inflate is not None:
                self.ekf.inflate_pose(*m.inflate)
        self.prev_motion = m.cur
        self.step_cov = self.step_noise(m)
        t2 = time.perf_counter()
        result = self.associate(z, C, self.ekf.predict_observations())  # Alg 3-5
        t3 = time.perf_counter()
        matched = result.pairs >= 0
        ids = result.pairs[matched]
        if len(ids):
            self.ekf.update(ids, z[matched], C[matched])  # eq 23-32, block update
        new_ids = self.ekf.augment(z[~matched], C[~matched])
        self._track_landmarks(k, ids, new_ids)
        self.ekf.check_health(k)
        t4 = time.perf_counter()
        pose = np.array(self.ekf.pose, dtype=float)
        sensor2map = matrix_from_pose(pose) @ matrix_from_pose(self.laser2base)
        self.n_steps += 1
        return StepRecord(
            step=k,
            stamp=frame.stamp,
            pose=pose,
            pose_var=np.diag(self.ekf.P[:3, :3]).copy(),
            cov_xy=float(self.ekf.P[0, 1]),
            odom=frame.odom,
            motion=m.cur,
            n_points=frame.n_points,
            n_lines=len(frame.segments),
            n_corners=len(z),
            n_candidates=int(np.sum(result.n_candidates)),
            n_matched=int(len(ids)),
            n_new=int(len(new_ids)),
            n_landmarks=self.ekf.n_landmarks,
            t_extract=frame.t_extract,
            t_scan_match=frame.t_scan_match,
            scan_fit=frame.scan_fit,
            t_predict=t2 - t1,
            t_match=t3 - t2,
            t_update=t4 - t3,
            segments_map=segments_to_map(frame.segments, sensor2map),
            nodes=int(result.nodes),
            budget_hit=bool(result.budget_hit),
        )

    def _track_landmarks(self, k: int, ids: np.ndarray, new_ids: np.ndarray) -> None:
        """First and last step of each landmark after step ``k`` matched ``ids`` and added ``new_ids``;
        the tentative landmarks the filter pruned are dropped with it."""
        self.last_step[ids] = k
        self.first_step = np.concatenate((self.first_step, np.full(len(new_ids), k)))
        self.last_step = np.concatenate((self.last_step, np.full(len(new_ids), k)))
        remap = self.ekf.prune_tentative()  # identity unless ekf.tentative_sightings > 1
        if np.any(remap < 0):
            kept = remap >= 0
            self.first_step, self.last_step = self.first_step[kept], self.last_step[kept]

    def landmark_table(self) -> dict[str, np.ndarray]:
        """map.csv's columns by name: the confirmed landmarks (all of them without a tentative stage)."""
        ids = np.flatnonzero(~self.ekf.tentative)
        L = np.asarray(self.ekf.landmarks).reshape(-1, 3)[ids]
        P = self.ekf.P
        idx = 3 + 3 * ids
        return {
            "id": ids,
            "x": L[:, 0],
            "y": L[:, 1],
            "phi": L[:, 2],
            "var_x": P[idx, idx],
            "var_y": P[idx + 1, idx + 1],
            "cov_xy": P[idx, idx + 1],
            "var_phi": P[idx + 2, idx + 2],
            "first_step": self.first_step[ids],
            "last_step": self.last_step[ids],
            "n_obs": self.ekf.n_obs[ids],
            "submap": np.zeros(len(ids), dtype=np.int64),
            "linked_to": np.full(len(ids), -1, dtype=np.int64),
        }


def globalise(
    r: StepRecord, origin: np.ndarray, origin_cov: np.ndarray, index: int, t_loop: float
) -> StepRecord:
    """A local step record in the global frame: its submap's ``origin`` ∘ the local pose; the pose's
    covariance to first order from the origin's marginal ``origin_cov`` (with the lever arm of its
    heading error over the local pose) and the local one turned by the origin (its x–θ and y–θ
    covariances are not in the record: taken as 0); segments moved with it."""
    local = np.array(
        [[r.pose_var[0], r.cov_xy, 0.0], [r.cov_xy, r.pose_var[1], 0.0], [0.0, 0.0, r.pose_var[2]]]
    )
    pose = compose(origin, r.pose)
    cov = propagate(origin_cov, origin, pose, local)
    return replace(
        r,
        pose=pose,
        pose_var=np.diag(cov).copy(),
        cov_xy=float(cov[0, 1]),
        segments_map=transform_points(r.segments_map.reshape(-1, 2), origin).reshape(-1, 4),
        t_loop=t_loop,
        submap=index,
    )
