"""Config sections of the two-level SLAM (graph/, hierarchy.py): ``submaps``, ``loops``, ``graph``."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from ..ranges import check_ranges, num


@dataclass(frozen=True)
class SubmapConfig:
    """Local EKF submaps (Hierarchical SLAM, Estrada et al. 2005): the paper's filter runs on a bounded
    local map in its own frame; a submap closes when any limit is reached and the next one starts at the
    robot's pose with zero relative uncertainty. ``enabled: false`` is the paper's single-map filter
    (configs/paper.yaml). On by default: more accurate on 6 of the 7 radish logs (README)."""

    enabled: bool = True
    # m travelled over one submap's steps, counted from its first step (the move from its origin, the
    # previous submap's last step, is not counted: one step, 0.25–1 m on the radish logs)
    max_distance: float = num(10.0, gt=0.0, le=1e6)
    max_landmarks: int = num(60, ge=1, le=1000)  # landmarks in one submap
    max_steps: int = num(300, ge=2, le=1_000_000)  # keyframes in one submap
    # m: a submap's scan points (kept for loop closing and the occupancy grid) thinned to one per cell
    voxel: float = num(0.05, gt=0.0, le=10.0)

    def __post_init__(self) -> None:
        check_ranges(self)


@dataclass(frozen=True)
class LoopConfig:
    """Loop closing between submaps (graph/loops.py): candidates from the pose graph's estimate and
    marginals; verification by corner-pair hypotheses, the configured associator and ICP on the scan
    points; accepted only with ``min_corners`` corners matched and a point fitness ≥ ``min_fitness``."""

    enabled: bool = True
    min_corners: int = num(4, ge=2, le=1000)  # corners jointly matched for a closure
    min_fitness: float = num(0.5, ge=0.0, le=1.0)  # share of overlapping points within inlier_distance
    inlier_distance: float = num(0.1, gt=0.0, le=10.0)  # m
    # corner pairs agree when their lengths differ by less than this (m) and their φ by less than pair_phi
    pair_distance: float = num(0.15, gt=0.0, le=10.0)
    pair_phi: float = num(0.15, gt=0.0, le=math.pi)
    # σ given to a hypothesis' pose when the associator looks for the jointly compatible set under it
    hypothesis_sigma_xy: float = num(0.3, gt=0.0, le=100.0)
    hypothesis_sigma_theta: float = num(0.1, gt=0.0, le=math.pi)
    max_hypotheses: int = num(200, ge=1, le=100_000)  # corner-pair hypotheses tried per submap pair
    # search nodes of the associator under one hypothesis (0 = no bound); a search cut short rejects
    # the match ("search budget"): a few pairs of many-corner submaps otherwise took 10–40 s each
    max_nodes: int = num(30_000, ge=0, le=10**12)
    # a candidate: an earlier submap whose path came within candidate_distance of the new one's, plus
    # candidate_sigmas σ of the new one's marginal (hierarchy.py)
    candidate_distance: float = num(3.0, ge=0.0, le=1e6)  # m
    candidate_sigmas: float = num(3.0, gt=0.0, le=100.0)
    max_candidates: int = num(5, ge=1, le=1000)  # candidates verified per closed submap (nearest first)
    # ... stopping once this many were accepted by the gate: on ground revisited many times every close
    # had all its candidates to verify (8 then), and a third or fourth agreeing closure adds little
    max_closures: int = num(3, ge=1, le=1000)
    # a pair the corners cannot verify (few corners, no hypothesis: a corridor seen the other way round;
    # low fitness: a corner pose the points refute) is searched on its scan points inside the graph's
    # prediction ± 3σ, at most point_max_xy / point_max_theta (graph/points.py); accepted when the fit
    # is distinct: moved point_shift along the fit's weakest direction the fitness falls below
    # point_distinct × its own (not a corridor),
    # and no pose of the window away from it scores point_distinct × as well (not a repeated structure)
    point_search: bool = True
    # ... for at most this many candidates per closed submap (nearest first): each costs a correlative
    # search or two, ~15–25 ms; at 8 a close, loop closing made infinite-corridor's last 10 % of steps 2.6×
    # its first
    point_searches: int = num(1, ge=0, le=1000)
    # m, and at most 25 cells of the point search's grid (graph/points.py: 2 × scan_match.search_resolution,
    # 5 m). 5 (was 2): the window must cover the prediction's ±3σ for "no other pose scores as well" to
    # mean anything — capped at 2 m with a 3σ of 3 m, orebro verified a place 2.6 m off the truth near
    # the window's edge (radish_panel.py --set scan_match.warmup=10000 at 98044d2: ATE 0.82 m; 0.10 at
    # 5 m); the default panel within its spread (docs/results/variant_loops.point_max_xy-5.md)
    point_max_xy: float = num(5.0, gt=0.0, le=100.0)
    point_max_theta: float = num(0.5, gt=0.0, le=math.pi)  # rad
    point_shift: float = num(0.5, gt=0.0, le=100.0)  # m
    point_distinct: float = num(0.7, gt=0.0, le=1.0)
    min_gap: int = num(2, ge=1, le=1_000_000)  # b − a at least (1: neighbours too, which share a factor)
    # a closure must agree with the graph's prediction within this χ²₃ (Mahalanobis², marginal covariance)
    gate: float = num(30.7, gt=0.0, le=1e9)
    # ... unless two or more closures of the new submap agree with each other and each is within this
    # (10 × gate: the graph's σ too small by up to ~3×, as after a false closure); beyond it, refused
    group_gate: float = num(307.0, gt=0.0, le=1e12)
    # two closures of one submap placing it apart (> 0.5 m / 0.2 rad) agree when the a1→a2 pose they
    # imply fits the graph's within this χ²₃ (their covariances carry the front end's learnt scale, so
    # this guards against aliasing only as far as the graph knows a1→a2)
    pair_gate: float = num(30.7, gt=0.0, le=1e12)

    def __post_init__(self) -> None:
        check_ranges(self)


@dataclass(frozen=True)
class GraphConfig:
    """The global pose graph (graph/posegraph.py, GTSAM): keyframe nodes along each closed submap (one
    where the robot has moved ``node_spacing`` m or turned ``node_angle`` rad since the last, and at its
    last step: the next submap's origin) joined by the steps' motion, and loop closures between them
    under a robust kernel (hierarchy.py)."""

    solver: Literal["isam2", "lm"] = "isam2"  # incremental (iSAM2) or batch Levenberg–Marquardt
    kernel: Literal["cauchy", "dcs", "none"] = "cauchy"  # robust kernel of loop-closure factors
    # in units of the factor's σ (whitened residual): √χ²₃(0.95) = 2.8, so a right closure keeps full
    # weight 95 % of the time (at 1.0 Cauchy halved the median right closure and iSAM2 converged slowly)
    kernel_scale: float = num(2.8, gt=0.0, le=1e6)
    node_spacing: float = num(1.0, ge=0.0, le=1e6)  # m between keyframe nodes (0: every keyframe)
    node_angle: float = num(0.5, ge=0.0, le=math.pi)  # rad: a turn this large makes a node too
    # the smoothed trajectory's keyframe chain gets, at the steps before the front end first took a bias
    # term out, that term as fitted on the whole run (motion/fusion.py carry_back: only terms the whole run
    # holds and the learner never dropped once taken), each increment moved by the share of the odometry
    # in it (graph/smooth.py recalibrated); the online estimate and the closures stay as they were
    # (docs/results/README.md, "The smoothed chain, recalibrated": every exact-odometry log unchanged;
    # edmonton 0.352 -> 0.316 at the default submaps, but its mean over submaps.max_distance 9.5/10/10.5 m
    # 0.295 -> 0.354: off)
    recalibrate: bool = False
    # dense refinement (graph/refine.py; off: docs/results/README.md, "Dense refinement"): as the run goes,
    # each node's scan registered against its refine_neighbours nearest earlier nodes within refine_radius m
    # that lie refine_min_path m of path back (each with its chain neighbours' points, those as far back),
    # kept when the fit reaches refine_min_fitness; after the keyframe graph is solved, those that move their
    # pair at most refine_max_xy m / refine_max_theta rad from it become factors, and it is solved again
    refine: bool = False
    refine_radius: float = num(5.0, gt=0.0, le=1e6)
    refine_min_path: float = num(5.0, ge=0.0, le=1e9)
    refine_neighbours: int = num(2, ge=1, le=1000)
    refine_min_fitness: float = num(0.5, ge=0.0, le=1.0)
    refine_max_xy: float = num(0.3, gt=0.0, le=100.0)
    refine_max_theta: float = num(0.05, gt=0.0, le=math.pi)

    def __post_init__(self) -> None:
        check_ranges(self)
        if self.solver not in ("isam2", "lm"):
            raise ValueError(f"solver must be 'isam2' or 'lm', got {self.solver!r}")
        if self.kernel not in ("cauchy", "dcs", "none"):
            raise ValueError(f"kernel must be 'cauchy', 'dcs' or 'none', got {self.kernel!r}")
