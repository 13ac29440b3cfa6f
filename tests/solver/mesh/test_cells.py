"""Candidate faces per cell (solver/mesh/cells.py): the same closest points as the tree's search,
wherever the points are and whatever the cache holds."""

import numpy as np
import pytest

from hairport.solver.mesh import bvh, cells
from hairport.solver.mesh.query import _pseudonormal_table
from hairport.solver.mesh.signed_distance import signed_distance
from tests.solver.mesh.meshes import icosphere, sample_near_features


def assert_same_as_the_tree(tree, pseudonormals, points, cache):
    """The cached query gives the tree's distance to the bit (the same triangle test, the same
    minimum); faces and closest points may differ only on ties (equal distance)."""
    by_tree = signed_distance(tree, pseudonormals, points)
    by_cells = signed_distance(tree, pseudonormals, points, cells=cache)
    np.testing.assert_array_equal(np.abs(by_cells[0]), np.abs(by_tree[0]))
    np.testing.assert_array_equal(by_cells[0] < 0, by_tree[0] < 0)
    same = by_cells[3] == by_tree[3]
    np.testing.assert_array_equal(by_cells[1][same], by_tree[1][same])
    np.testing.assert_array_equal(by_cells[2][same], by_tree[2][same])
    return by_cells


def hair_like(vertices, n, rng, reach=0.02):
    """Points off the surface's vertices, most within a few mm, up to ``reach`` (m), some inside."""
    along = rng.normal(size=(n, 3))
    along /= np.linalg.norm(along, axis=1, keepdims=True)
    return vertices[rng.integers(0, len(vertices), n)] + along * np.minimum(rng.exponential(3e-3, n), reach)[:, None]


@pytest.fixture(scope="module")
def sphere():
    vertices, faces = icosphere(subdivisions=3)
    return vertices, faces, bvh.build_tree(vertices, faces), _pseudonormal_table(vertices, faces)


def test_cached_cells_answer_as_the_tree_on_a_sphere(sphere):
    vertices, faces, tree, pseudonormals = sphere
    rng = np.random.default_rng(0)
    points = np.concatenate([sample_near_features(vertices, faces, rng, n=3000), hair_like(vertices, 5000, rng)])
    cache = cells.CellCache(tree, size=3e-3)
    assert_same_as_the_tree(tree, pseudonormals, points, cache)  # fills
    filled = cache.n_cells
    assert filled > 1000 and cache.n_candidates > filled
    assert_same_as_the_tree(tree, pseudonormals, points + rng.normal(scale=3e-4, size=points.shape), cache)
    assert cache.n_cells < 2 * filled  # the next iterate reuses most cells
    again = cache.n_cells
    assert_same_as_the_tree(tree, pseudonormals, points, cache)
    assert cache.n_cells == again  # nothing new to fill


def test_cached_cells_answer_as_the_tree_on_the_body(makehuman_body):
    vertices, faces = makehuman_body
    tree, pseudonormals = bvh.build_tree(vertices, faces), _pseudonormal_table(vertices, faces)
    rng = np.random.default_rng(1)
    points = hair_like(vertices, 60000, rng)
    points[:20000] = vertices[rng.integers(0, len(vertices), 20000)] + rng.normal(size=(20000, 3)) * np.geomspace(
        1e-9, 5e-2, 20000)[:, None]
    cache = cells.CellCache(tree)
    assert_same_as_the_tree(tree, pseudonormals, points, cache)
    assert_same_as_the_tree(tree, pseudonormals, points + rng.normal(scale=3e-4, size=points.shape), cache)


def test_points_on_cell_faces_edges_and_corners(sphere):
    """Points exactly on the planes between cells (either cell may take them)."""
    vertices, faces, tree, pseudonormals = sphere
    cache = cells.CellCache(tree, size=4e-3)
    rng = np.random.default_rng(2)
    points = hair_like(vertices, 3000, rng)
    snapped = cache.origin + np.round((points - cache.origin) / cache.size) * cache.size
    for axes in ([0], [0, 1], [0, 1, 2]):  # on a face, an edge, a corner of the cells
        on = points.copy()
        on[:, axes] = snapped[:, axes]
        assert_same_as_the_tree(tree, pseudonormals, on, cache)


def test_crowded_cells_go_to_the_tree(sphere, monkeypatch):
    """Cells needing more candidates than the cap (deep inside the sphere: every face is about
    as far) keep none and answer by the tree."""
    vertices, faces, tree, pseudonormals = sphere
    monkeypatch.setattr(cells, "MAX_CANDIDATES", 3)
    cache = cells.CellCache(tree, size=5e-3)
    rng = np.random.default_rng(3)
    points = np.concatenate([rng.normal(scale=0.01, size=(500, 3)), hair_like(vertices, 2000, rng)])
    assert_same_as_the_tree(tree, pseudonormals, points, cache)
    counts = cache.slots[cache.slots[:, 0] >= 0, 1] % cells.COUNT_FACTOR - 1
    assert (counts == -1).sum() > 100 and counts.max() <= 3


def test_a_full_cache_starts_over(sphere, monkeypatch):
    vertices, faces, tree, pseudonormals = sphere
    monkeypatch.setattr(cells, "MAX_CACHED_CANDIDATES", 5000)
    monkeypatch.setattr(cells, "FILL_CHUNK", 64)
    cache = cells.CellCache(tree, size=2e-3)
    rng = np.random.default_rng(4)
    for _ in range(3):
        assert_same_as_the_tree(tree, pseudonormals, hair_like(vertices, 4000, rng), cache)
        assert cache.n_candidates <= 5000


def test_non_finite_and_far_points(sphere):
    vertices, faces, tree, pseudonormals = sphere
    cache = cells.CellCache(tree)
    points = np.array([[np.nan, 0.0, 0.0], [np.inf, 0.0, 0.0], [1e7, 0.0, 0.0], [0.0, -3e4, 0.0], [0.1, 0.0, 0.0]])
    distance, closest, normal, found, feature = assert_same_as_the_tree(tree, pseudonormals, points, cache)
    assert np.isnan(distance[:2]).all() and np.isnan(closest[:2]).all() and np.isnan(normal[:2]).all()
    np.testing.assert_array_equal(found[:2], 0)
    np.testing.assert_allclose(distance[2:4], [1e7 - 0.1, 3e4 - 0.1], rtol=1e-9)
    assert cache.n_cells == 1  # only the point near the sphere has a cell within the keys' range


def test_cell_size_must_be_positive(sphere):
    with pytest.raises(ValueError):
        cells.CellCache(sphere[2], size=0.0)
    with pytest.raises(ValueError):
        cells.CellCache(sphere[2], size=np.nan)
