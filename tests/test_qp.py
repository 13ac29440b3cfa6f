"""The linearize-then-QP loop (Sec. 4.6)."""

import numpy as np
import pytest

from hairport.solver.adaptation.energies import EnergyWeights, ShapeModel
from hairport.solver.adaptation.neighbours import knn_other_strands, laplacian_operator
from hairport.solver.adaptation.options import Cancelled, SolveOptions
from hairport.solver.adaptation.osqp_backend import solve_shape_adaptation
from hairport.solver.mesh.query import MeshQuery
from tests.test_transfer import outward_strands, sphere_character


def model_of(hair, k=5):
    nb = knn_other_strands(hair.points, hair.strand_of, k)
    K = laplacian_operator(nb, np.arange(hair.n_particles), hair.n_particles)
    return ShapeModel.build(hair.points, hair.segments, K)


def tilt_into_surface(hair, query, angle_from_normal):
    """Each strand rigidly rotated about its root so it leaves at ``angle_from_normal`` (rad)
    from the surface normal: beyond pi/2 it dips into the body."""
    points = hair.points.copy()
    roots = hair.roots
    sd = query.signed_distance(points[roots + 1])
    normal = sd.normal
    for s, r in enumerate(roots):
        rel = points[r:hair.offsets[s + 1]] - points[r]
        d = rel[1] / np.linalg.norm(rel[1])
        axis = np.cross(normal[s], d)
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(normal[s], [1.0, 0.0, 0.0])
        axis /= np.linalg.norm(axis)
        tangent = np.cross(axis, normal[s])
        goal = np.cos(angle_from_normal) * normal[s] + np.sin(angle_from_normal) * tangent
        # rotation taking d to goal about axis
        theta = np.arctan2(np.dot(np.cross(d, goal), axis), np.dot(d, goal))
        K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        R = np.eye(3) + np.sin(theta) * K + (1 - np.cos(theta)) * K @ K
        points[r:hair.offsets[s + 1]] = points[r] + rel @ R.T
    return points


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
    from hairport.solver.metrics import mean_segment_angle

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
