"""Initial transfer, anchoring (solver/transfer/anchors.py, Eq. 2-3): anchors on the source, placed on a target."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.character import Character
from hairport.solver.model.errors import InputError
from hairport.solver.transfer.anchors import (
    ANCHOR_AUTO,
    ANCHOR_BY_BONES,
    ANCHOR_BY_SURFACE,
    compute_anchors,
    place_anchors,
    resolve_anchoring,
    root_targets,
    surface_anchors,
)
from tests.solver.hair_shapes import ellipsoid_head, hanging_groom, outward_strands, sphere_character


def test_reflexive_anchoring_reproduces_particles():
    source = sphere_character()
    hair = outward_strands(source)
    anchors = compute_anchors(source, hair.points, hair.is_root)
    assert not anchors.fallback.any()
    np.testing.assert_allclose(place_anchors(anchors, source), hair.points, atol=1e-12)


def test_anchoring_follows_a_translation_and_uniform_scale_about_the_bone():
    source = sphere_character()
    hair = outward_strands(source)
    anchors = compute_anchors(source, hair.points, hair.is_root)
    moved = sphere_character(shift=(0.05, 0.02, -0.01))
    np.testing.assert_allclose(place_anchors(anchors, moved), hair.points + [0.05, 0.02, -0.01], atol=1e-12)
    # a uniformly scaled head: hit points scale, the distance beyond the surface is kept
    scaled = sphere_character(scale=(1.2, 1.2, 1.2))
    placed = place_anchors(anchors, scaled)
    surface = MeshQuery(scaled.vertices, scaled.faces).signed_distance(placed[~hair.is_root]).distance
    original = MeshQuery(source.vertices, source.faces).signed_distance(hair.points[~hair.is_root]).distance
    np.testing.assert_allclose(surface, original, atol=2e-3)


def test_roots_land_on_the_target_surface():
    source = sphere_character()
    hair = outward_strands(source)
    anchors = compute_anchors(source, hair.points, hair.is_root)
    target = sphere_character(scale=(1.15, 0.9, 1.05))
    roots = place_anchors(anchors, target)[hair.roots]
    assert np.abs(MeshQuery(target.vertices, target.faces).signed_distance(roots).distance).max() < 1e-12


def test_surface_anchors_reproduce_roots():
    head = ellipsoid_head()
    hair = hanging_groom(head)
    query = MeshQuery(head.vertices, head.faces)
    faces, bary = surface_anchors(query, query.signed_distance(hair.points[hair.roots]))
    assert faces.shape == (hair.n_strands,) and bary.shape == (hair.n_strands, 3)
    np.testing.assert_allclose(bary.sum(axis=1), 1.0, atol=1e-12)
    assert (bary > -1e-9).all()
    np.testing.assert_allclose(root_targets(head, faces, bary), hair.points[hair.roots], rtol=0, atol=1e-12)


def test_roots_are_anchored_at_their_closest_surface_point():
    """compute_anchors anchors roots by surface_anchors (no bone), and root_targets places them."""
    source = sphere_character()
    hair = outward_strands(source)
    anchors = compute_anchors(source, hair.points, hair.is_root)
    query = MeshQuery(source.vertices, source.faces)
    faces, bary = surface_anchors(query, query.signed_distance(hair.points[hair.roots]))
    np.testing.assert_array_equal(anchors.face[hair.roots], faces)
    np.testing.assert_array_equal(anchors.barycentric[hair.roots], bary)
    assert (anchors.bone[hair.roots] == -1).all() and (anchors.eta[hair.roots] == 0).all()
    assert (anchors.bone[~hair.is_root] >= 0).all()  # the rest hangs from the head bone
    target = sphere_character(scale=(1.15, 0.9, 1.05), shift=(0.01, 0.0, 0.0))
    np.testing.assert_array_equal(root_targets(target, faces, bary), place_anchors(anchors, target)[hair.roots])
    # the root targets are the source roots' barycentric positions on the target's faces
    corners = target.vertices[target.faces[faces]]
    np.testing.assert_allclose(root_targets(target, faces, bary), np.einsum("sk,skd->sd", bary, corners), atol=1e-15)


def test_anchoring_by_bones_needs_a_rigged_source():
    source = sphere_character()
    hair = outward_strands(source, n_strands=3)
    bare = Character(source.vertices, source.faces, name="bare")
    with pytest.raises(InputError, match="no skeleton") as error:
        compute_anchors(bare, hair.points, hair.is_root)
    assert error.value.code == "no_skeleton"
    with pytest.raises(InputError, match="anchor by the surface") as error:
        resolve_anchoring(ANCHOR_BY_BONES, bare)
    assert error.value.code == "no_skeleton"


@pytest.mark.parametrize("rigged, asked, resolved", [
    (True, ANCHOR_AUTO, ANCHOR_BY_BONES), (False, ANCHOR_AUTO, ANCHOR_BY_SURFACE),
    (True, ANCHOR_BY_SURFACE, ANCHOR_BY_SURFACE), (False, ANCHOR_BY_SURFACE, ANCHOR_BY_SURFACE),
    (True, ANCHOR_BY_BONES, ANCHOR_BY_BONES),
])
def test_auto_anchors_by_the_bones_only_where_the_source_has_a_rig(rigged, asked, resolved):
    source = sphere_character()
    if not rigged:
        source = Character(source.vertices, source.faces, name="bare")
    assert resolve_anchoring(asked, source) == resolved


def test_an_unknown_anchoring_is_refused_by_name():
    with pytest.raises(InputError, match="unknown anchoring 'ribs'") as error:
        resolve_anchoring("ribs", sphere_character())
    assert error.value.code == "bad_option"


def test_surface_anchoring_needs_no_rig_and_is_exact_on_the_source_and_rigid_under_a_rigid_motion():
    source = sphere_character()
    bare = Character(source.vertices, source.faces, name="bare")
    hair = outward_strands(source, n_strands=12)
    anchors = compute_anchors(bare, hair.points, hair.is_root, anchoring=ANCHOR_BY_SURFACE)
    assert (anchors.bone == -1).all() and anchors.fallback.sum() == (~hair.is_root).sum()
    assert np.abs(place_anchors(anchors, bare) - hair.points).max() < 1e-12
    # a rotated and moved body carries every particle with it: the face frames turn with the faces
    turn = Rotation.from_euler("xyz", [0.3, -0.5, 0.2]).as_matrix()
    shift = np.array([0.1, -0.2, 0.05])
    moved = Character(source.vertices @ turn.T + shift, source.faces, name="moved")
    np.testing.assert_allclose(place_anchors(anchors, moved), hair.points @ turn.T + shift, atol=1e-12)


def test_bone_anchors_on_a_target_without_a_skeleton_are_refused():
    source = sphere_character()
    hair = outward_strands(source, n_strands=3)
    anchors = compute_anchors(source, hair.points, hair.is_root)
    bare = Character(source.vertices, source.faces, name="bare")
    with pytest.raises(InputError, match="anchored by bones") as error:
        place_anchors(anchors, bare)
    assert error.value.code == "no_skeleton"
