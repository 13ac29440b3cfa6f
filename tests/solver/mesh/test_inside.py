"""Inside and outside of closed and open bodies (solver/mesh/inside.py): the winding number, closedness, the
faces that separate inside from outside."""

import pickle

import igl
import numpy as np

from hairport.solver.mesh.inside import (
    INSIDE_WINDING,
    SIDE_PROBE,
    InsideTest,
    WindingNumber,
    closed_cycle,
    exit_faces,
    manifold_closed,
    manifold_features,
    shell_count,
)
from tests.solver.capsule import capsule_mesh
from tests.solver.mesh.meshes import icosphere

RADIUS = 0.1
HALF_HEIGHT = 0.2
RINGS, AROUND = 21, 32  # the middle ring lies at z = 0


def capsule():
    """A closed capsule along z, radius 0.1 m, 0.4 m tall."""
    return capsule_mesh(RINGS, AROUND, RADIUS, HALF_HEIGHT)


def open_capsule():
    """The capsule's upper half: a bust cut flat at z = 0 (a planar rim of radius 0.1 m)."""
    vertices, faces = capsule()
    keep = (vertices[faces, 2] > -1e-12).all(axis=1)
    return vertices, faces[keep]


def side_points(distances):
    """Points on the +x side at z = 0.05, ``distances`` (m) outside the wall (negative: inside)."""
    wall = RADIUS * (1.0 - (0.05 / HALF_HEIGHT) ** 6) ** (1.0 / 6.0)
    return np.array([[wall + d, 0.0, 0.05] for d in distances])


def test_a_closed_body_is_inside_at_any_depth_and_outside_beyond_its_wall():
    vertices, faces = capsule()
    winding = WindingNumber(vertices, faces)
    # 3 and 6 cm deep, 0.1 mm in, 0.1 mm out, 3 cm out, and the centre
    points = np.vstack([side_points([-0.03, -0.06, -1e-4, 1e-4, 0.03]), [[0.0, 0.0, 0.0]]])
    w = winding(points)
    np.testing.assert_allclose(w, [1, 1, 1, 0, 0, 1], atol=0.01)
    np.testing.assert_allclose(w, igl.winding_number(vertices, faces, points), atol=0.01)
    np.testing.assert_array_equal(winding.inside(points), [True, True, True, False, False, True])


def face_probes(vertices, faces, offset):
    """Every face's centroid moved ``offset`` (m) along its normal: (F, 3)."""
    corners = vertices[faces]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    return corners.mean(axis=1) + offset * normal / np.linalg.norm(normal, axis=1, keepdims=True)


def test_next_to_a_face_both_sides_are_told_apart_down_to_single_precision():
    vertices, faces = icosphere()
    winding = WindingNumber(vertices, faces)
    for offset in (1e-7, 1e-6, 1e-3):
        assert winding.inside(face_probes(vertices, faces, -offset)).all()
        assert not winding.inside(face_probes(vertices, faces, offset)).any()
    # libigl's fast winding number is single precision: 1 nm off a face of a 0.1 m sphere
    # (1e-8 of its coordinates) is noise, which is why the collision surface does not ask it there
    noise = winding.inside(face_probes(vertices, faces, 1e-9))
    assert 0 < noise.sum() < len(faces)


def test_an_open_bust_is_closed_by_the_flat_piece_of_its_cut():
    """Inside above the cut's plane within the rim, outside below it, 1/2 on it."""
    vertices, faces = open_capsule()
    winding = WindingNumber(vertices, faces)
    on_cut = np.array([[0.0, 0.0, 0.0], [0.05, 0.02, 0.0], [-0.07, 0.0, 0.0]])
    np.testing.assert_allclose(winding(on_cut), 0.5, atol=0.01)
    above = on_cut + [0.0, 0.0, 1e-3]
    below = on_cut - [0.0, 0.0, 1e-3]
    assert winding.inside(above).all() and not winding.inside(below).any()
    # 3 and 6 cm deep above the cut: inside; 3 and 6 cm below it, within the rim: outside
    deep = np.array([[0.0, 0.0, 0.03], [0.0, 0.0, 0.06], [0.0, 0.0, -0.03], [0.0, 0.0, -0.06]])
    np.testing.assert_array_equal(winding.inside(deep), [True, True, False, False])
    # the wall above the cut as on the closed body
    np.testing.assert_array_equal(winding.inside(side_points([-0.06, -0.03, -1e-4, 1e-4, 0.03])),
                                  [True, True, True, False, False])
    # the exact generalized winding number agrees
    np.testing.assert_allclose(winding(deep), igl.winding_number(vertices, faces, deep), atol=0.01)


def test_nested_and_overlapping_shells_are_inside_as_their_union():
    outer, outer_faces = icosphere(radius=0.1)
    inner, inner_faces = icosphere(radius=0.05)
    vertices = np.vstack([outer, inner])
    faces = np.vstack([outer_faces, inner_faces + len(outer)])
    winding = WindingNumber(vertices, faces)
    points = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.07], [0.0, 0.0, 0.12]])  # in both, between, outside
    np.testing.assert_allclose(winding(points), [2, 1, 0], atol=0.01)
    np.testing.assert_array_equal(winding.inside(points), [True, True, False])


def test_non_finite_points_are_not_inside_and_the_tree_is_rebuilt_after_pickling():
    vertices, faces = icosphere()
    winding = WindingNumber(vertices, faces)
    points = np.array([[0.0, 0.0, 0.0], [np.nan, 0.0, 0.0], [0.0, np.inf, 0.0]])
    w = winding(points)
    assert abs(w[0] - 1) < 0.01 and np.isnan(w[1:]).all()
    np.testing.assert_array_equal(winding.inside(points), [True, False, False])
    copy = pickle.loads(pickle.dumps(winding))
    assert copy._tree is None and copy.inside(points[:1]).all()
    assert WindingNumber(vertices, faces[:0]).inside(points[:1]).tolist() == [False]
    assert InsideTest(winding, True).inside(points).tolist() == [True, False, False]


def test_closedness_orientation_and_shells():
    vertices, faces = capsule()
    assert manifold_closed(faces) and closed_cycle(faces) and shell_count(faces) == 1
    _, cut = open_capsule()
    assert not manifold_closed(cut) and not closed_cycle(cut)
    flipped = faces.copy()
    flipped[0] = flipped[0, ::-1]
    assert not manifold_closed(flipped) and not closed_cycle(flipped)
    # two shells, one inside the other: still a closed cycle, each edge on two faces
    inner = np.vstack([faces, faces + len(vertices)])
    assert manifold_closed(inner) and closed_cycle(inner) and shell_count(inner) == 2
    # a fin on an edge: non-manifold and open along its free edges
    a, b = faces[0, 0], faces[0, 1]
    fin = np.vstack([faces, [[b, a, len(vertices)]]])
    assert not manifold_closed(fin) and not closed_cycle(fin)
    # a two-sided flap (a face and its reverse) closes its own edges: a cycle, not a manifold
    flap = np.vstack([faces, [[a, b, len(vertices)], [b, a, len(vertices)]]])
    assert closed_cycle(flap) and not manifold_closed(flap)
    assert not manifold_closed(faces[:0]) and not closed_cycle(faces[:0]) and shell_count(faces[:0]) == 0


def test_the_separating_faces_leave_out_inner_shells_and_keep_an_open_cut_body():
    outer, outer_faces = icosphere(radius=0.1)
    inner, inner_faces = icosphere(radius=0.05)
    vertices = np.vstack([outer, inner])
    faces = np.vstack([outer_faces, inner_faces + len(outer)])
    separating = exit_faces(vertices, faces, WindingNumber(vertices, faces))
    assert separating[: len(outer_faces)].all() and not separating[len(outer_faces):].any()
    # two spheres overlapping: the faces of each inside the other separate nothing
    shifted = outer + [0.1, 0.0, 0.0]
    both = np.vstack([outer, shifted])
    both_faces = np.vstack([outer_faces, outer_faces + len(outer)])
    separating = exit_faces(both, both_faces, WindingNumber(both, both_faces))
    centroids = both[both_faces].mean(axis=1)
    to_other = np.concatenate([np.linalg.norm(centroids[: len(outer_faces)] - [0.1, 0, 0], axis=1),
                               np.linalg.norm(centroids[len(outer_faces):], axis=1)])
    # clearly inside the other sphere (its facets reach 0.0983 m from its centre) or clearly out
    assert not separating[to_other < 0.098].any() and separating[to_other > 0.1].all()
    assert 0.2 < np.mean(~separating) < 0.3  # two spheres a radius apart: a quarter of each is in the other
    # the open bust: every face, up to its rim
    vertices, cut = open_capsule()
    assert exit_faces(vertices, cut, WindingNumber(vertices, cut)).all()
    # faces turned inward enclose nothing
    inward = outer_faces[:, ::-1]
    assert not exit_faces(outer, inward, WindingNumber(outer, inward)).any()


def two_sided(vertices, faces):
    """The separating faces by both probes, whatever the body: what the front probe alone must match when closed."""
    corners = vertices[faces]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(cross, axis=1)
    normal = cross / np.where(length > 0, length, 1.0)[:, None]
    step = SIDE_PROBE * float(np.linalg.norm(np.ptp(vertices, axis=0)))
    winding = WindingNumber(vertices, faces)
    front = winding(corners.mean(axis=1) + step * normal)
    back = winding(corners.mean(axis=1) - step * normal)
    return (length > 0) & (front < INSIDE_WINDING) & (back > INSIDE_WINDING)


def test_on_a_closed_body_the_front_probe_alone_gives_the_two_sided_answer():
    from hairport.solver.synthetic.makehuman import PRESETS, build_character

    outer, outer_faces = icosphere(radius=0.1)
    male = build_character(PRESETS["heavy-male"])
    bodies = [(np.vstack([outer, outer + [0.1, 0.0, 0.0]]), np.vstack([outer_faces, outer_faces + len(outer)])),
              (np.vstack([outer, 0.5 * outer]), np.vstack([outer_faces, outer_faces + len(outer)])),
              (np.vstack([outer, 0.5 * outer]), np.vstack([outer_faces, outer_faces[:, ::-1] + len(outer)])),
              (male.vertices, male.faces)]
    for vertices, faces in bodies:
        assert closed_cycle(faces)
        expected = two_sided(vertices, faces)
        np.testing.assert_array_equal(exit_faces(vertices, faces, WindingNumber(vertices, faces)), expected)
    assert 0 < np.count_nonzero(~expected) < 50  # the heavy male's lips cross: a few faces separate nothing


def test_manifold_features_flag_the_rim_of_an_open_cut():
    vertices, faces = open_capsule()
    features = manifold_features(faces)
    assert features[:, 0].all()
    rim = np.flatnonzero(np.abs(vertices[:, 2]) < 1e-12)
    assert len(rim) == AROUND
    on_rim = np.isin(faces, rim)
    np.testing.assert_array_equal(features[:, 4:7], ~on_rim)
    # an edge is off the manifold exactly when both its ends are on the rim (the rim's own edges)
    opposite = [(1, 2), (2, 0), (0, 1)]
    rim_edge = np.stack([on_rim[:, i] & on_rim[:, j] for i, j in opposite], axis=1)
    np.testing.assert_array_equal(features[:, 1:4], ~rim_edge)
    assert (~features[:, 1:4]).sum() == AROUND
    assert manifold_features(capsule()[1]).all()
