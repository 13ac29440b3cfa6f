"""The linearize-then-QP loop of Sec. 4.6 with OSQP (solver/adaptation/coupled/osqp_backend.py)."""

import numpy as np
import pytest

from hairport.solver.adaptation.coupled.osqp_backend import BACKEND, solve_shape_adaptation
from hairport.solver.adaptation.loop.options import Cancelled, SolveOptions
from hairport.solver.adaptation.problem.energies import EnergyWeights
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.metrics import mean_segment_angle
from tests.solver.hair_shapes import model_of, outward_strands, sphere_character, tilt_into_surface


@pytest.fixture(scope="module")
def head_case():
    source = sphere_character()
    hair = outward_strands(source, n_strands=60, n_points=10)
    return hair, model_of(hair), MeshQuery(source.vertices, source.faces)


def test_source_is_a_fixed_point(head_case):
    hair, model, query = head_case
    points, report = solve_shape_adaptation(model, hair.points, hair.is_root, query)
    assert report.converged and report.iterations == 1
    assert np.abs(points - hair.points).max() < 1e-12


def test_penetrating_start_is_pushed_out_with_clearance_and_roots_stay(head_case):
    hair, model, query = head_case
    start = tilt_into_surface(hair, query, np.radians(95.0))
    roots = hair.is_root
    assert (query.signed_distance(start[~roots]).distance < 0).sum() > 100
    eps_c = 5e-4
    points, report = solve_shape_adaptation(model, start, roots, query, options=SolveOptions(eps_c=eps_c))
    distance = query.signed_distance(points[~roots]).distance
    assert distance.min() >= eps_c - 1e-5
    np.testing.assert_array_equal(points[roots], start[roots])
    # Eq. 7 turns the segments back toward the source directions while pushing out
    assert mean_segment_angle(points, hair.points, hair.segments) < 0.8 * mean_segment_angle(start, hair.points, hair.segments)


def test_larger_clearance_is_met(head_case):
    hair, model, query = head_case
    eps_c = 6e-3  # more than the source's first particles have
    assert (query.signed_distance(hair.points[~hair.is_root]).distance < eps_c).sum() > 30
    points, report = solve_shape_adaptation(model, hair.points, hair.is_root, query, options=SolveOptions(eps_c=eps_c))
    assert report.converged
    assert query.signed_distance(points[~hair.is_root]).distance.min() >= eps_c - 1e-5


def test_cancel_stops_the_loop(head_case):
    hair, model, target = head_case
    with pytest.raises(Cancelled):
        solve_shape_adaptation(model, hair.points, hair.is_root, target, should_stop=lambda: True)


def test_weights_trade_off_terms(head_case):
    """A larger beta keeps the result closer to the initial transfer."""
    hair, model, target = head_case
    start = tilt_into_surface(hair, target, np.radians(80.0))
    far = {}
    for beta in (1e2, 1e4):
        points, _ = solve_shape_adaptation(model, start, hair.is_root, target, EnergyWeights(3e3, beta))
        far[beta] = np.linalg.norm(points - start, axis=1).mean()
    assert far[1e4] < far[1e2]


def test_report_and_progress_of_every_iteration(head_case):
    hair, model, query = head_case
    start = tilt_into_surface(hair, query, np.radians(95.0))
    seen = []
    options = SolveOptions(max_iterations=4)
    points, report = solve_shape_adaptation(
        model, start, hair.is_root, query, options=options, progress=lambda *call: seen.append(call)
    )
    assert report.backend == BACKEND == "osqp"
    assert report.iterations == len(seen) == 4 and not report.converged
    assert [(stage, fraction) for stage, fraction, _ in seen] == [("solve", k / 4) for k in range(1, 5)]
    assert [message for _, _, message in seen] == [
        f"iteration {k + 1}: max step {step:.2e} m" for k, step in enumerate(report.max_step)
    ]
    for per_iteration in (report.max_step, report.min_clearance, report.step_fractions, report.osqp_status,
                          report.osqp_iterations):
        assert len(per_iteration) == 4
    assert set(report.osqp_status) <= {"solved", "solved inaccurate"} and min(report.osqp_iterations) > 0
    # the active-set fields stay empty
    assert report.groups == 0 and report.open_groups == report.active_set_rounds == report.merit == []
    # stopped by the cap: whatever was short of the clearance has been pushed out
    assert query.signed_distance(points[~hair.is_root]).distance.min() >= options.eps_c - 1e-9


def test_no_free_particle_is_converged_at_once(head_case):
    hair, model, query = head_case
    points, report = solve_shape_adaptation(model, hair.points, np.ones(hair.n_particles, dtype=bool), query)
    assert report.converged and report.iterations == 0
    np.testing.assert_array_equal(points, hair.points)
