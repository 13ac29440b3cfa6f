"""Face-search and ray backends (solver/mesh/backends.py): the default, the fall-through, float32 search, Embree rays."""

import numpy as np
import pytest
import trimesh

from hairport.solver.mesh import backends
from hairport.solver.mesh import query as mesh_query
from hairport.solver.mesh.query import MeshQuery
from tests.solver.mesh.meshes import BACKENDS, icosphere, query_with


def test_float32_face_search_is_close_everywhere_and_exact_near_the_surface():
    if "fcpw" not in BACKENDS:
        pytest.skip("fcpw not installed")
    vertices, faces = icosphere(0.1, subdivisions=4)
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    surface, _ = trimesh.sample.sample_surface(mesh, 20000, seed=3)
    rng = np.random.default_rng(3)
    points = surface + rng.normal(size=surface.shape) * np.geomspace(1e-9, 1e-2, len(surface))[:, None]
    fast, exact = query_with(vertices, faces, "fcpw"), query_with(vertices, faces, "igl")
    a, b = fast.signed_distance(points), exact.signed_distance(points)
    np.testing.assert_array_equal(a.distance < 0, b.distance < 0)
    extent = np.linalg.norm(vertices.max(0) - vertices.min(0))
    np.testing.assert_allclose(a.distance, b.distance, atol=1e-6 * extent)
    near = np.abs(b.distance) < 0.5 * mesh_query.EXACT_BAND * extent
    np.testing.assert_allclose(a.distance[near], b.distance[near], atol=1e-14)


def test_default_backend_and_structures_are_built_once():
    vertices, faces = icosphere()
    query = MeshQuery(vertices, faces)
    assert query._closest is None  # lazily
    points = np.random.default_rng(4).normal(size=(50, 3)) * 0.1
    first = query.signed_distance(points)
    index = query._closest
    assert type(index) is backends._FACE_INDEXES[backends.CLOSEST_FACE_BACKENDS[0]]
    second = query.signed_distance(points)
    assert query._closest is index
    np.testing.assert_array_equal(first.distance, second.distance)


def test_an_unavailable_backend_falls_through(monkeypatch):
    vertices, faces = icosphere()

    def missing(*_):
        raise ImportError("not installed")

    monkeypatch.setitem(backends._FACE_INDEXES, "missing", missing)
    assert isinstance(backends._closest_face_index(vertices, faces, ["missing", "igl"]), backends._IglFaces)
    with pytest.raises(ImportError):
        backends._closest_face_index(vertices, faces, ["missing"])



def test_igl_faces_give_the_closest_face_and_point_of_a_square():
    vertices = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    index = backends._IglFaces(vertices, faces)
    assert index.exact
    points = np.array([[0.9, 0.1, 0.5], [0.1, 0.9, -2.0], [2.0, 0.5, 0.0]])
    found, closest = index.closest(points)
    np.testing.assert_array_equal(found, [0, 1, 0])
    np.testing.assert_allclose(closest, [[0.9, 0.1, 0.0], [0.1, 0.9, 0.0], [1.0, 0.5, 0.0]], rtol=0, atol=1e-15)


def test_embree_first_faces_hit_and_miss():
    vertices, faces = icosphere(0.1, subdivisions=2)
    rays = backends._EmbreeFaces(vertices, faces)
    origins = np.array([[0.0, 0.0, 0.5], [0.0, 0.0, 0.5], [0.0, 0.0, 0.0]])
    unit = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])  # at the sphere, away, from inside
    first = rays.first_faces(origins, unit)
    assert first.dtype == np.int64 and first[1] == -1 and first[0] >= 0 and first[2] >= 0
    # the hit faces are the ones the rays cross: near the top pole and at +x
    centroids = vertices[faces[first[[0, 2]]]].mean(axis=1)
    assert centroids[0, 2] > 0.09 and centroids[1, 0] > 0.09
