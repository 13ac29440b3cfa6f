"""Tests for solver/wrap/factor.py: the sparse factorisation of the fitting matrix."""

from __future__ import annotations

import numpy as np
import pytest

from hairport.solver.mesh.shells import edge_table
from hairport.solver.wrap.factor import SymmetricFactor
from hairport.solver.wrap.system import AmbergSystem
from tests.solver.wrap.conftest import sphere


def test_solves_the_fitting_system_and_refactors():
    vertices, faces = sphere(1.0, 2)
    system = AmbergSystem(vertices, edge_table(faces).ends, 1.0)
    rng = np.random.default_rng(1)
    factor = SymmetricFactor()
    for alpha in (10.0, 0.5):
        weights = (rng.random(len(vertices)) > 0.2).astype(float)
        matrix = system.matrix(alpha, weights)
        rhs = rng.normal(size=(matrix.shape[0], 3))
        factor.factor(matrix)
        solution = factor.solve(rhs)
        assert solution.shape == rhs.shape
        assert np.abs(matrix @ solution - rhs).max() < 1e-8 * np.abs(rhs).max()
    assert factor.factorisations == 2


def test_a_solve_needs_a_factor():
    with pytest.raises(RuntimeError):
        SymmetricFactor().solve(np.zeros((4, 3)))
