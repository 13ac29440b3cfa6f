"""One outer iteration's QP of the active-set solver (:mod:`.active_set`), by a primal-dual active-set method.

Each outer iteration solves the QP

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

Convention: particles ``(N, 3) float64`` in meters, vectors particle-major.
"""

from __future__ import annotations

import functools

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from hairport.solver.adaptation.coupled.coupled_kernels import RotatedHessian, reference_pinned_solve
from hairport.solver.adaptation.loop.options import MAX_ACTIVE_SET_ROUNDS
from hairport.solver.adaptation.problem import banded
from hairport.solver.adaptation.problem.constraints import fixed_coordinates
from hairport.solver.adaptation.problem.strand_problem import NewtonSystem

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


