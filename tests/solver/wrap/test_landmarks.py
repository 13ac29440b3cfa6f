"""Tests for solver/wrap/landmarks.py: landmarks derived from a head, and bound to the fitted patch."""

from __future__ import annotations

import numpy as np

from hairport.solver.body.head_frame import mesh_head_frame
from hairport.solver.model.character import Character
from hairport.solver.wrap.landmarks import Landmarks, bind_landmarks, derived_landmarks, head_landmarks


def test_head_landmarks_are_the_skull_s_extreme_points(toys):
    source = toys[0]
    frame = mesh_head_frame(Character(source.vertices, source.faces))
    points = head_landmarks(source.vertices, frame)
    assert set(points) == {"vertex", "back", "left", "right", "nose"}
    head = source.vertices[frame.head_vertices]
    assert points["vertex"][1] == head[:, 1].max()
    assert points["nose"][2] > points["back"][2] + 0.15  # the face is toward +Z
    assert points["left"][0] > 0.05 > -0.05 > points["right"][0]  # the character's left is +X
    # the same rule on a moved copy names the moved points
    moved = source.vertices + [0.0, 0.2, 0.0]
    pairs = derived_landmarks(source.vertices, frame, moved, mesh_head_frame(Character(moved, source.faces)))
    for name, (a, b) in pairs.items():
        np.testing.assert_allclose(b - a, [0.0, 0.2, 0.0], atol=1e-12, err_msg=name)


def test_bind_keeps_the_landmarks_on_the_patch(toys):
    source = toys[0]
    face = 100
    corners = source.faces[face]
    point = source.vertices[corners].T @ np.array([0.2, 0.3, 0.5])
    fitted = np.unique(source.faces[:400])  # a patch holding face 100
    far = source.vertices[source.faces[-1, 0]]  # a vertex of the last face: off the patch
    bound = bind_landmarks({"on": (point, [1.0, 2.0, 3.0]), "off": (far, [0.0, 0.0, 0.0])},
                           source.vertices, source.faces, fitted)
    assert bound.names == ("on",)
    np.testing.assert_array_equal(fitted[bound.corners[0]], corners)
    np.testing.assert_allclose(bound.weights[0], [0.2, 0.3, 0.5], atol=1e-9)
    np.testing.assert_allclose(bound.targets[0], [1.0, 2.0, 3.0])
    assert bind_landmarks({}, source.vertices, source.faces, fitted).names == ()
    assert Landmarks.none().corners.shape == (0, 3)
