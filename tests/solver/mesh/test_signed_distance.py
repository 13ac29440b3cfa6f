"""The compiled signed distance (solver/mesh/signed_distance.py, MeshQuery's "bvh" face search)
against its reference, libigl's face with the numpy steps: a closed sphere, the MakeHuman
body's collision surface, an open mesh and an open body's collision surface; with hints of
every kind and with cell caches; non-finite points."""

import numpy as np
import pytest

from hairport.solver.mesh import backends
from hairport.solver.mesh.collision import collision_query
from hairport.solver.mesh.query import MeshQuery
from tests.solver.mesh.meshes import check_normal_identity, icosphere, query_with, sample_near_features
from tests.solver.mesh.test_inside import open_capsule

#: m: the compiled and the reference distances and closest points agree to rounding
EXACT = 1e-12


def on_backend(query: MeshQuery, backend: str) -> MeshQuery:
    """A query over the same faces with the same inside test, on one face search."""
    copy = MeshQuery(query.vertices, query.faces, inside=query.inside_test)
    copy._prepare()
    copy._closest = query_with(query.vertices, query.faces, backend)._closest
    return copy


def check(compiled, reference, points):
    """Same distances, closest points, signs and normals; a face may differ only on a tie."""
    np.testing.assert_allclose(compiled.distance, reference.distance, rtol=0, atol=EXACT)
    np.testing.assert_allclose(compiled.closest, reference.closest, rtol=0, atol=EXACT)
    np.testing.assert_array_equal(compiled.distance < 0, reference.distance < 0)
    off = np.abs(reference.distance) > 1e-6  # nearer, a normal is the direction of a tiny offset
    np.testing.assert_allclose(compiled.normal[off], reference.normal[off], rtol=0, atol=1e-9)
    check_normal_identity(points, compiled)


def hair_like(vertices, n, rng, reach=0.02):
    """Points off the vertices, most within a few mm, up to ``reach`` (m), a few inside."""
    along = rng.normal(size=(n, 3))
    along /= np.linalg.norm(along, axis=1, keepdims=True)
    return vertices[rng.integers(0, len(vertices), n)] + along * np.minimum(rng.exponential(3e-3, n), reach)[:, None]


def sphere():
    return MeshQuery(*icosphere(subdivisions=3))


def open_mesh():
    """The open capsule as a plain query: pseudonormal signs of the nearest feature."""
    return MeshQuery(*open_capsule())


def open_body():
    """The open capsule's collision surface: winding numbers where the pseudonormal is not exact."""
    return collision_query(*open_capsule())


@pytest.mark.parametrize("make", [sphere, open_mesh, open_body])
def test_the_compiled_query_matches_the_reference_with_any_hint_and_a_cell_cache(make):
    query = make()
    rng = np.random.default_rng(0)
    points = np.concatenate([sample_near_features(query.vertices, query.faces, rng, n=2400),
                             hair_like(query.vertices, 4000, rng)])
    compiled, reference = on_backend(query, "bvh"), on_backend(query, "igl")
    expected = reference.signed_distance(points)
    plain = compiled.signed_distance(points)
    check(plain, expected, points)
    nearby = compiled.signed_distance(points + rng.normal(scale=2e-3, size=points.shape)).faces
    hints = {
        "right": plain.faces,
        "stale": nearby,
        "wrong": rng.integers(0, len(query.faces), len(points)),
        "out of range": rng.choice([-1, -(10**12), len(query.faces), 10**15], len(points)),
    }
    for name, hint in hints.items():
        check(compiled.signed_distance(points, hint=hint), expected, points)
    cache = compiled.cell_cache()
    check(compiled.signed_distance(points, cells=cache), expected, points)  # fills the cells
    moved = points + rng.normal(scale=3e-4, size=points.shape)
    check(compiled.signed_distance(moved, hint=plain.faces, cells=cache), reference.signed_distance(moved), moved)


def test_the_compiled_query_matches_the_reference_on_the_body(makehuman_body):
    body = collision_query(*makehuman_body)
    rng = np.random.default_rng(1)
    vertices = body.vertices
    points = np.concatenate([
        hair_like(vertices, 40000, rng),
        vertices[rng.integers(0, len(vertices), 20000)] + rng.normal(size=(20000, 3)) * np.geomspace(
            1e-9, 5e-2, 20000)[:, None],
        vertices.mean(axis=0) + rng.normal(size=(3000, 3)) * 0.5,  # deep inside and far outside
    ])
    compiled, reference = on_backend(body, "bvh"), on_backend(body, "igl")
    expected = reference.signed_distance(points)
    check(compiled.signed_distance(points), expected, points)
    cache = compiled.cell_cache()
    for _ in range(2):  # filling, then filled
        check(compiled.signed_distance(points, cells=cache), expected, points)
    assert (expected.distance < 0).sum() > 1000  # the check covered points inside


@pytest.mark.parametrize("backend", ["bvh", "igl"])
def test_non_finite_points_get_nan_and_face_0(backend):
    query = on_backend(sphere(), backend)
    points = np.array([[np.nan, 0.0, 0.0], [0.0, np.inf, 0.0], [0.0, 0.0, 0.2], [-np.inf, np.nan, 1.0]])
    for cells in ([None, query.cell_cache()] if backend == "bvh" else [None]):
        sd = query.signed_distance(points, cells=cells)
        bad = [0, 1, 3]
        assert np.isnan(sd.distance[bad]).all() and np.isnan(sd.closest[bad]).all() and np.isnan(sd.normal[bad]).all()
        np.testing.assert_array_equal(sd.faces[bad], 0)
        assert 0.09 < sd.distance[2] < 0.1 + 1e-12


def test_the_compiled_search_is_the_default_and_only_it_has_cell_caches():
    assert backends.CLOSEST_FACE_BACKENDS[0] == "bvh"
    vertices, faces = icosphere(subdivisions=1)
    assert MeshQuery(vertices, faces).cell_cache() is not None
    assert query_with(vertices, faces, "igl").cell_cache() is None
    points = np.random.default_rng(2).normal(size=(20, 3)) * 0.1
    reference = query_with(vertices, faces, "igl")
    np.testing.assert_array_equal(reference.signed_distance(points, hint=np.arange(20)).distance,
                                  reference.signed_distance(points).distance)  # libigl ignores hints
