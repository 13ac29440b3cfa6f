"""Block-tridiagonal band storage against dense matrices."""

import numpy as np

from hairport.solver.adaptation.problem import banded


def random_block_tridiagonal(n, rng, breaks=()):
    """SPD block-tridiagonal matrix as blocks and dense; no coupling after particles in ``breaks``."""
    diagonal = np.zeros((n, 3, 3))
    upper = rng.normal(size=(n, 3, 3))
    upper[-1] = 0.0
    for b in breaks:
        upper[b] = 0.0
    dense = np.zeros((3 * n, 3 * n))
    for i in range(n - 1):
        dense[3 * i:3 * i + 3, 3 * i + 3:3 * i + 6] = upper[i]
        dense[3 * i + 3:3 * i + 6, 3 * i:3 * i + 3] = upper[i].T
    for i in range(n):
        a = rng.normal(size=(3, 3))
        diagonal[i] = a @ a.T + 12.0 * np.eye(3)  # diagonally dominant: SPD
        dense[3 * i:3 * i + 3, 3 * i:3 * i + 3] = diagonal[i]
    return diagonal, upper, dense


def test_band_storage_matches_dense():
    rng = np.random.default_rng(0)
    diagonal, upper, dense = random_block_tridiagonal(7, rng)
    ab = banded.to_bands(diagonal, upper)
    for r in range(21):
        for c in range(r, min(21, r + banded.BANDS)):
            assert ab[banded.BANDS - 1 + r - c, c] == dense[r, c]
    assert np.abs(dense[np.triu_indices(21, banded.BANDS)]).max() == 0.0


def test_matvec_matches_dense():
    rng = np.random.default_rng(1)
    diagonal, upper, dense = random_block_tridiagonal(9, rng, breaks=(3,))
    x = rng.normal(size=(9, 3))
    np.testing.assert_allclose(banded.matvec(diagonal, upper, x).ravel(), dense @ x.ravel(), rtol=0, atol=1e-12)


def test_solve_with_fixed_unknowns_matches_dense_elimination():
    rng = np.random.default_rng(2)
    n = 8
    diagonal, upper, dense = random_block_tridiagonal(n, rng, breaks=(2, 5))
    rhs = rng.normal(size=(n, 3))
    fixed = rng.random((n, 3)) < 0.3
    values = rng.normal(size=(n, 3))
    x = banded.solve_with_fixed(diagonal, upper, rhs, fixed, values)
    f, free = fixed.ravel(), ~fixed.ravel()
    expected = values.ravel().copy()
    expected[free] = np.linalg.solve(dense[np.ix_(free, free)], rhs.ravel()[free] - dense[np.ix_(free, f)] @ values.ravel()[f])
    np.testing.assert_allclose(x.ravel(), expected, rtol=0, atol=1e-11)
    assert np.array_equal(x[fixed], values[fixed])


def test_independent_strands_solve_alone_as_together():
    """Zero coupling blocks make concatenated strands independent."""
    rng = np.random.default_rng(3)
    diagonal, upper, _ = random_block_tridiagonal(10, rng, breaks=(3,))
    rhs = rng.normal(size=(10, 3))
    none = np.zeros((10, 3), dtype=bool)
    together = banded.solve_with_fixed(diagonal, upper, rhs, none, rhs)
    first = banded.solve_with_fixed(diagonal[:4], upper[:4], rhs[:4], none[:4], rhs[:4])
    second = banded.solve_with_fixed(diagonal[4:], upper[4:], rhs[4:], none[4:], rhs[4:])
    np.testing.assert_allclose(together, np.concatenate([first, second]), rtol=0, atol=1e-13)
