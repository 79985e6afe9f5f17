"""The global pose graph, on GTSAM (issue 16, the global level).

Node 0 is the first submap's origin, held by a tight prior; node j > 0 joins node j−1 by a relative
pose and covariance (a *sequential* factor: a closed submap's end pose in hierarchy.py's online graph, a
link of a keyframe chain in graph/smooth.py's) and any earlier node by loop closures (*loop* factors,
under ``graph.kernel``). ``graph.solver`` picks
iSAM2 (incremental: each :meth:`PoseGraph.optimize` adds what came since the last one) or batch
Levenberg–Marquardt.

Covariance conventions (the crux; tests/test_posegraph.py checks them by Monte Carlo):

- ours (graph/submap.py): a relative pose a→b is b's origin in a's frame, (x, y, θ), and its
  covariance is of those three numbers in a's frame; a global pose is (x, y, θ) in the map frame.
- GTSAM: the noise of a ``BetweenFactorPose2`` lives in the tangent space of the *measured* pose,
  ``z ∘ Exp(ξ)``, and a marginal in the tangent space of the node's estimate, ``X ∘ Exp(ξ)``: both
  body-frame, to first order ξ = [R(θ)ᵀ δt; δθ].

So a covariance goes between the two with ``J = blockdiag(R(θ), 1)`` of the pose it belongs to
(:func:`tangent_from_frame`, :func:`frame_from_tangent`: the only place this conversion is made).

Robust kernels act on the whitened residual r = ‖Σ^{-1/2} e‖ of a loop factor; ``graph.kernel_scale``
is in those units for both: Cauchy ρ(r) = c²/2 · log(1 + r²/c²) (weight ½ at r = c), DCS (dynamic
covariance scaling, Agarwal et al. 2013) with Φ = c² (weight 1 up to r = c, then (2Φ/(Φ + r²))²).

>>> g = PoseGraph(GraphConfig())
>>> j = g.add_sequential(submap.end_pose, submap.end_cov)
>>> k = g.add_loop(a, j, match.pose, match.cov)
>>> g.optimize()
>>> g.pose(j), g.marginal(j), g.relative(a, j), g.loop_inlier(k)
"""

from __future__ import annotations

import gtsam
import numpy as np

from ..geometry import rotate_pose_covariance, wrap_angle
from .params import GraphConfig

PRIOR_SIGMA = 1e-6  # m and rad: node 0's prior, which fixes the graph's frame
# iSAM2: relinearise a variable when its step exceeds this (m, rad); optimize() repeats update() until
# no variable is relinearised (at most ISAM2_MAX_STEPS times), so the result matches a batch solve
ISAM2_RELINEARIZE = 1e-6
# ... the hierarchy's online graph (hierarchy.py) stops when no step exceeds 0.1 mm / 0.1 mrad (its poses
# then within ~0.5 mm of the optimum: tests/test_posegraph.py). It chooses and gates loop candidates
# (metres; χ² of centimetres), starts the smoothing's own solve, and gives the causal online_* and var_*
# columns of trajectory.csv. Under the Cauchy kernel each update after a closure relinearises every node
# and its steps shrink only geometrically: on infinite-corridor the optimisations after a closure took
# 5–31 updates at 1e-6 (one stopped at the cap), 4–21 at 1e-4 (−32 % in all, about half in its last
# 10 %); the smoothed ATE moved by 3·10⁻⁸ m with the same 55 closures, online_* by up to 0.3 mm
ONLINE_RELINEARIZE = 1e-4
ISAM2_MAX_STEPS = 30
LM_RELATIVE_TOL = 1e-12  # LM stops when the cost falls by less than this share …
LM_ABSOLUTE_TOL = 1e-12  # … or by less than this
LM_MAX_ITERATIONS = 100
_ASYMMETRY = 1e-9  # a covariance whose |Σ − Σᵀ| exceeds this share of max |Σ| is rejected


def _isam2_solve(isam: gtsam.ISAM2, factors, values) -> tuple[int, bool]:
    """``isam.update`` with ``factors`` and ``values``, then updates until no variable is relinearised
    (at most ``ISAM2_MAX_STEPS``): (updates made, whether that point was reached)."""
    isam.update(factors, values)
    for k in range(ISAM2_MAX_STEPS):
        if isam.update().getVariablesRelinearized() == 0:
            return k + 2, True
    return ISAM2_MAX_STEPS + 1, False


def tangent_from_frame(cov: np.ndarray, pose) -> np.ndarray:
    """Covariance (3, 3) of ``pose`` given in its parent frame (ours: (x, y, θ)) → in GTSAM's tangent
    space at ``pose`` (body frame): J⁻¹ Σ J⁻ᵀ with J = blockdiag(R(θ), 1)."""
    return rotate_pose_covariance(cov, -pose[2])


def frame_from_tangent(cov: np.ndarray, pose) -> np.ndarray:
    """Covariance (3, 3) in GTSAM's tangent space at ``pose`` → of (x, y, θ) in its parent frame:
    J Σ Jᵀ with J = blockdiag(R(θ), 1)."""
    return rotate_pose_covariance(cov, pose[2])


def _pose2(pose) -> gtsam.Pose2:
    return gtsam.Pose2(float(pose[0]), float(pose[1]), float(pose[2]))


def _array(pose: gtsam.Pose2) -> np.ndarray:
    return np.array([pose.x(), pose.y(), wrap_angle(pose.theta())])


def _check_pose(rel, what: str) -> np.ndarray:
    rel = np.asarray(rel, dtype=float)
    if rel.shape != (3,) or not np.all(np.isfinite(rel)):
        raise ValueError(f"{what}: a pose must be 3 finite numbers (x, y, θ), got {rel!r}")
    return rel


def _check_cov(cov, what: str) -> np.ndarray:
    """``cov`` as a symmetric (3, 3) array; ValueError naming ``what`` unless it is finite, symmetric
    (to a rounding error) and positive definite."""
    cov = np.asarray(cov, dtype=float)
    if cov.shape != (3, 3) or not np.all(np.isfinite(cov)):
        raise ValueError(f"{what}: a covariance must be a finite 3x3 matrix, got shape {cov.shape}")
    if np.max(np.abs(cov - cov.T)) > _ASYMMETRY * np.max(np.abs(cov)):
        raise ValueError(f"{what}: covariance is not symmetric:\n{cov}")
    cov = 0.5 * (cov + cov.T)
    try:
        np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        eig = np.linalg.eigvalsh(cov)
        raise ValueError(f"{what}: covariance is not positive definite (eigenvalues {eig})") from None
    return cov


def _kernel(cfg: GraphConfig):
    """The robust loss of loop factors, ``graph.kernel_scale`` in whitened units (None: quadratic)."""
    c = cfg.kernel_scale
    if cfg.kernel == "cauchy":
        return gtsam.noiseModel.mEstimator.Cauchy.Create(c)
    if cfg.kernel == "dcs":  # GTSAM's DCS compares Φ with r², not r
        return gtsam.noiseModel.mEstimator.DCS.Create(c * c)
    return None


class PoseGraph:
    """Pose graph of submap origins: poses (x, y, θ) in the frame of node 0, which sits at ``origin``.

    Poses and covariances going in and out are in our convention (module docstring); ``pose``,
    ``marginal``, ``relative`` and ``loop_inlier`` answer for the last :meth:`optimize` (``pose`` of a
    node added since is its initial guess: the one given to :meth:`add_sequential`, by default the
    previous node's pose composed with its factor)."""

    def __init__(self, cfg: GraphConfig, origin=(0.0, 0.0, 0.0), relinearize: float = ISAM2_RELINEARIZE):
        self.cfg = cfg
        self.relinearize = relinearize  # iSAM2's relinearisation threshold: optimize()'s tolerance
        self._kernel = _kernel(cfg)
        self._graph = gtsam.NonlinearFactorGraph()  # every factor (LM solves it; loop_inlier reads it)
        self._new_factors = gtsam.NonlinearFactorGraph()  # iSAM2: factors since the last optimize()
        self._new_values = gtsam.Values()  # iSAM2: initial guesses of nodes since the last optimize()
        self._estimate = gtsam.Values()  # the last optimize()'s result (LM: and the initial guesses)
        self._poses = [_check_pose(origin, "origin")]  # (x, y, θ) per node: estimate or initial guess
        self._n_optimized = 0  # nodes the last optimize() saw
        self._n_loops_optimized = 0  # loop factors the last optimize() saw
        self._loops: list[tuple[int, gtsam.noiseModel.Gaussian]] = []  # (factor index, its noise)
        self._marginals = None  # LM: gtsam.Marginals of the last optimize(), built when first asked
        self.iterations = 0  # the last optimize()'s iSAM2 updates or LM iterations
        self.converged = True  # whether it stopped before its step limit
        self.qr = False  # iSAM2 eliminates by QR since Cholesky found the system indeterminate
        self._isam = gtsam.ISAM2(self._isam2_params()) if cfg.solver == "isam2" else None
        prior = gtsam.noiseModel.Isotropic.Sigma(3, PRIOR_SIGMA)
        self._add_factor(gtsam.PriorFactorPose2(0, _pose2(origin), prior))
        self._add_guess(0, self._poses[0])

    def __len__(self) -> int:
        return len(self._poses)

    # --- building ---------------------------------------------------------------------------------

    def add_sequential(self, rel, cov, guess=None) -> int:
        """New node j = len(self), joined to node j−1 by ``rel`` (j's origin in j−1's frame) with
        covariance ``cov`` (3, 3, in j−1's frame); its initial guess ``guess`` (x, y, θ), by default
        pose(j−1) ∘ rel. Returns j."""
        j = len(self)
        rel = _check_pose(rel, f"sequential factor {j - 1}→{j}")
        noise = self._noise(rel, cov, f"sequential factor {j - 1}→{j}")
        if guess is None:
            guess = _array(_pose2(self._poses[-1]).compose(_pose2(rel)))
        else:
            guess = _check_pose(guess, f"initial guess of node {j}")
        self._poses.append(guess)
        self._add_factor(gtsam.BetweenFactorPose2(j - 1, j, _pose2(rel), noise))
        self._add_guess(j, guess)
        return j

    def add_loop(self, i: int, j: int, rel, cov) -> int:
        """Loop-closure factor between existing nodes i and j: ``rel`` is j's origin in i's frame,
        ``cov`` its covariance (3, 3, in i's frame), under ``graph.kernel``. Returns the loop's index
        k (for :meth:`loop_inlier`), counting loops from 0."""
        what = f"loop factor {i}→{j}"
        i, j = self._check_node(i, what), self._check_node(j, what)
        if i == j:
            raise ValueError(f"{what}: a loop must join two different nodes")
        rel = _check_pose(rel, what)
        gaussian = self._noise(rel, cov, what)
        noise = gtsam.noiseModel.Robust.Create(self._kernel, gaussian) if self._kernel else gaussian
        self._loops.append((self._graph.size(), gaussian))
        self._add_factor(gtsam.BetweenFactorPose2(i, j, _pose2(rel), noise))
        return len(self._loops) - 1

    def _noise(self, rel: np.ndarray, cov, what: str) -> gtsam.noiseModel.Gaussian:
        """GTSAM's noise model of a factor measuring ``rel`` with ``cov`` in our convention."""
        return gtsam.noiseModel.Gaussian.Covariance(tangent_from_frame(_check_cov(cov, what), rel))

    def _add_factor(self, factor) -> None:
        self._graph.add(factor)
        self._new_factors.add(factor)

    def _add_guess(self, key: int, pose: np.ndarray) -> None:
        if self._isam is not None:
            self._new_values.insert(key, _pose2(pose))
        else:
            self._estimate.insert(key, _pose2(pose))

    def _isam2_params(self, qr: bool = False) -> gtsam.ISAM2Params:
        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(self.relinearize)
        params.relinearizeSkip = 1
        if qr:
            params.setFactorization("QR")
        return params

    # --- solving ----------------------------------------------------------------------------------

    def optimize(self) -> None:
        """Solve the graph: iSAM2 adds the factors and nodes since the last call and updates until
        no variable needs relinearising; LM solves the whole graph from the current estimate.
        ``iterations`` and ``converged`` say how it went (not converged: stopped at the step limit,
        the estimate is the last step's)."""
        if self._isam is not None:
            self.iterations, self.converged = self._isam2_steps()
            self._estimate = self._isam.calculateEstimate()
            self._new_values = gtsam.Values()
        else:
            params = gtsam.LevenbergMarquardtParams()
            params.setRelativeErrorTol(LM_RELATIVE_TOL)
            params.setAbsoluteErrorTol(LM_ABSOLUTE_TOL)
            params.setMaxIterations(LM_MAX_ITERATIONS)
            lm = gtsam.LevenbergMarquardtOptimizer(self._graph, self._estimate, params)
            self._estimate = lm.optimize()
            self.iterations, self.converged = lm.iterations(), lm.iterations() < LM_MAX_ITERATIONS
            self._marginals = None
        self._new_factors = gtsam.NonlinearFactorGraph()
        self._n_optimized = len(self)
        self._n_loops_optimized = len(self._loops)
        poses = gtsam.utilities.extractPose2(self._estimate)
        poses[:, 2] = wrap_angle(poses[:, 2])
        self._poses = list(poses)

    def _isam2_steps(self) -> tuple[int, bool]:
        """iSAM2 update with the new factors and nodes, then updates that relinearise where a step
        moved a variable, until none does. Returns (updates, whether that point was reached).

        iSAM2 eliminates by Cholesky, which squares the condition number: with loop factors of a few
        millimetres beside sequential factors of metres (an odometry-only submap of a sparse log) GTSAM
        can find the system "indeterminate" although it is well posed. Then a new iSAM2 eliminating by
        QR takes the whole graph (from the last estimate and the new nodes' guesses) and is kept for the
        rest of the run — only once it has solved it: a QR failure leaves the graph as it was and is
        raised. A graph that never hits it is solved exactly as before."""
        try:
            return _isam2_solve(self._isam, self._new_factors, self._new_values)
        except RuntimeError as err:
            # GTSAM ≥ 4.3 says "Indeterminate linear system", earlier versions "Indeterminant …"
            if "Indetermina" not in str(err) or self.qr:
                raise
        values = gtsam.Values(self._estimate)
        values.insert(self._new_values)
        isam = gtsam.ISAM2(self._isam2_params(qr=True))
        steps = _isam2_solve(isam, self._graph, values)
        self._isam, self.qr = isam, True
        return steps

    # --- answers ----------------------------------------------------------------------------------

    def poses(self) -> np.ndarray:
        """(n, 3) every node's x, y, θ (θ in [-π, π))."""
        return np.array(self._poses)

    def pose(self, i: int) -> np.ndarray:
        """(3,) node i's x, y, θ."""
        return self._poses[self._check_node(i, "pose")].copy()

    def marginal(self, i: int) -> np.ndarray:
        """(3, 3) covariance of node i's (x, y, θ) in the global frame (after :meth:`optimize`)."""
        i = self._check_solved(i, "marginal")
        if self._isam is not None:
            cov = self._isam.marginalCovariance(i)
        else:
            cov = self._lm_marginals().marginalCovariance(i)
        return frame_from_tangent(cov, self._poses[i])

    def relative(self, i: int, j: int) -> tuple[np.ndarray, np.ndarray]:
        """The graph's prediction of j's origin in i's frame: (3,) pose and (3, 3) covariance in i's
        frame, from the joint marginal of i and j (so their correlation counts: two nodes far from
        node 0 but close in the graph are known well relative to each other)."""
        i, j = self._check_solved(i, "relative"), self._check_solved(j, "relative")
        if i == j:
            raise ValueError(f"relative: i and j are the same node ({i})")
        solver = self._isam if self._isam is not None else self._lm_marginals()
        joint = solver.jointMarginalCovariance([i, j])
        cov = np.block([[joint.at(i, i), joint.at(i, j)], [joint.at(j, i), joint.at(j, j)]])
        pi, pj = self._estimate.atPose2(i), self._estimate.atPose2(j)
        rel = pi.between(pj)
        # X_i⁻¹ X_j with X = X̂ Exp(ξ): the rel's tangent error is ξ_j − Ad(rel⁻¹) ξ_i to first order
        A = np.hstack((-rel.inverse().AdjointMap(), np.eye(3)))
        rel = _array(rel)
        return rel, frame_from_tangent(A @ cov @ A.T, rel)

    def loop_error(self, k: int) -> float:
        """Loop factor k's whitened residual r = ‖Σ^{-1/2} e‖ at the current estimate (e in the
        tangent space of its measurement, Σ its covariance: the kernel's argument)."""
        if not 0 <= k < len(self._loops):
            raise ValueError(f"loop_error: no loop factor {k} (the graph has {len(self._loops)})")
        if k >= self._n_loops_optimized:
            raise ValueError(
                f"loop_error: loop factor {k} was added after the last optimize() (call it first)"
            )
        index, gaussian = self._loops[k]
        factor = self._graph.at(index)
        return float(np.linalg.norm(gaussian.whiten(factor.unwhitenedError(self._estimate))))

    def loop_inlier(self, k: int) -> bool:
        """Whether loop factor k lies in its kernel's inlier region after :meth:`optimize`: whitened
        residual r ≤ ``graph.kernel_scale``, where DCS still weights it fully and Cauchy by at least ½.
        With ``kernel: none`` the same threshold is applied, though such a factor is never down-weighted."""
        return self.loop_error(k) <= self.cfg.kernel_scale

    # --- checks -----------------------------------------------------------------------------------

    def _check_node(self, i, what: str) -> int:
        """``i`` as an int (a GTSAM key); ValueError naming ``what`` unless it is a node's index."""
        if not isinstance(i, (int, np.integer)) or not 0 <= i < len(self):
            raise ValueError(f"{what}: no node {i!r} (the graph has nodes 0..{len(self) - 1})")
        return int(i)

    def _check_solved(self, i, what: str) -> int:
        """:meth:`_check_node`, and the node must have been in the last :meth:`optimize`."""
        i = self._check_node(i, what)
        if i >= self._n_optimized:
            raise ValueError(f"{what}: node {i} was added after the last optimize() (call it first)")
        return i

    def _lm_marginals(self) -> gtsam.Marginals:
        if self._marginals is None:
            self._marginals = gtsam.Marginals(self._graph, self._estimate)
        return self._marginals
