"""The numpy level of the active-set loop (solver/adaptation/coupled/numpy_level.py): coupled strands as one
group, each backtracking on its share of the merit."""

import numpy as np
import pytest

from hairport.solver.adaptation.coupled.numpy_level import NumpyLevel
from hairport.solver.adaptation.loop.options import INITIAL_RADIAL_DAMPING, STALLED_ITERATIONS, SolveOptions
from hairport.solver.adaptation.problem.constraints import BodyDistance
from hairport.solver.adaptation.problem.energies import EnergyWeights
from hairport.solver.adaptation.problem.strand_problem import group_energies, problem_from_shape_model
from hairport.solver.adaptation.solve import solve_strands
from hairport.solver.mesh.query import MeshQuery
from tests.solver.hair_shapes import fine_problem, model_of, outward_strands, sphere_character, tilt_into_surface


@pytest.fixture(scope="module")
def sphere():
    source = sphere_character()
    return source, MeshQuery(source.vertices, source.faces)


def test_coupled_strands_are_one_group_whose_merit_their_shares_add_up_to(sphere):
    source, query = sphere
    hair = outward_strands(source, n_strands=8, n_points=10, seed=3)
    start = tilt_into_surface(hair, query, np.radians(95.0))
    problem = problem_from_shape_model(model_of(hair), hair.offsets, start, hair.is_root)
    options, weights = SolveOptions(eps_c=5e-4), EnergyWeights()
    level = NumpyLevel(problem, BodyDistance(query), weights, options)
    assert level.coupled and level.n_groups == 1 and level.n_strands == 8
    step = level.newton_step(np.array([0]), np.full(8, INITIAL_RADIAL_DAMPING))
    assert step.merit.shape == (1,) and step.strand_merit.shape == step.predicted.shape == (8,)
    np.testing.assert_array_equal(step.strands, np.arange(8))
    assert step.strand_merit.sum() == pytest.approx(step.merit[0], rel=1e-12)
    assert np.all(step.predicted <= 1e-12)  # the QP's step lowers every strand's model
    # the full step: every strand's merit share, the clearance penalty included
    merits = level.trial_merits(np.ones(8), np.zeros(8, dtype=bool))
    expected = group_energies(problem, level.trial, weights, problem.strand_of, 8, level.particle_penalty,
                              level.trial_dist, options.eps_c)
    np.testing.assert_allclose(merits, expected, rtol=1e-12)  # compiled: the sums in another order
    # strands 0 and 1 stay where they were, the others move: one group, not failed
    stays = np.arange(8) < 2
    before = level.points.copy()
    outcome = level.settle(stays)
    assert outcome.failed.tolist() == [False] and outcome.merit.shape == (1,)
    moved = np.linalg.norm(level.points - before, axis=1)
    assert moved[problem.strand_of < 2].max() == 0.0 and moved[problem.strand_of >= 2].max() > 1e-4
    assert outcome.max_step[0] == moved.max()


def test_uncoupled_strands_are_a_group_each(sphere):
    source, query = sphere
    hair = outward_strands(source, n_strands=5, n_points=8, seed=7)
    problem = fine_problem(hair, hair.points, np.ones(hair.n_particles), hair.points)
    level = NumpyLevel(problem, BodyDistance(query), EnergyWeights(), SolveOptions())
    assert not level.coupled and level.n_groups == level.n_strands == 5
    step = level.newton_step(np.array([1, 3]), np.full(5, INITIAL_RADIAL_DAMPING))
    np.testing.assert_array_equal(step.strands, [1, 3])
    np.testing.assert_array_equal(step.merit, step.strand_merit)


def test_a_group_stops_after_two_iterations_in_a_row_below_the_energy_tolerance(sphere):
    """With a tolerance no decrease can beat (the whole merit), every iteration is "small": the
    coupled loop stops after exactly STALLED_ITERATIONS of them, not at the first."""
    source, query = sphere
    hair = outward_strands(source, n_strands=20, n_points=10)
    start = tilt_into_surface(hair, query, np.radians(95.0))
    problem = problem_from_shape_model(model_of(hair), hair.offsets, start, hair.is_root)
    assert problem.coupled
    _, report = solve_strands(problem, BodyDistance(query), options=SolveOptions(energy_tolerance=1.0, eps_c=5e-4))
    assert report.converged and report.iterations == STALLED_ITERATIONS == 2
    _, loose = solve_strands(problem, BodyDistance(query), options=SolveOptions(energy_tolerance=0.0, eps_c=5e-4))
    assert loose.iterations > STALLED_ITERATIONS


def test_coupled_strands_backtrack_on_their_own_and_the_merit_never_rises(sphere):
    """Coupled strands share one QP but each backtracks on its share of the merit: strands
    that overshoot stay or step short while the others take their full step, and (with the
    penalty fixed once it stops growing) the merit falls every iteration."""
    source, query = sphere
    hair = outward_strands(source, n_strands=40, n_points=10, seed=3)
    start = tilt_into_surface(hair, query, np.radians(95.0))
    problem = problem_from_shape_model(model_of(hair), hair.offsets, start, hair.is_root)
    assert problem.coupled
    points, report = solve_strands(problem, BodyDistance(query), options=SolveOptions(max_iterations=40, eps_c=5e-4))
    merits = np.array(report.merit)
    assert len(merits) >= 5
    assert np.all(np.diff(merits[2:]) <= 1e-9 * merits[2:-1])
    assert min(report.step_fractions) < 1.0  # some strand backtracked ...
    assert report.max_step[-1] < report.max_step[0]
    sd = query.signed_distance(points[~problem.fixed])
    assert sd.distance.min() >= 5e-4 - 1e-5

