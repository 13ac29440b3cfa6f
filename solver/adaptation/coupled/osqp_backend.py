"""The iterate-linearize-QP loop of Sec. 4.6, solved with OSQP (Eq. 1 under Eq. 12-13).

Each outer iteration linearises Eq. 7 (Gauss-Newton, see :mod:`.energies`) and freezes the
closest points and normals of Eq. 13 at the current iterate ``p``, and solves a convex QP
for the step ``delta`` (so that an already optimal hairstyle gives ``delta = 0`` exactly):

    min  1/2 delta^T P delta + g^T delta
    s.t. <n_i, delta_i> >= eps_c - s_i      for every free (non-root) particle i

with ``P`` the Gauss-Newton Hessian over the free particles, ``g`` the gradient at ``p``
and ``s_i`` the signed distance of particle i to the target. Roots (Eq. 12) are not
variables: they stay where the initial transfer put them. The constraints are those of
:mod:`.constraints`, shared with the active-set backend.

The step is then shortened by backtracking until Eq. 1's energy plus an l1 penalty on
violated clearance does not increase (Gauss-Newton's model is poor for segments that turn
far, and the linearised constraints are only local).

Convention: particles ``(N, 3) float64`` in meters; the QP vector is particle-major
(x, y, z of the first free particle, then of the second, ...).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from functools import partial

import numpy as np
import osqp
import scipy.sparse as sp

from hairport.solver.adaptation.loop.options import (
    BACKTRACK_FACTOR,
    INITIAL_RADIAL_DAMPING,
    MAX_BACKTRACKS,
    MERIT_PENALTY_FACTOR,
    SOLVE_STAGE,
    Cancelled,
    SolveOptions,
    SolveReport,
    adapt_damping,
)
from hairport.solver.adaptation.problem.constraints import (
    clearance_violation,
    free_coordinates,
    linearised_clearance,
    push_out_short,
)
from hairport.solver.adaptation.problem.energies import EnergyWeights, ShapeModel, energy_terms, gradient, hessian
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.progress import ProgressFn

#: this backend's name in :data:`.solve.QP_BACKENDS` and in its reports
BACKEND = "osqp"
#: OSQP's tolerance is at most this factor above the floor (options.osqp_eps_*) ...
QP_LOOSEST_EPS = 1e3
#: ... and at most this fraction (per meter of tolerance) of the previous step
QP_ACCURACY_PER_STEP = 1e-3


def _constraint_matrix(normals: np.ndarray) -> sp.csc_matrix:
    """Rows ``<n_i, delta_i>`` for ``(F, 3)`` normals, particle-major columns; explicit zeros
    are kept so that the pattern never changes."""
    f = len(normals)
    indptr = np.arange(3 * f + 1, dtype=np.int64)
    indices = np.repeat(np.arange(f, dtype=np.int64), 3)
    return sp.csc_matrix((normals.ravel(), indices, indptr), shape=(f, 3 * f))


def _merit(model, points, initial, weights, gamma, rest, distance, eps_c, penalty) -> float:
    """Eq. 1's energy (and the spacing term's) plus an l1 penalty on violated clearance (the line search's merit)."""
    violation = float(np.sum(clearance_violation(distance, eps_c)))
    return energy_terms(model, points, initial, gamma, rest, weights.spacing_band).total(weights) + penalty * violation


class _ReusedQP:
    """One OSQP workspace reused across outer iterations while the Hessian's sparsity pattern
    holds (set up again when it changes), warm-started from the previous iteration's duals."""

    def __init__(self, options: SolveOptions):
        self.options = options
        self.settings = dict(verbose=False, eps_abs=options.osqp_eps_abs, eps_rel=options.osqp_eps_rel,
                             max_iter=options.osqp_max_iter, polishing=False, warm_starting=True)
        self.solver: osqp.OSQP | None = None
        self.pattern: tuple[np.ndarray, np.ndarray] | None = None
        self.dual: np.ndarray | None = None

    def solve(self, P: sp.csc_matrix, q: np.ndarray, A: sp.csc_matrix, lower: np.ndarray, last_step: float):
        """The step ``x (3F,)`` of ``min 1/2 x^T P x + q^T x`` s.t. ``A x >= lower``, OSQP's result
        (status, iterations) and the constraints' duals."""
        upper = np.full(len(lower), np.inf)
        if self.solver is None or not (np.array_equal(self.pattern[0], P.indptr)
                                       and np.array_equal(self.pattern[1], P.indices)):
            self.solver = osqp.OSQP()
            self.solver.setup(P, q, A, lower, upper, **self.settings)
            self.pattern = (P.indptr.copy(), P.indices.copy())
        else:
            self.solver.update(q=q, l=lower, u=upper, Px=P.data, Ax=A.data)
        # the QP need only be as accurate as the step it yields is small: loose while the
        # hairstyle still moves by millimetres, tight (options.osqp_eps_*) near convergence
        options = self.options
        accuracy = min(QP_LOOSEST_EPS, max(1.0, QP_ACCURACY_PER_STEP * last_step / options.osqp_eps_abs))
        self.solver.update_settings(eps_abs=options.osqp_eps_abs * accuracy, eps_rel=options.osqp_eps_rel * accuracy)
        self.solver.warm_start(x=np.zeros(len(q)), y=self.dual if self.dual is not None else np.zeros(len(lower)))
        result = self.solver.solve(raise_error=False)
        if result.x is not None and np.all(np.isfinite(result.x)):
            self.dual = result.y
        return result


def solve_shape_adaptation(
    model: ShapeModel,
    initial: np.ndarray,
    fixed: np.ndarray,
    target: MeshQuery,
    weights: EnergyWeights = EnergyWeights(),
    options: SolveOptions = SolveOptions(),
    gamma: np.ndarray | None = None,
    start: np.ndarray | None = None,
    progress: ProgressFn | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> tuple[np.ndarray, SolveReport]:
    """Minimise Eq. 1 (and the spacing term when ``weights.spacing`` is not 0) under Eq. 12-13 by sequential QPs.

    Parameters
    ----------
    model : ShapeModel
        Source-only terms (segments, kNN Laplacian).
    initial : (N, 3) float64
        ``p-hat``: the initial transfer (hair-body reference, and the start by default).
    fixed : (N,) bool
        Particles that do not move (roots).
    target : MeshQuery
        The target body.
    weights : EnergyWeights
    options : SolveOptions
    gamma : (N,) float64, optional
        Eq. 21's weights.
    start : (N, 3) float64, optional
        First iterate (defaults to ``initial``).
    progress : ProgressFn, optional
        ``progress("solve", fraction, message)`` after every outer iteration.
    should_stop : callable() -> bool, optional
        Polled once per outer iteration; True raises :class:`Cancelled`.

    Returns
    -------
    points : (N, 3) float64
    report : SolveReport
        With the OSQP fields (``osqp_status``, ``osqp_iterations``).
    """
    began = time.perf_counter()
    points = np.array(initial if start is None else start, dtype=np.float64)
    free = np.flatnonzero(~fixed)
    report = SolveReport(backend=BACKEND)
    if len(free) == 0:
        report.converged = True
        return points, report
    qp = _ReusedQP(options)
    penalty = 0.0
    radial_damping = INITIAL_RADIAL_DAMPING
    last_step = np.inf
    free3 = free_coordinates(fixed)
    sd = target.signed_distance(points[free])
    rest = model.rest_lengths(initial) if weights.spacing else None
    merit = partial(_merit, model, initial=initial, weights=weights, gamma=gamma, rest=rest, eps_c=options.eps_c)
    for iteration in range(options.max_iterations):
        if should_stop is not None and should_stop():
            raise Cancelled("solve cancelled")
        H = hessian(model, points, weights, gamma, radial_damping, rest)[free3][:, free3]
        P = sp.triu(H, format="csc")
        P.sort_indices()
        q = gradient(model, points, initial, weights, gamma, rest)[free].ravel()
        # one half-space per free particle: without a broad phase every one is constrained
        _, lower = linearised_clearance(sd.distance, options.eps_c)
        result = qp.solve(P, q, _constraint_matrix(sd.normal), lower, last_step)
        status = str(result.info.status)
        if result.x is None or not np.all(np.isfinite(result.x)):
            raise RuntimeError(f"QP solver failed at outer iteration {iteration}: {status}")
        penalty = max(penalty, MERIT_PENALTY_FACTOR * float(np.max(np.abs(result.y), initial=0.0)))
        predicted = float(q @ result.x + 0.5 * result.x @ (H @ result.x))
        step = result.x.reshape(len(free), 3)
        points, sd, fraction, radial_damping = _backtrack(points, sd, free, step, target, merit, penalty, predicted,
                                                          radial_damping)
        last_step = fraction * float(np.max(np.linalg.norm(step, axis=1)))
        clearance = float(np.min(sd.distance))
        _record(report, iteration, fraction, last_step, status, int(result.info.iter), clearance)
        if progress is not None:
            progress(SOLVE_STAGE, (iteration + 1) / options.max_iterations,
                     f"iteration {iteration + 1}: max step {last_step:.2e} m")
        if last_step < options.step_tolerance and clearance >= options.eps_c - options.clearance_tolerance:
            report.converged = True
            break
    if not report.converged:
        distance = np.full(len(points), np.inf)
        distance[free] = sd.distance
        points, report.pushed_out = push_out_short(
            points, fixed, distance, target, options.eps_c, options.clearance_tolerance
        )
    report.seconds = time.perf_counter() - began
    return points, report


def _backtrack(points, sd, free, step, target, merit, penalty, predicted, radial_damping):
    """The QP's ``step (F, 3)`` shortened (by BACKTRACK_FACTOR, at most MAX_BACKTRACKS times) until the merit
    does not rise: the new points, their signed distances, the fraction taken and the adapted radial damping."""
    merit_now = merit(points, distance=sd.distance, penalty=penalty)
    fraction = 1.0
    for attempt in range(MAX_BACKTRACKS):
        trial = points.copy()
        trial[free] += fraction * step
        trial_sd = target.signed_distance(trial[free])
        merit_trial = merit(trial, distance=trial_sd.distance, penalty=penalty)
        if attempt == 0:
            radial_damping = float(adapt_damping(radial_damping, merit_trial - merit_now, predicted))
        if merit_trial <= merit_now:
            break
        fraction *= BACKTRACK_FACTOR
    return trial, trial_sd, fraction, radial_damping


def _record(report: SolveReport, iteration: int, fraction: float, max_step: float, status: str, qp_iterations: int,
            clearance: float) -> None:
    report.iterations = iteration + 1
    report.step_fractions.append(fraction)
    report.max_step.append(max_step)
    report.osqp_status.append(status)
    report.osqp_iterations.append(qp_iterations)
    report.min_clearance.append(clearance)
