"""Tests for solver/io/character/gltf/skin.py: bones from the joints of a glTF skin, skin weights."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from hairport.solver.io.character import load_character
from hairport.solver.io.character.bones import ISOLATED_BONE_FRACTION, LEAF_TAIL_FRACTION
from hairport.solver.model.errors import InputError
from tests.solver.io.character.samples import BONES_HEADS, GltfBuilder, rotation_x_quaternion, skinned_body_gltf


@pytest.mark.parametrize("with_inverse_bind", [True, False])
def test_glb_skin(tmp_path, with_inverse_bind):
    builder, vertices, faces, weights = skinned_body_gltf(with_inverse_bind, extra_mesh=True)
    path = tmp_path / "body.glb"
    path.write_bytes(builder.glb())
    character = load_character(path)
    # skinned mesh chosen over the bigger prop; its node transform is ignored (glTF spec)
    np.testing.assert_allclose(character.vertices, vertices, atol=1e-6)
    np.testing.assert_array_equal(character.faces, faces)
    skeleton = character.skeleton
    assert skeleton.names == ("root", "spine", "head")
    np.testing.assert_array_equal(skeleton.parents, [-1, 0, 1])
    np.testing.assert_allclose(skeleton.heads, BONES_HEADS, atol=1e-6)
    # tails: the child's head; the leaf extends half its parent distance
    np.testing.assert_allclose(skeleton.tails, [[0, 0, -0.1], [0, 0, 0.3], [0, 0, 0.5]], atol=1e-6)
    expected = np.zeros((len(vertices), 3))
    rounded = np.round(weights * 255) / 255
    joints_used = np.argsort(np.abs(vertices[:, None, 2] - (np.array(BONES_HEADS)[:, 2] + 0.2)[None]), axis=1)[:, :2]
    np.put_along_axis(expected, joints_used, rounded[:, :2], axis=1)
    expected /= expected.sum(axis=1, keepdims=True)
    np.testing.assert_allclose(character.weights.toarray(), expected, atol=1e-12)


def three_joint_box(names=("a", "b", "a"), inverse_bind=None, joints=None, weights=None, skin_joints=(0, 2, 3)):
    """A unit box skinned to joints ``a`` -> (helper, not a joint) -> ``b``, and an isolated joint turned about x."""
    box = trimesh.creation.box()
    n = len(box.vertices)
    if joints is None:
        joints = np.tile([0, 1, 2, 0], (n, 1))
        weights = np.tile([0.5, 0.25, 0.25, 0.0], (n, 1))
    builder = GltfBuilder()
    mesh = builder.mesh(box.vertices, box.faces, "box", joints, weights)
    builder.node(name=names[0], translation=[0, 1, 0], children=[1])
    builder.node(name="helper", translation=[0, 1, 0], children=[2])
    builder.node(name=names[1], translation=[0, 0, 2])
    builder.node(name=names[2], translation=[5, 0, 0], rotation=rotation_x_quaternion(np.pi / 2))
    skin = builder.skin(list(skin_joints), inverse_bind)
    builder.node(name="box", mesh=mesh, skin=skin)
    return builder, box


def test_joint_hierarchy_names_and_tails(tmp_path):
    builder, box = three_joint_box()
    path = tmp_path / "box.glb"
    path.write_bytes(builder.glb())
    character = load_character(path)
    skeleton = character.skeleton
    assert skeleton.names == ("a_0", "b", "a_2")  # repeated names get the joint index
    np.testing.assert_array_equal(skeleton.parents, [-1, 0, -1])  # b's parent skips the helper node
    np.testing.assert_allclose(skeleton.heads, [[0, 1, 0], [0, 2, 2], [5, 0, 0]], atol=1e-12)
    diagonal = np.sqrt(3.0)  # of the unit box
    np.testing.assert_allclose(
        skeleton.tails,
        [[0, 2, 2],  # the child's head
         [0, 2, 2] + LEAF_TAIL_FRACTION * np.array([0, 1, 2]),  # a leaf continues from its parent
         [5, 0, ISOLATED_BONE_FRACTION * diagonal]],  # local +Y, turned onto +z
        atol=1e-12,
    )
    # every vertex: a 0.5, b 0.25, the isolated joint 0.25 (weights stored as normalised bytes)
    np.testing.assert_allclose(character.weights.toarray(), np.tile(np.array([128, 64, 64]) / 256, (len(box.vertices), 1)))


@pytest.mark.parametrize(
    "change, code, words",
    [
        ({"skin_joints": ()}, "bad_skeleton", "no joints"),
        ({"skin_joints": (0, 0, 3)}, "bad_skeleton", "repeated joint"),
        ({"skin_joints": (0, 2, 9)}, "bad_skeleton", "invalid or repeated joint"),
        ({"inverse_bind": np.zeros((3, 4, 4))}, "bad_skeleton", "singular"),
        ({"inverse_bind": np.stack([np.eye(4)] * 2)}, "bad_skeleton", "do not match the joint count"),
        ({"joints": np.tile([0, 1, 7, 0], (8, 1)), "weights": np.tile([0.5, 0.25, 0.25, 0.0], (8, 1))},
         "bad_weights", "outside the skin"),
    ],
)
def test_bad_skins(tmp_path, change, code, words):
    builder, _ = three_joint_box(**change)
    path = tmp_path / "box.glb"
    path.write_bytes(builder.glb())
    with pytest.raises(InputError) as error:
        load_character(path)
    assert error.value.code == code and words in error.value.problem
