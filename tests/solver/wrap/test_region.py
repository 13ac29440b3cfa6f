"""Tests for solver/wrap/region.py: the hair's region of the source, its sub-mesh, and how the rest follows."""

from __future__ import annotations

import numpy as np

from hairport.solver.wrap.region import follow, hair_region, region_mesh
from tests.solver.wrap.conftest import grid, sphere


def test_hair_region_is_the_vertices_within_reach_closed_over_faces():
    vertices, faces = grid(11, 0.1)  # 1 cm spacing
    hair = np.array([[0.0, 0.0, 0.01], [0.0, 0.0, 0.02]])
    region = hair_region(vertices, faces, hair, 0.0255)
    distance = np.linalg.norm(vertices - hair[0], axis=1)
    assert region[distance <= 0.0255].all()
    # closed over faces: a face with two corners in reach brings its third
    in_reach = distance <= 0.0255
    assert region[faces[in_reach[faces].sum(axis=1) >= 2]].all()
    assert region.sum() > in_reach.sum()
    assert not region[distance > 0.05].any()
    assert not hair_region(vertices, faces, np.zeros((0, 3)), 1.0).any()


def test_region_mesh_keeps_whole_faces_in_local_ids():
    vertices, faces = grid(5)
    region = vertices[:, 0] <= 0.05 + 1e-9
    ids, triangles, edges = region_mesh(faces, region)
    assert region[ids].all()
    np.testing.assert_array_equal(np.sort(ids), ids)
    assert triangles.max() == len(ids) - 1
    assert (region[faces].all(axis=1)).sum() == len(triangles)
    assert len(np.unique(np.sort(edges, axis=1), axis=0)) == len(edges)


def test_the_rest_follows_smoothly_and_a_piece_the_region_does_not_touch_stays():
    vertices, faces = grid(11)
    second, second_faces = sphere(0.05, 1, centre=(1.0, 0.0, 0.0))  # a separate piece
    start = np.vstack([vertices, second])
    all_faces = np.vstack([faces, second_faces + len(vertices)])
    fitted = np.flatnonzero(start[:, 0] <= 0.02 + 1e-9)[:33]  # the grid's first three columns
    moved = follow(start, all_faces, fitted, start[fitted] + [0.0, 0.0, 0.01])
    np.testing.assert_allclose(moved[fitted], start[fitted] + [0.0, 0.0, 0.01])
    # a translation of the fitted part carries the grid along unchanged (harmonic, connected)
    np.testing.assert_allclose(moved[: len(vertices)] - vertices, np.tile([0.0, 0.0, 0.01], (len(vertices), 1)),
                               atol=1e-6)
    np.testing.assert_allclose(moved[len(vertices):], second, atol=1e-9)
    # nothing free: the fitted positions as they are
    np.testing.assert_allclose(follow(vertices, faces, np.arange(len(vertices)), vertices + 1.0), vertices + 1.0)
