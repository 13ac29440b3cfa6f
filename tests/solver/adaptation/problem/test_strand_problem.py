"""Eq. 1 over a set of strands (solver/adaptation/problem/strand_problem.py): layout, merit, derivatives."""

import numpy as np
import pytest
import scipy.sparse as sp

from hairport.solver.adaptation.problem.energies import EnergyWeights
from hairport.solver.adaptation.problem.spacing import EVEN_SPACING_WEIGHT, SPACING_BAND
from hairport.solver.adaptation.problem.strand_problem import (
    StrandProblem,
    compiled_newton_system,
    group_energies,
    newton_system,
    problem_from_shape_model,
    strand_energies,
)
from hairport.solver.model.hair import Hair
from tests.solver.hair_shapes import fine_problem, model_of, outward_strands, parallel_strands, sphere_character


def bent_strand_problem(features_shift=0.0):
    """One strand of 3 particles whose second segment turns 90 degrees from its source direction."""
    points = np.array([[0.0, 0.0, 0.0], [0.0, -0.01, 0.0], [0.01, -0.01, 0.0]])
    initial = points.copy()
    initial[2, 1] -= 0.002  # p-hat 2 mm from the tip
    problem = StrandProblem(
        np.array([0, 3]), np.tile([0.0, -1.0, 0.0], (3, 1)), initial, sp.identity(3, format="csr"),
        points + [features_shift, 0.0, 0.0], np.ones(3), np.array([True, False, False]),
    )
    return problem, points


def test_group_energies_of_a_hand_case():
    problem, points = bent_strand_problem(features_shift=-0.001)
    weights = EnergyWeights(alpha=3e3, beta=1e3)
    # Eq. 7: |u - d|^2 = 2 for the turned segment (it starts at particle 1); Eq. 10: 1 mm on every
    # particle, 3e3 * 1e-6 each; Eq. 11: 2 mm at the tip, 1e3 * 4e-6
    per_strand = group_energies(problem, points, weights, np.zeros(3, dtype=np.int64), 1)
    assert per_strand.tolist() == pytest.approx([2.0 + 3 * 3e-3 + 4e-3], rel=1e-12)
    per_particle = group_energies(problem, points, weights, np.arange(3), 3)
    assert per_particle.tolist() == pytest.approx([3e-3, 2.0 + 3e-3, 3e-3 + 4e-3], rel=1e-12)
    # the merit's clearance term: penalty times the shortfall below eps_c, never at the root
    distance = np.array([-1.0, 3e-4, 6e-4])
    merit = group_energies(problem, points, weights, np.arange(3), 3, penalty=10.0, distance=distance, eps_c=5e-4)
    np.testing.assert_allclose(merit - per_particle, [0.0, 10.0 * 2e-4, 0.0], rtol=1e-12, atol=1e-18)
    unpenalised = group_energies(problem, points, weights, np.arange(3), 3, penalty=0.0, distance=distance, eps_c=5e-4)
    np.testing.assert_array_equal(unpenalised, per_particle)


def test_layout_subset_and_coupling():
    hair = parallel_strands(n_strands=3, n_points=4)
    n = hair.n_particles
    problem = fine_problem(hair, hair.points, np.arange(n, dtype=float) + 1.0, hair.points + 1.0)
    assert (problem.n_particles, problem.n_strands) == (12, 3)
    np.testing.assert_array_equal(problem.strand_of, np.repeat([0, 1, 2], 4))
    np.testing.assert_array_equal(problem.segment_starts, [0, 1, 2, 4, 5, 6, 8, 9, 10])
    assert not problem.coupled  # K diagonal
    np.testing.assert_array_equal(problem.gram.diagonal(), (np.arange(n) + 1.0) ** 2)
    sub, index = problem.subset(np.array([0, 2]))
    np.testing.assert_array_equal(index, [0, 1, 2, 3, 8, 9, 10, 11])
    np.testing.assert_array_equal(sub.offsets, [0, 4, 8])
    np.testing.assert_array_equal(sub.initial, problem.initial[index])
    np.testing.assert_array_equal(sub.coupling.diagonal(), problem.coupling.diagonal()[index])
    np.testing.assert_array_equal(sub.fixed, [True, False, False, False] * 2)
    # one off-diagonal entry between strands couples them
    linked = StrandProblem(problem.offsets, problem.source_directions, problem.initial,
                           (problem.coupling + sp.csr_matrix(([0.5], ([0], [5])), shape=(n, n))).tocsr(),
                           problem.features, problem.gamma, problem.fixed)
    assert linked.coupled


def test_problem_from_shape_model():
    hair = parallel_strands(n_strands=3, n_points=4)
    model = model_of(hair, k=2)
    gamma = np.linspace(0.5, 1.0, hair.n_particles)
    problem = problem_from_shape_model(model, hair.offsets, hair.points + 0.01, hair.is_root, gamma)
    np.testing.assert_array_equal(problem.source_directions[model.segments[:, 0]], model.source_directions)
    np.testing.assert_array_equal(problem.source_directions[hair.offsets[1:] - 1], np.zeros((3, 3)))  # tips
    assert problem.coupling is model.K and problem.features is model.source_features
    np.testing.assert_array_equal(problem.gamma, gamma)
    assert problem.coupled  # Eq. 10's kNN of other strands
    default = problem_from_shape_model(model, hair.offsets, hair.points, hair.is_root)
    np.testing.assert_array_equal(default.gamma, np.ones(hair.n_particles))


def test_newton_system_at_the_source_has_zero_gradient():
    hair = Hair.from_strands([np.array([[0.0, 0, 0], [0.0, -0.01, 0], [0.0, -0.02, 0]])])
    problem = StrandProblem(hair.offsets, np.tile([0.0, -1.0, 0.0], (3, 1)), hair.points, sp.identity(3, format="csr"),
                            hair.points, np.ones(3), hair.is_root)
    system = newton_system(problem, hair.points, EnergyWeights(), np.zeros(3))
    np.testing.assert_array_equal(system.gradient, np.zeros((3, 3)))
    assert system.coupling is None  # K diagonal: the banded part is the whole Hessian


def test_gradient_matches_finite_differences():
    rng = np.random.default_rng(1)
    source_hair = outward_strands(sphere_character(), n_strands=4, n_points=6)
    points = source_hair.points + rng.normal(scale=1e-3, size=source_hair.points.shape)
    n = source_hair.n_particles
    K = sp.random(n, n, density=0.2, random_state=2, format="csr") + sp.identity(n, format="csr")
    problem = StrandProblem(source_hair.offsets, fine_problem(source_hair, points, np.ones(n), points).source_directions,
                            source_hair.points, K.tocsr(), rng.normal(scale=1e-3, size=(n, 3)), rng.random(n) + 0.5,
                            source_hair.is_root)
    weights = EnergyWeights()
    gradient = newton_system(problem, points, weights, np.zeros(n)).gradient
    group = np.zeros(n, dtype=np.int64)
    h = 1e-7
    numeric = np.zeros_like(points)
    for i in range(n):
        for c in range(3):
            plus, minus = points.copy(), points.copy()
            plus[i, c] += h
            minus[i, c] -= h
            numeric[i, c] = (group_energies(problem, plus, weights, group, 1)[0]
                             - group_energies(problem, minus, weights, group, 1)[0]) / (2 * h)
    np.testing.assert_allclose(gradient, numeric, rtol=1e-5, atol=1e-4)


def test_hessian_matches_finite_differences_of_the_gradient_where_convex():
    """Near the source no negative curvature is clamped: with no damping the model is the exact Hessian."""
    rng = np.random.default_rng(3)
    hair = outward_strands(sphere_character(), n_strands=3, n_points=5)
    points = hair.points + rng.normal(scale=1e-5, size=hair.points.shape)
    n = hair.n_particles
    problem = fine_problem(hair, hair.points, np.ones(n), hair.points)
    weights = EnergyWeights()
    system = newton_system(problem, points, weights, np.zeros(n))
    h = 1e-8
    for j in rng.choice(3 * n, size=10, replace=False):
        e = np.zeros((n, 3))
        e.ravel()[j] = 1.0
        numeric = (newton_system(problem, points + h * e, weights, np.zeros(n)).gradient
                   - newton_system(problem, points - h * e, weights, np.zeros(n)).gradient) / (2 * h)
        np.testing.assert_allclose(system.matvec(e), numeric, rtol=1e-4, atol=1e-2 * np.abs(numeric).max())



def test_coupled_hessian_matches_finite_differences_of_the_gradient_where_convex():
    """The kNN coupling (Eq. 10) enters the Newton model as the off-diagonal ``2 alpha K^T G K``,
    its diagonal with the strand-banded blocks."""
    rng = np.random.default_rng(4)
    hair = outward_strands(sphere_character(), n_strands=6, n_points=5)
    n = hair.n_particles
    gamma = rng.random(n) + 0.5
    problem = problem_from_shape_model(model_of(hair, k=3), hair.offsets, hair.points, hair.is_root, gamma)
    off_diagonal = problem.gram_off_diagonal
    assert problem.coupled and off_diagonal.nnz > 3 * n
    assert not off_diagonal.diagonal().any()
    np.testing.assert_allclose((off_diagonal + sp.diags(problem.gram.diagonal())).toarray(), problem.gram.toarray(),
                               rtol=0, atol=1e-15)
    points = hair.points + rng.normal(scale=1e-5, size=hair.points.shape)
    weights = EnergyWeights()
    system = newton_system(problem, points, weights, np.zeros(n))
    h = 1e-8
    for j in rng.choice(3 * n, size=10, replace=False):
        e = np.zeros((n, 3))
        e.ravel()[j] = 1.0
        numeric = (newton_system(problem, points + h * e, weights, np.zeros(n)).gradient
                   - newton_system(problem, points - h * e, weights, np.zeros(n)).gradient) / (2 * h)
        np.testing.assert_allclose(system.matvec(e), numeric, rtol=1e-4, atol=1e-2 * np.abs(numeric).max())


def coupled_problem_with_a_weld(rng: np.random.Generator) -> tuple[StrandProblem, np.ndarray, EnergyWeights]:
    """6 coupled strands of 9 particles, one segment welded, Eq. 21's gamma random, the spacing term on: the
    problem, an iterate 2 mm (rms) off the source and the weights."""
    hair = outward_strands(sphere_character(), n_strands=6, n_points=9, seed=5)
    points = hair.points.copy()
    points[3] = points[2] + 1e-12  # a segment degenerate in the source: welded
    hair = Hair(points, hair.offsets)
    moved = hair.points + rng.normal(scale=2e-3, size=hair.points.shape)
    problem = problem_from_shape_model(model_of(hair), hair.offsets, hair.points, hair.is_root,
                                       gamma=rng.uniform(0.5, 2.0, hair.n_particles))
    assert problem.coupled and not problem.source_directions[2].any()
    return problem, moved, EnergyWeights(spacing=EVEN_SPACING_WEIGHT, spacing_band=SPACING_BAND)


def test_the_compiled_strand_energies_of_a_coupled_problem_equal_the_reference():
    """Coupled ``K``, the spacing term, a welded segment, Eq. 21's gamma and the clearance penalty."""
    rng = np.random.default_rng(2)
    problem, moved, weights = coupled_problem_with_a_weld(rng)
    n = problem.n_particles
    distance = rng.uniform(-1e-3, 2e-3, n)
    merits = []
    for penalty, at in ((0.0, None), (7.0, distance)):
        compiled = strand_energies(problem, moved, weights, penalty, at, 5e-4)
        reference = group_energies(problem, moved, weights, problem.strand_of, problem.n_strands,
                                   np.full(n, penalty), at, 5e-4)
        np.testing.assert_allclose(compiled, reference, rtol=1e-12)
        merits.append(compiled)
    assert merits[1].sum() > merits[0].sum() + 1e-3  # some particles short of the clearance: penalised


def test_the_compiled_newton_system_of_a_coupled_problem_equals_the_reference():
    """Coupled ``K``, the spacing term, a welded segment, Eq. 21's gamma, each strand's own radial damping."""
    rng = np.random.default_rng(3)
    problem, moved, weights = coupled_problem_with_a_weld(rng)
    damping = rng.uniform(1e-4, 1.0, problem.n_strands)
    compiled = compiled_newton_system(problem, moved, weights, damping)
    reference = newton_system(problem, moved, weights, damping[problem.strand_of])
    scale = np.abs(reference.diagonal).max()
    for name in ("gradient", "diagonal", "upper"):
        np.testing.assert_allclose(getattr(compiled, name), getattr(reference, name), rtol=1e-12, atol=1e-12 * scale)
    assert compiled.coupling is not None and (compiled.coupling != reference.coupling).nnz == 0
    assert np.abs(reference.upper[2]).max() > 1e9  # the weld's spring is in it
