"""Geometric queries against a triangle mesh: closest point, signed distance, ray casting.

Convention: ``vertices (V, 3) float64``, ``faces (F, 3) int64`` with outward (counter-
clockwise) orientation; points and rays are ``(N, 3) float64``. Building a
:class:`MeshQuery` is the expensive setup (acceleration structures); its methods are the
cheap repeated queries.

Signed distance
---------------
The BVH over the triangles is built once per :class:`MeshQuery` (lazily, on the first
query) and only answers *which face* holds the closest point. Everything else is float64
numpy over all points at once: the closest point on that face (Ericson's region test, which
also tells whether it lies inside the face, on one of its edges or at one of its corners)
and the sign from the angle-weighted pseudonormal of that feature (Baerentzen & Aanaes
2005): the face normal inside a face, the sum of the adjacent face normals on an edge, the
angle-weighted vertex normal at a corner, all precomputed. This is the same sign rule as
``igl.signed_distance(..., SIGNED_DISTANCE_TYPE_PSEUDONORMAL)``, which rebuilt its tree and
normals on every call.

The pseudonormal sign is exact for a closed, consistently oriented, manifold mesh (the
MakeHuman body is one). On an open mesh it is still the side of the nearest feature, which
is what the collision constraint wants near the surface, but "inside" far from a hole is
not meaningful (a winding-number test would be, at a much higher price).

Face search backends, tried in order (:data:`CLOSEST_FACE_BACKENDS`): ``fcpw`` (float32
wide BVH, the fastest measured, see ``bench/geometry.py``) and libigl's ``AABB`` (float64).
fcpw works in single precision: where two faces that do *not* share the closest point are
within ~1e-7 (relative to the mesh size) of the same distance -- points on the medial axis
-- it may pick the farther one, and the float64 distance then exceeds the exact one by
that much. Ties between faces that share the closest point (an edge or a vertex, the
common case) are exact, since the closest point on either face is that shared point.
"""

from __future__ import annotations

from dataclasses import dataclass

import igl
import numpy as np
import trimesh

#: below this distance (m) a point counts as on the surface and the pseudonormal gives the direction
ON_SURFACE_DISTANCE = 1e-12

#: barycentric coordinate at or below which the closest point counts as on an edge or vertex
#: of its face (the pseudonormal's feature), libigl's value
FEATURE_EPSILON = 1e-12

#: face-search backends for :meth:`MeshQuery.signed_distance`, the first importable one is used
CLOSEST_FACE_BACKENDS = ("fcpw", "igl")

#: with a float32 face search, points closer to the surface than this fraction of the mesh's
#: bounding-box diagonal are searched again in float64 (exact sign next to sharp creases)
EXACT_BAND = 1e-4


@dataclass(frozen=True)
class SignedDistance:
    """Result of :meth:`MeshQuery.signed_distance`.

    Attributes
    ----------
    distance : (N,) float64
        Negative inside the mesh.
    closest : (N, 3) float64
        Closest surface point.
    normal : (N, 3) float64
        Unit vector with ``<p - closest, normal> == distance``: the outward direction of the
        distance field, the mesh pseudonormal where the point lies on the surface.
    faces : (N,) int64
        Face holding the closest point.
    """

    distance: np.ndarray
    closest: np.ndarray
    normal: np.ndarray
    faces: np.ndarray


@dataclass(frozen=True)
class RayHits:
    """Result of :meth:`MeshQuery.first_hits`.

    Attributes
    ----------
    hit : (N,) bool
    distance : (N,) float64
        Ray parameter of the hit along the (unit) direction, ``inf`` where missed.
    faces : (N,) int64
        ``-1`` where missed.
    barycentric : (N, 3) float64
        Of the hit point in its face; zeros where missed.
    points : (N, 3) float64
    """

    hit: np.ndarray
    distance: np.ndarray
    faces: np.ndarray
    barycentric: np.ndarray
    points: np.ndarray


class MeshQuery:
    """Acceleration structures over one mesh, built once, queried many times.

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        self._mesh = trimesh.Trimesh(self.vertices, self.faces, process=False)
        self._rays = None
        self._closest = None  # face search (BVH), built on the first signed_distance
        self._corners = None  # (F, 3, 3) triangle corners
        self._pseudonormals = None  # (F, 7, 3): face, edges opposite corners 0..2, corners 0..2
        self._exact = None  # float64 face search for points near the surface, when _closest is float32
        self._exact_band = 0.0

    def __getstate__(self):
        # the native BVHs do not pickle; they are rebuilt lazily after unpickling
        state = self.__dict__.copy()
        state["_closest"] = None
        state["_rays"] = None
        state["_exact"] = None
        return state

    def _prepare(self):
        if self._closest is None:
            self._corners = self.vertices[self.faces]
            self._pseudonormals = _pseudonormal_table(self.vertices, self.faces)
            self._closest = _closest_face_index(self.vertices, self.faces)
            extent = np.linalg.norm(self.vertices.max(axis=0) - self.vertices.min(axis=0)) if len(self.vertices) else 1.0
            self._exact_band = EXACT_BAND * extent
        return self._closest

    def _exact_index(self):
        if self._exact is None:
            self._exact = _IglFaces(self.vertices, self.faces)
        return self._exact

    def signed_distance(self, points: np.ndarray) -> SignedDistance:
        """Signed distance (negative inside), closest point and distance normal.

        Parameters
        ----------
        points : (N, 3) float64
        """
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        if len(points) == 0:
            return SignedDistance(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64))
        index = self._prepare()
        faces = index.closest_faces(points)
        closest, feature = _closest_points_on_triangles(points, self._corners[faces])
        offset = points - closest
        length = np.sqrt(np.einsum("ij,ij->i", offset, offset))
        if not index.exact:
            # near the surface a face picked in float32 may be on the wrong side of a sharp
            # crease: redo those few points with the float64 tree
            near = np.flatnonzero(length < self._exact_band)
            if len(near):
                faces[near] = self._exact_index().closest_faces(points[near])
                closest[near], feature[near] = _closest_points_on_triangles(points[near], self._corners[faces[near]])
                offset[near] = points[near] - closest[near]
                length[near] = np.sqrt(np.einsum("ij,ij->i", offset[near], offset[near]))
        pseudonormal = self._pseudonormals[faces, feature]
        sign = np.where(np.einsum("ij,ij->i", offset, pseudonormal) < 0.0, -1.0, 1.0)
        distance = sign * length
        on_surface = length < ON_SURFACE_DISTANCE
        normal = offset * (sign / np.where(on_surface, 1.0, length))[:, None]
        if on_surface.any():
            normal[on_surface] = pseudonormal[on_surface]
        return SignedDistance(distance, closest, normal, faces)

    def first_hits(self, origins: np.ndarray, directions: np.ndarray) -> RayHits:
        """First intersection of each ray with the mesh.

        Parameters
        ----------
        origins : (N, 3) float64
        directions : (N, 3) float64
            Need not be unit length; ``distance`` is measured along the unit direction.
        """
        origins = np.ascontiguousarray(origins, dtype=np.float64).reshape(-1, 3)
        unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
        n = len(origins)
        hit = np.zeros(n, dtype=bool)
        faces = np.full(n, -1, dtype=np.int64)
        points = np.zeros((n, 3))
        if n:
            if self._rays is None:
                from trimesh.ray.ray_pyembree import RayMeshIntersector

                self._rays = RayMeshIntersector(self._mesh)
            locations, ray_index, tri_index = self._rays.intersects_location(origins, unit, multiple_hits=False)
            hit[ray_index] = True
            faces[ray_index] = tri_index
            points[ray_index] = locations
        distance = np.where(hit, np.einsum("ij,ij->i", points - origins, unit), np.inf)
        barycentric = np.zeros((n, 3))
        if hit.any():
            barycentric[hit] = barycentric_coordinates(points[hit], self.vertices[self.faces[faces[hit]]])
        return RayHits(hit, distance, faces, barycentric, points)


def barycentric_coordinates(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Barycentric coordinates of points with respect to triangles (of the projection onto the plane).

    Parameters
    ----------
    points : (N, 3) float64
    triangles : (N, 3, 3) float64
        Corner positions, one triangle per point.

    Returns
    -------
    barycentric : (N, 3) float64
        Sums to 1 per row.
    """
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    v0, v1, v2 = b - a, c - a, points - a
    d00 = np.einsum("ij,ij->i", v0, v0)
    d01 = np.einsum("ij,ij->i", v0, v1)
    d11 = np.einsum("ij,ij->i", v1, v1)
    d20 = np.einsum("ij,ij->i", v2, v0)
    d21 = np.einsum("ij,ij->i", v2, v1)
    denom = d00 * d11 - d01 * d01
    denom = np.where(np.abs(denom) > 0, denom, 1.0)
    v = (d11 * d20 - d01 * d21) / denom
    w = (d00 * d21 - d01 * d20) / denom
    return np.stack([1.0 - v - w, v, w], axis=1)


def interpolate_barycentric(vertices: np.ndarray, faces: np.ndarray, face_ids: np.ndarray, barycentric: np.ndarray) -> np.ndarray:
    """Points given by face and barycentric coordinates.

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    face_ids : (N,) int64
    barycentric : (N, 3) float64

    Returns
    -------
    points : (N, 3) float64
    """
    corners = vertices[faces[face_ids]]
    return np.einsum("ij,ijk->ik", barycentric, corners)


def closest_points_on_segments(points: np.ndarray, heads: np.ndarray, tails: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest point on each segment to each point, for every (point, segment) pair.

    Parameters
    ----------
    points : (N, 3) float64
    heads, tails : (B, 3) float64

    Returns
    -------
    t : (N, B) float64
        Segment parameter in [0, 1].
    closest : (N, B, 3) float64
    """
    axis = tails - heads
    length_sq = np.maximum(np.einsum("ij,ij->i", axis, axis), np.finfo(float).tiny)
    t = np.clip(((points[:, None, :] - heads[None]) * axis[None]).sum(-1) / length_sq[None], 0.0, 1.0)
    return t, heads[None] + t[..., None] * axis[None]


def _closest_points_on_triangles(points: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest point on each triangle to each point, and the feature it lies on (float64).

    Ericson, *Real-Time Collision Detection*, 5.1.5, vectorised: the Voronoi regions are
    tested in his order and the first match wins. The feature is read off the barycentric
    coordinates of the result with tolerance :data:`FEATURE_EPSILON`.

    Parameters
    ----------
    points : (N, 3) float64
    triangles : (N, 3, 3) float64

    Returns
    -------
    closest : (N, 3) float64
    feature : (N,) int64
        0 inside the face, ``1 + k`` on the edge opposite corner k, ``4 + k`` at corner k.
    """
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    ab, ac = b - a, c - a
    ap, bp, cp = points - a, points - b, points - c

    def dot(u, v):
        return np.einsum("ij,ij->i", u, v)

    d1, d2 = dot(ab, ap), dot(ac, ap)
    d3, d4 = dot(ab, bp), dot(ac, bp)
    d5, d6 = dot(ab, cp), dot(ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2

    n = len(points)
    v = np.empty(n)  # weight of b
    w = np.empty(n)  # weight of c
    todo = np.ones(n, dtype=bool)

    def take(mask, v_value, w_value):
        mask &= todo
        v[mask] = v_value[mask] if isinstance(v_value, np.ndarray) else v_value
        w[mask] = w_value[mask] if isinstance(w_value, np.ndarray) else w_value
        todo[mask] = False

    with np.errstate(divide="ignore", invalid="ignore"):
        take((d1 <= 0) & (d2 <= 0), 0.0, 0.0)  # corner a
        take((d3 >= 0) & (d4 <= d3), 1.0, 0.0)  # corner b
        take((vc <= 0) & (d1 >= 0) & (d3 <= 0), d1 / (d1 - d3), 0.0)  # edge ab (opposite c)
        take((d6 >= 0) & (d5 <= d6), 0.0, 1.0)  # corner c
        take((vb <= 0) & (d2 >= 0) & (d6 <= 0), 0.0, d2 / (d2 - d6))  # edge ac (opposite b)
        e1, e2 = d4 - d3, d5 - d6
        t = e1 / (e1 + e2)
        take((va <= 0) & (e1 >= 0) & (e2 >= 0), 1.0 - t, t)  # edge bc (opposite a)
        if todo.any():  # inside the face
            denom = va + vb + vc
            denom = np.where(denom != 0, denom, 1.0)
            take(todo.copy(), vb / denom, vc / denom)
    closest = a + v[:, None] * ab + w[:, None] * ac
    # Classify by the barycentric coordinates as libigl's pseudonormal sign does, so that a
    # point on an edge up to rounding counts as on it (its surface normal is the edge's).
    small = np.stack([1.0 - v - w, v, w], axis=1) <= FEATURE_EPSILON
    count = small.sum(axis=1)
    feature = np.where(count == 0, 0, np.where(count == 1, 1 + np.argmax(small, axis=1), 4 + np.argmin(small, axis=1)))
    return closest, feature


def _pseudonormal_table(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit angle-weighted pseudonormals of every feature of every face.

    Returns
    -------
    table : (F, 7, 3) float64
        ``[f, 0]`` the face normal, ``[f, 1 + k]`` the normal of the edge opposite corner k
        (sum of the normals of the faces sharing it, as libigl's uniform edge normals),
        ``[f, 4 + k]`` the angle-weighted vertex normal at corner k.
    """
    corners = vertices[faces]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    face_normals = _normalized(cross)

    # edge k of a face is the one opposite corner k: (k + 1, k + 2)
    edges = np.stack([faces[:, [1, 2]], faces[:, [2, 0]], faces[:, [0, 1]]], axis=1).reshape(-1, 2)
    keys = edges.min(axis=1) * np.int64(len(vertices)) + edges.max(axis=1)  # undirected edge key
    _, edge_ids = np.unique(keys, return_inverse=True)
    edge_normals = _normalized(_sum_rows(edge_ids.reshape(-1), np.repeat(face_normals, 3, axis=0), edge_ids.max() + 1))

    angles = np.empty(faces.shape)
    for k in range(3):
        u = corners[:, (k + 1) % 3] - corners[:, k]
        v = corners[:, (k + 2) % 3] - corners[:, k]
        angles[:, k] = np.arctan2(np.linalg.norm(np.cross(u, v), axis=1), np.einsum("ij,ij->i", u, v))
    weighted = (angles[:, :, None] * face_normals[:, None, :]).reshape(-1, 3)
    vertex_normals = _normalized(_sum_rows(faces.reshape(-1), weighted, len(vertices)))

    table = np.empty((len(faces), 7, 3))
    table[:, 0] = face_normals
    table[:, 1:4] = edge_normals[edge_ids.reshape(-1, 3)]
    table[:, 4:7] = vertex_normals[faces]
    return table


def _sum_rows(index: np.ndarray, rows: np.ndarray, n: int) -> np.ndarray:
    """``out[i] = sum of rows[index == i]``, shape (n, 3)."""
    return np.stack([np.bincount(index, weights=rows[:, k], minlength=n) for k in range(3)], axis=1)


def _normalized(vectors: np.ndarray) -> np.ndarray:
    length = np.linalg.norm(vectors, axis=1, keepdims=True)
    return vectors / np.where(length > 0, length, 1.0)


class _FcpwFaces:
    """Closest face by fcpw's vectorised BVH (float32; coordinates centred first)."""

    exact = False

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        import fcpw

        self._fcpw = fcpw
        lo, hi = vertices.min(axis=0), vertices.max(axis=0)
        self._center = 0.5 * (lo + hi)
        scene = fcpw.scene_3D()
        scene.set_object_count(1)
        scene.set_object_vertices(np.asfortranarray(vertices - self._center, dtype=np.float32), 0)
        scene.set_object_triangles(np.asfortranarray(faces, dtype=np.int32), 0)
        scene.build(fcpw.aggregate_type.bvh_surface_area, True, False, False)
        self._scene = scene

    def closest_faces(self, points: np.ndarray) -> np.ndarray:
        n = len(points)
        interactions = self._fcpw.interaction_3D_list()
        self._scene.find_closest_points(
            np.asfortranarray(points - self._center, dtype=np.float32),
            np.full(n, np.inf, dtype=np.float32),
            interactions,
            False,
        )
        faces = np.fromiter((i.primitive_index for i in interactions), dtype=np.int64, count=n)
        return np.maximum(faces, 0)  # -1 only for non-finite points, whose results are NaN anyway


class _IglFaces:
    """Closest face by libigl's AABB tree (float64)."""

    exact = True

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        self._vertices, self._faces = vertices, faces
        self._tree = igl.AABB()
        self._tree.init(vertices, faces)

    def closest_faces(self, points: np.ndarray) -> np.ndarray:
        _, faces, _ = self._tree.squared_distance(self._vertices, self._faces, points)
        return np.maximum(faces.astype(np.int64), 0)


_FACE_INDEXES = {"fcpw": _FcpwFaces, "igl": _IglFaces}


def _closest_face_index(vertices: np.ndarray, faces: np.ndarray, backends=None):
    for name in backends or CLOSEST_FACE_BACKENDS:
        try:
            return _FACE_INDEXES[name](vertices, faces)
        except ImportError:
            continue
    raise ImportError(f"no closest-point backend available among {backends or CLOSEST_FACE_BACKENDS}")
