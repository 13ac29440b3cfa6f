"""Remeshed and cut characters (solver/synthetic/remesh.py): the same shape on another topology.

``presets`` (tests/solver/synthetic/conftest.py) skips without the MakeHuman assets. The bounds
below are the measured figures of ``heavy-male`` (the preset farthest from its remeshes) and
the other presets, seed 1, with a margin of about 1.5x; see the module docstring of
:mod:`hairport.solver.synthetic.remesh`.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from hairport.solver.mesh.topology import boundary_loops, corner_neighbours, face_adjacency
from hairport.solver.model.errors import InputError
from hairport.solver.synthetic.remesh import (
    METHODS,
    bust_cut,
    chest_height,
    cut_above,
    head_cut,
    neck_height,
    remesh,
    remeshed_character,
    split_long_edges,
    surface_distances,
)

MM = 1e-3
DENSITIES = (5_000, 20_000, 100_000)
#: (method, vertices) -> mean and max symmetric surface distance (m) over the body, then over the head
DISTANCE_BOUNDS = {
    ("isotropic", 5_000): (1.2 * MM, 60 * MM, 2.0 * MM, 25 * MM),
    ("isotropic", 20_000): (0.35 * MM, 15 * MM, 0.6 * MM, 13 * MM),
    ("isotropic", 100_000): (0.1 * MM, 6 * MM, 0.15 * MM, 6 * MM),
    ("decimate", 5_000): (0.5 * MM, 8 * MM, 0.7 * MM, 8 * MM),
    ("decimate", 20_000): (0.15 * MM, 8 * MM, 0.2 * MM, 8 * MM),
    ("decimate", 100_000): (0.08 * MM, 8 * MM, 0.08 * MM, 8 * MM),
}
#: smallest inner angle (degrees) a face may have: no degenerate faces; the quadric collapses
#: leave thin (not degenerate) triangles along creases
MIN_ANGLE_DEG = {"isotropic": 2.0, "decimate": 0.25}
#: faces in a fold (an edge neighbour facing the other way, normals' dot < -0.5); they sit where the
#: original folds on itself (lips, between toes and fingers, ears): the original has 24
MAX_FOLD_FACES = 120
SAMPLES = 100_000
SEED = 1


def min_angles_deg(vertices, faces):
    corners = vertices[faces]
    angles = []
    for k in range(3):
        u = corners[:, (k + 1) % 3] - corners[:, k]
        v = corners[:, (k + 2) % 3] - corners[:, k]
        cos = np.einsum("ij,ij->i", u, v) / (np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1))
        angles.append(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    return np.min(angles, axis=0)


def face_normals(vertices, faces):
    corners = vertices[faces]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    return normals / np.linalg.norm(normals, axis=1, keepdims=True)


def signed_volume(vertices, faces):
    corners = vertices[faces]
    return float(np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])).sum() / 6.0)


def edge_uses(faces):
    """How many faces hold each undirected edge, and how many hold each directed one."""
    directed = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    undirected = np.sort(directed, axis=1)
    return np.unique(undirected, axis=0, return_counts=True)[1], np.unique(directed, axis=0, return_counts=True)[1]


def components(faces):
    return connected_components(face_adjacency(faces), directed=False)[0]


@pytest.fixture(scope="module")
def body(presets):
    return presets["heavy-male"]


@pytest.fixture(scope="module")
def remeshes(body):
    cache = {}

    def get(method, n, seed=SEED):
        if (method, n, seed) not in cache:
            cache[method, n, seed] = remesh(body.vertices, body.faces, n, method, seed)
        return cache[method, n, seed]

    return get


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("n", DENSITIES)
def test_a_remesh_is_one_closed_surface_of_the_asked_size(remeshes, body, method, n):
    vertices, faces = remeshes(method, n)
    assert vertices.dtype == np.float64 and faces.dtype == np.int64
    assert abs(len(vertices) - n) <= 0.15 * n
    assert len(np.unique(faces)) == len(vertices)  # no unreferenced vertex
    undirected, directed = edge_uses(faces)
    assert (undirected == 2).all() and (directed == 1).all()  # closed, manifold, consistently oriented
    assert components(faces) == 1
    assert len(vertices) - len(undirected) + len(faces) == 2  # genus 0, like the body
    volume, original = signed_volume(vertices, faces), signed_volume(body.vertices, body.faces)
    assert volume == pytest.approx(original, rel=0.025 if n < 20_000 else 0.01)  # outward, same size


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("n", DENSITIES)
def test_a_remesh_has_no_degenerate_face_and_few_folds(remeshes, method, n):
    vertices, faces = remeshes(method, n)
    assert min_angles_deg(vertices, faces).min() >= MIN_ANGLE_DEG[method]
    normals = face_normals(vertices, faces)
    facing = np.einsum("ij,ikj->ik", normals, normals[corner_neighbours(faces)])
    assert len(np.unique(np.nonzero(facing < -0.5)[0])) <= MAX_FOLD_FACES


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("n", DENSITIES)
def test_a_remesh_stays_on_the_original_surface(remeshes, body, method, n):
    vertices, faces = remeshes(method, n)
    mean, worst, head_mean, head_worst = DISTANCE_BOUNDS[method, n]
    there, back = surface_distances(body.vertices, body.faces, vertices, faces, SAMPLES)
    assert max(there.mean(), back.mean()) <= mean
    assert max(there.max(), back.max()) <= worst
    # the head, where the hair is: the original's head against the remesh, the remesh's head against the original
    head, _ = head_cut(body)
    head_there = surface_distances(head.vertices, head.faces, vertices, faces, SAMPLES)[0]
    remeshed_head = cut_above(vertices, faces, neck_height(body))
    head_back = surface_distances(*remeshed_head[:2], body.vertices, body.faces, SAMPLES)[0]
    assert max(head_there.mean(), head_back.mean()) <= head_mean
    assert max(head_there.max(), head_back.max()) <= head_worst


@pytest.mark.parametrize("method", METHODS)
def test_a_remesh_has_other_triangles_and_another_vertex_order(remeshes, body, method):
    vertices, faces = remeshes(method, 20_000)
    # another order: a vertex's id says nothing about the id of the original vertex nearest to it
    nearest = cKDTree(body.vertices).query(vertices)[1]
    assert abs(np.corrcoef(np.arange(len(vertices)), nearest)[0, 1]) < 0.05
    centres = vertices[faces].mean(axis=1)
    nearest_face = cKDTree(body.vertices[body.faces].mean(axis=1)).query(centres)[1]
    assert abs(np.corrcoef(np.arange(len(faces)), nearest_face)[0, 1]) < 0.05
    # no vertex of the original survives
    assert cKDTree(body.vertices).query(vertices)[0].min() > 1e-9
    # other triangle sizes: the original's edges vary by 0.93 of their mean
    lengths = np.linalg.norm(vertices[faces] - vertices[faces[:, [1, 2, 0]]], axis=2).ravel()
    spread = lengths.std() / lengths.mean()
    assert spread < 0.25 if method == "isotropic" else spread > 0.4


def test_one_seed_gives_one_remesh_and_two_seeds_two(body, remeshes):
    first = remeshes("isotropic", 5_000, seed=3)
    again = remesh(body.vertices, body.faces, 5_000, "isotropic", seed=3)
    other = remeshes("isotropic", 5_000, seed=4)
    np.testing.assert_array_equal(first[0], again[0])
    np.testing.assert_array_equal(first[1], again[1])
    assert cKDTree(other[0]).query(first[0])[0].mean() > 1 * MM  # other vertices, not only another order


def test_a_remeshed_character_has_no_rig(body):
    character = remeshed_character(body, 5_000, "decimate", seed=2)
    assert character.skeleton is None and character.weights is None
    assert character.name == "makehuman:heavy-male~decimate-5000-s2"
    assert character.n_vertices == 5_000


def test_bad_arguments_are_refused(body):
    with pytest.raises(InputError, match="unknown remesh method"):
        remesh(body.vertices, body.faces, 5_000, "voxel")
    with pytest.raises(InputError, match="at least 100"):
        remesh(body.vertices, body.faces, 10)
    with pytest.raises(InputError, match="no face lies above"):
        cut_above(body.vertices, body.faces, 10.0)
    with pytest.raises(InputError, match="no skeleton"):
        head_cut(remeshed_character(body, 5_000))


def test_splitting_long_edges_is_crack_free_and_keeps_the_surface():
    # a tetrahedron with one long edge, split down to edges of at most 0.3
    vertices = np.array([[0, 0, 0], [2, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    points, triangles = split_long_edges(vertices, faces, 0.3)
    np.testing.assert_array_equal(points[:4], vertices)
    lengths = np.linalg.norm(points[triangles] - points[triangles[:, [1, 2, 0]]], axis=2)
    assert lengths.max() <= 0.3
    undirected, directed = edge_uses(triangles)
    assert (undirected == 2).all() and (directed == 1).all()
    assert signed_volume(points, triangles) == pytest.approx(signed_volume(vertices, faces))
    area = np.linalg.norm(np.cross(points[triangles[:, 1]] - points[triangles[:, 0]],
                                   points[triangles[:, 2]] - points[triangles[:, 0]]), axis=1).sum()
    original = np.linalg.norm(np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]],
                                       vertices[faces[:, 2]] - vertices[faces[:, 0]]), axis=1).sum()
    assert area == pytest.approx(original)


def test_a_head_cut_keeps_the_head_and_upper_neck_with_one_border(presets):
    for character in presets.values():
        head, kept = head_cut(character)
        height = neck_height(character)
        assert (np.diff(kept) > 0).all()
        np.testing.assert_array_equal(head.vertices, character.vertices[kept])
        assert head.vertices[:, 1].min() >= height
        assert len(boundary_loops(head.faces)) == 1 and components(head.faces) == 1
        assert head.weights.shape == (len(kept), character.skeleton.n_bones)
        assert 3_500 < head.n_vertices < 5_000


@pytest.mark.parametrize("method", METHODS)
def test_cuts_of_a_remesh_have_the_borders_of_the_originals_cuts(body, remeshes, method):
    vertices, faces = remeshes(method, 20_000)
    target = remeshed_character(body, 20_000, method, SEED)
    np.testing.assert_array_equal(target.vertices, vertices)
    head, kept = head_cut(target, neck_height(body))
    bust, _ = bust_cut(target, chest_height(body))
    assert len(boundary_loops(head.faces)) == 1
    assert len(boundary_loops(bust.faces)) == 3  # the chest and both upper arms
    assert len(boundary_loops(bust_cut(body)[0].faces)) == 3
    for part in (head, bust):
        assert components(part.faces) == 1
        uses = np.unique(np.sort(part.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0,
                         return_counts=True)[1]
        assert uses.max() == 2
    np.testing.assert_array_equal(head.vertices, vertices[kept])
    assert head.skeleton is None


@pytest.mark.parametrize("method", METHODS)
def test_an_open_mesh_remeshes_with_its_border(presets, method):
    head, _ = head_cut(presets["average-female"])
    vertices, faces = remesh(head.vertices, head.faces, 5_000, method, seed=0)
    assert abs(len(vertices) - 5_000) <= 0.15 * 5_000
    assert len(boundary_loops(faces)) == 1 and components(faces) == 1
    assert min_angles_deg(vertices, faces).min() >= MIN_ANGLE_DEG[method]
    there, back = surface_distances(head.vertices, head.faces, vertices, faces, SAMPLES)
    assert max(there.mean(), back.mean()) <= 0.2 * MM
    assert max(there.max(), back.max()) <= 4 * MM


def test_surface_distances_of_a_shifted_copy():
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=float)
    faces = np.array([[0, 1, 2]])
    there, back = surface_distances(vertices, faces, vertices + [0, 0, 0.01], faces, 1_000)
    np.testing.assert_allclose(there, 0.01)
    np.testing.assert_allclose(back, 0.01)
