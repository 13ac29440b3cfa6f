"""Geometric queries against a triangle mesh: closest point, signed distance, ray casting.

Convention: ``vertices (V, 3) float64``, ``faces (F, 3) int64`` with outward (counter-
clockwise) orientation; points and rays are ``(N, 3) float64``. Building a
:class:`MeshQuery` is the expensive setup (acceleration structures); its methods are the
cheap repeated queries.

Signed distance
---------------
A BVH built once per :class:`MeshQuery` (lazily, on the first query) finds the face holding
the closest point and the closest point itself. The sign is that of the offset along the
angle-weighted pseudonormal of the feature the closest point lies on (Baerentzen & Aanaes
2005): the face normal inside a face, the normalised sum of the adjacent face normals on an
edge, the angle-weighted vertex normal at a corner, all precomputed per face. The feature is
read off the barycentric coordinates with libigl's tolerance, so this is exactly the sign
rule of ``igl.signed_distance(..., SIGNED_DISTANCE_TYPE_PSEUDONORMAL)``, which an earlier
implementation called on every query, rebuilding its tree and normals each time.

The default face search is the compiled float64 BVH of :mod:`.bvh`: the whole signed
distance of a point in one compiled pass (:mod:`.signed_distance`), parallel over the
points, ~2x libigl's AABB on hair near the body (``bench/closest_point.py``). It takes a
*hint* per point (a face near it, e.g. :attr:`SignedDistance.faces` of the previous
iterate) and a *cell cache* (:meth:`MeshQuery.cell_cache`, :mod:`.cells`: candidate faces
per 3 mm cell, 3-4x libigl for a solver's iterates, which come back to the same cells);
both change nothing but the time (and which face of a tie is named). libigl's ``AABB``
(float64) with the numpy steps over all points at once is the tested reference: queries of
:data:`SORT_QUERIES_FROM` points or more are visited in Z-curve order there, so that
consecutive ones walk the same tree nodes (2-3x on scattered points).

The pseudonormal sign is exact for a closed, consistently oriented, manifold mesh (the
MakeHuman body is one). On an open mesh it is still the side of the nearest feature, but
"inside" far from a hole means nothing, and between nested shells it is the side of the
nearer shell. A query given an :class:`~.inside.InsideTest` (the collision surface of
:mod:`.collision`) takes the sign from the generalized winding number wherever the
pseudonormal's is not exact (:mod:`.inside`).

Face search backends, the first importable of :data:`CLOSEST_FACE_BACKENDS`: the compiled
BVH (``"bvh"``, float64, exact; the default), libigl's ``AABB`` (``"igl"``, float64, exact;
the reference) or, opted in, ``fcpw`` (float32 wide BVH; not a
declared dependency; in ``bench/geometry.py`` no faster end to end except ~15 % on
hair-like points far from the body). fcpw gives the face only; the closest point on it is
then Ericson's region test in float64 numpy. A point whose distance is within ~1e-7 of
the mesh size of that of another face not holding its closest point (near the medial axis;
next to an edge between slightly bent faces) may get that other face: its float64
distance is then too large by at most that much, and its closest point and normal are that
face's. Points closer to the surface than :data:`EXACT_BAND` of the mesh size are searched
again with the float64 tree, so near the surface, where a wrong face could flip the sign
at a sharp crease, the result is exact.

Rays
----
Embree (float32) finds the first face hit; the hit point is the float64 intersection of
the ray with that face's plane, as trimesh's ``intersects_location`` computed it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hairport.solver.mesh.backends import _PARALLEL, _closest_face_index, _EmbreeFaces, _IglFaces
from hairport.solver.mesh.cells import CellCache
from hairport.solver.mesh.closest_kernels import FEATURE_EPSILON, ON_SURFACE_DISTANCE
from hairport.solver.mesh.inside import InsideTest, manifold_closed, shell_count
from hairport.solver.mesh.space_order import search_in_space_order

#: on an open body's collision surface, points closer to a manifold part of it than this
#: fraction of the mesh's bounding-box diagonal (20 um on a 2 m body) take the pseudonormal's
#: sign: libigl's winding number is single precision, noise within ~1e-7 of the coordinates'
#: size of a face, and a hole's closing film is far from any point this near the skin
NEAR_SURFACE = 1e-5

#: with a float32 face search (fcpw), points closer to the surface than this fraction of the mesh's
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

    def take(self, rows: np.ndarray) -> "SignedDistance":
        """The results of some points: ``rows`` is an ``(K,) int64`` index or an ``(N,) bool`` mask."""
        return SignedDistance(self.distance[rows], self.closest[rows], self.normal[rows], self.faces[rows])


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
    inside : InsideTest, optional
        How the signs are told (a body's collision surface, :func:`.collision.collision_query`);
        by default from the pseudonormal of the closest feature.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, inside: InsideTest | None = None):
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        self._inside = inside  # None: pseudonormal signs
        self._rays = None  # Embree scene, built on the first first_hits
        self._closest = None  # face search (BVH), built on the first signed_distance
        self._triangles = None  # (12, F) per-face data for the closest point on a face
        self._pseudonormals = None  # (F, 7, 3): face, edges opposite corners 0..2, corners 0..2
        self._face_normals = None  # (3, F) unit face normals
        self._exact = None  # float64 face search for points near the surface, when _closest is float32
        self._exact_band = 0.0
        self._near_band = 0.0
        self._closed = None
        self._edge_ids = None  # (F, 3) int64: each face's edges (opposite corners 0..2), numbered once per mesh
        self._refit_from = None  # a face search over the same faces at other vertices, refit on first use

    def moved(self, vertices: np.ndarray, inside: InsideTest | None = None) -> "MeshQuery":
        """This mesh with its vertices moved (a frame of a sequence, the same faces): a query that gives what a new
        one over ``vertices`` would, keeping what depends on the faces alone (edge numbering, closedness) and
        refitting the compiled face search instead of building it (:meth:`.backends._CompiledFaces.moved`).

        Parameters
        ----------
        vertices : (V, 3) float64
            As many as this mesh's.
        inside : InsideTest
            The moved body's inside test: required when this query has one (a collision surface), refused when not.
        """
        vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        if vertices.shape != self.vertices.shape:
            raise ValueError(f"{len(vertices)} vertices moved for a mesh of {len(self.vertices)}")
        if (inside is None) != (self._inside is None):
            raise ValueError("a moved collision surface needs its own inside test, a plain query none")
        query = MeshQuery(vertices, self.faces, inside)
        query._edge_ids = self._edge_ids
        query._closed = self._closed if inside is None else None
        query._refit_from = self._closest if hasattr(self._closest, "moved") else self._refit_from
        return query

    def __getstate__(self):
        # the native BVHs do not pickle; they are rebuilt lazily after unpickling
        state = self.__dict__.copy()
        state["_closest"] = None
        state["_rays"] = None
        state["_exact"] = None
        state["_refit_from"] = None
        return state

    def _tables(self):
        if self._triangles is None:
            self._triangles = _triangle_table(self.vertices[self.faces])
            if self._edge_ids is None:
                self._edge_ids = _edge_ids(self.faces, len(self.vertices))
            self._pseudonormals = _pseudonormal_table(self.vertices, self.faces, self._edge_ids)
            self._face_normals = np.ascontiguousarray(self._pseudonormals[:, 0].T)

    def _prepare(self):
        if self._closest is None:
            self._tables()
            if self._refit_from is not None:
                self._closest, self._refit_from = self._refit_from.moved(self.vertices, self.faces), None
            else:
                self._closest = _closest_face_index(self.vertices, self.faces)
            extent = np.linalg.norm(self.vertices.max(axis=0) - self.vertices.min(axis=0)) if len(self.vertices) else 1.0
            self._exact_band = EXACT_BAND * extent
            self._near_band = NEAR_SURFACE * extent
        return self._closest

    @property
    def inside_test(self) -> InsideTest | None:
        """The body's inside test when the query was given one (a collision surface)."""
        return self._inside

    @property
    def closed(self) -> bool:
        """Whether the sign of the signed distance changes only across the surface: a single
        closed, consistently oriented manifold shell, or a collision surface of a body without
        an open cut (:attr:`.inside.InsideTest.closed`)."""
        if self._closed is None:
            if self._inside is not None:
                self._closed = self._inside.closed
            else:
                self._closed = manifold_closed(self.faces) and shell_count(self.faces) == 1
        return self._closed

    def inside(self, points: np.ndarray) -> np.ndarray:
        """(N,) bool: points with a negative signed distance. For a collision surface
        (:func:`.collision.collision_query`) that is the body's inside at any depth, closed
        or open; for a plain query the side of the nearest feature (exact on a single closed
        shell).

        Parameters
        ----------
        points : (N, 3) float64
        """
        return self.signed_distance(points).distance < 0.0

    def _exact_index(self):
        if self._exact is None:
            self._exact = _IglFaces(self.vertices, self.faces)
        return self._exact

    def cell_cache(self) -> CellCache | None:
        """An empty :class:`~.cells.CellCache` over this mesh for :meth:`signed_distance`, or None
        when the face search has none (libigl, fcpw). For a caller that queries the same region
        again and again (a solver's iterates); it grows with the cells visited."""
        index = self._prepare()
        return index.cell_cache() if getattr(index, "fused", False) else None

    def signed_distance(
        self, points: np.ndarray, hint: np.ndarray | None = None, cells: CellCache | None = None
    ) -> SignedDistance:
        """Signed distance (negative inside), closest point and distance normal.

        Parameters
        ----------
        points : (N, 3) float64
            Non-finite points get NaN (face 0).
        hint : (N,) int64, optional
            A face near each point, such as :attr:`SignedDistance.faces` of an earlier query of
            the same particles: it seeds the compiled search. Any value is allowed (out of range:
            ignored); the result is the same but for ties (a face at exactly the same distance
            may be another one). Ignored by libigl and fcpw.
        cells : CellCache, optional
            From :meth:`cell_cache` of this query: candidate faces of the cells visited, kept
            and reused (same results as without, but for ties).
        """
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        if len(points) == 0:
            return SignedDistance(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64))
        index = self._prepare()
        if getattr(index, "fused", False):
            distance, closest, normal, faces, feature = index.signed(points, self._pseudonormals, hint, cells)
            sign = np.where(distance < 0.0, -1.0, 1.0)
            length = np.abs(distance)
        else:
            closest, faces, feature, length, sign = self._signed_steps(index, points)
            distance = normal = None
        counted = self._untrusted(faces, feature, length)
        if len(counted):
            sign[counted] = np.where(self._inside.inside(points[counted]), -1.0, 1.0)
        if distance is None:
            distance = sign * length
            offset = points - closest
            on_surface = length < ON_SURFACE_DISTANCE
            normal = offset * (sign / np.where(on_surface, 1.0, length))[:, None]
            if on_surface.any():
                normal[on_surface] = self._pseudonormals[faces[on_surface], feature[on_surface]]
        elif len(counted):
            # the winding number overrides some signs of the compiled pass: redo those rows
            rows = counted[(distance[counted] < 0.0) != (sign[counted] < 0.0)]
            distance[rows] = sign[rows] * length[rows]
            off = rows[length[rows] >= ON_SURFACE_DISTANCE]
            normal[off] = (points[off] - closest[off]) * (sign[off] / length[off])[:, None]
        return SignedDistance(distance, closest, normal, faces)

    def _signed_steps(self, index, points: np.ndarray):
        """The numpy reference steps (libigl's or fcpw's face): closest, faces, feature,
        length, and the pseudonormal's sign."""
        faces, closest = search_in_space_order(index, points)
        if closest is None:
            closest, feature = _closest_on_table(points, self._triangles, faces)
        else:
            feature = _feature_of(closest, self._triangles, faces)
        offset = points - closest
        length = np.sqrt(np.einsum("ij,ij->i", offset, offset))
        if not index.exact:
            # near the surface a face picked in float32 may be on the wrong side of a sharp
            # crease: redo those few points with the float64 tree
            near = np.flatnonzero(length < self._exact_band)
            if len(near):
                faces[near], closest[near] = search_in_space_order(self._exact_index(), points[near])
                feature[near] = _feature_of(closest[near], self._triangles, faces[near])
                offset[near] = points[near] - closest[near]
                length[near] = np.sqrt(np.einsum("ij,ij->i", offset[near], offset[near]))
        pseudonormal = self._pseudonormals[faces, feature]
        sign = np.where(np.einsum("ij,ij->i", offset, pseudonormal) < 0.0, -1.0, 1.0)
        return closest, faces, feature, length, sign

    def _untrusted(self, faces: np.ndarray, feature: np.ndarray, length: np.ndarray) -> np.ndarray:
        """(K,) int64 rows whose sign the winding number decides (:mod:`.inside`)."""
        if self._inside is None or self._inside.manifold is None:
            return np.zeros(0, dtype=np.int64)
        trusted = self._inside.manifold[faces, feature]
        if not self._inside.closed:
            trusted &= length < self._near_band
        return np.flatnonzero(~trusted)

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
        distance = np.full(n, np.inf)
        barycentric = np.zeros((n, 3))
        if n == 0:
            return RayHits(hit, distance, faces, barycentric, points)
        if self._rays is None:
            self._rays = _EmbreeFaces(self.vertices, self.faces)
        self._tables()
        # embree (float32) says which face; the point is the float64 ray-plane intersection
        # with it, as trimesh's intersects_location computed it
        first = self._rays.first_faces(origins, unit)
        rays = np.flatnonzero(first >= 0)
        tri = first[rays]
        a0, a1, a2, b0, b1, b2, c0, c1, c2, g00, g01, g11 = (row[tri] for row in self._triangles)
        n0, n1, n2 = (row[tri] for row in self._face_normals)
        o, d = origins[rays], unit[rays]
        o0, o1, o2, d0, d1, d2 = o[:, 0], o[:, 1], o[:, 2], d[:, 0], d[:, 1], d[:, 2]
        along = d0 * n0 + d1 * n1 + d2 * n2
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((a0 - o0) * n0 + (a1 - o1) * n1 + (a2 - o2) * n2) / along
            p0, p1, p2 = o0 + t * d0, o1 + t * d1, o2 + t * d2
            # barycentric_coordinates, with the per-face Gram entries precomputed
            e0, e1, e2 = p0 - a0, p1 - a1, p2 - a2
            d20 = e0 * b0 + e1 * b1 + e2 * b2
            d21 = e0 * c0 + e1 * c1 + e2 * c2
            denom = g00 * g11 - g01 * g01
            denom = np.where(np.abs(denom) > 0, denom, 1.0)
            v = (g11 * d20 - g01 * d21) / denom
            w = (g00 * d21 - g01 * d20) / denom
        ok = np.abs(along) > _PARALLEL  # a ray in the plane of its face has no single point: a miss
        if not ok.all():
            rays, tri, t, p0, p1, p2, v, w = (x[ok] for x in (rays, tri, t, p0, p1, p2, v, w))
        hit[rays] = True
        faces[rays] = tri
        distance[rays] = t
        points[rays] = np.stack([p0, p1, p2], axis=1)
        barycentric[rays] = np.stack([1.0 - v - w, v, w], axis=1)
        return RayHits(hit, distance, faces, barycentric, points)


def _triangle_table(triangles: np.ndarray) -> np.ndarray:
    """Per-triangle data for :func:`_closest_on_table`, one contiguous row per quantity.

    Returns
    -------
    table : (12, T) float64
        Corner a (3 rows), ``ab = b - a`` (3), ``ac = c - a`` (3), and the Gram entries
        ``ab.ab``, ``ab.ac``, ``ac.ac``.
    """
    a = triangles[:, 0]
    ab, ac = triangles[:, 1] - a, triangles[:, 2] - a
    gram = np.stack([np.einsum("ij,ij->i", ab, ab), np.einsum("ij,ij->i", ab, ac), np.einsum("ij,ij->i", ac, ac)])
    return np.ascontiguousarray(np.concatenate([a.T, ab.T, ac.T, gram]))


def _closest_on_table(points: np.ndarray, table: np.ndarray, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest point on triangle ``ids[i]`` of ``table`` to ``points[i]`` and its feature.

    Ericson, *Real-Time Collision Detection*, 5.1.5, vectorised: the Voronoi regions are
    tested in his order and the first match wins. Only ``ab.(p - a)`` and ``ac.(p - a)``
    depend on the point; his other four dot products follow from the Gram entries. The
    feature is read off the barycentric coordinates of the result with tolerance
    :data:`FEATURE_EPSILON`, as libigl does for its pseudonormal sign.

    Returns
    -------
    closest : (N, 3) float64
    feature : (N,) int64
        0 inside the face, ``1 + k`` on the edge opposite corner k, ``4 + k`` at corner k.
    """
    rows = [row[ids] for row in table]
    a, ab, ac = rows[0:3], rows[3:6], rows[6:9]
    g00, g01, g11 = rows[9:12]
    ap = [points[:, k] - a[k] for k in range(3)]
    d1 = ab[0] * ap[0] + ab[1] * ap[1] + ab[2] * ap[2]
    d2 = ac[0] * ap[0] + ac[1] * ap[1] + ac[2] * ap[2]
    d3, d4 = d1 - g00, d2 - g01  # ab.(p - b), ac.(p - b)
    d5, d6 = d1 - g01, d2 - g11  # ab.(p - c), ac.(p - c)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    e1, e2 = d4 - d3, d5 - d6
    with np.errstate(divide="ignore", invalid="ignore"):
        # from the last region in Ericson's order to the first, so the first match wins
        denom = va + vb + vc
        denom = np.where(denom != 0, denom, 1.0)
        v, w = vb / denom, vc / denom  # inside the face
        t = e1 / (e1 + e2)
        mask = (va <= 0) & (e1 >= 0) & (e2 >= 0)  # edge bc
        v, w = np.where(mask, 1.0 - t, v), np.where(mask, t, w)
        mask = (vb <= 0) & (d2 >= 0) & (d6 <= 0)  # edge ac
        v, w = np.where(mask, 0.0, v), np.where(mask, d2 / (d2 - d6), w)
        mask = (d6 >= 0) & (d5 <= d6)  # corner c
        v, w = np.where(mask, 0.0, v), np.where(mask, 1.0, w)
        mask = (vc <= 0) & (d1 >= 0) & (d3 <= 0)  # edge ab
        v, w = np.where(mask, d1 / (d1 - d3), v), np.where(mask, 0.0, w)
        mask = (d3 >= 0) & (d4 <= d3)  # corner b
        v, w = np.where(mask, 1.0, v), np.where(mask, 0.0, w)
        mask = (d1 <= 0) & (d2 <= 0)  # corner a
        v, w = np.where(mask, 0.0, v), np.where(mask, 0.0, w)
    closest = np.empty((len(ids), 3))
    for k in range(3):
        closest[:, k] = a[k] + v * ab[k] + w * ac[k]
    return closest, _feature_from_coordinates(v, w)


def _feature_of(closest: np.ndarray, table: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """Feature (as :func:`_closest_on_table`) of points already on triangle ``ids[i]``."""
    rows = [row[ids] for row in table]
    a, ab, ac = rows[0:3], rows[3:6], rows[6:9]
    g00, g01, g11 = rows[9:12]
    ap = [closest[:, k] - a[k] for k in range(3)]
    d20 = ab[0] * ap[0] + ab[1] * ap[1] + ab[2] * ap[2]
    d21 = ac[0] * ap[0] + ac[1] * ap[1] + ac[2] * ap[2]
    denom = g00 * g11 - g01 * g01
    denom = np.where(np.abs(denom) > 0, denom, 1.0)
    v = (g11 * d20 - g01 * d21) / denom
    w = (g00 * d21 - g01 * d20) / denom
    return _feature_from_coordinates(v, w)


def _feature_from_coordinates(v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Face (0), edge opposite corner k (1 + k) or corner k (4 + k) from the barycentric
    coordinates ``(1 - v - w, v, w)``: one at or below :data:`FEATURE_EPSILON` puts the point
    on an edge, two at a corner (libigl's rule for its pseudonormal sign)."""
    u = 1.0 - v - w
    su, sv, sw = u <= FEATURE_EPSILON, v <= FEATURE_EPSILON, w <= FEATURE_EPSILON
    count = su.astype(np.int64) + sv + sw
    edge = np.where(su, 1, np.where(sv, 2, 3))  # the edge opposite the small coordinate
    corner = np.where(~su, 4, np.where(~sv, 5, 6))  # the corner whose coordinate is not small
    return np.where(count == 0, 0, np.where(count == 1, edge, corner))


def _closest_points_on_triangles(points: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest point on ``triangles[i]`` (N, 3, 3) to ``points[i]`` (N, 3), and its feature
    (see :func:`_closest_on_table`)."""
    return _closest_on_table(points, _triangle_table(triangles), np.arange(len(points)))


def _edge_ids(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """(F, 3) int64: the undirected edge opposite each corner of each face, numbered from 0 (shared edges alike)."""
    # edge k of a face is the one opposite corner k: (k + 1, k + 2)
    edges = np.stack([faces[:, [1, 2]], faces[:, [2, 0]], faces[:, [0, 1]]], axis=1).reshape(-1, 2)
    keys = edges.min(axis=1) * np.int64(n_vertices) + edges.max(axis=1)  # undirected edge key
    _, ids = np.unique(keys, return_inverse=True)
    return ids.reshape(-1, 3)


def _pseudonormal_table(vertices: np.ndarray, faces: np.ndarray, edge_ids: np.ndarray | None = None) -> np.ndarray:
    """Unit angle-weighted pseudonormals of every feature of every face (``edge_ids``: :func:`_edge_ids`, made
    here when omitted).

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

    edge_ids = _edge_ids(faces, len(vertices)) if edge_ids is None else edge_ids
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
