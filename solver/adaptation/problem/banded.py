"""Symmetric block-tridiagonal systems with 3x3 blocks, stored as LAPACK bands.

Convention: ``n`` particles along concatenated strands, 3 unknowns each, particle-major
(x0 y0 z0 x1 ...). The matrix is given by its diagonal blocks ``diagonal (n, 3, 3)`` and
the blocks right of the diagonal ``upper (n, 3, 3)``: ``upper[i]`` couples particle ``i``
(rows) with particle ``i + 1`` (columns); it is zero where ``i`` ends a strand, so strands
stay independent while all of them share one banded factorisation. Bandwidth: 5
super-diagonals. Storage follows ``scipy.linalg.cholesky_banded(lower=False)``:
``ab[BANDS - 1 + r - c, c] = A[r, c]`` for ``c - BANDS < r <= c``.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

#: rows of the band storage: the diagonal and 5 super-diagonals (a particle's 3 unknowns
#: reach the next particle's last unknown 5 columns away)
BANDS = 6


def to_bands(diagonal: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Band storage of the block-tridiagonal matrix.

    Parameters
    ----------
    diagonal : (n, 3, 3) float64
        Symmetric diagonal blocks.
    upper : (n, 3, 3) float64
        ``upper[i]`` = block (i, i+1); the last one is ignored.

    Returns
    -------
    ab : (6, 3n) float64
    """
    n = len(diagonal)
    ab = np.zeros((BANDS, 3 * n))
    base = 3 * np.arange(n)
    for a in range(3):
        for b in range(a, 3):
            ab[BANDS - 1 + a - b, base + b] = diagonal[:, a, b]
    if n > 1:
        for a in range(3):
            for b in range(3):
                ab[BANDS - 1 - (3 + b - a), base[1:] + b] = upper[:-1, a, b]
    return ab


def matvec(diagonal: np.ndarray, upper: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``A x`` for ``x (n, 3)``; returns ``(n, 3)``."""
    y = np.einsum("nij,nj->ni", diagonal, x)
    if len(x) > 1:
        y[:-1] += np.einsum("nij,nj->ni", upper[:-1], x[1:])
        y[1:] += np.einsum("nji,nj->ni", upper[:-1], x[:-1])
    return y


def with_fixed_unknowns(ab: np.ndarray, fixed: np.ndarray) -> np.ndarray:
    """Band storage with the rows and columns of ``fixed (3n,) bool`` unknowns replaced by identity."""
    size = ab.shape[1]
    columns = np.broadcast_to(np.arange(size), ab.shape)
    rows = columns + np.arange(BANDS)[:, None] - (BANDS - 1)
    touched = fixed[columns] | (fixed[np.maximum(rows, 0)] & (rows >= 0))
    out = np.where(touched, 0.0, ab)
    out[BANDS - 1, fixed] = 1.0
    return out


def solve_with_fixed(
    diagonal: np.ndarray, upper: np.ndarray, rhs: np.ndarray, fixed: np.ndarray, values: np.ndarray
) -> np.ndarray:
    """Solve ``A x = rhs`` for the free unknowns with ``x[fixed] = values[fixed]``.

    Parameters
    ----------
    diagonal, upper : (n, 3, 3) float64
        A symmetric positive definite block-tridiagonal ``A``.
    rhs : (n, 3) float64
    fixed : (n, 3) bool
    values : (n, 3) float64
        Values of the fixed unknowns (others ignored).

    Returns
    -------
    x : (n, 3) float64
    """
    pinned = np.where(fixed, values, 0.0)
    reduced = rhs - matvec(diagonal, upper, pinned)
    reduced[fixed] = pinned[fixed]
    ab = with_fixed_unknowns(to_bands(diagonal, upper), fixed.ravel())
    factor = scipy.linalg.cholesky_banded(ab, lower=False, check_finite=False)
    x = scipy.linalg.cho_solve_banded((factor, False), reduced.ravel(), check_finite=False)
    return x.reshape(-1, 3)
