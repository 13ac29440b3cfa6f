"""The active-set solver's outer loop (solver/adaptation/loop/active_set.py): fixed points, push-out, line search, stopping, agreement with OSQP."""

import numpy as np
import pytest

from hairport.solver.adaptation.coupled.osqp_backend import solve_shape_adaptation
from hairport.solver.adaptation.loop.active_set import BACKEND, NewtonStep, line_search
from hairport.solver.adaptation.loop.options import (
    BACKTRACK_FACTOR,
    DAMPING_FACTOR,
    INITIAL_RADIAL_DAMPING,
    MAX_BACKTRACKS,
    Cancelled,
    SolveOptions,
)
from hairport.solver.adaptation.problem.constraints import BodyDistance
from hairport.solver.adaptation.problem.energies import EnergyWeights, ShapeModel, segment_operator
from hairport.solver.adaptation.problem.strand_problem import problem_from_shape_model
from hairport.solver.adaptation.solve import solve_strands
from hairport.solver.mesh.query import MeshQuery
from tests.solver.hair_shapes import fine_problem, model_of, outward_strands, sphere_character, tilt_into_surface

#: both loops converge linearly once particles slide along the faceted surface (the half-spaces
#: carry no curvature); 1e-7 m steps are reached in < 100 iterations by both
TIGHT = SolveOptions(max_iterations=200, step_tolerance=1e-7, osqp_eps_abs=1e-10, osqp_eps_rel=1e-10)


@pytest.fixture(scope="module")
def sphere():
    source = sphere_character()
    return source, MeshQuery(source.vertices, source.faces)


def shape_model_of(problem, source_points):
    """The same energy as a :class:`ShapeModel` for the OSQP reference."""
    seg = problem.segment_starts
    segments = np.stack([seg, seg + 1], axis=1)
    return ShapeModel(segments, segment_operator(segments, problem.n_particles), problem.source_directions[seg],
                      problem.coupling, problem.features,
                      np.linalg.norm(source_points[seg + 1] - source_points[seg], axis=1))


def test_source_is_a_fixed_point(sphere):
    source, query = sphere
    hair = outward_strands(source, n_strands=20, n_points=8)
    problem = problem_from_shape_model(model_of(hair), hair.offsets, hair.points, hair.is_root)
    points, report = solve_strands(problem, BodyDistance(query))
    assert report.converged and report.iterations == 1
    assert np.abs(points - hair.points).max() < 1e-12


def test_penetrating_start_is_pushed_out_with_clearance_and_roots_stay(sphere):
    source, query = sphere
    hair = outward_strands(source, n_strands=40, n_points=10)
    start = tilt_into_surface(hair, query, np.radians(95.0))
    assert (query.signed_distance(start[~hair.is_root]).distance < 0).sum() > 50
    problem = problem_from_shape_model(model_of(hair), hair.offsets, start, hair.is_root)
    points, report = solve_strands(problem, BodyDistance(query), options=SolveOptions(eps_c=5e-4))
    assert query.signed_distance(points[~hair.is_root]).distance.min() >= 5e-4 - 1e-5
    np.testing.assert_array_equal(points[hair.is_root], start[hair.is_root])


@pytest.mark.parametrize("spacing", [0.0, 1.0], ids=["eq1", "spacing"])
def test_fine_solve_matches_osqp_reference_on_single_strands(sphere, spacing):
    """Issue 3: a few strands with fixed neighbours (Eq. 14), each solved alone by the OSQP loop
    (issue 16: with the spacing term too, which the OSQP loop takes from the ShapeModel's rest lengths)."""
    source, query = sphere
    hair = outward_strands(source, n_strands=4, n_points=12, seed=5)
    start = tilt_into_surface(hair, query, np.radians(92.0))  # strands dip into the sphere
    assert (query.signed_distance(start[~hair.is_root]).distance < 5e-4).sum() >= 4
    rng = np.random.default_rng(0)
    pull_weight = np.ones(hair.n_particles)
    pull_target = hair.points + rng.normal(scale=2e-3, size=hair.points.shape)  # guides' pull, elsewhere
    problem = fine_problem(hair, start, pull_weight, pull_target)
    weights = EnergyWeights(spacing=spacing)
    together, report = solve_strands(problem, BodyDistance(query), weights, options=TIGHT)
    assert report.converged
    for s in range(hair.n_strands):
        single, index = problem.subset(np.array([s]))
        reference, ref_report = solve_shape_adaptation(
            shape_model_of(single, hair.points[index]), single.initial, single.fixed, query, weights, options=TIGHT
        )
        assert ref_report.converged
        assert np.abs(together[index] - reference).max() <= 1e-6, s
    assert query.signed_distance(together[~hair.is_root]).distance.min() >= 5e-4 - 1e-5


def test_decoupled_strands_solve_alone_as_together(sphere):
    source, query = sphere
    hair = outward_strands(source, n_strands=6, n_points=10, seed=7)
    start = tilt_into_surface(hair, query, np.radians(93.0))
    problem = fine_problem(hair, start, np.full(hair.n_particles, 1.0), hair.points)
    together, _ = solve_strands(problem, BodyDistance(query))
    for s in range(hair.n_strands):
        single, index = problem.subset(np.array([s]))
        alone, _ = solve_strands(single, BodyDistance(query))
        np.testing.assert_allclose(together[index], alone, rtol=0, atol=1e-12)


def test_cancel_stops_the_loop(sphere):
    source, query = sphere
    hair = outward_strands(source, n_strands=5, n_points=6)
    problem = problem_from_shape_model(model_of(hair), hair.offsets, hair.points, hair.is_root)
    with pytest.raises(Cancelled):
        solve_strands(problem, BodyDistance(query), should_stop=lambda: True)


def test_report_and_progress_of_every_iteration(sphere):
    source, query = sphere
    hair = outward_strands(source, n_strands=6, n_points=10, seed=7)
    start = tilt_into_surface(hair, query, np.radians(93.0))
    problem = fine_problem(hair, start, np.full(hair.n_particles, 1.0), hair.points)
    seen = []
    options = SolveOptions(max_iterations=5)
    points, report = solve_strands(problem, BodyDistance(query), options=options,
                                   progress=lambda *call: seen.append(call))
    assert report.backend == BACKEND == "active-set"
    assert report.groups == 6 and report.open_groups[0] == 6  # uncoupled: a group per strand
    assert report.iterations == len(seen) == 5 and not report.converged
    assert [(stage, fraction) for stage, fraction, _ in seen] == [("solve", k / 5) for k in range(1, 6)]
    still_open = report.open_groups[1:] + [report.groups - report.converged_groups]
    assert [message for _, _, message in seen] == [
        f"iteration {k + 1}: max step {step:.2e} m, {n} open" for k, (step, n) in enumerate(zip(report.max_step, still_open))
    ]
    for per_iteration in (report.max_step, report.min_clearance, report.step_fractions, report.active_set_rounds,
                          report.cg_steps, report.merit):
        assert len(per_iteration) == report.iterations
    assert report.cg_steps == report.active_set_rounds  # K diagonal: one banded solve per round, no CG
    assert report.osqp_status == report.osqp_iterations == []
    # stopped by the cap: whatever was short of the clearance has been pushed out
    assert query.signed_distance(points[~hair.is_root]).distance.min() >= options.eps_c - 1e-9


class ScriptedLevel:
    """Three strands whose merit at a trial is ``merit(fraction)`` (the line search's view of a level): the loop's
    decisions without a body or a QP."""

    n_strands = 3

    def __init__(self, coupled, merit):
        self.coupled, self.merit = coupled, merit
        self.trials, self.kept = [], []

    def trial_merits(self, fraction, accepted):
        self.trials.append((fraction.copy(), accepted.copy()))
        return self.merit(fraction)

    def keep(self, accepted):
        self.kept.append(accepted.copy())


def test_line_search_backtracks_each_strand_on_its_own_merit():
    """Strand 0 is lowered by its full step, strand 1 from a quarter of it, strand 2 by none: each gets its own
    fraction. Coupled, strand 0's merit rises when strand 1 backtracks, and it is judged again (and backtracks)."""
    step = NewtonStep(np.arange(3), np.array([3.0]), np.ones(3), -np.ones(3), 1, 0)

    def uncoupled(fraction):
        return np.array([0.5, 0.5 if fraction[1] <= 0.25 else 2.0, 2.0])

    damping = np.full(3, 0.1)
    level = ScriptedLevel(False, uncoupled)
    fraction, accepted = line_search(level, step, damping)
    assert accepted.tolist() == [True, True, False] and len(level.trials) == MAX_BACKTRACKS
    np.testing.assert_array_equal(fraction, [1.0, 0.25, BACKTRACK_FACTOR ** (MAX_BACKTRACKS - 1)])
    assert level.trials[1][1].tolist() == [True, False, False]  # strand 0 is not tried again
    # the full step's actual against predicted change: half the prediction keeps strand 0's damping, a rise
    # raises the others'
    np.testing.assert_allclose(damping, [0.1, 0.1 * DAMPING_FACTOR, 0.1 * DAMPING_FACTOR], rtol=1e-15)

    def coupled(fraction):
        strand_0 = 0.5 if fraction[0] <= 0.5 or fraction[1] > 0.5 else 2.0
        return np.array([strand_0, 0.5 if fraction[1] <= 0.5 else 2.0, 0.5])

    level = ScriptedLevel(True, coupled)
    fraction, accepted = line_search(level, step, np.full(3, INITIAL_RADIAL_DAMPING))
    assert [kept.tolist() for kept in level.kept] == [[True, False, True], [False, True, True],
                                                      [True, True, True]]  # strand 0 accepted, then not, then again
    np.testing.assert_array_equal(fraction, [0.5, 0.5, 1.0])
