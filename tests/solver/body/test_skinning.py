"""Tests for solver/body/skinning.py: nearest visible bone, Laplacian smoothing."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import trimesh

from hairport.solver.body.skinning import MIN_DERIVED_WEIGHT, derive_skin_weights, nearest_visible_bones, smooth_weights
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.character import Skeleton

#: two triangles sharing the edge 1-2, and vertex 4 on no face
STRIP_FACES = np.array([[0, 1, 2], [1, 3, 2]])


def test_one_smoothing_step_averages_the_neighbours():
    hard = sp.csr_matrix(np.array([[1.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.0, 1.0], [1.0, 0.0]]))
    smoothed = smooth_weights(hard, STRIP_FACES, 1).toarray()
    # W <- W / 2 + (mean of the neighbours' W) / 2; vertex 4 has no neighbour and keeps its row
    np.testing.assert_allclose(
        smoothed, [[0.75, 0.25], [2 / 3, 1 / 3], [1 / 3, 2 / 3], [0.25, 0.75], [1.0, 0.0]], rtol=1e-15, atol=0
    )


def test_small_weights_are_dropped():
    weights = sp.csr_matrix(np.array([[1.0 - MIN_DERIVED_WEIGHT / 2, MIN_DERIVED_WEIGHT / 2], [0.5, 0.5]]))
    pruned = smooth_weights(weights, np.array([[0, 1, 0]]), 0)
    assert pruned.nnz == 3 and pruned[0, 1] == 0.0
    np.testing.assert_allclose(pruned.toarray(), [[1.0, 0.0], [0.5, 0.5]], rtol=1e-15, atol=0)


def test_nearest_bone_without_obstacles():
    # an icosahedron around two bones: every vertex sees both (convex), so the nearest one wins
    ico = trimesh.creation.icosphere(subdivisions=0, radius=1.0)
    skeleton = Skeleton(("left", "right"), [-1, -1], [[-0.5, 0, 0], [0.5, 0, 0]], [[-0.4, 0, 0], [0.4, 0, 0]])
    bone = nearest_visible_bones(ico.vertices, skeleton, MeshQuery(ico.vertices, ico.faces))
    expected = np.where(ico.vertices[:, 0] > 0, 1, 0)
    expected[ico.vertices[:, 0] == 0] = 0  # a tie goes to the first bone (stable order)
    np.testing.assert_array_equal(bone, expected)


def test_no_bones_gives_an_empty_matrix():
    ico = trimesh.creation.icosphere(subdivisions=0)
    weights = derive_skin_weights(ico.vertices, ico.faces, Skeleton((), [], np.zeros((0, 3)), np.zeros((0, 3))))
    assert weights.shape == (len(ico.vertices), 0)


@pytest.mark.parametrize("smoothing", [0, 2])
def test_derived_rows_sum_to_one_and_follow_the_bones(smoothing):
    sphere = trimesh.creation.icosphere(subdivisions=2)
    skeleton = Skeleton(("low", "high"), [-1, 0], [[0, 0, -0.6], [0, 0, 0.0]], [[0, 0, 0.0], [0, 0, 0.6]])
    weights = derive_skin_weights(sphere.vertices, sphere.faces, skeleton, smoothing=smoothing)
    np.testing.assert_allclose(np.asarray(weights.sum(axis=1)).ravel(), 1.0, rtol=1e-15)
    bone = weights.toarray().argmax(axis=1)
    assert (bone[sphere.vertices[:, 2] < -0.5] == 0).all() and (bone[sphere.vertices[:, 2] > 0.5] == 1).all()


def test_derived_weights_respect_visibility():
    """A vertex of sphere A nearer to bone b (inside sphere B, behind B's wall) goes to bone a."""
    a = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    b = trimesh.creation.icosphere(subdivisions=2, radius=0.5)
    vertices = np.concatenate([a.vertices, b.vertices + [2.0, 0.0, 0.0]])
    faces = np.concatenate([a.faces, b.faces + len(a.vertices)])
    skeleton = Skeleton(("a", "b"), [-1, -1], [[-0.05, 0, 0], [1.6, 0, -0.05]], [[0.05, 0, 0], [1.6, 0, 0.05]])
    weights = derive_skin_weights(vertices, faces, skeleton, smoothing=0).toarray()
    right_pole = int(np.argmax(a.vertices[:, 0]))
    assert np.linalg.norm(vertices[right_pole] - [1.6, 0, 0]) < np.linalg.norm(vertices[right_pole])
    assert weights[right_pole, 0] == 1.0
    assert (weights[: len(a.vertices), 0] == 1.0).all()
    assert (weights[len(a.vertices):, 1] == 1.0).all()
    smoothed = derive_skin_weights(vertices, faces, skeleton)
    np.testing.assert_allclose(smoothed.toarray(), weights)  # no edges join the spheres
