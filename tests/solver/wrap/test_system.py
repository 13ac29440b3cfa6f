"""Tests for solver/wrap/system.py: the normal equations of optimal-step NICP on a fixed pattern."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from hairport.solver.mesh.shells import edge_table
from hairport.solver.wrap.system import RIDGE, AmbergSystem
from tests.solver.wrap.conftest import sphere


def _explicit(points, edges, gamma, alpha, weights, beta, corners, bary):
    """``A`` written out as in Amberg et al.: the Kronecker product and the sparse D, D_L."""
    n = len(points)
    m = len(edges)
    incidence = sp.csr_matrix((np.r_[-np.ones(m), np.ones(m)], (np.r_[np.arange(m), np.arange(m)],
                                                                  np.r_[edges[:, 0], edges[:, 1]])), shape=(m, n))
    stiffness = sp.kron(incidence, sp.diags([1.0, 1.0, 1.0, gamma]))
    homogeneous = np.c_[points, np.ones(n)]
    d = sp.csr_matrix((homogeneous.ravel(), (np.repeat(np.arange(n), 4), np.arange(4 * n))), shape=(n, 4 * n))
    rows = np.repeat(np.arange(len(corners)), 4 * corners.shape[1])
    cols = (4 * corners[:, :, None] + np.arange(4)).ravel()
    values = (bary[:, :, None] * homogeneous[corners]).ravel()
    d_l = sp.csr_matrix((values, (rows, cols)), shape=(len(corners), 4 * n))
    w = sp.diags(weights)
    return (alpha ** 2 * stiffness.T @ stiffness + d.T @ w @ w @ d + beta ** 2 * d_l.T @ d_l
            + RIDGE * sp.identity(4 * n)), d, d_l


def _mesh():
    vertices, faces = sphere(1.0, 1)
    return vertices, faces, edge_table(faces).ends


def test_the_assembled_matrix_is_amberg_s():
    points, _, edges = _mesh()
    corners = np.array([[0, 1, 2], [5, 5, 7]])
    bary = np.array([[0.2, 0.3, 0.5], [0.5, 0.0, 0.5]])
    system = AmbergSystem(points, edges, 0.7, corners, bary)
    weights = np.linspace(0.0, 1.0, len(points))
    expected, d, d_l = _explicit(points, edges, 0.7, 3.0, weights, 2.0, corners, bary)
    np.testing.assert_allclose(system.matrix(3.0, weights, 2.0).toarray(), expected.toarray(), atol=1e-12)
    # the right-hand side, too
    rng = np.random.default_rng(0)
    targets, previous, landmark_targets = rng.normal(size=(len(points), 3)), rng.normal(size=(4 * len(points), 3)), \
        rng.normal(size=(2, 3))
    rhs = (d.T @ sp.diags(weights ** 2) @ targets + 4.0 * d_l.T @ landmark_targets + RIDGE * previous)
    np.testing.assert_allclose(system.rhs(weights, targets, previous, 2.0, landmark_targets), rhs, atol=1e-12)


def test_the_pattern_does_not_change_with_the_weights():
    points, _, edges = _mesh()
    system = AmbergSystem(points, edges, 1.0)
    stiff = system.matrix(10.0, np.ones(len(points)))
    soft = system.matrix(0.1, np.zeros(len(points)))  # zero weights stay explicit entries
    np.testing.assert_array_equal(stiff.indices, soft.indices)
    np.testing.assert_array_equal(stiff.indptr, soft.indptr)
    assert system.nnz == stiff.nnz


def test_identity_moves_nothing_and_a_global_affine_map_costs_no_stiffness():
    points, _, edges = _mesh()
    system = AmbergSystem(points, edges, 1.0)
    np.testing.assert_allclose(system.positions(system.identity()), points, atol=1e-15)
    linear = np.array([[1.1, 0.1, 0.0], [0.0, 0.9, 0.2], [0.05, 0.0, 1.2]])
    targets = points @ linear + [0.3, -0.2, 0.1]
    weights = np.ones(len(points))
    # at any stiffness the solve reproduces an affine map of the targets: its transforms are all equal
    for alpha in (0.1, 100.0):
        solved = spla.spsolve(system.matrix(alpha, weights), system.rhs(weights, targets, system.identity()))
        np.testing.assert_allclose(system.positions(solved), targets, atol=1e-6)


def test_stiffness_spreads_a_pull_and_landmarks_pull_their_point():
    points, _, edges = _mesh()
    corners, bary = np.array([[0, 0, 0]]), np.array([[1.0, 0.0, 0.0]])
    system = AmbergSystem(points, edges, 1.0, corners, bary)
    weights = np.ones(len(points))
    goal = points[0] + [0.0, 0.0, 0.5]
    solved = spla.spsolve(system.matrix(1.0, weights, 30.0),
                          system.rhs(weights, points, system.identity(), 30.0, goal[None]))
    solved = solved.reshape(-1, 3)
    np.testing.assert_allclose(system.landmark_positions(solved)[0], goal, atol=0.01)
    moved = np.linalg.norm(system.positions(solved) - points, axis=1)
    assert moved[0] > 0.49 and 0.0 < np.median(moved) < 0.2  # neighbours follow, less
