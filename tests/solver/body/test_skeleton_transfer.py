"""Tests for solver/body/skeleton_transfer.py: joint regressor, skeleton transfer, ensure_skeleton."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from hairport.solver.body.skeleton_transfer import (
    JointRegressor,
    ensure_skeleton,
    fit_joint_regressor,
    sphere_directions,
    transfer_skeleton,
)
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.character import Character, Skeleton
from hairport.solver.model.errors import InputError, TopologyMismatch
from tests.solver.capsule import BODY_RADIUS, capsule_mesh, chain_skeleton


def make_body_mesh() -> tuple[np.ndarray, np.ndarray]:
    """The capsule with 30 rings of 24 vertices, as triangles."""
    return capsule_mesh(30, 24)


def make_character(offset_x: float = 0.0) -> Character:
    """The body with a 3-bone chain along z (shifted by ``offset_x``) and smooth weights."""
    vertices, faces = make_body_mesh()
    skeleton = chain_skeleton(offset_x)
    centre = 0.5 * (skeleton.heads + skeleton.tails)
    d2 = ((vertices[:, None, 2] - centre[None, :, 2]) / 0.2) ** 2
    w = np.exp(-d2)
    w[w < 1e-3] = 0
    w /= w.sum(axis=1, keepdims=True)
    return Character(vertices, faces, skeleton, sp.csr_matrix(w), name="body")


def bulge(points: np.ndarray) -> np.ndarray:
    """A smooth non-affine body change: wider belly, flatter front-back, taller, shifted."""
    x, y, z = points.T
    s = 1.0 + 0.4 * np.exp(-(((z - 0.1) / 0.25) ** 2))
    return np.stack([x * s, y * s * 0.85, 1.1 * z + 0.02], axis=1)


@pytest.fixture(scope="module")
def body() -> Character:
    return make_character()


@pytest.fixture(scope="module")
def regressor(body) -> JointRegressor:
    return fit_joint_regressor(body)


def test_regressor_rows_are_affine_and_sparse(body, regressor):
    assert regressor.matrix.shape == (2 * body.skeleton.n_bones, body.n_vertices)
    np.testing.assert_allclose(np.asarray(regressor.matrix.sum(axis=1)).ravel(), 1.0, atol=1e-12)
    assert regressor.matrix.getnnz(axis=1).max() < body.n_vertices // 2


def test_reflexive(body, regressor):
    skeleton = regressor.apply(body.vertices)
    np.testing.assert_allclose(skeleton.heads, body.skeleton.heads, atol=1e-10, rtol=0)
    np.testing.assert_allclose(skeleton.tails, body.skeleton.tails, atol=1e-10, rtol=0)
    assert skeleton.names == body.skeleton.names
    np.testing.assert_array_equal(skeleton.parents, body.skeleton.parents)


def test_affine_equivariance(body, regressor):
    rng = np.random.default_rng(7)
    q1, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q2, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    a = q1 @ np.diag(rng.uniform(0.7, 1.4, 3)) @ q2  # well conditioned, may reflect
    t = rng.normal(size=3)
    target = body.vertices @ a.T + t
    skeleton = transfer_skeleton(body, target, regressor=regressor)
    np.testing.assert_allclose(skeleton.heads, body.skeleton.heads @ a.T + t, atol=1e-9, rtol=0)
    np.testing.assert_allclose(skeleton.tails, body.skeleton.tails @ a.T + t, atol=1e-9, rtol=0)


@pytest.mark.parametrize("offset_x", [0.0, 0.07])
def test_joints_stay_inside_deformed_body(offset_x):
    source = make_character(offset_x)
    target_vertices = bulge(source.vertices)
    skeleton = transfer_skeleton(source, target_vertices)
    joints = np.concatenate([skeleton.heads, skeleton.tails])
    distance = MeshQuery(target_vertices, source.faces).signed_distance(joints).distance
    assert (distance < 0).all(), distance
    # and close to where the deformation takes them (the map is smooth, the body is 0.15 m wide)
    expected = bulge(np.concatenate([source.skeleton.heads, source.skeleton.tails]))
    error = np.linalg.norm(joints - expected, axis=1)
    assert error.max() < 0.25 * BODY_RADIUS, error


@pytest.mark.parametrize("offset_x", [0.0, 0.07, 0.11])
def test_regressor_is_insensitive_to_surface_noise(offset_x):
    """Joint noise per unit vertex noise is the row L2 norm of the weights: keep it small.

    (The 24 nearest vertices of an off-centre joint lie on one side; their weights reach an
    L2 norm of ~0.9 there, the all-sides support stays near 0.1.)
    """
    regressor = fit_joint_regressor(make_character(offset_x))
    gain = np.sqrt(np.asarray(regressor.matrix.multiply(regressor.matrix).sum(axis=1)).ravel())
    assert gain.max() < 0.2, gain


def test_coincident_joints_stay_coincident(body, regressor):
    skeleton = regressor.apply(bulge(body.vertices))
    children = np.flatnonzero(skeleton.parents >= 0)
    np.testing.assert_array_equal(skeleton.heads[children], skeleton.tails[skeleton.parents[children]])


def test_joint_outside_body_is_still_exact():
    vertices, faces = make_body_mesh()
    skeleton = Skeleton(("a", "b"), [-1, 0], [[0, 0, 0.2], [0, 0, 0.6]], [[0, 0, 0.6], [0, 0.05, 0.9]])
    character = Character(vertices, faces, skeleton)
    regressor = fit_joint_regressor(character)
    np.testing.assert_allclose(regressor.apply(vertices).tails, skeleton.tails, atol=1e-10, rtol=0)
    shifted = regressor.apply(vertices * 1.2 + 0.1)
    np.testing.assert_allclose(shifted.tails, skeleton.tails * 1.2 + 0.1, atol=1e-9, rtol=0)


def test_open_mesh_without_caps():
    source = make_character()
    n_around = 24
    open_faces = source.faces[n_around:-n_around]  # drop both caps
    character = Character(source.vertices, open_faces, source.skeleton, source.weights)
    regressor = fit_joint_regressor(character)
    skeleton = regressor.apply(character.vertices)
    np.testing.assert_allclose(skeleton.heads, source.skeleton.heads, atol=1e-10, rtol=0)


def test_ensure_skeleton_carries_weights_over(body, regressor):
    target = Character(bulge(body.vertices), body.faces, name="target")
    rigged = ensure_skeleton(body, target, regressor=regressor)
    assert rigged.name == "target"
    assert rigged.weights is body.weights or (rigged.weights != body.weights).nnz == 0
    np.testing.assert_array_equal(rigged.vertices, target.vertices)
    assert rigged.skeleton.names == body.skeleton.names
    assert ensure_skeleton(body, rigged) is rigged  # already rigged: unchanged


def test_ensure_skeleton_checks_topology_and_skeletons(body):
    other = Character(body.vertices, body.faces[::-1], name="flipped")
    with pytest.raises(TopologyMismatch):
        ensure_skeleton(body, other)
    bare = Character(body.vertices, body.faces)
    with pytest.raises(InputError) as error:
        ensure_skeleton(bare, Character(body.vertices, body.faces))
    assert error.value.code == "no_skeleton"


def test_transfer_rejects_wrong_shapes(body, regressor):
    with pytest.raises(InputError):
        transfer_skeleton(body, body.vertices[:-1], regressor=regressor)
    bad = body.vertices.copy()
    bad[3, 1] = np.nan
    with pytest.raises(InputError):
        transfer_skeleton(body, bad, regressor=regressor)
    with pytest.raises(InputError):
        fit_joint_regressor(Character(body.vertices, body.faces))


def test_sphere_directions_are_unit_and_balanced():
    d = sphere_directions(64)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0)
    assert np.linalg.norm(d.mean(axis=0)) < 0.05
