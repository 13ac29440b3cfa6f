"""Scalp extraction, hairline split and refinement on the MakeHuman head (paper Section 6.1)."""

import re

import numpy as np
import pytest
import scipy.sparse as sp
import trimesh

from hairport.solver.body.head_frame import head_frame
from hairport.solver.hairline.scalp import (
    DEFAULT_MIN_TRIANGLES,
    Scalp,
    ScalpWarning,
    _disk_defect,
    extract_scalp,
    refine_scalp,
    split_boundary_ears,
    turning_points,
)
from hairport.solver.mesh.areas import signed_areas
from hairport.solver.mesh.parameterization import PARAMETERIZATIONS, parameterize
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.mesh.shells import shell_labels
from hairport.solver.mesh.topology import (
    boundary_edges,
    boundary_loops,
    euler_characteristic,
    face_adjacency,
    fill_holes,
)
from hairport.solver.model.character import Character
from hairport.solver.model.errors import InputError
from hairport.solver.synthetic.makehuman.bust import keep_faces

#: roots dropped within this distance (m) of the crown make a hole no closing can fill
HOLE_RADIUS_M = 0.04


def assert_disk_scalp(scalp: Scalp, character, frame) -> None:
    n, k = len(scalp.vertices), len(scalp.faces)
    assert scalp.triangles.shape == (k, 3)
    assert np.array_equal(character.faces[scalp.faces], scalp.vertices[scalp.triangles])
    assert np.array_equal(np.unique(scalp.triangles), np.arange(n))
    # one disk: V - E + F == 1 and exactly one boundary loop, the hairline
    assert euler_characteristic(scalp.triangles) == 1
    loops = boundary_loops(scalp.triangles)
    assert len(loops) == 1
    b = scalp.boundary
    assert len(np.unique(b)) == len(b) == len(loops[0])
    # closed and ordered: consecutive loop vertices (and last -> first) are boundary edges
    start = int(np.argmax(loops[0] == b[0]))
    assert np.array_equal(np.roll(loops[0], -start), b)
    # counter-clockwise seen from above: positive area in the (forward, side) plane
    local = frame.local(character.vertices[scalp.vertices[b]])
    x, y = local[:, 1], local[:, 2]
    assert 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) > 0
    # front and back partition the loop, front first
    f = len(scalp.front)
    assert np.array_equal(np.concatenate([scalp.front, scalp.back]), b)
    assert 2 <= f < len(b)
    front = frame.local(character.vertices[scalp.vertices[scalp.front]])
    back = frame.local(character.vertices[scalp.vertices[scalp.back]])
    assert front[:, 1].mean() > 0 > back[:, 1].mean()
    # split at the ears: the front runs from the right ear (side < 0) to the left (side > 0)
    assert front[0, 2] < 0 < front[-1, 2]
    assert abs(front[0, 2]) > 0.8 * frame.half_width and abs(front[-1, 2]) > 0.8 * frame.half_width
    tp = scalp.turning_points
    assert tp[0] == 0 and tp[-1] == f - 1 and np.all(np.diff(tp) > 0)


def test_scalp_of_a_groom_is_a_disk_with_a_hairline_split_at_the_ears(character, frame, roots, scalp):
    assert_disk_scalp(scalp, character, frame)
    assert np.isin(roots[1], scalp.faces).all()
    assert len(scalp.strays) == 0
    # 300 roots hit 211 of the 518 scalp faces in 72 pieces; one closing ring joins them
    assert len(np.unique(roots[1])) == 211
    assert scalp.closing_rings == 1
    assert (len(scalp.faces), len(scalp.vertices), len(scalp.boundary), len(scalp.front)) == (466, 264, 60, 33)
    # the groom's plane-cut hairline is a smooth arch: no corner besides the ends
    assert scalp.turning_points.tolist() == [0, len(scalp.front) - 1]


def test_dense_roots_need_no_closing(character, frame, scalp):
    # every face of the scalp holds a root: the scalp is those faces, as in the paper
    again = extract_scalp(character, np.repeat(scalp.faces, 2), frame)
    assert again.closing_rings == 0
    assert np.array_equal(again.faces, scalp.faces)
    assert np.array_equal(again.boundary, scalp.boundary)


def test_a_hole_in_the_roots_comes_back_filled(character, frame, roots):
    points, faces = roots
    crown = frame.world(frame.crown, 0.5 * (frame.front + frame.back))
    dropped = np.linalg.norm(points - crown, axis=1) < HOLE_RADIUS_M
    assert 10 < dropped.sum() < len(points) - 100
    kept = faces[~dropped]
    holed = extract_scalp(character, kept, frame)
    assert_disk_scalp(holed, character, frame)
    assert np.isin(kept, holed.faces).all()
    # the centre of the hole, far from every kept root, is in the scalp
    centres = character.vertices[character.faces[holed.faces]].mean(axis=1)
    gap = np.min(np.linalg.norm(centres[:, None] - points[~dropped][None], axis=2), axis=1)
    assert gap.max() > 0.5 * HOLE_RADIUS_M
    assert np.isin(faces[dropped], holed.faces).mean() > 0.9


def test_fill_holes_on_a_hand_made_hole(character, scalp):
    adjacency = face_adjacency(character.faces)
    region = np.zeros(character.n_faces, dtype=bool)
    region[scalp.faces] = True
    interior = scalp.faces[~np.isin(scalp.triangles, scalp.boundary).any(axis=1)]
    holed = region.copy()
    holed[interior[:5]] = False
    assert np.array_equal(fill_holes(holed, adjacency), region)
    assert np.array_equal(fill_holes(region, adjacency), region)


def test_stray_roots_are_reported_and_left_out(character, frame, roots, scalp):
    foot = int(np.argmin(character.vertices[character.faces].mean(axis=1)[:, 1]))
    with pytest.warns(ScalpWarning, match="1 roots on 1 faces"):
        strayed = extract_scalp(character, np.append(roots[1], foot), frame)
    assert strayed.strays.tolist() == [foot]
    assert np.array_equal(strayed.faces, scalp.faces)


def test_turning_points_of_a_hand_made_arch(frame):
    # seen from the front: up the right temple, across the forehead, down the left temple
    up = np.linspace(0.05, 0.11, 13)
    across = np.linspace(-0.05, 0.05, 21)
    side = np.concatenate([np.full(12, -0.05), across, np.full(12, 0.05)])
    height = np.concatenate([up[:-1], np.full(21, 0.11), up[::-1][1:]])
    corners = turning_points(frame.world(height, 0.08, side), frame)
    assert corners.tolist() == [0, 12, 32, 44]


def test_refine_scalp_keeps_the_surface_and_the_hairline(character, scalp, query):
    vertices, triangles, boundary = refine_scalp(character.vertices[scalp.vertices], scalp.triangles, scalp.boundary)
    assert len(triangles) >= DEFAULT_MIN_TRIANGLES
    assert (len(vertices), len(triangles), len(boundary)) == (993, 1864, 120)
    assert np.abs(query.signed_distance(vertices).distance).max() < 1e-9
    assert np.array_equal(vertices[: len(scalp.vertices)], character.vertices[scalp.vertices])
    # still a disk whose loop is the refined boundary, in order, from the same first vertex
    assert euler_characteristic(triangles) == 1
    loops = boundary_loops(triangles)
    assert len(loops) == 1 and len(np.unique(boundary)) == len(boundary)
    start = int(np.argmax(loops[0] == boundary[0]))
    assert np.array_equal(np.roll(loops[0], -start), boundary)
    assert boundary[0] == scalp.boundary[0]
    assert np.array_equal(boundary[::2], scalp.boundary)
    fine = refine_scalp(character.vertices[scalp.vertices], scalp.triangles, scalp.boundary, min_triangles=4000)
    assert (len(fine[0]), len(fine[1]), len(fine[2])) == (3849, 7456, 240)
    assert np.array_equal(fine[2][::4], scalp.boundary)
    # one round: the old loop at every second place
    few = refine_scalp(
        character.vertices[scalp.vertices], scalp.triangles, scalp.boundary, min_triangles=len(scalp.faces) + 1
    )
    assert len(few[1]) == 4 * len(scalp.faces)
    assert np.array_equal(few[2][::2], scalp.boundary)


@pytest.mark.parametrize("method", PARAMETERIZATIONS)
def test_parameterizations_of_the_refined_scalp(character, scalp, method):
    vertices, triangles, boundary = refine_scalp(character.vertices[scalp.vertices], scalp.triangles, scalp.boundary)
    uv = parameterize(vertices, triangles, method)
    assert (signed_areas(uv, triangles) > 0).all()
    assert np.linalg.norm(uv, axis=1).max() <= 1.0 + 1e-9


def test_refine_scalp_with_enough_triangles_is_a_copy(character, scalp):
    vertices, triangles, boundary = refine_scalp(
        character.vertices[scalp.vertices], scalp.triangles, scalp.boundary, min_triangles=len(scalp.faces)
    )
    assert np.array_equal(triangles, scalp.triangles) and np.array_equal(boundary, scalp.boundary)


@pytest.mark.parametrize(
    "faces, message",
    [
        (np.zeros(0, np.int64), "roots lie on 0 faces"),
        (np.array([7, 7, 7]), "roots lie on 1 faces"),
        (np.array([-1, 2, 3]), "root face ids must lie in"),
        (np.array([0.5, 1.5, 2.5]), "integer face ids"),
    ],
)
def test_bad_root_faces_are_refused(character, frame, faces, message):
    with pytest.raises(InputError, match=message):
        extract_scalp(character, faces, frame)


def test_roots_that_do_not_reach_the_ears_are_refused(character, frame, scalp):
    # the front half of the scalp only: its hairline never crosses the ear plane
    front = frame.local(character.vertices[character.faces[scalp.faces]].mean(axis=1))[:, 1] > 0.03
    with pytest.raises(InputError, match="ear plane"):
        extract_scalp(character, scalp.faces[front], frame)


def test_ears_are_split_into_triangles_with_one_hairline_edge():
    # a fan of four triangles around vertex 0; the two outer ones are ears of the square
    points = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.5, -0.5]])
    triangles = np.array([[0, 4, 1], [0, 1, 2], [0, 2, 3]])
    assert (boundary_edges(triangles, 5).sum(axis=1) == 2).sum() == 2
    new_points, new_triangles, split = split_boundary_ears(points, triangles)
    assert split == 2 and len(new_triangles) == len(triangles) + 2 * split
    assert boundary_edges(new_triangles, len(new_points)).sum(axis=1).max() == 1
    np.testing.assert_array_equal(new_points[:5], points)
    # midpoints of the inner edges, same orientation and covered area
    np.testing.assert_allclose(new_points[5:], [[0.5, 0.0], [0.5, 0.5]])
    assert (signed_areas(new_points, new_triangles) > 0).all()
    assert signed_areas(new_points, new_triangles).sum() == pytest.approx(signed_areas(points, triangles).sum(),
                                                                          abs=1e-15)
    loop = boundary_loops(new_triangles)[0]
    assert set(loop.tolist()) == {0, 1, 2, 3, 4}  # the hairline keeps its vertices


def test_the_scalp_of_a_groom_has_ears_to_split(character, scalp):
    uv_like = character.vertices[scalp.vertices][:, :2]
    before = (boundary_edges(scalp.triangles, scalp.n_vertices).sum(axis=1) >= 2).sum()
    _, triangles, split = split_boundary_ears(uv_like, scalp.triangles)
    assert before > 0 and split == before
    assert boundary_edges(triangles, scalp.n_vertices + split).sum(axis=1).max() == 1


def test_the_scalp_on_a_bust_is_the_scalp_on_the_body(character, frame, scalp, bust, bust_roots):
    """Eyes and teeth as separate shells and a body cut open at the chest change nothing."""
    bust_frame = head_frame(bust)
    for name in ("crown", "front", "back", "half_width"):
        assert getattr(bust_frame, name) == getattr(frame, name), name
    on_bust = extract_scalp(bust, bust_roots, bust_frame)
    assert_disk_scalp(on_bust, bust, bust_frame)
    assert (len(on_bust.faces), len(on_bust.vertices), len(on_bust.boundary), len(on_bust.front)) == (466, 264, 60, 33)
    np.testing.assert_array_equal(bust.vertices[on_bust.vertices[on_bust.boundary]],
                                  character.vertices[scalp.vertices[scalp.boundary]])
    assert on_bust.turning_points.tolist() == scalp.turning_points.tolist()


def crown_faces(character, scalp, frame):
    """The faces around the scalp vertex nearest the top of the head (a ring of 4-8 faces)."""
    top = scalp.vertices[np.argmax(frame.local(character.vertices[scalp.vertices])[:, 0])]
    return np.flatnonzero((character.faces == top).any(axis=1))


@pytest.mark.parametrize("damage", ["removed", "flipped"])
def test_a_gap_in_the_mesh_under_the_roots_is_refused(bust, bust_roots, roots, damage):
    bust_frame = head_frame(bust)
    ring = crown_faces(bust, extract_scalp(bust, bust_roots, bust_frame), bust_frame)
    assert 4 <= len(ring) <= 8
    if damage == "removed":
        keep = np.ones(bust.n_faces, dtype=bool)
        keep[ring] = False
        holed = keep_faces(bust, keep)
    else:
        faces = bust.faces.copy()
        faces[ring[:1]] = faces[ring[:1], ::-1]
        holed = Character(bust.vertices, faces, bust.skeleton, bust.weights, bust.name)
    root_faces = MeshQuery(holed.vertices, holed.faces).signed_distance(roots[0]).faces
    with pytest.raises(InputError, match=r"the scalp under the roots has a hole: it surrounds a gap in the mesh") as e:
        extract_scalp(holed, root_faces)
    assert e.value.code == "mesh_hole" and e.value.source == bust.name
    near = np.array(re.search(r"near \[([^]]+)\]", e.value.problem).group(1).split(", "), dtype=float)
    top = bust.vertices[np.unique(bust.faces[ring])].mean(axis=0)
    assert np.linalg.norm(near - top) < 0.01


def test_a_fin_on_the_scalp_is_left_out(bust, bust_roots):
    """A face hanging on an edge inside the scalp (a non-manifold edge) is a piece of its own."""
    plain = extract_scalp(bust, bust_roots)
    inner = np.flatnonzero(~np.isin(plain.triangles, plain.boundary).any(axis=1))
    edge = plain.vertices[plain.triangles[inner[len(inner) // 2], :2]]  # an inner edge of the scalp
    tip = bust.vertices[edge].mean(axis=0) - [0.0, 0.01, 0.0]  # 1 cm down, inside the head
    finned = Character(np.vstack([bust.vertices, tip]), np.vstack([bust.faces, [[edge[1], edge[0], bust.n_vertices]]]),
                       bust.skeleton, sp.vstack([bust.weights, bust.weights[edge[0]]]), bust.name)
    with_fin = extract_scalp(finned, bust_roots)
    np.testing.assert_array_equal(with_fin.faces, plain.faces)
    np.testing.assert_array_equal(with_fin.boundary, plain.boundary)


def test_roots_on_an_eye(bust, bust_roots):
    """A few roots on an eye are strays; a tenth of them make two pieces, which is refused."""
    labels = shell_labels(bust.faces)
    eye = np.flatnonzero(labels == labels[-1 - 2 * 134])  # the right eye: before both teeth shells
    assert len(eye) == 140
    plain = extract_scalp(bust, bust_roots)
    with pytest.warns(ScalpWarning, match="5 roots on 5 faces lie outside the scalp"):
        some = extract_scalp(bust, np.concatenate([bust_roots, eye[:5]]))
    np.testing.assert_array_equal(some.faces, plain.faces)
    assert np.array_equal(some.strays, eye[:5])
    with pytest.raises(InputError, match=r"the roots lie on 2 separate pieces of the mesh \(300 on a piece of 11118 "
                                         r"faces, 40 on a piece of 140 faces\)") as e:
        extract_scalp(bust, np.concatenate([bust_roots, eye[:40]]))
    assert e.value.code == "roots_on_several_pieces"


def test_roots_everywhere_leave_no_hairline(character, frame):
    with pytest.raises(InputError, match="the roots do not make one disk-shaped scalp: the scalp would cover a whole "
                                         "closed piece of the mesh, leaving no hairline") as e:
        extract_scalp(character, np.arange(character.n_faces), frame)
    assert e.value.code == "not_a_disk"


def test_what_keeps_a_region_from_being_a_disk_in_words():
    from tests.solver.triangle_grids import grid

    _, square = grid(4, 4, 0.0, 1.0, 0.0, 1.0)
    ring = np.delete(square, [5, 21], axis=0)  # the two triangles of cell (1, 1)
    assert _disk_defect(ring, "scalp") == ("its border has 2 loops (the roots surround 1 piece(s) of the mesh "
                                           "they leave bare)")
    torus = np.asarray(trimesh.creation.torus(major_radius=1.0, minor_radius=0.3).faces)
    assert _disk_defect(torus, "head patch") == ("the head patch would cover a whole closed piece of the mesh, "
                                                 "leaving no hairline")
    # the torus but one face: one border loop round a surface with a handle
    assert _disk_defect(torus[1:], "scalp") == "the scalp wraps around 1 tunnel(s) through the mesh"
