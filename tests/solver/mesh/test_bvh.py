"""The compiled BVH (solver/mesh/bvh.py): the tree's invariants, closest points against brute
force and libigl, hints of every kind, non-finite points."""

import igl
import numpy as np
import pytest

from hairport.solver.mesh import bvh
from hairport.solver.mesh.query import _closest_on_table, _triangle_table
from tests.solver.mesh.meshes import icosphere, sample_near_features


def brute_force(points, vertices, faces):
    """(squared distance, closest point) to the nearest face, every face tried (numpy reference)."""
    table = _triangle_table(vertices[faces])
    best = np.full(len(points), np.inf)
    closest = np.full((len(points), 3), np.nan)
    for face in range(len(faces)):
        ids = np.full(len(points), face)
        on_face, _ = _closest_on_table(points, table, ids)
        squared = np.einsum("ij,ij->i", points - on_face, points - on_face)
        better = squared < best
        best[better], closest[better] = squared[better], on_face[better]
    return best, closest


@pytest.mark.parametrize("leaf_faces", [1, 3, 4, 16])
def test_every_face_is_in_exactly_one_leaf_inside_every_box_above_it(leaf_faces):
    vertices, faces = icosphere(subdivisions=2)
    tree = bvh.build_tree(vertices, faces, leaf_faces)
    np.testing.assert_array_equal(np.sort(tree.faces), np.arange(len(faces)))
    np.testing.assert_array_equal(tree.faces[tree.rank], np.arange(len(faces)))
    leaves = tree.child < 0
    assert tree.count[leaves].min() >= 1 and tree.count[leaves].max() <= leaf_faces
    assert tree.count[leaves].sum() == len(faces) and (tree.count[~leaves] == 0).all()
    # each leaf's box holds its triangles; each inner box holds both children's boxes
    corners = vertices[faces[tree.faces]]
    for node in np.flatnonzero(leaves):
        inside = corners[tree.first[node]: tree.first[node] + tree.count[node]].reshape(-1, 3)
        assert (inside >= tree.boxes[node, :3]).all() and (inside <= tree.boxes[node, 3:]).all()
    for node in np.flatnonzero(~leaves):
        for kid in (tree.child[node], tree.child[node] + 1):
            assert (tree.boxes[kid, :3] >= tree.boxes[node, :3]).all()
            assert (tree.boxes[kid, 3:] <= tree.boxes[node, 3:]).all()
    # the triangle table rows are the faces in leaf order
    np.testing.assert_array_equal(tree.table, _triangle_table(corners).T)


def test_closest_points_equal_brute_force_on_a_sphere():
    vertices, faces = icosphere(subdivisions=2)
    points = sample_near_features(vertices, faces, np.random.default_rng(0), n=900)
    tree = bvh.build_tree(vertices, faces)
    found, closest, coordinates, squared = bvh.closest_points(tree, points)
    best, reference = brute_force(points, vertices, faces)
    np.testing.assert_allclose(squared, best, rtol=1e-14, atol=0)  # the same operations: the same minimum
    np.testing.assert_allclose(closest, reference, rtol=0, atol=1e-15)
    # the face holds the closest point at the coordinates given
    a, b, c = (vertices[faces[found, k]] for k in range(3))
    np.testing.assert_allclose(a + coordinates[:, :1] * (b - a) + coordinates[:, 1:] * (c - a), closest,
                               rtol=0, atol=1e-15)


def test_closest_points_equal_libigl_on_the_body_near_and_far(makehuman_body):
    vertices, faces = makehuman_body
    rng = np.random.default_rng(1)
    n = 40000
    near = vertices[rng.integers(0, len(vertices), n)] + rng.normal(size=(n, 3)) * np.geomspace(1e-9, 2e-2, n)[:, None]
    far = vertices.mean(axis=0) + rng.normal(size=(2000, 3))
    points = np.concatenate([near, far])
    found, closest, _, squared = bvh.closest_points(bvh.build_tree(vertices, faces), points)
    igl_squared, igl_faces, igl_closest = _igl_closest(vertices, faces, points)
    np.testing.assert_allclose(np.sqrt(squared), np.sqrt(igl_squared), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(closest, igl_closest, rtol=0, atol=1e-15)
    # a face may differ only where another one is as near (a tie: a shared edge or vertex)
    differ = np.flatnonzero(found != igl_faces)
    on_theirs, _ = _closest_on_table(points[differ], _triangle_table(vertices[faces]), igl_faces[differ])
    np.testing.assert_allclose(on_theirs, closest[differ], rtol=0, atol=1e-15)


def _igl_closest(vertices, faces, points):
    tree = igl.AABB()
    tree.init(vertices, faces)
    return tree.squared_distance(vertices, faces, points)


def test_a_hint_never_changes_the_distance_whatever_it_is():
    vertices, faces = icosphere(subdivisions=3)
    points = sample_near_features(vertices, faces, np.random.default_rng(2), n=1200)
    tree = bvh.build_tree(vertices, faces)
    plain_faces, _, _, plain = bvh.closest_points(tree, points)
    rng = np.random.default_rng(3)
    hints = {
        "right": plain_faces,
        "stale": bvh.closest_points(tree, points + rng.normal(scale=3e-3, size=points.shape))[0],
        "wrong": rng.integers(0, len(faces), len(points)),
        "out of range": rng.choice([-1, -(10**12), len(faces), 10**15], len(points)),
    }
    for name, hint in hints.items():
        found, closest, _, squared = bvh.closest_points(tree, points, hint)
        np.testing.assert_array_equal(squared, plain, err_msg=name)
        if name == "right":
            np.testing.assert_array_equal(found, plain_faces)  # the hint kept on ties
    with pytest.raises(ValueError, match="one face per point"):
        bvh.closest_points(tree, points, plain_faces[:-1])


def test_non_finite_points_get_nan_and_no_face():
    vertices, faces = icosphere(subdivisions=1)
    points = np.array([[np.nan, 0.0, 0.0], [0.0, np.inf, 0.0], [0.2, 0.0, 0.0], [0.0, 0.0, -np.inf]])
    found, closest, coordinates, squared = bvh.closest_points(bvh.build_tree(vertices, faces), points, [3, 3, 3, 3])
    np.testing.assert_array_equal(found[[0, 1, 3]], -1)
    assert np.isnan(closest[[0, 1, 3]]).all() and np.isnan(squared[[0, 1, 3]]).all()
    assert found[2] >= 0 and squared[2] == np.sum((points[2] - closest[2]) ** 2)
    assert 0.09 < np.sqrt(squared[2]) < 0.1 + 1e-12  # the sphere of radius 0.1 m, a vertex on the x axis


def test_a_tree_needs_a_face():
    with pytest.raises(ValueError):
        bvh.build_tree(np.zeros((3, 3)), np.zeros((0, 3), dtype=np.int64))


def test_coincident_centroids_split_at_the_median():
    """Forty copies of one triangle and a few others: no binned split separates the copies,
    the median split does; the tree stays valid and finds the right points."""
    vertices = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 2, 2], [3, 2, 2], [2, 3, 2]])
    faces = np.array([[0, 1, 2]] * 40 + [[3, 4, 5]] * 3)
    tree = bvh.build_tree(vertices, faces)
    np.testing.assert_array_equal(np.sort(tree.faces), np.arange(len(faces)))
    assert tree.count[tree.child < 0].max() <= bvh.LEAF_FACES
    points = np.array([[0.2, 0.2, 1.0], [2.2, 2.2, 1.5], [-1.0, -1.0, 0.0]])
    found, closest, _, squared = bvh.closest_points(tree, points)
    np.testing.assert_allclose(squared, [1.0, 0.25, 2.0], rtol=1e-15)
    assert (found[[0, 2]] < 40).all() and found[1] >= 40


@pytest.mark.parametrize("seed", range(5))
def test_selection_puts_the_median_in_place(seed):
    from hairport.solver.mesh.bvh_build import _select

    rng = np.random.default_rng(seed)
    centroids = np.round(rng.normal(size=(501, 3)), 1)  # many equal values
    order = rng.permutation(501)
    start, stop = 17, 480
    before = order.copy()
    middle = (start + stop) // 2
    _select(centroids, order, start, stop, 2, middle)
    np.testing.assert_array_equal(np.sort(order[start:stop]), np.sort(before[start:stop]))
    np.testing.assert_array_equal(order[:start], before[:start])
    np.testing.assert_array_equal(order[stop:], before[stop:])
    keys = centroids[order, 2]
    assert (keys[start:middle] <= keys[middle]).all() and (keys[middle + 1:stop] >= keys[middle]).all()


def test_a_refit_tree_answers_as_a_fresh_build_on_the_moved_body(makehuman_body):
    vertices, faces = makehuman_body
    from hairport.solver.synthetic.makehuman import PRESETS, build_character

    moved = build_character(PRESETS["heavy-male"]).vertices  # the same mesh, every vertex moved (up to ~15 cm)
    assert np.linalg.norm(moved - vertices, axis=1).max() > 0.05
    tree = bvh.build_tree(vertices, faces)
    # unmoved, a refit gives back the built boxes and table; the compiled pass is its numpy reference
    same = bvh.refit_tree(tree, vertices, faces)
    np.testing.assert_array_equal(same.boxes, tree.boxes)
    np.testing.assert_array_equal(same.table, tree.table)
    refit = bvh.refit_tree(tree, moved, faces)
    corners = moved[faces[tree.faces]]
    np.testing.assert_array_equal(
        refit.boxes, bvh._refit_boxes_reference(tree.child, tree.first, tree.count, corners.min(axis=1),
                                                corners.max(axis=1)))
    assert refit.built_area == tree.built_area == bvh.node_area(tree.boxes) > 0
    rng = np.random.default_rng(2)
    points = moved[rng.integers(0, len(moved), 20000)] + rng.normal(size=(20000, 3)) * 0.01
    _, closest, _, squared = bvh.closest_points(refit, points)
    _, reference_closest, _, reference = bvh.closest_points(bvh.build_tree(moved, faces), points)
    np.testing.assert_allclose(squared, reference, rtol=1e-12, atol=0)
    np.testing.assert_allclose(closest, reference_closest, rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="refit"):
        bvh.refit_tree(tree, moved, faces[:-1])
