"""Tests for solver/body/head_frame.py: the head-aligned frame of a rigged character, and of one without a rig."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import trimesh

from hairport.solver.body.head_frame import (
    BROW_HEIGHT,
    FRAME_FROM_BONE,
    FRAME_FROM_MESH,
    HEAD_WEIGHT_MIN,
    REFERENCE_CROWN_M,
    SKULL_REFERENCE_HEIGHT,
    head_frame,
    mesh_head_frame,
)
from hairport.solver.model.character import Character, Skeleton
from hairport.solver.model.errors import InputError
from hairport.solver.synthetic.makehuman import PRESETS, build_character
from hairport.solver.synthetic.toy import HEAD_HALF_AXES_M, toy_character
from tests.solver.frames import faces_only, head_faces


@pytest.fixture(scope="module")
def toy() -> Character:
    return toy_character()


def test_axes_follow_the_head_bone(toy):
    frame = head_frame(toy)
    head = toy.skeleton.index("head")
    np.testing.assert_array_equal(frame.origin, toy.skeleton.heads[head])
    bone = toy.skeleton.tails[head] - toy.skeleton.heads[head]
    np.testing.assert_allclose(frame.up, bone / np.linalg.norm(bone), rtol=1e-15)
    # forward is +Z made orthogonal to up; side = up x forward is the character's left (+X)
    axes = np.stack([frame.up, frame.forward, frame.side])
    np.testing.assert_allclose(axes @ axes.T, np.eye(3), atol=1e-15)
    assert frame.forward[0] == 0.0 and frame.forward[2] > 0.98
    np.testing.assert_allclose(frame.side, [1.0, 0.0, 0.0], atol=1e-15)


def test_extents_measure_the_toy_head(toy):
    """The toy's skull is an ellipsoid of half-axes 0.09 (x), 0.12 (y), 0.10 (z) m whose centre
    lies 0.03 m above the head joint: the crown is 0.15 m up (the reference head)."""
    frame = head_frame(toy)
    half_x, _, half_z = HEAD_HALF_AXES_M
    assert frame.crown == pytest.approx(REFERENCE_CROWN_M, abs=1e-3)
    assert frame.half_width == pytest.approx(half_x, abs=2e-3)
    assert frame.front - frame.back == pytest.approx(2 * half_z, abs=5e-3)
    assert frame.brow_height == BROW_HEIGHT * frame.crown
    np.testing.assert_allclose(
        frame.centre, frame.world(SKULL_REFERENCE_HEIGHT * frame.crown, 0.5 * (frame.front + frame.back)), rtol=1e-15
    )
    wider = head_frame(toy_character(head_scale=(1.2, 1.0, 1.0)))
    assert wider.half_width == pytest.approx(1.2 * half_x, abs=3e-3)


def test_head_vertices_are_the_head_dominant_ones(toy):
    frame = head_frame(toy)
    head_weight = toy.weights[:, toy.skeleton.index("head")].toarray().ravel()
    total = np.asarray(toy.weights.sum(axis=1)).ravel()
    np.testing.assert_array_equal(frame.head_vertices, head_weight >= HEAD_WEIGHT_MIN * total)
    assert 1000 < frame.head_vertices.sum() < toy.n_vertices // 2
    # without skin weights every vertex above the head joint counts
    bare = head_frame(Character(toy.vertices, toy.faces, toy.skeleton))
    np.testing.assert_array_equal(bare.head_vertices, (toy.vertices - frame.origin) @ frame.up > 0)


def with_shell(toy, centre, radius, weights=True):
    """The toy with a separate closed shell (an icosphere skinned to the head alone) in its mesh."""
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=radius)
    vertices = np.vstack([toy.vertices, np.asarray(sphere.vertices) + centre])
    faces = np.vstack([toy.faces, np.asarray(sphere.faces) + toy.n_vertices])
    if not weights:
        return Character(vertices, faces, toy.skeleton)
    n = len(sphere.vertices)
    head = sp.csr_matrix((np.ones(n), (np.arange(n), np.full(n, toy.skeleton.index("head")))),
                         shape=(n, toy.skeleton.n_bones))
    return Character(vertices, faces, toy.skeleton, sp.vstack([toy.weights, head]))


@pytest.mark.parametrize("weights", [True, False])
def test_a_separate_shell_does_not_shape_the_frame(toy, weights):
    """A hat floating 3 cm over the crown and 3 cm before the brow, in the same mesh, skinned
    to the head: the frame is the one of the head alone."""
    plain = head_frame(toy if weights else Character(toy.vertices, toy.faces, toy.skeleton))
    hat = plain.world(plain.crown + 0.05, plain.front + 0.03)
    frame = head_frame(with_shell(toy, hat, 0.02, weights))
    for name in ("crown", "front", "back", "half_width"):
        assert getattr(frame, name) == getattr(plain, name), name
    np.testing.assert_array_equal(frame.head_vertices[: toy.n_vertices], plain.head_vertices)
    assert not frame.head_vertices[toy.n_vertices:].any()


def test_coordinates(toy):
    frame = head_frame(toy)
    points = toy.vertices[:50]
    local = frame.local(points)
    np.testing.assert_allclose(frame.world(*local.T), points, atol=1e-15)
    mid = 0.5 * (frame.front + frame.back)
    corners = frame.world([frame.crown, 0.0, 0.0], [mid, frame.front, frame.back], [0.0, 0.0, -frame.half_width])
    np.testing.assert_allclose(frame.normalised(corners), [[1, 0, 0], [0, 1, 0], [0, -1, -1]], atol=1e-12)


def rigged(toy, names=None, tails=None, weights=None):
    """The toy with other bone names, bone tails or skin weights."""
    skeleton = toy.skeleton
    skeleton = Skeleton(names or skeleton.names, skeleton.parents, skeleton.heads,
                        skeleton.tails if tails is None else tails)
    return Character(toy.vertices, toy.faces, skeleton, toy.weights if weights is None else weights)


def test_refusals(toy):
    head = toy.skeleton.index("head")
    along_z = toy.skeleton.tails.copy()
    along_z[head] = toy.skeleton.heads[head] + [0.0, 0.0, 0.1]
    zero_length = toy.skeleton.tails.copy()
    zero_length[head] = toy.skeleton.heads[head]
    downward = toy.skeleton.tails.copy()
    downward[head] = toy.skeleton.heads[head] - [0.0, 0.1, 0.0]
    no_head_weight = sp.csr_matrix(toy.weights.multiply(np.arange(toy.skeleton.n_bones) != head))
    # the head weights only on the skull, above the joint, with a bone that points down
    skull = toy.vertices[:, 1] > toy.skeleton.heads[head][1]
    skull_only = sp.csr_matrix((np.ones(toy.n_vertices), (np.arange(toy.n_vertices), np.where(skull, head, 0))),
                               shape=toy.weights.shape)
    cases = [
        (rigged(toy, names=tuple("skull" if n == "head" else n for n in toy.skeleton.names)), "no bone named 'head'"),
        (rigged(toy, tails=zero_length), "zero length"),
        (rigged(toy, tails=along_z), "points along Z"),
        (rigged(toy, weights=no_head_weight), "no vertex is dominated"),
        (rigged(toy, tails=downward, weights=skull_only), "below the head joint"),
    ]
    for character, words in cases:
        with pytest.raises(InputError) as error:
            head_frame(character)
        assert error.value.code == "bad_skeleton" and words in error.value.problem, words


#: how far the rigless estimate may land from the rig's head joint (m) and crown height (share)
MESH_JOINT_TOLERANCE_M = 0.02
MESH_CROWN_TOLERANCE = 0.12


@pytest.mark.parametrize("preset", sorted(PRESETS))
def test_a_head_without_a_rig_gets_its_frame_from_the_mesh_near_the_rigs(preset):
    """The MakeHuman presets with their rigs taken off: the mesh's frame against the head bone's
    (joint 0.3-1.8 cm apart, crown heights within 11 %); the same frame from the head alone, cut
    open at the neck, and in another place."""
    rigged = build_character(PRESETS[preset])
    bone = head_frame(rigged)
    bare = Character(rigged.vertices, rigged.faces, name=preset)
    mesh = head_frame(bare)
    assert (bone.source, mesh.source) == (FRAME_FROM_BONE, FRAME_FROM_MESH)
    assert np.linalg.norm(mesh.origin - bone.origin) < MESH_JOINT_TOLERANCE_M
    assert abs(mesh.crown / bone.crown - 1) < MESH_CROWN_TOLERANCE
    np.testing.assert_array_equal(np.stack([mesh.up, mesh.forward, mesh.side]), np.eye(3)[[1, 2, 0]])
    assert abs(mesh.half_width / bone.half_width - 1) < 0.02
    assert abs(mesh.front - bone.front) < 0.005 and abs(mesh.back - bone.back) < 0.005
    # the face and the skull are head; the chest is not
    a = mesh.local(rigged.vertices)[:, 0]
    assert mesh.head_vertices[a > 0].all() and not mesh.head_vertices[a < -0.5 * mesh.crown].any()

    head = faces_only(rigged, head_faces(rigged, 0.10), "head")
    cut = mesh_head_frame(head)
    np.testing.assert_allclose(cut.origin, mesh.origin, atol=1e-12)
    assert cut.crown == mesh.crown
    moved = mesh_head_frame(Character(head.vertices + [0.3, -1.0, 2.0], head.faces))
    np.testing.assert_allclose(moved.origin, mesh.origin + [0.3, -1.0, 2.0], atol=1e-12)
    # a stylised head three times the size (far from the reference crown height) scales with it
    big = mesh_head_frame(Character(3.0 * head.vertices, head.faces))
    np.testing.assert_allclose(big.origin, 3.0 * mesh.origin, atol=1e-9)
    assert big.crown == pytest.approx(3.0 * mesh.crown, rel=1e-9)


def test_a_rigless_mesh_that_is_no_head_is_refused_by_name():
    flat = Character(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), np.array([[0, 1, 2]]),
                     name="flat")
    with pytest.raises(InputError, match="no depth from the face to the back of the head") as error:
        head_frame(flat)
    assert error.value.code == "not_a_head" and error.value.source == "flat"
    sideways = Character(np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 1.0], [0.0, 0.0, 0.0]]), np.array([[0, 1, 2]]),
                         name="edge-on")
    with pytest.raises(InputError, match="no width") as error:
        head_frame(sideways)
    assert error.value.code == "not_a_head"
