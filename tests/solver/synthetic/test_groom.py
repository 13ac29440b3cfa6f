"""Tests for solver/synthetic/groom.py: the scalp, the roots and procedural grooms on the toy."""

from __future__ import annotations

import dataclasses

import igl
import numpy as np
import pytest

from hairport.solver.body.head_frame import HEAD_WEIGHT_MIN, head_frame
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.character import Character, Skeleton
from hairport.solver.model.errors import InputError
from hairport.solver.synthetic.groom import DEFAULT_CLEARANCE_M, STYLES, generate_groom, sample_roots, scalp_faces
from hairport.solver.synthetic.toy import toy_character
from tests.solver.synthetic.toy_fixtures import N_STRANDS, PARTICLES, PRESET_B

#: the solver's clearance eps_c is 0.5 mm; grooms must stay at least twice that far out
MIN_CLEARANCE_M = 1e-3


def turning_per_length(hair) -> float:
    """Total turning angle (rad) divided by total length (m)."""
    p = hair.points.reshape(hair.n_strands, -1, 3)
    d = np.diff(p, axis=1)
    length = np.linalg.norm(d, axis=2)
    u = d / length[..., None]
    angle = np.arccos(np.clip((u[:, 1:] * u[:, :-1]).sum(axis=2), -1.0, 1.0))
    return float(angle.sum() / length.sum())


@pytest.mark.parametrize("preset", [{}, PRESET_B])
def test_scalp_faces(preset):
    c = toy_character(**preset)
    frame = head_frame(c)
    scalp = scalp_faces(c, frame)
    assert scalp.dtype == np.int64 and len(scalp) > 100
    assert np.all(np.diff(scalp) > 0)
    head = c.skeleton.index("head")
    assert c.weights[:, head].toarray().ravel()[c.faces[scalp]].min() >= HEAD_WEIGHT_MIN
    local = frame.local(c.vertices[c.faces[scalp]].mean(axis=1))
    assert local[:, 0].min() > 0  # above the head joint
    # not on the face: nothing in front of the skull centre below the brows
    front_low = (local[:, 1] > 0.5 * (frame.front + frame.back)) & (local[:, 0] < frame.brow_height)
    assert not front_low.any()
    # covers the crown and the back of the head
    assert local[:, 0].max() > 0.95 * frame.crown
    assert local[:, 1].min() < frame.back + 0.02


def test_groom_needs_a_head_bone_in_a_rig_and_a_known_style(toy_a):
    sk = toy_a.skeleton
    names = tuple("skull" if n == "head" else n for n in sk.names)
    no_head = Character(toy_a.vertices, toy_a.faces, Skeleton(names, sk.parents, sk.heads, sk.tails), toy_a.weights)
    with pytest.raises(InputError, match="head"):
        generate_groom(no_head, "short", 10, 8)
    with pytest.raises(InputError, match="style"):
        generate_groom(toy_a, "mohawk", 10, 8)


def test_a_head_without_a_rig_grows_a_groom_on_its_scalp(toy_a):
    """The head frame from the mesh: roots on the surface in the rigged scalp's region, strands outside."""
    bare = Character(toy_a.vertices, toy_a.faces)
    hair = generate_groom(bare, "short", 40, 8, seed=0)
    distance = MeshQuery(bare.vertices, bare.faces).signed_distance(hair.points).distance
    assert np.abs(distance[hair.is_root]).max() < 1e-9 and distance[~hair.is_root].min() > 0
    rigged_scalp = scalp_faces(toy_a)
    shared = np.intersect1d(rigged_scalp, scalp_faces(bare))
    assert len(shared) >= 0.9 * len(rigged_scalp)


@pytest.mark.parametrize("style", STYLES)
def test_groom_layout_and_roots(style, grooms, toy_a, query_a):
    hair = grooms[style]
    assert hair.n_strands == N_STRANDS
    assert np.all(hair.counts == PARTICLES)
    assert np.isfinite(hair.points).all()
    roots = hair.points[hair.roots]
    # on the surface ...
    assert np.abs(query_a.signed_distance(roots).distance).max() < 1e-9
    # ... of the scalp
    scalp = scalp_faces(toy_a)
    sq, _, _ = igl.point_mesh_squared_distance(roots, toy_a.vertices, toy_a.faces[scalp])
    assert np.sqrt(sq).max() < 1e-9


@pytest.mark.parametrize("style", STYLES)
def test_groom_is_collision_free_on_source(style, grooms, query_a):
    hair = grooms[style]
    distance = query_a.signed_distance(hair.points[~hair.is_root]).distance
    assert distance.min() >= DEFAULT_CLEARANCE_M - 1e-9
    assert distance.min() >= MIN_CLEARANCE_M


@pytest.mark.parametrize("style", ["long", "fringe", "curly"])
def test_groom_clearance_parameter_on_other_body(style, toy_b):
    clearance = 2e-3
    hair = generate_groom(toy_b, style, 150, 20, seed=5, clearance=clearance)
    q = MeshQuery(toy_b.vertices, toy_b.faces)
    assert q.signed_distance(hair.points[~hair.is_root]).distance.min() >= clearance - 1e-9
    assert np.abs(q.signed_distance(hair.points[hair.roots]).distance).max() < 1e-9


def test_groom_seed_reproducible(toy_a, query_a):
    a = generate_groom(toy_a, "wavy", 60, 12, seed=7, query=query_a)
    b = generate_groom(toy_a, "wavy", 60, 12, seed=7, query=query_a)
    c = generate_groom(toy_a, "wavy", 60, 12, seed=8, query=query_a)
    assert np.array_equal(a.points, b.points) and np.array_equal(a.offsets, b.offsets)
    assert not np.allclose(a.points, c.points)


def test_groom_segment_lengths(grooms):
    # step length = length / (particles - 1): segments are regular except where pushed out
    hair = grooms["long"]
    seg = np.linalg.norm(np.diff(hair.points.reshape(N_STRANDS, PARTICLES, 3), axis=1), axis=2)
    ratio = seg / np.median(seg, axis=1, keepdims=True)
    assert np.median(np.abs(ratio - 1)) < 0.05


def test_short_is_short_and_close(grooms, query_a):
    hair = grooms["short"]
    p = hair.points.reshape(N_STRANDS, PARTICLES, 3)
    length = np.linalg.norm(np.diff(p, axis=1), axis=2).sum(axis=1)
    assert np.median(length) < 0.07
    assert np.linalg.norm(p[:, -1] - p[:, 0], axis=1).max() < 0.065
    # follows the scalp: the median particle stays within 1.5 cm of the body
    assert np.median(query_a.signed_distance(hair.points).distance) < 0.015


def test_long_reaches_below_the_neck(grooms, toy_a):
    hair = grooms["long"]
    tips = hair.points[hair.offsets[1:] - 1]
    neck_base_y = toy_a.skeleton.heads[toy_a.skeleton.index("neck_01")][1]
    assert tips[:, 1].min() < neck_base_y
    assert np.mean(tips[:, 1] < neck_base_y) > 0.5
    # and down the back: some tips are behind the torso's back
    assert tips[:, 2].min() < toy_a.vertices[:, 2].min() + 0.02


def test_curls_and_waves_turn_more_than_straight(grooms):
    straight = turning_per_length(grooms["long"])
    assert turning_per_length(grooms["wavy"]) > 2 * straight
    assert turning_per_length(grooms["curly"]) > 3 * straight
    assert turning_per_length(grooms["curly"]) > turning_per_length(grooms["wavy"])


def test_fringe_covers_the_forehead(grooms, toy_a):
    hair = grooms["fringe"]
    frame = head_frame(toy_a)
    local = frame.local(toy_a.vertices)
    forehead_z = toy_a.vertices[frame.head_vertices & (local[:, 0] >= frame.brow_height), 2].max()
    brow_y = frame.world(frame.brow_height, 0.0)[1]
    roots = hair.points[hair.roots]
    tips = hair.points[hair.offsets[1:] - 1]
    g, sigma = frame.normalised(roots)[:, 1:].T
    front = (g > 0.6) & (np.abs(sigma) < 0.3)
    assert front.sum() >= 5
    over = (tips[front, 2] > forehead_z) & (tips[front, 1] < brow_y)
    assert over.mean() >= 0.7
    assert np.median(tips[front, 2]) > forehead_z
    # cheek strands: tips beside the face, below the brows, in front of the ears
    side = (g > 0.2) & (np.abs(sigma) > 0.7)
    assert side.any()
    assert np.median(tips[side, 1]) < brow_y - 0.03


def test_groom_counts_for_a_larger_groom(toy_a):
    q = MeshQuery(toy_a.vertices, toy_a.faces)
    hair = generate_groom(toy_a, "long", 1000, 32, seed=0, query=q)
    assert hair.n_particles == 32000 and hair.n_strands == 1000


def test_roots_are_area_weighted_points_on_the_faces():
    """Two triangles of areas 1/2 and 3/2: a quarter of the roots on the first."""
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [4, 0, 0], [4, 1, 0], [0, 3, 1]], dtype=float)
    faces = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]])
    character = Character(vertices, faces)
    small, large = 0, 1
    corners = vertices[faces[[small, large]]]
    areas = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    np.testing.assert_allclose(areas, [0.5, 1.5])
    face_ids, barycentric, points = sample_roots(character, np.array([small, large]), 4000, np.random.default_rng(0))
    assert set(face_ids.tolist()) == {small, large}
    assert abs(np.mean(face_ids == small) - 0.25) < 0.02
    assert (barycentric >= 0).all()
    np.testing.assert_allclose(barycentric.sum(axis=1), 1.0, rtol=1e-15)
    np.testing.assert_allclose(points, np.einsum("nk,nkd->nd", barycentric, vertices[faces[face_ids]]), atol=1e-15)
    again = sample_roots(character, np.array([small, large]), 4000, np.random.default_rng(0))
    np.testing.assert_array_equal(again[2], points)


def test_groom_sizes_are_checked(toy_a):
    for n_strands, particles, clearance in [(0, 8, 3e-3), (10, 1, 3e-3), (10, 8, 0.0)]:
        with pytest.raises(InputError) as error:
            generate_groom(toy_a, "short", n_strands, particles, clearance=clearance)
        assert error.value.code == "bad_groom"
    with pytest.raises(InputError) as error:
        generate_groom(toy_a, "mohawk", 10, 8)
    assert error.value.code == "bad_style" and "short, long, wavy, curly, fringe" in error.value.problem


def test_a_head_without_scalp_is_refused(toy_a):
    # a frame whose head has no vertex: no face can be scalp
    frame = head_frame(toy_a)
    bald = dataclasses.replace(frame, head_vertices=np.zeros_like(frame.head_vertices))
    with pytest.raises(InputError) as error:
        scalp_faces(Character(toy_a.vertices, toy_a.faces, name="bald"), bald)
    assert error.value.code == "no_scalp" and error.value.source == "bald"
