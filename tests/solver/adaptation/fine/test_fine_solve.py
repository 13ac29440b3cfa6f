"""The compiled level over uncoupled strands (solver/adaptation/fine/fine_solve.py) against its reference, the
numpy level (coupled/numpy_level.py), both run by the one loop."""

import numpy as np
import pytest
import scipy.sparse as sp

from hairport.solver.adaptation.fine.fine_solve import pull_weights, solve_uncoupled
from hairport.solver.adaptation.loop.options import ENGINES, Cancelled, SolveOptions
from hairport.solver.adaptation.problem.constraints import BodyDistance
from hairport.solver.adaptation.solve import solve_strands
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.hair import Hair
from tests.solver.hair_shapes import fine_problem, outward_strands, sphere_character, tilt_into_surface

EPS_C = 5e-4


@pytest.fixture(scope="module")
def sphere():
    source = sphere_character()
    return source, MeshQuery(source.vertices, source.faces)


@pytest.fixture(scope="module")
def groom(sphere):
    """Strands dipping into the sphere at several angles (constraints active, some particles inside), a strand of
    2 particles, and a strand at its minimum far from the body (converged at the start)."""
    source, query = sphere
    hair = outward_strands(source, n_strands=10, n_points=12, seed=5)
    angles = np.radians(np.linspace(80.0, 110.0, hair.n_strands))
    start = np.concatenate([tilt_into_surface(hair, query, angle)[hair.offsets[s]:hair.offsets[s + 1]]
                            for s, angle in enumerate(angles)])
    short = hair.points[hair.offsets[3]:hair.offsets[3] + 2]
    still = np.array([0.0, 0.5, 0.0]) + np.outer(np.arange(6) * 0.004, [0.0, 1.0, 0.0])  # far above the head
    strands = [start[hair.offsets[s]:hair.offsets[s + 1]] for s in range(hair.n_strands)]
    sources = [hair.points[hair.offsets[s]:hair.offsets[s + 1]] for s in range(hair.n_strands)]
    both = Hair.from_strands(sources + [short, still])
    first = np.concatenate(strands + [short + [0.0, 0.0, -0.002], still])
    rng = np.random.default_rng(0)
    is_still = np.arange(both.n_particles) >= both.offsets[-2]
    pull_weight = np.where(is_still, 1.0, rng.uniform(0.5, 1.5, both.n_particles))
    pull_target = both.points + rng.normal(scale=2e-3, size=both.points.shape)
    pull_target[is_still] = still  # its pull is satisfied where it is
    problem = fine_problem(both, first, pull_weight, pull_target)
    inside = query.signed_distance(first[~both.is_root]).distance < 0
    assert inside.sum() >= 10
    return problem, first


@pytest.mark.parametrize("options", [
    SolveOptions(eps_c=EPS_C),
    SolveOptions(eps_c=EPS_C, energy_tolerance=1e-3),
    SolveOptions(eps_c=EPS_C, max_iterations=4),  # stopped by the cap: the push-out
    SolveOptions(eps_c=EPS_C, max_iterations=200, step_tolerance=1e-8),
], ids=["default", "energy-tolerance", "capped", "tight"])
def test_compiled_loop_equals_the_numpy_reference(sphere, groom, options):
    _, query = sphere
    problem, first = groom
    reference, expected = solve_strands(problem, BodyDistance(query), options=options, start=first, engine="numpy")
    points, report = solve_strands(problem, BodyDistance(query), options=options, start=first, engine="compiled")
    np.testing.assert_allclose(points, reference, rtol=0, atol=1e-9)
    assert report.backend == expected.backend == "active-set"
    assert report.iterations == expected.iterations and report.converged == expected.converged
    assert report.open_groups == expected.open_groups and report.groups == expected.groups == problem.n_strands
    assert report.converged_groups == expected.converged_groups
    assert report.active_set_rounds == expected.active_set_rounds == report.cg_steps
    assert report.step_fractions == expected.step_fractions
    assert report.pushed_out == expected.pushed_out
    # on the way the two may part by more than at the end: particles sliding over the facets amplify
    # rounding differences (measured 7.7e-9 m in a step, 5.5e-10 m in the result); the clearance
    # penalty (up to ~1e5 per m here) scales them in the merit
    np.testing.assert_allclose(report.merit, expected.merit, rtol=1e-6)
    np.testing.assert_allclose(report.max_step, expected.max_step, rtol=0, atol=1e-7)
    np.testing.assert_allclose(report.min_clearance, expected.min_clearance, rtol=0, atol=1e-7)
    # what the reference promises holds for the compiled result too
    np.testing.assert_array_equal(points[problem.fixed], first[problem.fixed])
    assert query.signed_distance(points[~problem.fixed]).distance.min() >= EPS_C - options.clearance_tolerance
    assert max(report.active_set_rounds) > 1  # constraints came and went
    if options.max_iterations == 30 and options.energy_tolerance == 0:
        assert 0.0 in report.step_fractions  # a strand stayed where no trial lowered its merit


def test_a_strand_at_its_minimum_stops_after_one_iteration_unmoved(sphere, groom):
    _, query = sphere
    problem, first = groom
    still, rows = problem.strand_run(problem.n_strands - 1, problem.n_strands)
    points, report = solve_uncoupled(still, BodyDistance(query), start=first[rows])
    assert report.iterations == 1 and report.converged and report.max_step == [0.0]
    np.testing.assert_array_equal(points, first[rows])


class TiltedSphere:
    """A :class:`BodyDistance` stand-in: the exact signed distance to a sphere at the origin, with normals turned
    by ``tilt`` (rad) about z, as a faceted body's may be off the direction that restores the clearance: the
    projection of a line-search trial then leaves it short, and the merit's clearance penalty decides steps.
    Each point's result depends on that point alone (no batch-dependent rounding). It has no mesh: the solves
    under it check no segments (``segment_rounds`` 0)."""

    query = None
    margin = None

    def __init__(self, radius: float, tilt: float):
        self.radius, self.cos, self.sin = radius, np.cos(tilt), np.sin(tilt)

    def __call__(self, points, rows=None):
        x, y, z = points[:, 0], points[:, 1], points[:, 2]
        r = np.sqrt(x * x + y * y + z * z)
        normal = np.stack([(self.cos * x - self.sin * y) / r, (self.sin * x + self.cos * y) / r, z / r], axis=1)
        return r - self.radius, normal, np.ones(len(points), dtype=bool)


@pytest.mark.parametrize("engine", ENGINES)
def test_a_strand_solved_alone_or_in_any_chunk_gives_the_same_result(sphere, engine):
    """The merit's clearance penalty is each strand's own, so a strand's result does not depend on the strands
    it is solved with (with one penalty for all, the largest multiplier of any strand, this case's strands
    moved by up to 9 mm between a chunk and alone)."""
    source, query = sphere
    hair = outward_strands(source, n_strands=10, n_points=12, seed=5)
    angles = np.radians(np.linspace(80.0, 110.0, hair.n_strands))
    start = np.concatenate([tilt_into_surface(hair, query, angle)[hair.offsets[s]:hair.offsets[s + 1]]
                            for s, angle in enumerate(angles)])
    rng = np.random.default_rng(0)
    problem = fine_problem(hair, start, rng.uniform(0.5, 1.5, hair.n_particles),
                           hair.points + rng.normal(scale=2e-3, size=hair.points.shape))
    body = TiltedSphere(0.1, 0.4)
    particles_only = SolveOptions(segment_rounds=0)
    together, report = solve_strands(problem, body, options=particles_only, engine=engine)
    assert report.converged and len(set(report.open_groups)) > 2  # strands leave the loop at different iterations
    for s in range(problem.n_strands):
        single, rows = problem.strand_run(s, s + 1)
        alone, _ = solve_strands(single, body, options=particles_only, engine=engine)
        np.testing.assert_array_equal(alone, together[rows])
    for half, rows in [problem.strand_run(0, 4), problem.strand_run(4, problem.n_strands)]:
        chunked, _ = solve_strands(half, body, options=particles_only, engine=engine)
        np.testing.assert_array_equal(chunked, together[rows])


class RepellingStart:
    """A :class:`BodyDistance` stand-in under which only the given points are outside (1 m off a body below
    them); any other point is 1 m deep: every trial step of the line search raises the merit. Not a
    distance (not 1-Lipschitz): solves under it query every trial point (``query_margin`` inf) and, with no
    mesh, check no segments (``segment_rounds`` 0)."""

    query = None
    margin = None

    def __init__(self, start):
        self.start = start

    def __call__(self, points, rows=None):
        at_start = (points[:, None, :] == self.start[None, :, :]).all(axis=2).any(axis=1)
        normal = np.zeros_like(points)
        normal[:, 1] = 1.0
        return np.where(at_start, 1.0, -1.0), normal, np.ones(len(points), dtype=bool)


@pytest.mark.parametrize("engine", ENGINES)
def test_a_strand_without_a_better_trial_stays_and_stops(groom, engine):
    problem, first = groom
    points, report = solve_strands(problem, RepellingStart(first),
                                   options=SolveOptions(query_margin=np.inf, segment_rounds=0),
                                   start=first, engine=engine)
    np.testing.assert_array_equal(points, first)  # the shortest step is not taken anyway
    assert report.converged and report.iterations == 2  # two failed line searches in a row: stalled
    assert report.step_fractions == [0.0, 0.0] and report.max_step == [0.0, 0.0]
    assert report.open_groups == [problem.n_strands, problem.n_strands - 1]  # the one at its minimum left at once


@pytest.mark.parametrize("engine", ENGINES)
def test_a_strand_stops_after_one_small_decrease_its_model_predicted(sphere, groom, engine):
    """With a tolerance no decrease can beat, every iteration is small: an uncoupled strand stops after one,
    where the QP's prediction is small too (coupled ones need two: test_active_set)."""
    _, query = sphere
    problem, first = groom
    _, report = solve_strands(problem, BodyDistance(query), start=first, engine=engine,
                              options=SolveOptions(eps_c=EPS_C, energy_tolerance=1.0))
    assert report.converged and report.iterations == 1


def test_cancel_stops_the_compiled_loop(sphere, groom):
    _, query = sphere
    problem, first = groom
    polls = []

    def stop_on_third_poll():
        polls.append(1)
        return len(polls) == 3

    with pytest.raises(Cancelled):
        solve_uncoupled(problem, BodyDistance(query), start=first, should_stop=stop_on_third_poll)
    assert len(polls) == 3  # polled before every iteration


def test_only_a_diagonal_coupling_takes_the_compiled_loop(sphere):
    _, query = sphere
    assert pull_weights(sp.diags([1.0, 2.0, 0.0], format="csr")).tolist() == [1.0, 2.0, 0.0]
    assert pull_weights(sp.csr_matrix((3, 3))).tolist() == [0.0, 0.0, 0.0]
    within_strand = sp.csr_matrix(np.array([[1.0, -1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
    assert pull_weights(within_strand) is None
    source, _ = sphere
    hair = outward_strands(source, n_strands=1, n_points=3)
    problem = fine_problem(hair, hair.points, np.ones(3), hair.points)
    problem = type(problem)(problem.offsets, problem.source_directions, problem.initial, within_strand,
                            problem.features, problem.gamma, problem.fixed)
    with pytest.raises(ValueError, match="diagonal K"):
        solve_uncoupled(problem, BodyDistance(query))
    # solve_strands takes the numpy path for it whatever the engine
    compiled, _ = solve_strands(problem, BodyDistance(query), engine="compiled")
    reference, _ = solve_strands(problem, BodyDistance(query), engine="numpy")
    np.testing.assert_array_equal(compiled, reference)
    with pytest.raises(ValueError, match="unknown engine"):
        solve_strands(problem, BodyDistance(query), engine="fortran")


class CountingDistance(BodyDistance):
    """A :class:`BodyDistance` that counts the points it was asked about."""

    asked = 0

    def __call__(self, points, rows=None):
        self.asked += len(points)
        return super().__call__(points, rows)


@pytest.mark.parametrize("engine", ENGINES)
def test_trial_points_far_enough_get_no_query_and_the_result_holds(sphere, groom, engine):
    """The line search asks only about trial points whose bound from their last query is short of eps_c
    plus the margin, and a QP step that reaches a bounded particle's slack is taken again with exact
    queries: fewer queries, the same iterates to rounding, the clearance kept."""
    _, query = sphere
    problem, first = groom
    exact_body, lazy_body = CountingDistance(query), CountingDistance(query)
    exact, exact_report = solve_strands(problem, exact_body, options=SolveOptions(eps_c=EPS_C, query_margin=np.inf),
                                        start=first, engine=engine)
    lazy, lazy_report = solve_strands(problem, lazy_body, options=SolveOptions(eps_c=EPS_C, query_margin=1e-3),
                                      start=first, engine=engine)
    assert lazy_body.asked < 0.8 * exact_body.asked
    assert lazy_report.iterations == exact_report.iterations and lazy_report.open_groups == exact_report.open_groups
    assert lazy_report.step_fractions == exact_report.step_fractions
    np.testing.assert_allclose(lazy_report.merit, exact_report.merit, rtol=1e-9)
    np.testing.assert_allclose(lazy, exact, rtol=0, atol=1e-9)
    free = ~problem.fixed
    assert query.signed_distance(lazy[free]).distance.min() >= EPS_C - SolveOptions().clearance_tolerance
