"""Pushing points out of a body to a clearance (solver/mesh/clearance.py)."""

import numpy as np

from hairport.solver.mesh.clearance import (
    INSIDE_PUSH_ROUNDS,
    MAX_PUSH_ROUNDS,
    PUSH_TOLERANCE,
    push_inside_out,
    push_out,
)
from hairport.solver.mesh.query import MeshQuery, SignedDistance
from tests.solver.hair_shapes import HEAD_RADIUS, ellipsoid_head
from tests.solver.mesh.meshes import icosphere


def test_push_out_direct():
    head = ellipsoid_head()
    query = MeshQuery(head.vertices, head.faces)
    rng = np.random.default_rng(3)
    points = rng.normal(size=(500, 3)) * HEAD_RADIUS  # inside and outside
    is_root = np.zeros(len(points), dtype=bool)
    is_root[:5] = True
    out = push_out(points, is_root, query, 2e-3)
    d = query.signed_distance(out).distance
    assert d[~is_root].min() >= 2e-3 - 1e-9
    np.testing.assert_array_equal(out[:5], points[:5])
    before = query.signed_distance(points).distance
    np.testing.assert_array_equal(out[before >= 2e-3], points[before >= 2e-3])
    # pushed particles sit at exactly the clearance
    moved = (~is_root) & (before < 2e-3)
    np.testing.assert_allclose(d[moved], 2e-3, atol=1e-9)


def test_points_over_a_face_go_along_its_normal_to_the_clearance():
    vertices, faces = icosphere()
    query = MeshQuery(vertices, faces)
    corners = vertices[faces[:4]]
    centroid = corners.mean(axis=1)
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    height = np.array([-1e-3, 0.0, 2e-4, 5e-3])  # inside, on, short of, beyond the clearance
    points = centroid + height[:, None] * normal
    out = push_out(points, np.zeros(4, dtype=bool), query, 1e-3)
    assert out is not points and np.array_equal(points, centroid + height[:, None] * normal)  # input kept
    np.testing.assert_allclose(out[:3], centroid[:3] + 1e-3 * normal[:3], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(out[3], points[3])


class _FlatFloor:
    """A stand-in body that always reports distance 0 and normal +x: every round pushes again."""

    def signed_distance(self, points):
        n = len(points)
        return SignedDistance(np.zeros(n), points.copy(), np.tile([1.0, 0.0, 0.0], (n, 1)), np.zeros(n, np.int64))


def test_rounds_are_capped_and_the_tolerance_counts_as_clear():
    out = push_out(np.zeros((1, 3)), np.zeros(1, dtype=bool), _FlatFloor(), 1e-3)
    np.testing.assert_allclose(out, [[MAX_PUSH_ROUNDS * 1e-3, 0.0, 0.0]], rtol=1e-15)
    # a clearance within the tolerance: nothing is short
    out = push_out(np.zeros((2, 3)), np.zeros(2, dtype=bool), _FlatFloor(), 0.5 * PUSH_TOLERANCE)
    np.testing.assert_array_equal(out, np.zeros((2, 3)))


class _Wall:
    """A stand-in body whose surface is always 1 mm along +x of the point, and which says every
    point is inside: every round of :func:`push_inside_out` pushes again."""

    def signed_distance(self, points):
        n = len(points)
        return SignedDistance(np.full(n, -1e-3), points + [1e-3, 0.0, 0.0], np.tile([1.0, 0.0, 0.0], (n, 1)),
                              np.zeros(n, np.int64))

    def inside(self, points):
        return np.ones(len(points), dtype=bool)


def test_inside_push_goes_through_the_closest_point_halving_the_clearance_each_round():
    points = np.zeros((3, 3))
    out, left = push_inside_out(points, np.array([0, 2]), _Wall(), 2e-3)
    np.testing.assert_array_equal(left, [0, 2])  # still inside after the last round
    # each round: 1 mm to the surface, then the clearance 2, 1, 0.5, ... mm
    expected = INSIDE_PUSH_ROUNDS * 1e-3 + 2e-3 * (2.0 - 2.0 ** (1 - INSIDE_PUSH_ROUNDS))
    np.testing.assert_allclose(out[[0, 2], 0], expected, rtol=1e-14)
    np.testing.assert_array_equal(out[1], [0.0, 0.0, 0.0])
    assert not np.shares_memory(out, points) and (points == 0).all()


def test_inside_push_lands_at_the_clearance_beyond_the_closest_point():
    vertices, faces = icosphere()
    query = MeshQuery(vertices, faces)
    points = np.array([[0.0, 0.0, 0.05], [0.0, 0.0, 0.2], [0.03, 0.0, 0.0]])
    out, left = push_inside_out(points, np.array([0, 2]), query, 1e-3)
    assert left.size == 0
    np.testing.assert_allclose(query.signed_distance(out[[0, 2]]).distance, 1e-3, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(out[1], points[1])
