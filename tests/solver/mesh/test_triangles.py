"""Per-triangle quantities (solver/mesh/triangles.py): barycentric coordinates and interpolation, face frames."""

import numpy as np

from hairport.solver.mesh.triangles import barycentric_coordinates, face_frames, interpolate_barycentric
from tests.solver.hair_shapes import ellipsoid_head


def test_barycentric_helpers_round_trip():
    rng = np.random.default_rng(7)
    triangles = rng.normal(size=(500, 3, 3))
    weights = rng.dirichlet(np.ones(3), 500)
    weights[:50] = np.eye(3)[rng.integers(0, 3, 50)]  # corners
    points = np.einsum("ij,ijk->ik", weights, triangles)
    np.testing.assert_allclose(barycentric_coordinates(points, triangles), weights, atol=1e-9)
    # off the plane: coordinates of the projection
    normal = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    lifted = points + normal * rng.normal(size=(500, 1))
    np.testing.assert_allclose(barycentric_coordinates(lifted, triangles), weights, atol=1e-9)
    # interpolate through a face table
    vertices = triangles.reshape(-1, 3)
    faces = np.arange(len(vertices)).reshape(-1, 3)
    ids = rng.permutation(500)
    np.testing.assert_allclose(interpolate_barycentric(vertices, faces, ids, weights[ids]), points[ids], atol=1e-12)


def test_face_frames_are_rotations():
    head = ellipsoid_head()
    frames, valid = face_frames(head.vertices, head.faces, np.arange(head.n_faces))
    assert valid.all()
    np.testing.assert_allclose(frames @ frames.transpose(0, 2, 1), np.broadcast_to(np.eye(3), frames.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(frames), 1.0, atol=1e-12)


def test_face_frame_columns_and_degenerate_faces():
    vertices = np.array([[0.0, 0, 0], [2, 0, 0], [0, 3, 0], [1, 0, 0], [0.0, 0, 0]])
    faces = np.array([[0, 1, 2], [0, 2, 1], [0, 1, 3], [0, 4, 0]])  # ccw, cw, collinear, a point
    frames, valid = face_frames(vertices, faces, np.array([0, 1, 2, 3, 0]))
    np.testing.assert_array_equal(valid, [True, True, False, False, True])
    # columns: normal, first edge direction, normal x edge
    np.testing.assert_array_equal(frames[0], [[0, 1, 0], [0, 0, 1], [1, 0, 0]])
    np.testing.assert_array_equal(frames[1], [[0, 0, 1], [0, 1, 0], [-1, 0, 0]])
    np.testing.assert_array_equal(frames[2], np.eye(3))
    np.testing.assert_array_equal(frames[3], np.eye(3))
    np.testing.assert_array_equal(frames[4], frames[0])
