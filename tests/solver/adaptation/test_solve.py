"""The single-level solves (solver/adaptation/solve.py): the choice of QP backend (the choice of level:
fine/test_fine_solve.py)."""

import numpy as np
import pytest

from hairport.solver.adaptation.coupled.osqp_backend import solve_shape_adaptation
from hairport.solver.adaptation.loop.options import SolveOptions
from hairport.solver.adaptation.problem.constraints import BodyDistance
from hairport.solver.adaptation.problem.strand_problem import problem_from_shape_model
from hairport.solver.adaptation.solve import QP_BACKENDS, solve_hairstyle, solve_strands
from hairport.solver.mesh.query import MeshQuery
from tests.solver.hair_shapes import model_of, outward_strands, sphere_character, tilt_into_surface

OPTIONS = SolveOptions(max_iterations=4)


@pytest.fixture(scope="module")
def case():
    """20 strands of a sphere head tilted 5 degrees into it."""
    source = sphere_character()
    hair = outward_strands(source, n_strands=20, n_points=8)
    query = MeshQuery(source.vertices, source.faces)
    return hair, model_of(hair), query, tilt_into_surface(hair, query, np.radians(95.0))


def test_the_backends_are_the_active_set_and_osqp():
    assert QP_BACKENDS == ("active-set", "osqp")


def test_active_set_backend_is_the_default_and_solves_the_strand_problem(case):
    hair, model, query, start = case
    points, report = solve_hairstyle(model, hair.offsets, start, hair.is_root, query, options=OPTIONS)
    assert report.backend == "active-set" and report.groups == 1  # kNN couples every strand
    problem = problem_from_shape_model(model, hair.offsets, start, hair.is_root)
    direct, _ = solve_strands(problem, BodyDistance(query), options=OPTIONS)
    np.testing.assert_array_equal(points, direct)


def test_osqp_backend_solves_the_same_problem(case):
    hair, model, query, start = case
    points, report = solve_hairstyle(model, hair.offsets, start, hair.is_root, query, options=OPTIONS, backend="osqp")
    assert report.backend == "osqp" and len(report.osqp_status) == report.iterations
    direct, _ = solve_shape_adaptation(model, start, hair.is_root, query, options=OPTIONS)
    np.testing.assert_array_equal(points, direct)
    np.testing.assert_array_equal(points[hair.is_root], start[hair.is_root])
    free = ~hair.is_root
    assert query.signed_distance(points[free]).distance.min() >= OPTIONS.eps_c - OPTIONS.clearance_tolerance


def test_unknown_backend_is_an_error_naming_the_valid_ones(case):
    hair, model, query, start = case
    with pytest.raises(ValueError) as error:
        solve_hairstyle(model, hair.offsets, start, hair.is_root, query, backend="simplex")
    assert str(error.value) == "unknown QP backend 'simplex'; expected one of active-set, osqp"
