"""Compiled linear algebra of a coupled active-set round: ``H' y = rhs`` with pinned unknowns, by
conjugate gradients preconditioned by the strand-banded part of ``H'``.

``H' = R^T H R`` is the Newton Hessian of Eq. 1 in contact frames (:mod:`.active_set`): its
strand-banded blocks, rotated (``rotated_diagonal``, ``rotated_upper``, :mod:`.banded` layout),
plus the scalar coupling ``C`` between particles of different strands
(``2 alpha K^T G K`` minus its diagonal, a CSR matrix) taken to world coordinates and back:
``H' y = B' y + R^T C R y``. Pinned unknowns (roots; active constraints' normal components)
take given values and drop out.

The kernels are the compiled counterparts of :func:`.active_set._pinned_solve`'s numpy
reference (the same arithmetic, the same stopping rule; they agree to rounding):

* :func:`factor_bands`: banded Cholesky ``B' = U^T U`` of the strand-banded part with the
  pinned rows and columns replaced by identity (LAPACK's ``dpbtrf`` upper factor, stored
  row-wise ``factor[r, m] = U[r, r + m]``), each run of rows the band decouples (a strand)
  factorised on its own;
* :func:`rotated_product`: ``H' y``;
* :func:`conjugate_gradients`: the preconditioned CG loop, from a warm start.

Convention: ``n`` particles, 3 unknowns each, particle-major; ``(n, 3)`` arrays are float64
C-contiguous, index arrays int64.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from hairport.solver.jit import kernel, warms

#: super-diagonals of the strand-banded part (a particle's unknowns reach the next particle's last one)
BANDWIDTH = 5


def band_runs(rotated_upper: np.ndarray) -> np.ndarray:
    """Row ranges where the strand-banded matrix decouples: the particles after a zero off-diagonal block.

    Parameters
    ----------
    rotated_upper : (n, 3, 3) float64
        ``upper[i]`` couples particle ``i`` with ``i + 1``; zero where a strand ends.

    Returns
    -------
    starts : (r + 1,) int64
        Run ``j`` is particles ``starts[j] .. starts[j + 1] - 1``: independent blocks of the
        band (each strand, or a piece of one), factorised and solved one by one.
    """
    n = len(rotated_upper)
    ends = np.flatnonzero(~np.any(rotated_upper[: n - 1] != 0.0, axis=(1, 2))) + 1
    return np.concatenate([[0], ends, [n]]).astype(np.int64)


@kernel
def rotate_blocks(R, diagonal, upper, rotated_diagonal, rotated_upper):
    """``R_i^T D_i R_i`` and ``R_i^T U_i R_{i+1}`` into the two ``(n, 3, 3)`` outputs."""
    n = diagonal.shape[0]
    for i in range(n):
        for a in range(3):
            for b in range(3):
                d = 0.0
                u = 0.0
                for c in range(3):
                    for e in range(3):
                        d += R[i, c, a] * diagonal[i, c, e] * R[i, e, b]
                        if i < n - 1:
                            u += R[i, c, a] * upper[i, c, e] * R[i + 1, e, b]
                rotated_diagonal[i, a, b] = d
                rotated_upper[i, a, b] = u


@kernel
def factor_bands(rotated_diagonal, rotated_upper, pinned, runs, factor):
    """Banded Cholesky of the strand-banded part with pinned unknowns as identity rows.

    Parameters
    ----------
    rotated_diagonal, rotated_upper : (n, 3, 3) float64
    pinned : (n, 3) bool
    runs : (r + 1,) int64
        :func:`band_runs`.
    factor : (3n, 6) float64
        Output: ``factor[r, m] = U[r, r + m]`` with ``B' = U^T U``.

    Returns
    -------
    ok : bool
        False if a pivot was not positive (the matrix is not positive definite).
    """
    flat_pinned = pinned.ravel()
    failed = np.zeros(len(runs) - 1, dtype=np.bool_)
    for run in range(len(runs) - 1):
        lo = 3 * runs[run]
        hi = 3 * runs[run + 1]
        for r in range(lo, hi):
            i, a = r // 3, r % 3
            for m in range(BANDWIDTH + 1):
                c = r + m
                value = 0.0
                j, b = c // 3, c % 3
                if c < hi and j <= i + 1 and not flat_pinned[r] and not flat_pinned[c]:
                    value = rotated_diagonal[i, a, b] if j == i else rotated_upper[i, a, b]
                factor[r, m] = value
            if flat_pinned[r]:
                factor[r, 0] = 1.0
        for r in range(lo, hi):
            pivot = factor[r, 0]
            if not pivot > 0.0:
                failed[run] = True
                pivot = 1.0
            pivot = np.sqrt(pivot)
            factor[r, 0] = pivot
            for m in range(1, BANDWIDTH + 1):
                factor[r, m] /= pivot
            for m1 in range(1, BANDWIDTH + 1):
                if r + m1 >= hi:
                    break
                u1 = factor[r, m1]
                if u1 != 0.0:
                    for m2 in range(m1, BANDWIDTH + 1):
                        factor[r + m1, m2 - m1] -= u1 * factor[r, m2]
    return not failed.any()


@kernel
def solve_bands(factor, runs, pinned, rhs, out):
    """``out = (U^T U)^{-1} rhs`` with ``out[pinned] = 0``, for ``rhs, out (n, 3)``."""
    b = rhs.ravel()
    x = out.ravel()
    flat_pinned = pinned.ravel()
    for run in range(len(runs) - 1):
        lo = 3 * runs[run]
        hi = 3 * runs[run + 1]
        for r in range(lo, hi):  # U^T z = b
            value = b[r]
            for m in range(1, BANDWIDTH + 1):
                if r - m < lo:
                    break
                value -= factor[r - m, m] * x[r - m]
            x[r] = value / factor[r, 0]
        for r in range(hi - 1, lo - 1, -1):  # U x = z
            value = x[r]
            for m in range(1, BANDWIDTH + 1):
                if r + m >= hi:
                    break
                value -= factor[r, m] * x[r + m]
            x[r] = value / factor[r, 0]
        for r in range(lo, hi):
            if flat_pinned[r]:
                x[r] = 0.0


@kernel
def rotated_product(R, rotated_diagonal, rotated_upper, indptr, indices, data, pinned, y, world, out):
    """``out = H' y`` (``B' y + R^T C R y``), zero at ``pinned``; ``world (n, 3)`` is scratch."""
    n = y.shape[0]
    for i in range(n):
        for a in range(3):
            world[i, a] = R[i, a, 0] * y[i, 0] + R[i, a, 1] * y[i, 1] + R[i, a, 2] * y[i, 2]
    for i in range(n):
        c0 = c1 = c2 = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            j = indices[k]
            c0 += data[k] * world[j, 0]
            c1 += data[k] * world[j, 1]
            c2 += data[k] * world[j, 2]
        for a in range(3):
            value = R[i, 0, a] * c0 + R[i, 1, a] * c1 + R[i, 2, a] * c2
            for b in range(3):
                value += rotated_diagonal[i, a, b] * y[i, b]
                if i < n - 1:
                    value += rotated_upper[i, a, b] * y[i + 1, b]
                if i > 0:
                    value += rotated_upper[i - 1, b, a] * y[i - 1, b]
            out[i, a] = 0.0 if pinned[i, a] else value


@kernel
def _dot(x, y):
    flat_x = x.ravel()
    flat_y = y.ravel()
    total = 0.0
    for k in range(flat_x.size):
        total += flat_x[k] * flat_y[k]
    return total


@kernel
def conjugate_gradients(R, rotated_diagonal, rotated_upper, indptr, indices, data, factor, runs, pinned, rhs, x,
                        relative_tolerance, max_steps, cold_residual_norm):
    """Preconditioned CG on the free unknowns of ``H' y = rhs``, in place on ``x``.

    Parameters
    ----------
    R, rotated_diagonal, rotated_upper : (n, 3, 3) float64
    indptr, indices, data
        The coupling ``C`` (CSR, int64 indices, no diagonal).
    factor, runs
        :func:`factor_bands` of the pinned strand-banded part.
    pinned : (n, 3) bool
    rhs : (n, 3) float64
    x : (n, 3) float64
        In: pinned values at ``pinned``, a first guess elsewhere. Out: the solution.
    relative_tolerance : float
        Stop once the residual is this times ``cold_residual_norm`` ...
    max_steps : int
        ... or after this many steps.
    cold_residual_norm : float
        The residual's norm from the zero guess (``rhs - H' x_pinned`` on the free unknowns).

    Returns
    -------
    steps : int
        Counted like the reference: one more than the products taken when converged.
    """
    n = x.shape[0]
    world = np.empty((n, 3))
    product = np.empty((n, 3))
    residual = np.empty((n, 3))
    z = np.empty((n, 3))
    rotated_product(R, rotated_diagonal, rotated_upper, indptr, indices, data, pinned, x, world, product)
    for i in range(n):
        for a in range(3):
            residual[i, a] = 0.0 if pinned[i, a] else rhs[i, a] - product[i, a]
    solve_bands(factor, runs, pinned, residual, z)
    direction = z.copy()
    rz = _dot(residual, z)
    target = relative_tolerance * cold_residual_norm
    flat_x, flat_r, flat_z = x.ravel(), residual.ravel(), z.ravel()
    flat_d, flat_q = direction.ravel(), product.ravel()
    steps = 0
    for steps in range(1, max_steps + 1):
        if np.sqrt(_dot(residual, residual)) <= target or rz <= 0.0:
            break
        rotated_product(R, rotated_diagonal, rotated_upper, indptr, indices, data, pinned, direction, world, product)
        step = rz / _dot(direction, product)
        for k in range(flat_x.size):
            flat_x[k] += step * flat_d[k]
            flat_r[k] -= step * flat_q[k]
        solve_bands(factor, runs, pinned, residual, z)
        rz_next = _dot(residual, z)
        ratio = rz_next / rz
        for k in range(flat_d.size):
            flat_d[k] = flat_z[k] + ratio * flat_d[k]
        rz = rz_next
    return steps


@dataclass(frozen=True, eq=False)
class RotatedHessian:
    """``H' = R^T H R`` of one QP for the kernels: the arrays they take, prepared once per QP.

    Attributes
    ----------
    R : (n, 3, 3) float64
        Contact frames (identity for unconstrained particles).
    rotated_diagonal, rotated_upper : (n, 3, 3) float64
    indptr, indices : int64
    data : float64
        The coupling ``C`` (CSR, no diagonal).
    runs : (r + 1,) int64
        :func:`band_runs`.
    """

    R: np.ndarray
    rotated_diagonal: np.ndarray
    rotated_upper: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    data: np.ndarray
    runs: np.ndarray

    @classmethod
    def build(cls, R: np.ndarray, diagonal: np.ndarray, upper: np.ndarray, coupling: sp.csr_matrix) -> "RotatedHessian":
        """From the world-frame blocks ``(n, 3, 3)`` of ``H``'s strand-banded part and the coupling ``(n, n)``."""
        R = np.ascontiguousarray(R, dtype=np.float64)
        rotated_diagonal, rotated_upper = np.empty_like(R), np.empty_like(R)
        rotate_blocks(R, np.ascontiguousarray(diagonal), np.ascontiguousarray(upper), rotated_diagonal, rotated_upper)
        return cls(R, rotated_diagonal, rotated_upper, coupling.indptr.astype(np.int64),
                   coupling.indices.astype(np.int64), np.ascontiguousarray(coupling.data, dtype=np.float64),
                   band_runs(rotated_upper))

    def product(self, y: np.ndarray) -> np.ndarray:
        """``H' y`` for ``y (n, 3)``."""
        out = np.empty_like(y)
        rotated_product(self.R, self.rotated_diagonal, self.rotated_upper, self.indptr, self.indices, self.data,
                        np.zeros(y.shape, dtype=np.bool_), np.ascontiguousarray(y), np.empty_like(y), out)
        return out

    def pinned_solve(self, rhs: np.ndarray, pinned: np.ndarray, values: np.ndarray, guess: np.ndarray | None,
                     relative_tolerance: float, max_steps: int) -> tuple[np.ndarray, int]:
        """``H' y = rhs`` for the free unknowns with ``y[pinned] = values[pinned]``, by CG from ``guess``.

        Parameters
        ----------
        rhs : (n, 3) float64
        pinned : (n, 3) bool
        values : (n, 3) float64
        guess : (n, 3) float64 or None
            First iterate of the free unknowns (0 by default).
        relative_tolerance, max_steps
            CG stops at this residual relative to the zero guess's, or after this many steps.

        Returns
        -------
        y : (n, 3) float64
        steps : int

        Raises
        ------
        numpy.linalg.LinAlgError
            If the strand-banded part is not positive definite.
        """
        n = len(rhs)
        factor = np.empty((3 * n, BANDWIDTH + 1))
        if not factor_bands(self.rotated_diagonal, self.rotated_upper, pinned, self.runs, factor):
            raise np.linalg.LinAlgError("the strand-banded Hessian is not positive definite")
        start = np.where(pinned, values, 0.0)
        cold = np.where(pinned, 0.0, rhs - self.product(start))
        y = start if guess is None else np.where(pinned, values, guess)
        steps = conjugate_gradients(self.R, self.rotated_diagonal, self.rotated_upper, self.indptr, self.indices,
                                    self.data, factor, self.runs, pinned, np.ascontiguousarray(rhs), y,
                                    relative_tolerance, max_steps, float(np.sqrt(_dot(cold, cold))))
        return y, steps


@warms("coupled active-set kernels")
def _warm() -> None:
    n = 4
    R = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    diagonal = np.broadcast_to(4.0 * np.eye(3), (n, 3, 3)).copy()
    upper = np.broadcast_to(-np.eye(3), (n, 3, 3)).copy()
    upper[1] = 0.0  # two strands of two particles
    coupling = sp.csr_matrix(([-0.5, -0.5], ([0, 2], [2, 0])), shape=(n, n))
    pinned = np.zeros((n, 3), dtype=bool)
    pinned[[0, 2]] = True
    hessian = RotatedHessian.build(R, diagonal, upper, coupling)
    hessian.pinned_solve(np.ones((n, 3)), pinned, np.zeros((n, 3)), np.ones((n, 3)), 1e-6, 10)
