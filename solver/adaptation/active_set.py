"""Eq. 1 under Eq. 12-13 by sequential QPs, solved by a primal-dual active-set method with strand-banded factorisations.

The Newton Hessian of Eq. 1 is ``S + 2 alpha K^T G K + 2 beta G`` (``G = diag(gamma)``):
``S``, Eq. 7's per-segment 3x3 blocks (:func:`.energies.shape_blocks`), is block-tridiagonal
along each strand; ``K`` (Eq. 10) couples a particle with its kNN on other strands. Each
outer iteration solves the QP

    min  1/2 d^T H d + g^T d   s.t.  <n_i, d_i> >= eps_c - s_i  (particles near the body),  d_i = 0 (roots)

by a primal-dual active-set method (Hintermueller, Ito & Kunisch 2002): after rotating each
constrained particle into its ``(n, t1, t2)`` frame a constraint bounds one unknown, and
each active-set round is a linear solve with those unknowns pinned. The linear solve is a
conjugate-gradient method preconditioned by the strand-banded part of ``H`` (``S``, the
diagonal terms and the diagonal of ``K^T G K``), factorised by banded Cholesky
(:mod:`.banded`): exact, in one step, when ``K`` is diagonal (Eq. 14's fine level, whose
neighbours are fixed guides), a few dozen steps when strands are coupled.

Coupled rounds (the guides of the multi-scale solve, the global solve) run on compiled
kernels (:mod:`.coupled_kernels`, beside their numpy reference). Only the pins
change from one round to the next, so each round's CG starts from the previous solution and
refactorises only the strands whose pins changed; rounds whose active set is still changing
are solved loosely (:data:`SCREENING_CG_TOLERANCE`) and the set they settle on accurately;
an active set that comes back (inexact solves can cycle) makes the rounds accurate, and a
second cycle ends the QP. On request, coupled systems up to a size are solved exactly by a
sparse LU factorisation of ``R^T H R`` instead (:data:`DIRECT_SOLVE_MAX_PARTICLES`).

When no entry of ``K`` links two strands every strand is its own problem: each gets its own
backtracking line search, damping and convergence test, and leaves the loop when done.
Coupled problems solve one QP for all strands but still backtrack strand by strand, on each
strand's share of the merit (its particles' terms of Eq. 1, the coupling included): with one
step length for all, a few overshooting strands cut every step to a quarter or less, and at
10^6 particles (300 guides of 100) the guides ended the 30 iterations at merit 901 where
per-strand steps reach 888, 18 % faster. The constraints are those of :mod:`.constraints`,
shared with the OSQP backend.

Convention: particles ``(N, 3) float64`` in meters, strands in CSR layout (``offsets``),
vectors particle-major.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from hairport.solver.adaptation import banded
from hairport.solver.adaptation.constraints import BodyDistance, fixed_coordinates, linearised_clearance, push_out_short
from hairport.solver.adaptation.coupled_kernels import RotatedHessian, reference_pinned_solve
from hairport.solver.adaptation.energies import EnergyWeights
from hairport.solver.adaptation.fine_solve import pull_weights, solve_uncoupled
from hairport.solver.adaptation.options import (
    BACKTRACK_FACTOR,
    ENGINE_COMPILED,
    ENGINES,
    INITIAL_RADIAL_DAMPING,
    MAX_ACTIVE_SET_ROUNDS,
    MAX_BACKTRACKS,
    MERIT_PENALTY_FACTOR,
    SOLVE_STAGE,
    Cancelled,
    SolveOptions,
    SolveReport,
    adapt_damping,
    groups_done,
)
from hairport.solver.adaptation.strand_problem import NewtonSystem, StrandProblem, group_energies, newton_system
from hairport.solver.model.progress import ProgressFn

#: this backend's name in :data:`.coupled.QP_BACKENDS` and in its reports
BACKEND = "active-set"
#: conjugate gradients stop at this residual relative to the zero step's (the pinned values alone) ...
CG_RELATIVE_TOLERANCE = 1e-6
#: ... or at this one in the rounds of a coupled QP whose active set is still changing: their
#: solution only decides the next active set (its multipliers' and violations' signs), and the
#: set that settles is solved again to CG_RELATIVE_TOLERANCE (bench/coarse_stage.py at 10^5
#: particles: 478 CG steps in 71 rounds against 803 in 52 with every round accurate, the guides
#: within 1.2e-5 m of those rounds' result; 1e-2 took 520 steps in 104 rounds, 1e-4 558 in 72)
SCREENING_CG_TOLERANCE = 1e-3
#: ... or after this many steps
CG_MAX_STEPS = 1000
#: coupled systems of at most this many particles are solved by a sparse direct factorisation
#: (SuperLU) instead of conjugate gradients: by default none. ``K^T G K`` links a particle with
#: its neighbours' neighbours, so the factor fills in: a 300-guide coarse level of 1.5e4
#: particles factors into 6.4e6 entries in 0.9 s a round against 0.08 s for a numpy CG solve
#: (bench/coarse_stage.py). Below 2e3 particles the direct solves were as fast as numpy's CG,
#: but the compiled CG is faster at every size: a first QP of 50 / 200 / 500 / 2,000 / 4,000
#: coupled particles took 0.8 / 1.6 / 3.0 / 42 / 68 ms against 2.9 / 7.6 / 91 / 303 / 559 ms
#: direct (2026-11-25), and the cycle guard of :func:`solve_qp` stands in for the exactness.
DIRECT_SOLVE_MAX_PARTICLES = 0
#: how coupled systems beyond that size are solved: by the compiled kernels of
#: :mod:`.coupled_kernels` or by their numpy reference (scipy's banded Cholesky, sparse products)
LINEAR_SOLVERS = ("compiled", "numpy")


def normal_frames(normals: np.ndarray) -> np.ndarray:
    """Orthonormal frames ``(N, 3, 3)`` whose first column is each unit normal ``(N, 3)``."""
    axis = np.zeros_like(normals)
    axis[np.arange(len(normals)), np.argmin(np.abs(normals), axis=1)] = 1.0
    t1 = np.cross(normals, axis)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(normals, t1)
    return np.stack([normals, t1, t2], axis=2)


class Frames:
    """Per-particle rotations ``R_i`` (identity except at ``rows``), applied to ``(N, 3)`` arrays."""

    def __init__(self, n: int, rows: np.ndarray, normals: np.ndarray):
        self.n = n
        # near the body most particles are constrained: rotate all rows then (identity
        # elsewhere), which is cheaper than gathering and scattering a large subset
        self.dense = len(rows) > n // 2
        if self.dense:
            all_normals = np.zeros((n, 3))
            all_normals[rows] = normals
            R = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
            R[rows] = normal_frames(normals)
            self.rows = np.arange(n)
        else:
            R = normal_frames(normals)
            self.rows = rows
        self.R = R
        self.RT = np.ascontiguousarray(np.transpose(R, (0, 2, 1)))

    def all_rotations(self) -> np.ndarray:
        """``R_i`` of every particle ``(n, 3, 3)`` (identity off ``rows``)."""
        if self.dense:
            return self.R
        R = np.broadcast_to(np.eye(3), (self.n, 3, 3)).copy()
        R[self.rows] = self.R
        return R

    def to_local(self, x: np.ndarray) -> np.ndarray:
        """``R_i^T x_i``."""
        if self.dense:
            return np.einsum("nij,nj->ni", self.RT, x)
        y = x.copy()
        y[self.rows] = np.einsum("nij,nj->ni", self.RT, x[self.rows])
        return y

    def to_world(self, y: np.ndarray) -> np.ndarray:
        """``R_i y_i``."""
        if self.dense:
            return np.einsum("nij,nj->ni", self.R, y)
        x = y.copy()
        x[self.rows] = np.einsum("nij,nj->ni", self.R, y[self.rows])
        return x

    def rotate_blocks(self, diagonal: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Blocks of ``R^T H R``."""
        if self.dense:
            rotated_upper = np.zeros_like(upper)
            rotated_upper[:-1] = np.matmul(np.matmul(self.RT[:-1], upper[:-1]), self.R[1:])
            return np.matmul(np.matmul(self.RT, diagonal), self.R), rotated_upper
        rotated_diagonal = diagonal.copy()
        rotated_diagonal[self.rows] = np.matmul(np.matmul(self.RT, diagonal[self.rows]), self.R)
        rotated_upper = upper.copy()
        rotated = np.zeros(self.n, dtype=np.int64) - 1
        rotated[self.rows] = np.arange(len(self.rows))
        left = self.rows[self.rows < self.n - 1]  # block (i, i+1) gets R_i^T on the left
        rotated_upper[left] = np.matmul(self.RT[rotated[left]], rotated_upper[left])
        right = self.rows[self.rows > 0] - 1  # ... and R_{i+1} on the right
        rotated_upper[right] = np.matmul(rotated_upper[right], self.R[rotated[right + 1]])
        return rotated_diagonal, rotated_upper


def rotated_matrix(system: NewtonSystem, frames: Frames, rotated_diagonal, rotated_upper) -> sp.csr_matrix:
    """``H' = R^T H R`` as a ``(3N, 3N)`` sparse matrix (particle-major unknowns)."""
    n = frames.n
    R = frames.all_rotations()
    rows, cols = np.arange(n), np.arange(n)
    blocks = [rotated_diagonal]
    if n > 1:
        rows = np.concatenate([rows, rows[:-1], rows[1:]])
        cols = np.concatenate([cols, cols[1:], cols[:-1]])
        blocks += [rotated_upper[:-1], np.transpose(rotated_upper[:-1], (0, 2, 1))]
    if system.coupling is not None:
        # the coupling is a scalar per particle pair: its block (i, j) is c_ij R_i^T R_j
        coupling = system.coupling.tocoo()
        rows, cols = np.concatenate([rows, coupling.row]), np.concatenate([cols, coupling.col])
        blocks.append(coupling.data[:, None, None] * np.matmul(np.transpose(R[coupling.row], (0, 2, 1)), R[coupling.col]))
    entries = np.concatenate(blocks)
    scalar_rows = np.broadcast_to(3 * rows[:, None, None] + np.arange(3)[None, :, None], entries.shape)
    scalar_cols = np.broadcast_to(3 * cols[:, None, None] + np.arange(3)[None, None, :], entries.shape)
    return sp.csr_matrix((entries.ravel(), (scalar_rows.ravel(), scalar_cols.ravel())), shape=(3 * n, 3 * n))


def _direct_pinned_solve(matrix: sp.csr_matrix, rhs, pinned, values) -> np.ndarray:
    """:func:`_pinned_solve` by a sparse LU factorisation of the free unknowns' block of ``H'``."""
    start = np.where(pinned, values, 0.0).ravel()
    free = ~pinned.ravel()
    reduced = (rhs.ravel() - matrix @ start)[free]
    block = matrix[free][:, free].tocsc()
    # symmetric positive definite: a symmetric fill-reducing ordering and no pivoting
    factor = spla.splu(block, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    start[free] = factor.solve(reduced)
    return start.reshape(-1, 3)


def _pinned_solve(system: NewtonSystem, frames: Frames, rotated_diagonal, rotated_upper, rhs, pinned, values,
                  direct: bool = False) -> tuple[np.ndarray, int]:
    """Solve ``H' y = rhs`` (``H' = R^T H R``) for the free unknowns with ``y[pinned] = values[pinned]``.

    Returns the solution and the CG steps taken (0 when solved by ``direct`` factorisation,
    which a coupled system may ask for; an uncoupled one is always solved by one banded
    factorisation, a coupled one otherwise by the numpy CG from zero)."""
    if direct and system.coupling is not None:
        return _direct_pinned_solve(rotated_matrix(system, frames, rotated_diagonal, rotated_upper), rhs, pinned, values), 0
    if system.coupling is not None:
        hessian = RotatedHessian(frames.all_rotations(), rotated_diagonal, rotated_upper, system.coupling)
        y, steps, _ = reference_pinned_solve(hessian, rhs, pinned, values, None, CG_RELATIVE_TOLERANCE, CG_MAX_STEPS)
        return y, steps
    start = np.where(pinned, values, 0.0)
    residual = rhs - frames.to_local(system.matvec(frames.to_world(start)))
    residual[pinned] = 0.0
    ab = banded.with_fixed_unknowns(banded.to_bands(rotated_diagonal, rotated_upper), pinned.ravel())
    factor = scipy.linalg.cholesky_banded(ab, lower=False, check_finite=False)
    z = scipy.linalg.cho_solve_banded((factor, False), residual.ravel(), check_finite=False).reshape(-1, 3)
    z[pinned] = 0.0
    return start + z, 1


def solve_qp(
    system: NewtonSystem,
    fixed: np.ndarray,
    constrained: np.ndarray,
    normals: np.ndarray,
    lower: np.ndarray,
    active: np.ndarray,
    direct_max_particles: int | None = None,
    linear_solver: str = "compiled",
    warm_start: bool = True,
    screening: bool = True,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, int]:
    """``min 1/2 d^T H d + g^T d  s.t. <n_i, d_i> >= l_i (i constrained), d_i = 0 (i fixed)``.

    Parameters
    ----------
    system : NewtonSystem
        Positive definite ``H`` and ``g``.
    fixed, constrained : (N,) bool
    normals : (N, 3) float64
        Unit normals (rows of unconstrained particles unused).
    lower : (N,) float64
    active : (N,) bool
        Initial guess of the active constraints (e.g. the previous QP's).
    direct_max_particles : int, optional
        Coupled systems of at most this many particles are solved by sparse LU instead of
        conjugate gradients (:data:`DIRECT_SOLVE_MAX_PARTICLES` by default).
    linear_solver : str
        One of :data:`LINEAR_SOLVERS`: how larger coupled systems are solved.
    warm_start : bool
        Coupled: each round's CG starts from the previous round's solution (only the pins
        changed), not from zero.
    screening : bool
        Coupled: rounds whose active set is still changing solve to :data:`SCREENING_CG_TOLERANCE`
        only, and the set they settle on is solved again to :data:`CG_RELATIVE_TOLERANCE`;
        an active set met again (inexact solves can make the rounds cycle) makes every later
        round accurate, and a cycle among those ends the QP. False: every round is accurate.

    Returns
    -------
    step : (N, 3) float64
    multipliers : (N,) float64
        Zero off the active set.
    active : (N,) bool
    rounds, cg_steps : int
    """
    if linear_solver not in LINEAR_SOLVERS:
        raise ValueError(f"unknown linear solver {linear_solver!r}; expected one of {', '.join(LINEAR_SOLVERS)}")
    n = len(system.gradient)
    frames = Frames(n, np.flatnonzero(constrained), normals[constrained])
    limit = DIRECT_SOLVE_MAX_PARTICLES if direct_max_particles is None else direct_max_particles
    direct = n <= limit
    iterative = system.coupling is not None and not direct
    if iterative and linear_solver == "compiled":
        hessian = RotatedHessian.build(frames.all_rotations(), system.diagonal, system.upper, system.coupling)
        rotated_diagonal, rotated_upper = hessian.rotated_diagonal, hessian.rotated_upper
        pinned_solve = hessian.pinned_solve
    else:
        rotated_diagonal, rotated_upper = frames.rotate_blocks(system.diagonal, system.upper)
        if iterative:
            hessian = RotatedHessian(frames.all_rotations(), rotated_diagonal, rotated_upper, system.coupling)
            pinned_solve = functools.partial(reference_pinned_solve, hessian)
    rotated_gradient = frames.to_local(system.gradient)
    curvature = rotated_diagonal[:, 0, 0]
    active = active & constrained & ~fixed
    pinned = fixed_coordinates(fixed)
    values = np.zeros((n, 3))
    values[:, 0] = np.where(constrained, lower, 0.0)
    rounds = cg_steps = 0
    y = np.zeros((n, 3))
    multipliers = np.zeros(n)
    screened = screening and iterative
    accurate, forced, visited = not screened, False, set()
    for rounds in range(1, MAX_ACTIVE_SET_ROUNDS + 1):
        pinned[:, 0] = fixed | active
        if iterative:
            guess = y if warm_start and rounds > 1 else None
            tolerance = CG_RELATIVE_TOLERANCE if accurate else SCREENING_CG_TOLERANCE
            y, steps, rest = pinned_solve(-rotated_gradient, pinned, values, guess, tolerance, CG_MAX_STEPS)
            residual = -rest
        else:
            y, steps = _pinned_solve(system, frames, rotated_diagonal, rotated_upper, -rotated_gradient, pinned, values,
                                     direct)
            residual = frames.to_local(system.matvec(frames.to_world(y))) + rotated_gradient
        cg_steps += steps
        multipliers = np.where(active, residual[:, 0], 0.0)
        next_active = constrained & ~fixed & (multipliers + curvature * (values[:, 0] - y[:, 0]) > 0)
        if np.array_equal(next_active, active):
            if accurate:
                break
            accurate = True  # settled on screening solves: solve this set accurately
            continue
        if screened:
            visited.add(np.packbits(active).tobytes())
            if np.packbits(next_active).tobytes() in visited:  # a cycle
                if forced:
                    break
                forced = True
            accurate = forced
        active = next_active
    return frames.to_world(y), multipliers, active, rounds, cg_steps


def solve_strands(
    problem: StrandProblem,
    distance: BodyDistance,
    weights: EnergyWeights = EnergyWeights(),
    options: SolveOptions = SolveOptions(),
    start: np.ndarray | None = None,
    progress: ProgressFn | None = None,
    should_stop: Callable[[], bool] | None = None,
    engine: str = ENGINE_COMPILED,
) -> tuple[np.ndarray, SolveReport]:
    """Minimise Eq. 1 under Eq. 12-13 by sequential QPs (Sec. 4.6).

    Each outer iteration: the projected-Newton QP (:func:`solve_qp`), then backtracking on
    Eq. 1 plus an l1 penalty on clearance short of ``eps_c``, with a second-order correction
    (particles a step leaves short of ``eps_c`` are projected back out along the normal:
    the linearised half-spaces ignore the body's curvature, and without it the loop zig-zags
    along the surface); each strand backtracks on its own share of the merit, and a strand
    whose every trial raised it stays where it is. Uncoupled strands each run this loop on their own, with their own
    merit penalty (so a strand's result does not depend on the strands solved with it); with
    a diagonal ``K`` the compiled loop of :mod:`.fine_solve` runs it unless ``engine`` asks
    for this numpy code, its reference.

    A group stops when no particle moved more than ``step_tolerance`` or its merit fell by
    less than ``energy_tolerance`` (relative) in :data:`.options.STALLED_ITERATIONS`
    iterations in a row, with its clearance kept. An uncoupled strand also stops after one
    such iteration when its QP predicted a decrease below the tolerance too (the model agrees
    the minimum is near), and when no trial of its line search lowered the merit it stays where
    it is, which counts as such an iteration.

    Parameters
    ----------
    problem : StrandProblem
    distance : BodyDistance
        Over the target body.
    weights : EnergyWeights
    options : SolveOptions
        ``eps_c``, ``max_iterations``, ``step_tolerance``, ``clearance_tolerance``.
    start : (N, 3) float64, optional
        First iterate (``problem.initial`` by default).
    progress : ProgressFn, optional
        ``progress("solve", fraction, message)`` after every outer iteration.
    should_stop : callable() -> bool, optional
        Polled once per outer iteration; True raises :class:`.options.Cancelled`.
    engine : str
        One of :data:`.options.ENGINES`: ``"compiled"`` (a diagonal ``K`` only; others take
        the numpy path) or ``"numpy"``.

    Returns
    -------
    points : (N, 3) float64
    report : SolveReport
        With the active-set fields (``groups``, ``active_set_rounds``, ...).
    """
    if engine not in ENGINES:
        raise ValueError(f"unknown engine {engine!r}; expected one of {', '.join(ENGINES)}")
    if engine == ENGINE_COMPILED and pull_weights(problem.coupling) is not None:
        points, report = solve_uncoupled(problem, distance, weights, options, start, progress, should_stop)
        report.backend = BACKEND
        return points, report
    began = time.perf_counter()
    points = np.array(problem.initial if start is None else start, dtype=np.float64)
    coupled = problem.coupled
    n_groups = 1 if coupled else problem.n_strands
    report = SolveReport(backend=BACKEND, groups=n_groups)
    # the damping is per strand, coupled or not: one strand that turns far must not stiffen
    # every other strand's segments
    damping = np.full(problem.n_strands, INITIAL_RADIAL_DAMPING)
    active_set = np.zeros(problem.n_particles, dtype=bool)
    open_groups = np.arange(n_groups)
    small_steps = np.zeros(n_groups, dtype=np.int64)  # consecutive iterations below the energy tolerance
    dist_all, normal_all, near_all = distance(points)
    penalty = np.zeros(n_groups)  # the merit's l1 penalty, each group's own running maximum
    for iteration in range(options.max_iterations):
        if len(open_groups) == 0:
            break
        if should_stop is not None and should_stop():
            raise Cancelled("solve cancelled")
        if coupled:
            sub, index = problem, np.arange(problem.n_particles)
            group = np.zeros(problem.n_particles, dtype=np.int64)
        else:
            sub, index = problem.subset(open_groups)
            group = sub.strand_of
        k = len(open_groups)
        p = points[index]
        dist, normal, near = dist_all[index], normal_all[index], near_all[index]
        strands = np.arange(problem.n_strands) if coupled else open_groups
        system = newton_system(sub, p, weights, damping[strands][sub.strand_of])
        constrained, lower = linearised_clearance(dist, options.eps_c, sub.fixed, near)
        step, multipliers, active, rounds, cg_steps = solve_qp(
            system, sub.fixed, constrained, normal, lower, active_set[index]
        )
        active_set[index] = active
        report.active_set_rounds.append(rounds)
        report.cg_steps.append(cg_steps)
        report.open_groups.append(k)
        largest = np.zeros(k)
        np.maximum.at(largest, group, np.abs(multipliers))
        penalty[open_groups] = np.maximum(penalty[open_groups], MERIT_PENALTY_FACTOR * largest)
        particle_penalty = penalty[open_groups][group]
        merit_now = group_energies(sub, p, weights, group, k, particle_penalty, dist, options.eps_c)
        model_change = np.sum(step * (system.gradient + 0.5 * system.matvec(step)), axis=1)
        strand_predicted = np.bincount(sub.strand_of, model_change, minlength=sub.n_strands)
        # uncoupled, a group is a strand: the per-strand merits are the group merits
        strand_merit_now = merit_now if not coupled else group_energies(
            sub, p, weights, sub.strand_of, sub.n_strands, particle_penalty, dist, options.eps_c)

        # the line search backtracks each strand on its own merit, coupled or not: one strand whose
        # Newton step overshoots must not shorten every other strand's step (coupled, a strand's
        # merit holds its share of the coupling, and a strand whose neighbours' backtracking
        # raised it backtracks in turn; all strands' merits down means the total is down)
        fraction = np.ones(sub.n_strands)
        accepted = np.zeros(sub.n_strands, dtype=bool)
        trial = p.copy()
        trial_dist, trial_normal, trial_near = dist.copy(), normal.copy(), near.copy()
        for attempt in range(MAX_BACKTRACKS):
            todo = ~accepted[sub.strand_of]
            moved = p[todo] + fraction[sub.strand_of][todo, None] * step[todo]
            d, nrm, nr = distance(moved)
            short = nr & (d < options.eps_c) & ~sub.fixed[todo]
            if short.any():
                moved[short] += (options.eps_c - d[short])[:, None] * nrm[short]
                d2, nrm2, nr2 = distance(moved[short])
                d[short], nrm[short], nr[short] = d2, nrm2, nr2
            trial[todo] = moved
            trial_dist[todo], trial_normal[todo], trial_near[todo] = d, nrm, nr
            strand_merit_trial = group_energies(
                sub, trial, weights, sub.strand_of, sub.n_strands, particle_penalty, trial_dist, options.eps_c)
            if attempt == 0:
                damping[strands] = adapt_damping(
                    damping[strands], strand_merit_trial - strand_merit_now, strand_predicted)
            lowered = strand_merit_trial <= strand_merit_now
            accepted = lowered if coupled else accepted | lowered
            if accepted.all() or attempt == MAX_BACKTRACKS - 1:
                break
            fraction = np.where(accepted, fraction, BACKTRACK_FACTOR * fraction)
        # a strand whose every trial raised its merit stays where it is (and, uncoupled, the
        # iteration counts towards its stall): the shortest step taken anyway made such strands
        # oscillate until the cap
        stays = ~accepted
        if stays.any():
            stay = stays[sub.strand_of]
            trial[stay], trial_dist[stay], trial_normal[stay], trial_near[stay] = p[stay], dist[stay], normal[stay], near[stay]
            fraction = np.where(stays, 0.0, fraction)
            strand_merit_trial = np.where(stays, strand_merit_now, strand_merit_trial) if not coupled else group_energies(
                sub, trial, weights, sub.strand_of, sub.n_strands, particle_penalty, trial_dist, options.eps_c)
        failed = stays if not coupled else np.array([fraction.max() == 0.0])
        merit_trial = np.array([strand_merit_trial.sum()]) if coupled else strand_merit_trial
        report.merit.append(float(merit_trial.sum()))
        report.step_fractions.append(float(fraction.min(initial=1.0)))
        points[index] = trial
        dist_all[index], normal_all[index], near_all[index] = trial_dist, trial_normal, trial_near
        moved_by = np.linalg.norm(trial - p, axis=1)
        max_step = np.zeros(k)
        np.maximum.at(max_step, group, moved_by)
        shortfall = np.full(k, -np.inf)
        np.maximum.at(shortfall, group, np.where(sub.fixed, -np.inf, options.eps_c - trial_dist))
        done, small_steps[open_groups] = groups_done(
            options, merit_now, merit_trial, failed, small_steps[open_groups], max_step, shortfall,
            # one small decrease suffices where the QP's model also predicted a small one
            None if coupled else strand_predicted)
        report.converged_groups += int(done.sum())
        report.max_step.append(float(max_step.max(initial=0.0)))
        report.min_clearance.append(float(np.min(np.where(sub.fixed, np.inf, trial_dist), initial=np.inf)))
        open_groups = open_groups[~done]
        report.iterations = iteration + 1
        if progress is not None:
            progress(
                SOLVE_STAGE,
                (iteration + 1) / options.max_iterations,
                f"iteration {iteration + 1}: max step {report.max_step[-1]:.2e} m, {len(open_groups)} open",
            )
    report.converged = len(open_groups) == 0
    if not report.converged:
        points, report.pushed_out = push_out_short(
            points, problem.fixed, dist_all, distance.query, options.eps_c, options.clearance_tolerance
        )
    report.seconds = time.perf_counter() - began
    return points, report
