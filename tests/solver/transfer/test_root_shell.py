"""Roots on the skin (solver/transfer/root_shell.py): roots closer to another piece of the mesh
move onto the piece that carries the roots, on a hand-made skin with a small closed shell
above it and on a MakeHuman bust with eyes."""

import numpy as np
import pytest

from hairport.solver.mesh.query import MeshQuery
from hairport.solver.mesh.shells import shell_labels
from hairport.solver.synthetic.makehuman.bust import build_bust
from hairport.solver.transfer.anchors import compute_anchors
from hairport.solver.transfer.root_shell import snap_roots_to_skin
from tests.solver.triangle_grids import grid

#: a 10 cm square of skin (z = 0) in 1 cm cells, and a closed tetrahedron (an "eye") whose
#: lowest face lies 2 mm above the skin around (5 cm, 5 cm)
POINTS_2D, SKIN = grid(10, 10, 0.0, 0.1, 0.0, 0.1)
EYE_POINTS = np.array([[0.045, 0.045, 0.002], [0.055, 0.045, 0.002], [0.05, 0.055, 0.002], [0.05, 0.05, 0.012]])
EYE = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]]) + len(POINTS_2D)
VERTICES = np.vstack([np.column_stack([POINTS_2D, np.zeros(len(POINTS_2D))]), EYE_POINTS])
FACES = np.vstack([SKIN, EYE])


def roots_over_the_skin(height):
    """Twenty roots 3 mm over the skin in a row at y = 2 cm, and one ``height`` (m) above
    the skin under the eye's lowest face."""
    row = np.column_stack([np.linspace(0.01, 0.09, 20), np.full(20, 0.02), np.full(20, 0.003)])
    return np.vstack([row, [[0.05, 0.049, height]]])


def test_a_root_closer_to_an_eye_than_to_the_skin_moves_onto_the_skin():
    query = MeshQuery(VERTICES, FACES)
    points = roots_over_the_skin(0.0018)  # the last: 0.2 mm below the eye's face, 1.8 mm above the skin
    is_root = np.ones(len(points), dtype=bool)
    surface = query.signed_distance(points)
    labels = shell_labels(FACES)
    assert labels[surface.faces[-1]] != labels[0]  # anchored on the eye
    snapped, moved = snap_roots_to_skin(query, points, surface, is_root)
    assert moved == 1
    assert labels[snapped.faces[-1]] == labels[0]
    np.testing.assert_allclose(snapped.closest[-1], [0.05, 0.049, 0.0], atol=1e-12)
    assert snapped.distance[-1] == pytest.approx(0.0018)
    # the other roots and the input are untouched
    np.testing.assert_array_equal(snapped.faces[:-1], surface.faces[:-1])
    assert labels[surface.faces[-1]] != labels[0]


def test_roots_mostly_on_another_piece_stay_where_they_are():
    query = MeshQuery(VERTICES, FACES)
    points = roots_over_the_skin(0.0018)
    # 3 of the 21 roots on the eye: the skin holds less than 90%
    points[:2] = [[0.05, 0.049, 0.0019], [0.051, 0.049, 0.0019]]
    surface = query.signed_distance(points)
    labels = shell_labels(FACES)
    assert (labels[surface.faces] != labels[0]).sum() == 3
    snapped, moved = snap_roots_to_skin(query, points, surface, np.ones(len(points), dtype=bool))
    assert moved == 0 and np.array_equal(snapped.faces, surface.faces)
    # particles that are not roots are never moved
    snapped, moved = snap_roots_to_skin(query, points, surface, np.zeros(len(points), dtype=bool))
    assert moved == 0


def test_a_root_in_front_of_a_makehuman_eye_is_anchored_on_the_skin():
    bust = build_bust("average-female")
    labels = shell_labels(bust.faces)
    skin = np.argmax(np.bincount(labels))
    query = MeshQuery(bust.vertices, bust.faces)
    # the point of the left eyeball (the first shell after the body) farthest out of the
    # skin (the eyes show between the lids, 3 mm out), and a root 0.5 mm off it
    eye_faces = np.flatnonzero(labels == labels[np.flatnonzero(labels != skin)[0]])
    eye = bust.vertices[np.unique(bust.faces[eye_faces])]
    out = MeshQuery(bust.vertices, bust.faces[labels == skin]).signed_distance(eye).distance
    assert 0.003 < out.max() < 0.004
    tip = eye[np.argmax(out)]
    tip = tip + 0.0005 * (tip - eye.mean(axis=0)) / np.linalg.norm(tip - eye.mean(axis=0))
    # a forehead groom's roots: 30 points 3 mm over the forehead's skin, plus the root at the eye
    forehead = bust.vertices[(bust.vertices[:, 1] > 0.70) & (bust.vertices[:, 2] > 0.08)][:30]
    found = query.signed_distance(forehead)
    strands = np.vstack([forehead + 0.003 * found.normal, tip])
    points = np.repeat(strands, 2, axis=0)
    points[1::2] += [0.0, 0.0, 0.01]  # each root with one particle 1 cm before it
    is_root = np.zeros(len(points), dtype=bool)
    is_root[::2] = True
    assert labels[query.signed_distance(points[-2:-1]).faces[0]] != skin  # closest to the eye
    anchors = compute_anchors(bust, points, is_root, query)
    assert (labels[anchors.face[is_root]] == skin).all()
    assert (anchors.bone[is_root] == -1).all()
