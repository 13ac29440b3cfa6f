"""The active-set solver's outer loop (solver/adaptation/active_set.py): fixed points, push-out, line search, stopping, agreement with OSQP."""

import numpy as np
import pytest

from hairport.solver.adaptation.active_set import BACKEND, solve_strands
from hairport.solver.adaptation.constraints import BodyDistance
from hairport.solver.adaptation.energies import EnergyWeights, ShapeModel, segment_operator
from hairport.solver.adaptation.options import STALLED_ITERATIONS, Cancelled, SolveOptions
from hairport.solver.adaptation.osqp_backend import solve_shape_adaptation
from hairport.solver.adaptation.strand_problem import problem_from_shape_model
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

