"""Meshes and references shared by the mesh query and backend tests: test meshes, a MeshQuery
forced onto one face-search backend, and libigl's per-call signed distance (the implementation
before the tree was cached) with the checks against it."""

import igl
import numpy as np
import trimesh

from hairport.solver.mesh import backends
from hairport.solver.mesh import query as mesh_query
from hairport.solver.mesh.query import MeshQuery


def _available(name):
    try:
        backends._FACE_INDEXES[name](np.eye(3), np.array([[0, 1, 2]]))
        return True
    except ImportError:
        return False


BACKENDS = [name for name in backends._FACE_INDEXES if _available(name)]  # the default and the opt-in ones


def query_with(vertices, faces, backend):
    """A MeshQuery whose face search is forced to ``backend``."""
    query = MeshQuery(vertices, faces)
    query._prepare()
    query._closest = backends._closest_face_index(query.vertices, query.faces, [backend])
    return query


def old_signed_distance(points, vertices, faces):
    """The previous implementation: libigl, tree and normals rebuilt per call."""
    distance, face, closest, pseudonormal = igl.signed_distance(
        points, vertices, faces, igl.SIGNED_DISTANCE_TYPE_PSEUDONORMAL
    )
    return distance, face, closest, pseudonormal / np.linalg.norm(pseudonormal, axis=1, keepdims=True)


def icosphere(radius=0.1, subdivisions=3):
    """``(vertices (V, 3) float64, faces (F, 3) int64)`` of trimesh's icosphere."""
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)


def dented_box():
    """A subdivided cube whose top-face centre vertex is pushed in: a concave vertex ringed by
    convex and concave edges, where a single face normal gets the sign wrong."""
    mesh = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    for _ in range(2):
        mesh = mesh.subdivide()
    mesh.merge_vertices()
    vertices = np.array(mesh.vertices)
    top = np.flatnonzero((np.abs(vertices[:, 2] - 0.5) < 1e-9) & (np.abs(vertices[:, 0]) < 1e-9) & (np.abs(vertices[:, 1]) < 1e-9))
    assert len(top) == 1
    vertices[top[0], 2] = 0.2
    return vertices, np.asarray(mesh.faces, dtype=np.int64), top[0]


def assert_matches_old(sd, distance, closest, backend, vertices):
    """Equal to the previous implementation: to rounding with the float64 search; with the
    float32 one exactly within the near-surface band and to ~1e-7 of the size beyond it
    (a near-tie face may be picked there, so the closest point is not compared)."""
    if backends._FACE_INDEXES[backend].exact:
        np.testing.assert_allclose(sd.distance, distance, rtol=0, atol=1e-12)
        np.testing.assert_allclose(sd.closest, closest, rtol=0, atol=1e-12)
        return
    extent = np.linalg.norm(vertices.max(0) - vertices.min(0))
    np.testing.assert_allclose(sd.distance, distance, rtol=0, atol=1e-6 * extent)
    near = np.abs(distance) < 0.5 * mesh_query.EXACT_BAND * extent
    np.testing.assert_allclose(sd.distance[near], distance[near], rtol=0, atol=1e-12)
    np.testing.assert_allclose(sd.closest[near], closest[near], rtol=0, atol=1e-12)
    return near


def check_normal_identity(points, sd):
    """<p - closest, normal> == distance, unit normal, |p - closest| == |distance|."""
    offset = points - sd.closest
    np.testing.assert_allclose(np.einsum("ij,ij->i", offset, sd.normal), sd.distance, atol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(sd.normal, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(offset, axis=1), np.abs(sd.distance), atol=1e-14)


def sample_near_features(vertices, faces, rng, n=600):
    """Points inside/outside near the vertices, edge midpoints and face centroids, plus deep
    inside and far outside."""
    corners = vertices[faces]
    centroid = corners.mean(axis=1)
    midpoint = 0.5 * (corners[:, 0] + corners[:, 1])
    extent = np.linalg.norm(vertices.max(0) - vertices.min(0))
    anchors = np.concatenate([vertices, midpoint, centroid])
    anchors = anchors[rng.integers(0, len(anchors), n)]
    offsets = rng.normal(size=(n, 3)) * extent * np.geomspace(1e-7, 1e-1, n)[:, None]
    center = vertices.mean(axis=0)
    deep = center + rng.normal(size=(n // 6, 3)) * 0.1 * extent
    far = center + rng.normal(size=(n // 6, 3)) * 2.0 * extent
    return np.concatenate([anchors + offsets, deep, far])
