"""The banded kernels of one strand's system (solver/adaptation/fine/band_kernels.py) against solver/adaptation/problem/banded.py."""

import numpy as np
import pytest

from hairport.solver.adaptation.fine import band_kernels
from hairport.solver.adaptation.problem import banded
from tests.solver.adaptation.problem.test_banded import random_block_tridiagonal


@pytest.mark.parametrize("n", [1, 2, 8])
def test_pinned_band_cholesky_solve_matches_banded(n):
    rng = np.random.default_rng(3 + n)
    diagonal, upper, _ = random_block_tridiagonal(n, rng)
    rhs = rng.normal(size=(n, 3))
    pinned = rng.random((n, 3)) < 0.3
    pinned[0] = True
    values = rng.normal(size=(n, 3))
    expected = banded.solve_with_fixed(diagonal, upper, rhs, pinned, values)
    # the kernel's pinned solve as active_set_qp does it: residual of the pinned values, then the free unknowns
    start = np.where(pinned, values, 0.0)
    product = np.empty((n, 3))
    band_kernels.block_matvec(diagonal, upper, start, product)
    np.testing.assert_allclose(product, banded.matvec(diagonal, upper, start), rtol=0, atol=1e-13)
    x = np.where(pinned, 0.0, rhs - product).ravel()
    band = np.empty((3 * n, 6))
    band_kernels.pinned_band(diagonal, upper, pinned, band)
    assert band_kernels.band_cholesky(band)
    band_kernels.band_solve(band, x)
    np.testing.assert_allclose(start + x.reshape(n, 3), expected, rtol=0, atol=1e-12)


def test_band_cholesky_refuses_an_indefinite_matrix():
    rng = np.random.default_rng(4)
    diagonal, upper, _ = random_block_tridiagonal(4, rng)
    diagonal[2] *= -1.0
    band = np.empty((12, 6))
    band_kernels.pinned_band(diagonal, upper, np.zeros((4, 3), dtype=bool), band)
    assert not band_kernels.band_cholesky(band)
