"""Compiled linear algebra of a coupled active-set round: ``H' y = rhs`` with pinned unknowns, by
conjugate gradients preconditioned by the strand-banded part of ``H'``.

``H' = R^T H R`` is the Newton Hessian of Eq. 1 in contact frames (:mod:`.numpy_level`): its
strand-banded part ``B`` rotated (``B' = R^T B R``, :mod:`.banded` block layout) plus the scalar
coupling ``C`` between particles of different strands (``2 alpha K^T G K`` minus its diagonal,
CSR) taken to world coordinates and back: ``H' y = B' y + R^T C R y``. Pinned unknowns (roots,
the normal components of active constraints) take given values and drop out.

The kernels are the compiled counterparts of the numpy reference at the end of this module
(:func:`reference_pinned_solve`: scipy's banded Cholesky, sparse products, the same
arithmetic and stopping rule), equal to it to rounding.

* :func:`rotate_blocks`: ``B'`` from ``B`` and the frames;
* :func:`factor_bands`: banded Cholesky ``U^T U`` of ``B'`` with the pinned rows and columns
  replaced by identity (LAPACK's ``dpbtrf`` upper factor; see :func:`factor_bands` for the
  storage), strand by strand (:func:`band_runs`);
* :func:`solve_bands`: the preconditioner ``(U^T U)^{-1} r``;
* :func:`rotated_product`: ``H' y``; :func:`sparse_product`: the same for a ``y`` that is zero
  but at a few particles (the pinned values);
* :func:`conjugate_gradients`: the preconditioned CG loop, from a warm start;
* :class:`RotatedHessian`: one QP's arrays, with the pinned solve and product built on them;
* :func:`reference_pinned_solve`, :func:`reference_product`: the numpy reference.

A CG step's product and preconditioner split the particles and the strands among numba's
threads (:func:`rotated_product`, :func:`solve_bands`; each output is summed in the
serial order, so the result does not depend on the thread count): at 300 guides of 100
particles a step took 3 ms on one core, and the two halves 1.0 + 0.6 ms on two against 2.0 +
0.95 (``bench/coarse_stage.py``). The dot products stay serial, for the same reason.

Convention: ``n`` particles, 3 unknowns each, particle-major; ``(n, 3)`` arrays float64 and
C-contiguous; ``(n, 3, 3)`` blocks act on a particle's 3 unknowns.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
import scipy.sparse as sp

from hairport.solver.adaptation.problem import banded
from hairport.solver.jit import kernel, parallel_kernel, prange, warms

#: super-diagonals of the strand-banded part (a particle's first unknown reaches the next particle's last)
BANDWIDTH = 5


@kernel
def rotate_blocks(R, diagonal, upper, rotated_diagonal, rotated_upper):
    """``B'``: ``R_i^T D_i R_i`` and ``R_i^T U_i R_{i+1}`` (all ``(n, 3, 3)``) into the two outputs."""
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


def band_runs(rotated_upper: np.ndarray) -> np.ndarray:
    """Where ``B'`` decouples: the particles that follow a zero off-diagonal block (strand ends).

    Parameters
    ----------
    rotated_upper : (n, 3, 3) float64

    Returns
    -------
    starts : (r + 1,) int64
        Run ``k`` is particles ``starts[k] .. starts[k + 1] - 1``: an independent block of the
        band (a strand, or a piece of one) that :func:`factor_bands` factorises on its own.
    """
    n = len(rotated_upper)
    ends = np.flatnonzero(~np.any(rotated_upper[: n - 1] != 0.0, axis=(1, 2))) + 1
    return np.concatenate([[0], ends, [n]]).astype(np.int64)


@kernel
def factor_bands(rotated_diagonal, rotated_upper, pinned, runs, which, factor):
    """Banded Cholesky ``U^T U`` of ``B'`` with the pinned unknowns' rows and columns as identity, run by run.

    Parameters
    ----------
    rotated_diagonal, rotated_upper : (n, 3, 3) float64
        ``B'``.
    pinned : (n, 3) bool
    runs : (r + 1,) int64
        :func:`band_runs` of ``rotated_upper``.
    which : (w,) int64
        The runs to factorise; the rows of the others are left as they are.
    factor : (3n, 6) float64
        Output, row ``q`` of ``U``: ``factor[q, m] = U[q, q + m]`` for ``m = 1 .. 5`` and the
        reciprocal pivot ``factor[q, 0] = 1 / U[q, q]`` (the solves multiply by it).

    Returns
    -------
    ok : bool
        False if a pivot was not positive (``B'`` not positive definite).
    """
    flat_pinned = pinned.ravel()
    ok = True
    for run in which:
        lo, hi = 3 * runs[run], 3 * runs[run + 1]
        for q in range(lo, hi):
            i, a = q // 3, q % 3
            for m in range(BANDWIDTH + 1):
                c = q + m
                j, b = c // 3, c % 3
                value = 0.0
                if c < hi and j <= i + 1 and not flat_pinned[q] and not flat_pinned[c]:
                    value = rotated_diagonal[i, a, b] if j == i else rotated_upper[i, a, b]
                factor[q, m] = value
            if flat_pinned[q]:
                factor[q, 0] = 1.0
        for q in range(lo, hi):
            pivot = factor[q, 0]
            if not pivot > 0.0:
                ok = False
                pivot = 1.0
            inverse = 1.0 / np.sqrt(pivot)
            factor[q, 0] = inverse
            for m in range(1, BANDWIDTH + 1):
                factor[q, m] *= inverse
            for m1 in range(1, min(BANDWIDTH, hi - 1 - q) + 1):
                u1 = factor[q, m1]
                if u1 != 0.0:
                    for m2 in range(m1, BANDWIDTH + 1):
                        factor[q + m1, m2 - m1] -= u1 * factor[q, m2]
    return ok


@kernel
def sparse_product(R, rotated_diagonal, rotated_upper, indptr, indices, data, rows, x, out):
    """``out = H' x`` for an ``x (n, 3)`` that is zero off ``rows (k,) int64``, in time linear in ``k``
    (``C`` is symmetric: row ``j`` of it lists the rows that column ``j`` reaches)."""
    n = x.shape[0]
    out[:] = 0.0
    for j in rows:
        w0 = R[j, 0, 0] * x[j, 0] + R[j, 0, 1] * x[j, 1] + R[j, 0, 2] * x[j, 2]
        w1 = R[j, 1, 0] * x[j, 0] + R[j, 1, 1] * x[j, 1] + R[j, 1, 2] * x[j, 2]
        w2 = R[j, 2, 0] * x[j, 0] + R[j, 2, 1] * x[j, 1] + R[j, 2, 2] * x[j, 2]
        for k in range(indptr[j], indptr[j + 1]):
            i = indices[k]
            for a in range(3):
                out[i, a] += data[k] * (R[i, 0, a] * w0 + R[i, 1, a] * w1 + R[i, 2, a] * w2)
        for a in range(3):
            for b in range(3):
                out[j, a] += rotated_diagonal[j, a, b] * x[j, b]
                if j > 0:
                    out[j - 1, a] += rotated_upper[j - 1, a, b] * x[j, b]
                if j < n - 1:
                    out[j + 1, a] += rotated_upper[j, b, a] * x[j, b]


@parallel_kernel
def rotated_product(R, rotated_diagonal, rotated_upper, indptr, indices, data, y, world, out):
    """``out = H' y = B' y + R^T C R y``; ``world (n, 3)`` is scratch. Particles split among
    numba's threads (each output row summed in one order whatever their number)."""
    n = y.shape[0]
    for i in prange(n):
        for a in range(3):
            world[i, a] = R[i, a, 0] * y[i, 0] + R[i, a, 1] * y[i, 1] + R[i, a, 2] * y[i, 2]
    for i in prange(n):
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
            out[i, a] = value


@parallel_kernel
def solve_bands(factor, pinned, runs, rhs, out):
    """``out = (U^T U)^{-1} rhs`` (:func:`factor_bands`), then 0 at ``pinned``; ``rhs, out (n, 3)``.
    Run by run (:func:`band_runs`: the factor has no entry across two), the runs split among
    numba's threads."""
    b = rhs.ravel()
    x = out.ravel()
    flat_pinned = pinned.ravel()
    for run in prange(len(runs) - 1):
        lo, hi = 3 * runs[run], 3 * runs[run + 1]
        for r in range(lo, hi):  # U^T z = b
            value = b[r]
            for m in range(min(BANDWIDTH, r - lo), 0, -1):
                value -= factor[r - m, m] * x[r - m]
            x[r] = value * factor[r, 0]
        for r in range(hi - 1, lo - 1, -1):  # U x = z
            value = x[r]
            for m in range(min(BANDWIDTH, hi - 1 - r), 0, -1):
                value -= factor[r, m] * x[r + m]
            x[r] = value * factor[r, 0]
        for r in range(lo, hi):
            if flat_pinned[r]:
                x[r] = 0.0


@kernel
def _dot(x, y):
    """``sum(x * y)`` over all entries."""
    flat_x = x.ravel()
    flat_y = y.ravel()
    total = 0.0
    for k in range(flat_x.size):
        total += flat_x[k] * flat_y[k]
    return total


@kernel
def _free_norm(x, pinned):
    """Euclidean norm of the entries of ``x`` off ``pinned``."""
    flat_x = x.ravel()
    flat_pinned = pinned.ravel()
    total = 0.0
    for k in range(flat_x.size):
        if not flat_pinned[k]:
            total += flat_x[k] * flat_x[k]
    return np.sqrt(total)


@kernel
def conjugate_gradients(R, rotated_diagonal, rotated_upper, indptr, indices, data, factor, runs, pinned, x, residual,
                        target, max_steps):
    """Preconditioned CG on the free unknowns of ``H' y = rhs``, in place on ``x`` and ``residual``.

    Parameters
    ----------
    R, rotated_diagonal, rotated_upper : (n, 3, 3) float64
    indptr, indices, data
        The coupling ``C`` (CSR, no diagonal).
    factor : (3n, 6) float64
        :func:`factor_bands` of ``B'`` with these pins.
    runs : (r + 1,) int64
        :func:`band_runs`: the product and the preconditioner split among threads by them.
    pinned : (n, 3) bool
    x : (n, 3) float64
        In: pinned values at ``pinned``, a first guess elsewhere. Out: the solution.
    residual : (n, 3) float64
        In: ``rhs - H' x``. Out: the same at the solution, at every unknown (the pinned ones'
        give the multipliers), kept up to date by the recursion.
    target : float
        Stop once the free residual's norm is at most this ...
    max_steps : int
        ... or after this many steps.

    Returns
    -------
    steps : int
        Counted like the reference: when it converges, one more than the products taken.
    """
    n = x.shape[0]
    world = np.empty((n, 3))
    product = np.empty((n, 3))
    z = np.empty((n, 3))
    solve_bands(factor, pinned, runs, residual, z)
    direction = z.copy()
    rz = _dot(residual, z)
    flat_x, flat_r, flat_z = x.ravel(), residual.ravel(), z.ravel()
    flat_d, flat_q = direction.ravel(), product.ravel()
    steps = 0
    for steps in range(1, max_steps + 1):
        if _free_norm(residual, pinned) <= target or rz <= 0.0:
            break
        rotated_product(R, rotated_diagonal, rotated_upper, indptr, indices, data, direction, world, product)
        step = rz / _dot(direction, product)
        for k in range(flat_x.size):
            flat_x[k] += step * flat_d[k]
            flat_r[k] -= step * flat_q[k]
        solve_bands(factor, pinned, runs, residual, z)
        rz_next = _dot(residual, z)
        ratio = rz_next / rz
        for k in range(flat_d.size):
            flat_d[k] = flat_z[k] + ratio * flat_d[k]
        rz = rz_next
    return steps


class RotatedHessian:
    """``H' = R^T H R`` of one QP as the kernels take it, prepared once per QP, and its pinned solves.

    It keeps the last band factor and its pins: the next round refactorises only the runs
    (:func:`band_runs`, strands) whose pins changed, and none for a repeated set of pins.

    Attributes
    ----------
    R : (n, 3, 3) float64
        Contact frames (identity for unconstrained particles).
    rotated_diagonal, rotated_upper : (n, 3, 3) float64
        ``B'``.
    coupling : (n, n) csr_matrix
        ``C``, symmetric, no diagonal.
    runs : (r + 1,) int64
        :func:`band_runs`.
    """

    def __init__(self, R: np.ndarray, rotated_diagonal: np.ndarray, rotated_upper: np.ndarray,
                 coupling: sp.csr_matrix):
        self.R = R
        self.rotated_diagonal = rotated_diagonal
        self.rotated_upper = rotated_upper
        self.coupling = coupling
        self.runs = band_runs(rotated_upper)
        self._factor = np.empty((3 * len(R), BANDWIDTH + 1))
        self._factor_pins: np.ndarray | None = None

    @classmethod
    def build(cls, R: np.ndarray, diagonal: np.ndarray, upper: np.ndarray, coupling: sp.csr_matrix) -> "RotatedHessian":
        """From the frames ``R (n, 3, 3)``, ``H``'s world-frame strand-banded blocks ``(n, 3, 3)`` and ``C (n, n)``."""
        R = np.ascontiguousarray(R, dtype=np.float64)
        rotated_diagonal, rotated_upper = np.empty_like(R), np.empty_like(R)
        rotate_blocks(R, np.ascontiguousarray(diagonal), np.ascontiguousarray(upper), rotated_diagonal, rotated_upper)
        return cls(R, rotated_diagonal, rotated_upper, sp.csr_matrix(coupling))

    def product(self, y: np.ndarray) -> np.ndarray:
        """``H' y`` for ``y (n, 3)``."""
        out, C = np.empty_like(y), self.coupling
        rotated_product(self.R, self.rotated_diagonal, self.rotated_upper, C.indptr, C.indices, C.data,
                         np.ascontiguousarray(y, dtype=np.float64), np.empty_like(y), out)
        return out

    def factor(self, pinned: np.ndarray) -> np.ndarray:
        """:func:`factor_bands` with these pins ``(n, 3) bool``, refactorising only the runs whose pins changed.

        Raises
        ------
        numpy.linalg.LinAlgError
            If ``B'`` with these pins is not positive definite.
        """
        if self._factor_pins is None:
            which = np.arange(len(self.runs) - 1)
        else:
            changed = np.flatnonzero(np.any(pinned != self._factor_pins, axis=1))
            which = np.unique(np.searchsorted(self.runs, changed, side="right") - 1)
        self._factor_pins = None  # unusable until factorised
        if not factor_bands(self.rotated_diagonal, self.rotated_upper, pinned, self.runs, which, self._factor):
            raise np.linalg.LinAlgError("the strand-banded Hessian is not positive definite")
        self._factor_pins = pinned.copy()
        return self._factor

    def pinned_solve(self, rhs: np.ndarray, pinned: np.ndarray, values: np.ndarray, guess: np.ndarray | None,
                     relative_tolerance: float, max_steps: int) -> tuple[np.ndarray, int, np.ndarray]:
        """``H' y = rhs`` for the free unknowns with ``y[pinned] = values[pinned]``, by CG from ``guess``.

        Parameters
        ----------
        rhs : (n, 3) float64
        pinned : (n, 3) bool
        values : (n, 3) float64
        guess : (n, 3) float64 or None
            First iterate of the free unknowns (0 by default).
        relative_tolerance : float
            CG stops once the free residual is this times the zero step's (``rhs - H' x`` with
            ``x`` the pinned values, 0 elsewhere) ...
        max_steps : int
            ... or after this many steps.

        Returns
        -------
        y : (n, 3) float64
        steps : int
        residual : (n, 3) float64
            ``rhs - H' y`` at every unknown.

        Raises
        ------
        numpy.linalg.LinAlgError
            If ``B'`` with these pins is not positive definite.
        """
        pinned = np.ascontiguousarray(pinned)
        factor = self.factor(pinned)
        start = np.where(pinned, values, 0.0)
        C = self.coupling
        residual = np.empty_like(start)
        sparse_product(self.R, self.rotated_diagonal, self.rotated_upper, C.indptr, C.indices, C.data,
                       np.flatnonzero(np.any(start != 0.0, axis=1)), start, residual)
        residual = rhs - residual
        target = relative_tolerance * _free_norm(residual, pinned)
        y = start
        if guess is not None:
            y = np.where(pinned, values, guess)
            residual = rhs - self.product(y)
        steps = conjugate_gradients(self.R, self.rotated_diagonal, self.rotated_upper, C.indptr, C.indices, C.data,
                                    factor, self.runs, pinned, y, residual, target, max_steps)
        return y, steps, residual

def reference_product(hessian: RotatedHessian, y: np.ndarray) -> np.ndarray:
    """:meth:`RotatedHessian.product` in numpy: ``B' y + R^T C R y`` for ``y (n, 3)``."""
    world = np.einsum("nij,nj->ni", hessian.R, y)
    coupled = np.einsum("nji,nj->ni", hessian.R, hessian.coupling @ world)
    return banded.matvec(hessian.rotated_diagonal, hessian.rotated_upper, y) + coupled


def _length(x: np.ndarray) -> float:
    """Euclidean norm of all entries. Not ``np.linalg.norm``: its BLAS dot wakes OpenBLAS's
    threads, which on a busy machine cost milliseconds a call."""
    return float(np.sqrt(np.einsum("ij,ij->", x, x)))


def reference_pinned_solve(hessian: RotatedHessian, rhs: np.ndarray, pinned: np.ndarray, values: np.ndarray,
                           guess: np.ndarray | None, relative_tolerance: float,
                           max_steps: int) -> tuple[np.ndarray, int, np.ndarray]:
    """:meth:`RotatedHessian.pinned_solve` in numpy (scipy's banded Cholesky, the whole band
    factorised every call): the tested reference of the kernels, and the path before them."""
    start = np.where(pinned, values, 0.0)
    residual = rhs - reference_product(hessian, start)
    target = relative_tolerance * _length(np.where(pinned, 0.0, residual))
    ab = banded.with_fixed_unknowns(banded.to_bands(hessian.rotated_diagonal, hessian.rotated_upper), pinned.ravel())
    factor = scipy.linalg.cholesky_banded(ab, lower=False, check_finite=False)

    def precondition(r: np.ndarray) -> np.ndarray:
        z = scipy.linalg.cho_solve_banded((factor, False), r.ravel(), check_finite=False).reshape(-1, 3)
        z[pinned] = 0.0
        return z

    y = start
    if guess is not None:
        y = np.where(pinned, values, guess)
        residual = rhs - reference_product(hessian, y)
    z = precondition(residual)
    direction = z.copy()
    rz = float(np.sum(residual * z))
    steps = 0
    for steps in range(1, max_steps + 1):
        if _length(np.where(pinned, 0.0, residual)) <= target or rz <= 0:
            break
        q = reference_product(hessian, direction)
        step = rz / float(np.sum(direction * q))
        y = y + step * direction
        residual -= step * q
        z = precondition(residual)
        rz_next = float(np.sum(residual * z))
        direction = z + (rz_next / rz) * direction
        rz = rz_next
    return y, steps, residual


@warms
def _warm() -> None:
    n = 4
    R = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    diagonal = np.broadcast_to(4.0 * np.eye(3), (n, 3, 3)).copy()
    upper = np.broadcast_to(-np.eye(3), (n, 3, 3)).copy()
    upper[1] = 0.0  # two strands of two particles, coupled at their tips
    coupling = sp.csr_matrix(([-0.5, -0.5], ([1, 3], [3, 1])), shape=(n, n))
    pinned = np.zeros((n, 3), dtype=bool)
    pinned[[0, 2]] = True
    hessian = RotatedHessian.build(R, diagonal, upper, coupling)
    hessian.pinned_solve(np.ones((n, 3)), pinned, np.zeros((n, 3)), None, 1e-6, 10)
    pinned[1, 0] = True
    hessian.pinned_solve(np.ones((n, 3)), pinned, np.ones((n, 3)), np.ones((n, 3)), 1e-6, 10)
    hessian.product(np.ones((n, 3)))
