"""Tests for solver/wrap/surface.py: closest target points, their normals, and the target's border."""

from __future__ import annotations

import numpy as np

from hairport.solver.wrap.surface import TargetSurface, border_features, face_normals, outer_faces, vertex_normals
from tests.solver.wrap.conftest import grid, sphere


def test_a_closed_mesh_has_no_border_and_an_open_one_has_its_rim():
    vertices, faces = sphere()
    edges, corners = border_features(faces, len(vertices))
    assert not edges.any() and not corners.any()
    assert not TargetSurface(vertices, faces).is_open
    vertices, faces = grid(5)
    edges, corners = border_features(faces, len(vertices))
    ids = np.arange(25).reshape(5, 5)
    rim = np.zeros(25, dtype=bool)
    rim[np.concatenate([ids[0], ids[-1], ids[:, 0], ids[:, -1]])] = True
    np.testing.assert_array_equal(corners, rim)
    assert edges.sum() == 16  # four sides of four edges each
    # the edge opposite corner k joins the two other corners: both on the rim
    f, k = np.nonzero(edges)
    others = np.stack([faces[f, (k + 1) % 3], faces[f, (k + 2) % 3]], axis=1)
    assert rim[others].all()


def test_closest_points_past_the_rim_are_on_the_border_and_rejected():
    vertices, faces = grid(11, 0.1)
    surface = TargetSurface(vertices, faces)
    points = np.array([[0.05, 0.05, 0.01],   # above the middle
                       [0.15, 0.05, 0.0],    # past the right edge
                       [-0.02, -0.02, 0.0],  # past a corner
                       [0.05, 0.05, 0.2]])   # above the middle, far
    normals = np.tile([0.0, 0.0, 1.0], (4, 1))
    match = surface.match(points, normals, max_distance=0.05, min_cosine=0.5)
    np.testing.assert_array_equal(match.border, [False, True, True, False])
    np.testing.assert_array_equal(match.accepted, [True, False, False, False])
    np.testing.assert_allclose(match.closest[0], [0.05, 0.05, 0.0], atol=1e-12)
    np.testing.assert_allclose(match.distance, [0.01, 0.05, np.sqrt(8) * 0.01, 0.2], atol=1e-12)
    np.testing.assert_allclose(match.normal, normals, atol=1e-12)


def test_normals_that_disagree_are_rejected():
    vertices, faces = sphere(0.1)
    surface = TargetSurface(vertices, faces)
    points = np.array([[0.0, 0.11, 0.0], [0.0, 0.11, 0.0]])
    normals = np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])  # the second looks inward: a fold
    match = surface.match(points, normals, max_distance=0.05, min_cosine=np.cos(np.radians(60)))
    np.testing.assert_array_equal(match.accepted, [True, False])
    assert not match.border.any()


def test_vertex_and_face_normals_of_a_sphere_point_outward():
    vertices, faces = sphere(0.2, 2)
    np.testing.assert_allclose(vertex_normals(vertices, faces), vertices / 0.2, atol=0.05)
    centroids = vertices[faces].mean(axis=1)
    outward = np.einsum("ij,ij->i", face_normals(vertices, faces), centroids / np.linalg.norm(centroids, axis=1)[:, None])
    assert outward.min() > 0.98
    # a degenerate face and an unused vertex get zero normals, not NaN
    vertices = np.vstack([vertices, [[9.0, 9.0, 9.0]]])
    assert not np.isnan(vertex_normals(vertices, faces)).any()
    assert np.allclose(face_normals(np.zeros((3, 3)), np.array([[0, 1, 2]])), 0.0)


def test_the_outer_faces_of_several_shells_leave_out_inner_shells_and_sheets():
    skin, skin_faces = sphere(0.1, 3)
    inner, inner_faces = sphere(0.02, 2)  # an eyeball deep inside
    strip = np.array([[0.2, 0.0, 0.0], [0.3, 0.0, 0.0], [0.2, 0.01, 0.0], [0.3, 0.01, 0.0]])  # a lash outside
    vertices = np.vstack([skin, inner, strip])
    faces = np.vstack([skin_faces, inner_faces + len(skin), np.array([[0, 1, 3], [0, 3, 2]]) + len(skin) + len(inner)])
    kept = outer_faces(vertices, faces)
    np.testing.assert_array_equal(kept[: len(skin_faces)], skin_faces)  # the skin, all of it
    assert kept.min() < len(skin) and not np.isin(kept, np.arange(len(skin), len(skin) + len(inner))).any()
    # an open sheet has no inside: the winding number's half-step across it may keep a face of it
    assert len(kept) <= len(skin_faces) + 2
    # one shell is kept whole, untested
    np.testing.assert_array_equal(outer_faces(skin, skin_faces), skin_faces)
    # no face has the inside behind it (two shells turned inside out): nothing to choose, all kept
    flipped = np.vstack([skin_faces[:, ::-1], skin_faces[:, ::-1] + len(skin)])
    apart = np.vstack([skin, skin + [1.0, 0.0, 0.0]])
    np.testing.assert_array_equal(outer_faces(apart, flipped), flipped)
