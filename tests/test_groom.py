"""Toy character, procedural grooms and preview images."""

from __future__ import annotations

import igl
import numpy as np
import pytest
import trimesh
from PIL import Image

from hairport.solver.body.head_frame import HEAD_WEIGHT_MIN, head_frame
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.character import Character, Skeleton
from hairport.solver.model.errors import InputError
from hairport.solver.render.preview import render_preview
from hairport.solver.synthetic.groom import DEFAULT_CLEARANCE_M, STYLES, generate_groom, scalp_faces
from hairport.solver.synthetic.toy import TOY_BONES, toy_character

N_STRANDS = 200
PARTICLES = 24
#: the solver's clearance eps_c is 0.5 mm; grooms must stay at least twice that far out
MIN_CLEARANCE_M = 1e-3

PRESET_B = dict(head_scale=(1.1, 0.95, 1.05), neck_radius=0.065, shoulder_width=0.44, neck_length=0.11)


@pytest.fixture(scope="module")
def toy_a() -> Character:
    return toy_character()


@pytest.fixture(scope="module")
def toy_b() -> Character:
    return toy_character(**PRESET_B, name="toy-b")


@pytest.fixture(scope="module")
def query_a(toy_a) -> MeshQuery:
    return MeshQuery(toy_a.vertices, toy_a.faces)


@pytest.fixture(scope="module")
def grooms(toy_a, query_a) -> dict:
    return {style: generate_groom(toy_a, style, N_STRANDS, PARTICLES, seed=3, query=query_a) for style in STYLES}


def turning_per_length(hair) -> float:
    """Total turning angle (rad) divided by total length (m)."""
    p = hair.points.reshape(hair.n_strands, -1, 3)
    d = np.diff(p, axis=1)
    length = np.linalg.norm(d, axis=2)
    u = d / length[..., None]
    angle = np.arccos(np.clip((u[:, 1:] * u[:, :-1]).sum(axis=2), -1.0, 1.0))
    return float(angle.sum() / length.sum())


# ---------------------------------------------------------------- toy character


def test_toy_topology_identical_across_parameters(toy_a, toy_b):
    others = [toy_b, toy_character(head_scale=(0.8, 1.2, 0.9), neck_radius=0.04, chest_depth=0.3, nose=False)]
    for other in others:
        assert other.n_vertices == toy_a.n_vertices
        assert np.array_equal(other.faces, toy_a.faces)
        assert not np.allclose(other.vertices, toy_a.vertices)
    assert 2000 <= toy_a.n_faces <= 20000


@pytest.mark.parametrize("preset", [{}, PRESET_B])
def test_toy_is_watertight_and_outward(preset):
    c = toy_character(**preset)
    mesh = trimesh.Trimesh(c.vertices, c.faces, process=False)
    assert mesh.is_watertight
    assert mesh.is_winding_consistent
    assert mesh.volume > 0.01  # m^3: head + neck + torso
    assert np.all(mesh.area_faces > 0)
    lo, hi = c.vertices.min(0), c.vertices.max(0)
    assert hi[1] - lo[1] == pytest.approx(0.6, abs=0.1)  # Y up, meters


@pytest.mark.parametrize("preset", [{}, PRESET_B])
def test_toy_skeleton_inside_and_weights(preset):
    c = toy_character(**preset)
    sk = c.skeleton
    assert set(TOY_BONES) <= set(sk.names)
    assert sk.parents[sk.index("head")] == sk.index("neck_01")
    assert sk.parents[sk.index("neck_01")] == sk.index("spine_03")
    assert sk.parents[sk.index("upperarm_l")] == sk.index("clavicle_l")
    assert sk.heads[sk.index("upperarm_l")][0] > 0 > sk.heads[sk.index("upperarm_r")][0]  # left = +X
    t = np.linspace(0.02, 0.98, 25)[:, None]
    for b in range(sk.n_bones):
        samples = sk.heads[b] + t * (sk.tails[b] - sk.heads[b])
        assert igl.fast_winding_number(c.vertices, c.faces, samples).min() > 0.5, sk.names[b]
    # the head bone runs up through the head to near its top
    head = sk.index("head")
    assert sk.tails[head][1] > sk.heads[head][1]
    assert c.vertices[:, 1].max() - sk.tails[head][1] < 0.03
    rows = np.asarray(c.weights.sum(axis=1)).ravel()
    np.testing.assert_allclose(rows, 1.0, atol=1e-12)
    assert c.weights.min() >= 0
    head_w = c.weights[:, head].toarray().ravel()
    top = c.vertices[:, 1] > sk.tails[head][1] - 0.05
    assert head_w[top].min() == 1.0
    assert head_w[c.vertices[:, 1] < sk.heads[sk.index("neck_01")][1]].max() == 0.0


# ---------------------------------------------------------------- scalp


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


def test_groom_needs_head_bone(toy_a):
    sk = toy_a.skeleton
    names = tuple("skull" if n == "head" else n for n in sk.names)
    no_head = Character(toy_a.vertices, toy_a.faces, Skeleton(names, sk.parents, sk.heads, sk.tails), toy_a.weights)
    with pytest.raises(InputError, match="head"):
        generate_groom(no_head, "short", 10, 8)
    with pytest.raises(InputError, match="skeleton"):
        generate_groom(Character(toy_a.vertices, toy_a.faces), "short", 10, 8)
    with pytest.raises(InputError, match="style"):
        generate_groom(toy_a, "mohawk", 10, 8)


# ---------------------------------------------------------------- grooms


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


# ---------------------------------------------------------------- preview


def test_render_preview(tmp_path, grooms, toy_a, toy_b, query_a):
    hair = grooms["long"]
    inside = query_a.signed_distance(hair.points).distance < 0.004
    path = render_preview(
        tmp_path / "sub" / "preview.png",
        [(hair, toy_a, inside, "source"), (grooms["curly"], toy_b, None, "other"), (None, toy_a, None, "bare")],
        view_size=(200, 260),
    )
    image = Image.open(path)
    assert image.size[0] == 3 * 2 * 200 and image.size[1] > 260
    pixels = np.asarray(image.convert("RGB")).reshape(-1, 3)
    assert ((pixels[:, 0] > 200) & (pixels[:, 1] < 60)).any()  # red highlight dots
    assert len(np.unique(pixels, axis=0)) > 20  # mesh shading and strands, not a blank image
