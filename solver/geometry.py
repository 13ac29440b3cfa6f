"""Geometric queries against a triangle mesh: closest point, signed distance, ray casting.

Convention: ``vertices (V, 3) float64``, ``faces (F, 3) int64`` with outward (counter-
clockwise) orientation; points and rays are ``(N, 3) float64``. Building a
:class:`MeshQuery` is the expensive setup (acceleration structures); its methods are the
cheap repeated queries.
"""

from __future__ import annotations

from dataclasses import dataclass

import igl
import numpy as np
import trimesh

#: below this distance (m) a point counts as on the surface and the pseudonormal gives the direction
ON_SURFACE_DISTANCE = 1e-12


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

    def signed_distance(self, points: np.ndarray) -> SignedDistance:
        """Signed distance (negative inside), closest point and distance normal.

        Parameters
        ----------
        points : (N, 3) float64
        """
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        if len(points) == 0:
            return SignedDistance(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64))
        distance, faces, closest, pseudonormal = igl.signed_distance(
            points, self.vertices, self.faces, igl.SIGNED_DISTANCE_TYPE_PSEUDONORMAL
        )
        offset = points - closest
        length = np.linalg.norm(offset, axis=1)
        on_surface = length < ON_SURFACE_DISTANCE
        normal = offset * (np.sign(distance) / np.where(on_surface, 1.0, length))[:, None]
        if on_surface.any():
            surface_normal = pseudonormal[on_surface]
            normal[on_surface] = surface_normal / np.linalg.norm(surface_normal, axis=1, keepdims=True)
        return SignedDistance(distance, closest, normal, faces.astype(np.int64))

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
