"""Compiled kernels of one strand's block-tridiagonal system: products and the pinned banded Cholesky solve.

The per-strand counterpart of :mod:`.banded` (its numpy functions are the tested references):
a strand's ``m`` particles give ``3m`` unknowns, particle-major, and a symmetric matrix of 3x3
blocks on and next to the diagonal (``diagonal (m, 3, 3)``, ``upper (m, 3, 3)``: ``upper[i]``
couples particles ``i`` and ``i + 1``). Its band storage here is row-major per unknown:
``band[r, k] = A[r, r + k]``, ``k = 0 .. BAND_REACH``.

:mod:`.strand_kernels` compiles these into its own kernels, and numba's on-disk cache of a
kernel does not notice a change in another module: after editing this one, clear the cache
(``__pycache__/*.nbi``, ``*.nbc`` beside both modules) or touch strand_kernels.py.
"""

from __future__ import annotations

import numpy as np

from hairport.solver.jit import kernel, warms

#: super-diagonals a particle's 3 unknowns reach (the next particle's last unknown; as
#: :data:`.banded.BANDS` - 1)
BAND_REACH = 5


@kernel
def block_matvec(diagonal, upper, x, out):
    """``out = A x`` for a block-tridiagonal ``A`` (:func:`.banded.matvec`); ``x, out (m, 3)``."""
    m = len(x)
    for i in range(m):
        for a in range(3):
            value = diagonal[i, a, 0] * x[i, 0] + diagonal[i, a, 1] * x[i, 1] + diagonal[i, a, 2] * x[i, 2]
            if i + 1 < m:
                value += upper[i, a, 0] * x[i + 1, 0] + upper[i, a, 1] * x[i + 1, 1] + upper[i, a, 2] * x[i + 1, 2]
            if i > 0:
                value += upper[i - 1, 0, a] * x[i - 1, 0] + upper[i - 1, 1, a] * x[i - 1, 1] + upper[i - 1, 2, a] * x[i - 1, 2]
            out[i, a] = value


@kernel
def pinned_band(diagonal, upper, pinned, band):
    """Band storage of the block-tridiagonal matrix with pinned unknowns' rows and columns replaced by identity.

    Parameters
    ----------
    diagonal, upper : (m, 3, 3) float64
    pinned : (m, 3) bool
    band : (3m, 6) float64
        Receives ``band[r, k] = A[r, r + k]`` (:func:`.banded.with_fixed_unknowns` of :func:`.banded.to_bands`,
        row-major per unknown).
    """
    m = len(diagonal)
    band[:] = 0.0
    for i in range(m):
        for a in range(3):
            row = 3 * i + a
            if pinned[i, a]:
                band[row, 0] = 1.0
                continue
            for b in range(a, 3):
                if not pinned[i, b]:
                    band[row, b - a] = diagonal[i, a, b]
            if i + 1 < m:
                for b in range(3):
                    if not pinned[i + 1, b]:
                        band[row, 3 + b - a] = upper[i, a, b]


@kernel
def band_cholesky(band) -> bool:
    """``A = U^T U`` in place (``band[r, k] = U[r, r + k]`` after); False if ``A`` is not positive definite."""
    n = band.shape[0]
    for j in range(n):
        pivot = band[j, 0]
        if not pivot > 0.0:
            return False
        pivot = np.sqrt(pivot)
        band[j, 0] = pivot
        reach = min(BAND_REACH, n - 1 - j)
        for k in range(1, reach + 1):
            band[j, k] /= pivot
        for k in range(1, reach + 1):
            factor = band[j, k]
            if factor != 0.0:
                for step in range(k, reach + 1):
                    band[j + k, step - k] -= factor * band[j, step]
    return True


@kernel
def band_solve(band, x):
    """Solve ``U^T U x = b`` in place (``x (3m,)`` holds ``b``) with the factor of :func:`band_cholesky`."""
    n = band.shape[0]
    for j in range(n):
        value = x[j]
        for k in range(1, min(BAND_REACH, j) + 1):
            value -= band[j - k, k] * x[j - k]
        x[j] = value / band[j, 0]
    for j in range(n - 1, -1, -1):
        value = x[j]
        for k in range(1, min(BAND_REACH, n - 1 - j) + 1):
            value -= band[j, k] * x[j + k]
        x[j] = value / band[j, 0]


@warms
def _warm() -> None:
    """A 2-particle system with one pinned unknown through every kernel."""
    diagonal = np.broadcast_to(4.0 * np.eye(3), (2, 3, 3)).copy()
    upper = np.zeros((2, 3, 3))
    upper[0] = -np.eye(3)
    out = np.empty((2, 3))
    block_matvec(diagonal, upper, np.ones((2, 3)), out)
    pinned = np.zeros((2, 3), dtype=np.bool_)
    pinned[0, 0] = True
    band = np.empty((6, BAND_REACH + 1))
    pinned_band(diagonal, upper, pinned, band)
    band_cholesky(band)
    band_solve(band, np.ones(6))
