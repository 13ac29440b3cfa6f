"""Energies of Eq. 7, 10 and 11 (solver/adaptation/problem/energies.py): hand-solvable cases and identities."""

import numpy as np
import pytest

from hairport.solver.adaptation.problem.energies import (
    EnergyWeights,
    clamped_direction_hessians,
    energy_terms,
    gradient,
    hessian,
    segment_operator,
)
from hairport.solver.model.hair import Hair
from tests.solver.hair_shapes import model_of, parallel_strands

#: the kNN count of these tests' shape models
K_NEIGHBOURS = 2


def test_segment_operator_differences():
    D = segment_operator(np.array([[0, 1], [1, 2]]), 3)
    np.testing.assert_array_equal(D.toarray(), [[-1, 1, 0], [0, -1, 1]])


def test_energies_vanish_at_source_and_scale_invariance_of_shape_term():
    hair = parallel_strands()
    model = model_of(hair, K_NEIGHBOURS)
    terms = energy_terms(model, hair.points, hair.points)
    assert terms.strand_shape < 1e-28 and terms.inter_strand < 1e-28 and terms.hair_body == 0.0
    # Eq. 7 only sees directions: a uniformly stretched hairstyle has zero shape energy
    assert energy_terms(model, 1.7 * hair.points, hair.points).strand_shape < 1e-26


def test_shape_energy_of_one_rotated_segment():
    strand = np.array([[0.0, 0, 0], [0.0, -0.01, 0]])
    hair = Hair.from_strands([strand])
    model = model_of(hair, k=1)
    angle = 0.3
    bent = np.array([[0.0, 0, 0], [0.01 * np.sin(angle), -0.01 * np.cos(angle), 0]])
    # |u - d|^2 = 2 - 2 cos(angle)
    assert energy_terms(model, bent, hair.points).strand_shape == pytest.approx(2 - 2 * np.cos(angle), rel=1e-12)


def test_gradient_matches_finite_differences_of_eq1():
    rng = np.random.default_rng(3)
    hair = parallel_strands(n_strands=3, n_points=5)
    model = model_of(hair, K_NEIGHBOURS)
    weights = EnergyWeights(alpha=3e3, beta=1e3)
    points = hair.points + 1e-3 * rng.normal(size=hair.points.shape)
    initial = hair.points + 1e-3 * rng.normal(size=hair.points.shape)
    gamma = rng.uniform(0.2, 1.0, size=hair.n_particles)

    def energy(p):
        return energy_terms(model, p, initial, gamma).total(weights)

    g = gradient(model, points, initial, weights, gamma)
    h = 1e-7
    numeric = np.zeros_like(points)
    for i in range(points.shape[0]):
        for c in range(3):
            e = np.zeros_like(points)
            e[i, c] = h
            numeric[i, c] = (energy(points + e) - energy(points - e)) / (2 * h)
    np.testing.assert_allclose(g, numeric, rtol=1e-5, atol=1e-4)


def test_hessian_is_exact_where_directions_match_the_source():
    """At zero direction residual (a stretched source) Gauss-Newton is the exact Hessian."""
    rng = np.random.default_rng(4)
    hair = parallel_strands(n_strands=3, n_points=5)
    model = model_of(hair, K_NEIGHBOURS)
    weights = EnergyWeights()
    points = 1.3 * hair.points  # same directions, longer segments
    initial = hair.points
    H = hessian(model, points, weights)
    step = 1e-7 * rng.normal(size=points.shape)
    numeric = gradient(model, points + step, initial, weights) - gradient(model, points - step, initial, weights)
    np.testing.assert_allclose(H @ (2 * step).ravel(), numeric.ravel(), rtol=1e-5, atol=1e-9)
    # symmetric positive definite (beta > 0)
    dense = H.toarray()
    np.testing.assert_allclose(dense, dense.T, atol=1e-9)
    assert np.linalg.eigvalsh(dense).min() > 0


def test_closed_form_clamped_hessians_match_an_eigensolver():
    rng = np.random.default_rng(0)
    u = rng.normal(size=(500, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    d = rng.normal(size=(500, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[:5], d[5:10] = u[:5], -u[5:10]  # parallel and opposite: the degenerate cases
    floor = rng.random(500) * 0.5
    c = np.sum(u * d, axis=1)
    outer = u[:, :, None] * d[:, None, :]
    exact = outer + outer.transpose(0, 2, 1) + c[:, None, None] * (np.eye(3) - 3 * u[:, :, None] * u[:, None, :])
    values, vectors = np.linalg.eigh(exact)
    reference = np.einsum("mij,mj,mkj->mik", vectors, np.maximum(values, -floor[:, None]), vectors)
    np.testing.assert_allclose(clamped_direction_hessians(u, d, floor), reference, rtol=0, atol=1e-13)
    assert np.linalg.eigvalsh(clamped_direction_hessians(u, d, floor)).min() >= -floor.max() - 1e-13
