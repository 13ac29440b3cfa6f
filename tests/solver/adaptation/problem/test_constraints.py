"""Eq. 12-13 (solver/adaptation/problem/constraints.py): fixed roots, linearised clearance, merit violation, push-out, broad phase."""

import numpy as np
import pytest

from hairport.solver.adaptation.problem.constraints import (
    BodyDistance,
    clearance_violation,
    fixed_coordinates,
    free_coordinates,
    linearised_clearance,
    push_out_short,
)
from hairport.solver.mesh.collision import collision_query
from hairport.solver.mesh.distance_grid import DistanceGrid
from hairport.solver.mesh.query import MeshQuery
from tests.solver.mesh.meshes import icosphere

EPS_C = 5e-4


@pytest.fixture(scope="module")
def sphere():
    """An icosphere of radius 0.1 m and points along the normals of its first faces."""
    vertices, faces = icosphere()
    corners = vertices[faces[:6]]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    return MeshQuery(vertices, faces), corners.mean(axis=1), normal


def test_roots_are_fixed_in_every_coordinate():
    fixed = np.array([True, False, False, True, False])
    pinned = fixed_coordinates(fixed)
    np.testing.assert_array_equal(pinned, np.repeat(fixed[:, None], 3, axis=1))
    pinned[1, 0] = True  # a new array: the caller may pin more unknowns
    assert not fixed[1]
    np.testing.assert_array_equal(free_coordinates(fixed), [3, 4, 5, 6, 7, 8, 12, 13, 14])
    assert free_coordinates(np.ones(2, dtype=bool)).shape == (0,)


def test_linearised_clearance_rows_and_bounds():
    distance = np.array([0.001, -0.002, 0.0005, np.inf])
    fixed = np.array([True, False, False, False])
    near = np.array([True, True, True, False])
    constrained, lower = linearised_clearance(distance, EPS_C, fixed, near)
    np.testing.assert_array_equal(constrained, [False, True, True, False])  # no root, nothing far
    np.testing.assert_array_equal(lower, [EPS_C - 0.001, EPS_C + 0.002, 0.0, -np.inf])
    everything, same = linearised_clearance(distance, EPS_C)
    assert everything.all()
    np.testing.assert_array_equal(same, lower)


def test_the_linearised_step_reaches_the_clearance_over_a_face(sphere):
    """Over a flat face, the step ``lower * n`` of Eq. 13's half-space lands at ``eps_c`` exactly."""
    query, centroid, normal = sphere
    height = np.array([-2e-3, -1e-4, 0.0, 1e-4, 3e-4, 2e-3])
    sd = query.signed_distance(centroid + height[:, None] * normal)
    constrained, lower = linearised_clearance(sd.distance, EPS_C)
    np.testing.assert_allclose(lower, EPS_C - height, rtol=0, atol=1e-15)
    moved = centroid + height[:, None] * normal + lower[:, None] * sd.normal
    np.testing.assert_allclose(query.signed_distance(moved).distance, EPS_C, rtol=0, atol=1e-15)


def test_clearance_violation_is_the_shortfall_off_the_roots():
    distance = np.array([-0.01, -0.002, 0.0002, EPS_C, 0.003, np.inf])
    fixed = np.array([True, False, False, False, False, False])
    np.testing.assert_array_equal(clearance_violation(distance, EPS_C), [EPS_C + 0.01, EPS_C + 0.002, EPS_C - 0.0002,
                                                                         0.0, 0.0, 0.0])
    np.testing.assert_array_equal(clearance_violation(distance, EPS_C, fixed), [0.0, EPS_C + 0.002, EPS_C - 0.0002,
                                                                                0.0, 0.0, 0.0])


def test_push_out_short_counts_and_pushes_free_particles(sphere):
    query, centroid, normal = sphere
    height = np.array([-1e-3, 2e-4, EPS_C - 5e-6, 1e-3, -3e-3, 2e-3])
    points = centroid + height[:, None] * normal
    fixed = np.array([False, False, False, False, True, False])  # the deepest one is a root
    distance = query.signed_distance(points).distance
    out, pushed = push_out_short(points, fixed, distance, query, EPS_C, tolerance=1e-5)
    assert pushed == 2  # short by more than the tolerance: the first two (the third is within it)
    np.testing.assert_array_equal(out[fixed], points[fixed])
    after = query.signed_distance(out).distance
    np.testing.assert_allclose(after[~fixed], np.maximum(height[~fixed], EPS_C), rtol=0, atol=1e-15)
    # nothing short: the same array back, untouched
    clear = centroid + 2e-3 * normal
    same, none = push_out_short(clear, np.zeros(6, dtype=bool), query.signed_distance(clear).distance, query, EPS_C,
                                tolerance=1e-5)
    assert none == 0 and same is clear


def test_body_distance_without_a_broad_phase_is_exact(sphere):
    query, centroid, normal = sphere
    points = centroid + np.linspace(-0.01, 0.05, 6)[:, None] * normal
    distance, normals, near = BodyDistance(query)(points)
    sd = query.signed_distance(points)
    np.testing.assert_array_equal(distance, sd.distance)
    np.testing.assert_array_equal(normals, sd.normal)
    assert near.all()


def test_body_distance_skips_particles_the_broad_phase_puts_far_outside(sphere):
    query, centroid, normal = sphere
    # 1 mm out, 2 mm in, 5 and 20 cm out, 8 mm out, 3 cm out, 3 and 6 cm deep (the sphere's radius is 10 cm)
    height = np.array([1e-3, -2e-3, 0.05, 0.2, 0.008, 0.03, -0.03, -0.06])
    points = centroid[np.arange(8) % 6] + height[:, None] * normal[np.arange(8) % 6]
    band = 0.02
    grid = DistanceGrid.build(query)
    distance, normals, near = BodyDistance(query, band, grid)(points)
    np.testing.assert_array_equal(near, [True, True, False, False, True, False, True, True])
    sd = query.signed_distance(points[near])
    np.testing.assert_array_equal(distance[near], sd.distance)
    np.testing.assert_array_equal(normals[near], sd.normal)
    assert np.isinf(distance[~near]).all() and (normals[~near] == 0).all()
    # far particles get no half-space and no violation; deep ones must come out by their depth
    constrained, lower = linearised_clearance(distance, EPS_C, near=near)
    np.testing.assert_array_equal(constrained, near)
    assert (clearance_violation(distance, EPS_C)[~near] == 0).all()
    np.testing.assert_allclose(lower[6:], EPS_C + np.array([0.03, 0.06]), rtol=0, atol=1e-3)  # the icosphere's facets
    # a deep particle's normal points to its closest point: a step along it by ``lower`` lands out
    moved = points[6:] + lower[6:, None] * normals[6:]
    np.testing.assert_allclose(query.signed_distance(moved).distance, EPS_C, rtol=0, atol=1e-12)


def test_body_distance_on_an_open_body_asks_the_winding_number_far_from_the_surface():
    """A sphere of radius 0.1 m open below z = -0.05: the grid knows no sign; a particle deep
    inside is queried (its winding number says inside), one far below the cut is not."""
    vertices, faces = icosphere()
    keep = ~(vertices[faces, 2] < -0.05).any(axis=1)
    query = collision_query(vertices, faces[keep])
    assert not query.closed
    grid = DistanceGrid.build(query)
    points = np.array([[0.0, 0.0, 0.02], [0.0, 0.0, -0.03], [0.0, 0.0, -0.078], [0.0, 0.0, 0.3]])
    distance, normals, near = BodyDistance(query, 0.02, grid)(points)
    # the centre and 3 cm below it are inside (above the cut's plane); 2.8 cm below the
    # cut's plane (9 cm from the rim) and 20 cm over the top are outside and far
    np.testing.assert_array_equal(near, [True, True, False, False])
    assert distance[0] < -0.07 and distance[1] < -0.02
    # their normals point from them to their closest points: out of the body
    assert np.all(np.einsum("ij,ij->i", normals[:2], points[:2] - query.signed_distance(points[:2]).closest) < 0)


def test_body_distance_keeps_a_cell_cache_and_answers_as_the_reference():
    """The broad phase plus the compiled query through the cache the object keeps, against the
    same broad phase over libigl's face search (the reference): the same near particles,
    distances and normals, call after call on moving particles."""
    from hairport.solver.mesh import backends

    vertices, faces = icosphere(subdivisions=3)
    query = collision_query(vertices, faces)
    reference_query = MeshQuery(vertices, faces, inside=query.inside_test)
    reference_query._prepare()
    reference_query._closest = backends._IglFaces(reference_query.vertices, reference_query.faces)
    grid = DistanceGrid.build(query)
    compiled, reference = BodyDistance(query, 0.02, grid), BodyDistance(reference_query, 0.02, grid)
    rng = np.random.default_rng(5)
    direction = rng.normal(size=(4000, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    points = direction * rng.uniform(0.07, 0.15, size=(4000, 1))  # 3 cm deep to 5 cm out
    for step in range(3):
        distance, normal, near = compiled(points)
        ref_distance, ref_normal, ref_near = reference(points)
        np.testing.assert_array_equal(near, ref_near)
        np.testing.assert_allclose(distance[near], ref_distance[near], rtol=0, atol=1e-12)
        np.testing.assert_allclose(normal[near], ref_normal[near], rtol=0, atol=1e-9)
        assert np.isinf(distance[~near]).all() and near.sum() > 1000 and (~near).sum() > 500
        if step == 0:
            cache = compiled._cells
            assert cache is not None and cache.n_cells > 500
        points = points + rng.normal(scale=3e-4, size=points.shape)
    assert compiled._cells is cache  # one cache for the object's life
    assert reference._cells is None  # libigl has none
