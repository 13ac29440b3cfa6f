"""MakeHuman busts (solver/synthetic/makehuman/bust.py): extra shells, the chest cut, open eye
sockets and fins, on one topology for every shape.

``assets`` (tests/solver/synthetic/conftest.py) skips without the MakeHuman assets.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from hairport.solver.mesh.shells import edge_table, shell_labels
from hairport.solver.mesh.topology import boundary_loops
from hairport.solver.model.character import check_same_topology
from hairport.solver.model.errors import InputError
from hairport.solver.synthetic.makehuman import build_preset
from hairport.solver.synthetic.makehuman.bust import FIN_DEPTH_M, build_bust, cut_height, helper_quads, shell_geometry
from hairport.solver.synthetic.makehuman.store import asset_store

#: vertices and faces of the extra shells: eyes 72 / 140 each, teeth 68 + 1 centre / 96 + 38 fan each
EYE_SIZE, TEETH_SIZE = (72, 140), (69, 134)


def signed_volume(vertices, faces):
    corners = vertices[faces]
    return float(np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])).sum() / 6.0)


@pytest.fixture(scope="module")
def busts(assets):
    return {name: build_bust(name, assets) for name in ("average-female", "heavy-male")}


def test_a_bust_carries_closed_eyes_and_teeth_and_is_open_at_the_chest(assets, busts):
    bust = busts["average-female"]
    body = build_preset("average-female", assets)
    labels = shell_labels(bust.faces)
    sizes = np.bincount(labels)
    assert sorted(sizes.tolist()) == [134, 134, 140, 140, 11118]
    skin = labels == np.argmax(sizes)
    # the skin: the body's faces above the cut (decided on the base mesh), on the body's positions
    n_skin = len(np.unique(bust.faces[skin]))
    assert bust.n_vertices == n_skin + 2 * EYE_SIZE[0] + 2 * TEETH_SIZE[0] == 5892
    assert cut_height(body) == pytest.approx(0.308, abs=0.01)
    assert bust.vertices[:n_skin, 1].min() > 0.25 and body.vertices[:, 1].min() < -0.8
    distance, _ = cKDTree(body.vertices).query(bust.vertices[:n_skin])
    assert distance.max() == 0.0
    # the cut leaves three borders: the chest and both arms
    loops = boundary_loops(bust.faces[skin])
    assert sorted(len(loop) for loop in loops) == [29, 29, 46]
    # the shells are closed, outward and no edge is non-manifold
    edges = edge_table(bust.faces)
    assert edges.border.sum() == 104 and (edges.count <= 2).all()
    for k in np.flatnonzero(sizes < 1000):
        faces = bust.faces[labels == k]
        assert edge_table(faces).border.sum() == 0
        assert signed_volume(bust.vertices, faces) > 0
    # skinned to the head alone; the body rows sum to 1
    head = bust.skeleton.index("head")
    weights = bust.weights.toarray()
    np.testing.assert_allclose(weights.sum(axis=1), 1.0, atol=1e-9)
    assert (weights[n_skin:, head] == 1.0).all()


def test_every_shape_has_the_same_faces(busts):
    check_same_topology(busts["average-female"], busts["heavy-male"])
    female, male = busts["average-female"], busts["heavy-male"]
    # the heavy male's eyes sit where his head is: farther apart than hers
    labels = shell_labels(female.faces)
    eyes = [np.unique(female.faces[labels == k]) for k in np.flatnonzero(np.bincount(labels) == EYE_SIZE[1])]
    apart = [np.linalg.norm(c.vertices[eyes[0]].mean(0) - c.vertices[eyes[1]].mean(0)) for c in (female, male)]
    assert 0.05 < apart[0] < apart[1] < 0.08


def test_open_eyes_and_fins(assets):
    bust = build_bust("average-female", assets, open_eyes=True, fins=3)
    plain = build_bust("average-female", assets)
    edges = edge_table(bust.faces)
    assert (edges.count == 3).sum() == 3  # one non-manifold edge per fin
    labels = shell_labels(bust.faces)
    sizes = np.bincount(labels)
    assert sorted(sizes.tolist())[:3] == [1, 1, 1]
    skin = labels == np.argmax(sizes)
    loops = sorted(len(loop) for loop in boundary_loops(bust.faces[skin]))
    assert loops == [29, 29, 30, 30, 46]  # two eye openings besides the cut
    assert skin.sum() < (shell_labels(plain.faces) == 0).sum() - 1000  # the eyelids' pockets went too
    # the fins' tips lie inside the body
    tips = bust.vertices[-3:]
    corners = bust.vertices[bust.faces[-3:, :2]].mean(axis=1)
    np.testing.assert_allclose(np.linalg.norm(tips - corners, axis=1), FIN_DEPTH_M, rtol=1e-9)


def test_teeth_are_closed_by_a_fan(assets):
    store = asset_store(assets)
    average, triangles = shell_geometry(helper_quads(store.assets)["helper-upper-teeth"], store.model.vertices, True)
    assert average.shape == (TEETH_SIZE[0], store.model.vertices.shape[0]) and len(triangles) == TEETH_SIZE[1]
    np.testing.assert_allclose(np.asarray(average.sum(axis=1)).ravel(), 1.0)
    assert average[-1].nnz == 38  # the centre of the 38-vertex border loop
    assert edge_table(triangles).border.sum() == 0
    open_average, open_triangles = shell_geometry(helper_quads(store.assets)["helper-upper-teeth"],
                                                  store.model.vertices, False)
    assert len(open_triangles) == 96 and len(boundary_loops(open_triangles)) == 1


def test_bad_options_are_refused(assets):
    with pytest.raises(InputError, match="unknown helper shell 'helper-hat'"):
        build_bust("average-female", assets, shells=("helper-hat",))
    with pytest.raises(InputError, match="unknown preset"):
        build_bust("giant", assets)
