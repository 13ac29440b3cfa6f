"""Geometric queries (solver/mesh/query.py): signed distance with a cached tree, ray hits, closest points on triangles.

The reference for the signed distance is libigl's ``signed_distance`` with the
pseudonormal sign (the implementation before the tree was cached), the analytic distance
inside a convex polyhedron, and the exact winding number for the sign on non-convex meshes.
"""

import pickle

import igl
import numpy as np
import pytest
import trimesh

from hairport.solver.mesh import query as mesh_query
from hairport.solver.mesh import space_order
from hairport.solver.mesh.query import ON_SURFACE_DISTANCE, MeshQuery
from hairport.solver.mesh.triangles import barycentric_coordinates, interpolate_barycentric
from tests.solver.mesh.meshes import (
    BACKENDS,
    assert_matches_old,
    check_normal_identity,
    dented_box,
    icosphere,
    old_signed_distance,
    query_with,
    sample_near_features,
)


@pytest.mark.parametrize("backend", BACKENDS)
def test_icosphere_matches_previous_implementation(backend):
    vertices, faces = icosphere()
    query = query_with(vertices, faces, backend)
    points = sample_near_features(vertices, faces, np.random.default_rng(0))
    sd = query.signed_distance(points)
    distance, face, closest, _ = old_signed_distance(points, vertices, faces)
    assert sd.distance.shape == (len(points),) and sd.closest.shape == (len(points), 3)
    assert sd.normal.shape == (len(points), 3) and sd.faces.dtype == np.int64
    np.testing.assert_array_equal(np.sign(sd.distance[distance != 0]), np.sign(distance[distance != 0]))
    near = assert_matches_old(sd, distance, closest, backend, vertices)
    assert near is None or near.sum() > 100
    check_normal_identity(points, sd)
    # the face holds the closest point
    bary = barycentric_coordinates(sd.closest, vertices[faces[sd.faces]])
    assert bary.min() > -1e-9
    np.testing.assert_allclose(interpolate_barycentric(vertices, faces, sd.faces, bary), sd.closest, atol=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
def test_icosphere_analytic(backend):
    radius = 0.1
    vertices, faces = icosphere(radius)
    query = query_with(vertices, faces, backend)
    corners = vertices[faces]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    heights = np.einsum("ij,ij->i", corners[:, 0], normals)  # plane offsets from the centre
    rng = np.random.default_rng(1)

    # outside along a vertex direction: the vertex is the closest point
    scale = 1.0 + rng.uniform(1e-4, 1.0, len(vertices))
    sd = query.signed_distance(vertices * scale[:, None])
    np.testing.assert_allclose(sd.distance, (scale - 1.0) * radius, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(sd.closest, vertices, atol=1e-12)
    np.testing.assert_allclose(sd.normal, vertices / radius, atol=1e-9)

    # along a face normal through the centroid, inside and outside
    centroid = corners.mean(axis=1)
    along = rng.uniform(-0.5, 0.5, len(faces)) * radius * 0.2
    sd = query.signed_distance(centroid + along[:, None] * normals)
    np.testing.assert_allclose(sd.distance, along, atol=1e-12)
    np.testing.assert_allclose(sd.closest, centroid, atol=1e-12)

    # outside along an edge-midpoint direction: the midpoint is the closest point
    midpoint = 0.5 * (corners[:, 0] + corners[:, 1])
    grow = 1.0 + rng.uniform(1e-3, 0.5, len(faces))
    sd = query.signed_distance(midpoint * grow[:, None])
    np.testing.assert_allclose(sd.distance, (grow - 1.0) * np.linalg.norm(midpoint, axis=1), rtol=1e-9)
    np.testing.assert_allclose(sd.closest, midpoint, atol=1e-12)

    # anywhere inside a convex polyhedron: minus the distance to the nearest face plane
    inside = rng.normal(size=(2000, 3))
    inside *= (rng.uniform(0.0, 0.9 * heights.min(), 2000) / np.linalg.norm(inside, axis=1))[:, None]
    sd = query.signed_distance(inside)
    np.testing.assert_allclose(sd.distance, -(heights[None] - inside @ normals.T).min(axis=1), atol=1e-6 * radius)
    assert (sd.distance < 0).all()
    # and close to a sphere of the same radius (the polyhedron is inscribed)
    assert np.abs(sd.distance - (np.linalg.norm(inside, axis=1) - radius)).max() < radius - heights.min() + 1e-12


@pytest.mark.parametrize("backend", BACKENDS)
def test_points_on_the_surface_get_the_outward_pseudonormal(backend):
    vertices, faces = icosphere()
    query = query_with(vertices, faces, backend)
    corners = vertices[faces]
    face_normals = igl.per_face_normals(vertices, faces, np.array([0.0, 0.0, 1.0]))
    vertex_normals = igl.per_vertex_normals(vertices, faces, igl.PER_VERTEX_NORMALS_WEIGHTING_TYPE_ANGLE)

    # at the vertices: the angle-weighted vertex normal
    sd = query.signed_distance(vertices)
    assert np.abs(sd.distance).max() < ON_SURFACE_DISTANCE
    np.testing.assert_allclose(sd.normal, vertex_normals, atol=1e-12)

    # at edge midpoints: the normalised sum of the two face normals
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    pairs = mesh.face_adjacency
    edges = mesh.face_adjacency_edges
    midpoints = 0.5 * (vertices[edges[:, 0]] + vertices[edges[:, 1]])
    sd = query.signed_distance(midpoints)
    assert np.abs(sd.distance).max() < ON_SURFACE_DISTANCE
    expected = face_normals[pairs[:, 0]] + face_normals[pairs[:, 1]]
    np.testing.assert_allclose(sd.normal, expected / np.linalg.norm(expected, axis=1, keepdims=True), atol=1e-12)

    # at face centroids: the face normal
    sd = query.signed_distance(corners.mean(axis=1))
    assert np.abs(sd.distance).max() < ON_SURFACE_DISTANCE
    np.testing.assert_allclose(sd.normal, face_normals, atol=1e-12)
    # all of it as the previous implementation had it
    points = np.concatenate([vertices, midpoints, corners.mean(axis=1)])
    _, _, _, old_normal = old_signed_distance(points, vertices, faces)
    np.testing.assert_allclose(query.signed_distance(points).normal, old_normal, atol=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("shape", ["torus", "dented_box"])
def test_sign_near_features_of_non_convex_meshes(backend, shape):
    rng = np.random.default_rng(2)
    if shape == "torus":
        mesh = trimesh.creation.torus(major_radius=1.0, minor_radius=0.3, major_sections=32, minor_sections=16)
        vertices, faces = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)
        anchors = vertices
    else:
        vertices, faces, dent = dented_box()
        ring = np.unique(faces[(faces == dent).any(axis=1)])
        anchors = np.concatenate([vertices[[dent]]] * 50 + [vertices[ring]] * 10)
    assert trimesh.Trimesh(vertices, faces, process=False).is_watertight
    # points very close to vertices (and their edges), in every direction
    directions = rng.normal(size=(len(anchors) * 4, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    step = np.geomspace(1e-6, 1e-2, len(directions))
    points = np.repeat(anchors, 4, axis=0) + directions * step[:, None]
    query = query_with(vertices, faces, backend)
    sd = query.signed_distance(points)
    winding = igl.winding_number(vertices, faces, points)
    decided = np.abs(winding - 0.5) > 0.25  # exact winding number: 1 inside, 0 outside
    assert decided.mean() > 0.99
    np.testing.assert_array_equal(sd.distance[decided] < 0, winding[decided] > 0.5)
    distance, _, closest, _ = old_signed_distance(points, vertices, faces)
    assert_matches_old(sd, distance, closest, backend, vertices)
    check_normal_identity(points, sd)


@pytest.mark.parametrize("backend", BACKENDS)
def test_sign_next_to_a_knife_edge(backend):
    """A thin wedge (5 degree edge), points from 1e-8 to 1e-3 away from its sharp edge: the
    sign must follow the edge and vertex pseudonormals there."""
    vertices = np.array([[0, 0, 0], [1, -0.0437, 0], [1, 0.0437, 0], [0, 0, 0.5], [1, -0.0437, 0.5], [1, 0.0437, 0.5]], float)
    faces = np.array([[0, 2, 1], [3, 4, 5], [0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4], [2, 0, 3], [2, 3, 5]])
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    mesh = mesh.subdivide().subdivide()
    vertices, faces = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)
    assert mesh.is_watertight and mesh.volume > 0
    rng = np.random.default_rng(10)
    n = 4000
    on_edge = np.stack([rng.uniform(0, 0.02, n), np.zeros(n), rng.uniform(0.05, 0.45, n)], axis=1)  # at the sharp edge x = 0
    points = on_edge + rng.normal(size=(n, 3)) * np.geomspace(1e-8, 1e-3, n)[:, None]
    sd = query_with(vertices, faces, backend).signed_distance(points)
    distance, _, closest, _ = old_signed_distance(points, vertices, faces)
    assert_matches_old(sd, distance, closest, backend, vertices)
    np.testing.assert_array_equal(np.sign(sd.distance[distance != 0]), np.sign(distance[distance != 0]))
    winding = igl.winding_number(vertices, faces, points)
    decided = np.abs(winding - 0.5) > 0.25
    np.testing.assert_array_equal(sd.distance[decided] < 0, winding[decided] > 0.5)
    check_normal_identity(points, sd)


@pytest.fixture(scope="module")
def body():
    from hairport.solver.synthetic.assets import fetch_makehuman_assets
    from hairport.solver.synthetic.makehuman import build_preset

    assets = fetch_makehuman_assets(offline_ok=True)
    if assets is None:
        pytest.skip("MakeHuman assets unavailable")
    character = build_preset("average-female", assets)
    return np.asarray(character.vertices, float), np.asarray(character.faces, np.int64)


@pytest.mark.parametrize("backend", BACKENDS)
def test_body_points_within_micrometres_of_the_surface(backend, body):
    """On the MakeHuman body, creases where a face picked in float32 had the wrong sign
    within ~1 um of the surface (before the float64 re-search of the near band)."""
    vertices, faces = body
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    n = 60000
    rng = np.random.default_rng(12)
    points, face_ids = trimesh.sample.sample_surface(mesh, n, seed=12)
    third = n // 3
    points[:third] = vertices[faces[face_ids[:third], 0]]  # at vertices
    t = rng.random((third, 1))
    edge = faces[face_ids[third : 2 * third]]
    points[third : 2 * third] = t * vertices[edge[:, 0]] + (1 - t) * vertices[edge[:, 1]]  # on edges
    points += rng.normal(size=(n, 3)) * np.geomspace(1e-8, 1e-3, n)[:, None]
    sd = query_with(vertices, faces, backend).signed_distance(points)
    distance, _, closest, _ = old_signed_distance(points, vertices, faces)
    assert_matches_old(sd, distance, closest, backend, vertices)
    np.testing.assert_array_equal(np.sign(sd.distance[distance != 0]), np.sign(distance[distance != 0]))
    check_normal_identity(points, sd)


@pytest.mark.parametrize("backend", BACKENDS)
def test_z_order_sorting_does_not_change_results(backend, monkeypatch):
    vertices, faces = icosphere()
    query = query_with(vertices, faces, backend)
    points = sample_near_features(vertices, faces, np.random.default_rng(11), n=3000)
    monkeypatch.setattr(space_order, "SORT_QUERIES_FROM", 1)
    sorted_ = query.signed_distance(points)
    monkeypatch.setattr(space_order, "SORT_QUERIES_FROM", 10**12)
    plain = query.signed_distance(points)
    for field in ("distance", "closest", "normal", "faces"):
        np.testing.assert_array_equal(getattr(sorted_, field), getattr(plain, field))


def test_pickle_and_empty_input():
    vertices, faces = icosphere()
    query = MeshQuery(vertices, faces)
    points = np.random.default_rng(5).normal(size=(40, 3)) * 0.1
    before = query.signed_distance(points)
    query.first_hits(points, -points)
    clone = pickle.loads(pickle.dumps(query))
    after = clone.signed_distance(points)
    np.testing.assert_array_equal(before.distance, after.distance)
    np.testing.assert_array_equal(before.normal, after.normal)
    empty = query.signed_distance(np.zeros((0, 3)))
    assert empty.distance.shape == (0,) and empty.closest.shape == (0, 3) and empty.faces.dtype == np.int64
    hits = query.first_hits(np.zeros((0, 3)), np.zeros((0, 3)))
    assert hits.hit.shape == (0,) and hits.points.shape == (0, 3)


def test_take_selects_rows_of_a_result():
    vertices, faces = icosphere()
    points = np.random.default_rng(13).normal(size=(30, 3)) * 0.1
    sd = MeshQuery(vertices, faces).signed_distance(points)
    rows = np.array([4, 0, 17])
    part = sd.take(rows)
    for field in ("distance", "closest", "normal", "faces"):
        np.testing.assert_array_equal(getattr(part, field), getattr(sd, field)[rows])
    mask = sd.distance < 0
    np.testing.assert_array_equal(sd.take(mask).distance, sd.distance[mask])


def test_first_hits_match_trimesh_reference():
    vertices, faces = icosphere(0.1, subdivisions=2)
    query = MeshQuery(vertices, faces)
    rng = np.random.default_rng(6)
    n = 400
    origins = rng.normal(size=(n, 3)) * 0.1
    origins[: n // 4] *= 0.3  # some start inside
    aim = rng.normal(size=(n, 3)) * 0.08 - origins  # roughly at the sphere: hits and misses
    directions = aim * rng.uniform(0.1, 10.0, (n, 1))  # not unit length
    hits = query.first_hits(origins, directions)

    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    reference = trimesh.ray.ray_triangle.RayMeshIntersector(trimesh.Trimesh(vertices, faces, process=False))
    locations, ray_index, _ = reference.intersects_location(origins, unit, multiple_hits=True)
    t = np.einsum("ij,ij->i", locations - origins[ray_index], unit[ray_index])
    first = np.full(n, np.inf)
    np.minimum.at(first, ray_index, np.where(t >= 0, t, np.inf))
    expect_hit = np.isfinite(first)
    assert 0.2 < expect_hit.mean() < 0.9
    np.testing.assert_array_equal(hits.hit, expect_hit)
    np.testing.assert_allclose(hits.distance[expect_hit], first[expect_hit], atol=1e-6)
    assert np.isinf(hits.distance[~expect_hit]).all() and (hits.faces[~expect_hit] == -1).all()
    assert (hits.barycentric[~expect_hit] == 0).all()
    h = hits.hit
    np.testing.assert_allclose(hits.points[h], origins[h] + hits.distance[h, None] * unit[h], atol=1e-9)
    np.testing.assert_allclose(interpolate_barycentric(vertices, faces, hits.faces[h], hits.barycentric[h]), hits.points[h], atol=1e-9)
    assert hits.barycentric[h].min() > -1e-6
    np.testing.assert_allclose(hits.barycentric[h].sum(axis=1), 1.0, atol=1e-12)


def test_closest_point_regions_against_brute_force():
    """The vectorised point-triangle routine on random (also thin) triangles."""
    rng = np.random.default_rng(9)
    n = 3000
    triangles = rng.normal(size=(n, 3, 3))
    triangles[:300, 2] = triangles[:300, 0] + 1e-4 * rng.normal(size=(300, 3)) + (triangles[:300, 1] - triangles[:300, 0]) * 0.5
    points = rng.normal(size=(n, 3)) * 2.0
    closest, feature = mesh_query._closest_points_on_triangles(points, triangles)
    # squared distance from libigl per (point, triangle)
    for i in range(0, n, 100):
        v = triangles[i]
        sqr, _, c = igl.point_mesh_squared_distance(points[i : i + 1], v, np.array([[0, 1, 2]]))
        assert abs(np.sum((points[i] - closest[i]) ** 2) - sqr[0]) < 1e-12
    bary = barycentric_coordinates(closest, triangles)
    inside = feature == 0
    assert (bary[inside] > -1e-9).all()
    for k in range(3):
        on_edge = feature == 1 + k
        assert np.abs(bary[on_edge, k]).max(initial=0) < 1e-6
        at_corner = feature == 4 + k
        np.testing.assert_allclose(closest[at_corner], triangles[at_corner, k])


def test_a_moved_query_answers_as_one_built_on_the_moved_vertices():
    vertices, faces, _ = dented_box()
    before = MeshQuery(vertices, faces)
    rng = np.random.default_rng(4)
    points = rng.uniform(-1.5, 1.5, size=(4000, 3))
    before.signed_distance(points[:1])
    # a smooth motion of every vertex: stretched along x, bent in y
    moved_vertices = vertices * [1.3, 1.0, 0.9] + [0.0, 0.1, 0.0] * vertices[:, :1] ** 2
    moved = before.moved(moved_vertices)
    fresh = MeshQuery(moved_vertices, faces)
    got, expected = moved.signed_distance(points), fresh.signed_distance(points)
    np.testing.assert_allclose(got.distance, expected.distance, rtol=0, atol=1e-14)
    np.testing.assert_allclose(got.normal, expected.normal, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(moved._edge_ids, before._edge_ids)
    assert moved.closed == fresh.closed
    # a query moved before its own search was built moves the one it came from, once more
    again = moved.moved(vertices)
    np.testing.assert_allclose(again.signed_distance(points).distance, before.signed_distance(points).distance,
                               rtol=0, atol=1e-14)
    assert pickle.loads(pickle.dumps(moved))._refit_from is None
