"""The target's surface as the wrap sees it: closest points, their normals, and where it ends.

:class:`TargetSurface` wraps the closest-point engine (:class:`~hairport.solver.mesh.query.MeshQuery`,
the compiled float64 BVH) with what a correspondence test needs besides the closest point:
the unit normal of the face holding it and whether it lies on the target's *border* (an edge
held by one face, or a vertex on one). A closest point on the border means the target has no
surface there (a head cut at the neck, a bust cut at the chest, a hole): the source point
is past the end of the target and gets no data term (Amberg et al. 2007, section 3.3).

The feature is read off the barycentric coordinates of the closest point in its face: a
coordinate at or below :data:`BORDER_BARYCENTRIC` puts the point on the edge opposite that
corner, one at or above ``1 - BORDER_BARYCENTRIC`` on the corner itself. The closest point
of a point past an open edge is that edge's projection, whose opposite coordinate is zero
up to rounding (1e-16), so the tolerance only has to absorb rounding.

A target of several shells (a game character's eyeballs, teeth, tongue and lashes beside its
skin) is wrapped onto its outer surface only (:func:`outer_faces`): the faces that separate
the body's inside from outside (:func:`~hairport.solver.mesh.collision.collision_faces`), so
that the lips do not reach for the teeth nor the eyelids for the lashes. On a MakeHuman bust
with all its shells, open eye sockets and fins, the share of the wrapped region whose normals
agree with the target's rose from 0.86 to 0.96 with it. A single shell is its own outer
surface, and is kept whole without the test (~4 s on 200k faces).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hairport.solver.mesh.collision import collision_faces
from hairport.solver.mesh.inside import shell_count
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.mesh.shells import edge_table
from hairport.solver.mesh.triangles import barycentric_coordinates
from hairport.solver.model.errors import InputError

#: a barycentric coordinate at or below this puts a closest point on the edge opposite its corner
#: (at or above ``1 -`` this: on the corner); rounding of the projection onto an edge is ~1e-16
BORDER_BARYCENTRIC = 1e-9


@dataclass(frozen=True)
class Match:
    """Closest target points of some source points and whether each is a usable correspondence.

    Attributes
    ----------
    closest : (N, 3) float64
        Closest point on the target (m).
    distance : (N,) float64
        Unsigned distance to it (m).
    normal : (N, 3) float64
        Unit normal of the target face holding it.
    faces : (N,) int64
        That face.
    border : (N,) bool
        The closest point lies on the target's border (no surface past it).
    accepted : (N,) bool
        Within the distance threshold, normals agreeing, not on the border.
    """

    closest: np.ndarray
    distance: np.ndarray
    normal: np.ndarray
    faces: np.ndarray
    border: np.ndarray
    accepted: np.ndarray


class TargetSurface:
    """A target mesh prepared for repeated correspondence queries (build once per target).

    Parameters
    ----------
    vertices : (V, 3) float64
        Meters.
    faces : (F, 3) int64
        Counter-clockwise seen from outside.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        self.query = MeshQuery(self.vertices, self.faces)
        self.face_normals = face_normals(self.vertices, self.faces)
        self.border_edges, self.border_vertices = border_features(self.faces, len(self.vertices))

    @property
    def is_open(self) -> bool:
        """Whether the target has a border (a cut or a hole)."""
        return bool(self.border_edges.any())

    def closest(self, points: np.ndarray, hint: np.ndarray | None = None):
        """Closest points, distances, faces and the border flag of ``points (N, 3)`` (m).

        ``hint (N,) int64``: faces near the points (the previous iterate's), only a speed-up.
        """
        sd = self.query.signed_distance(points, hint=hint)
        return sd.closest, np.abs(sd.distance), sd.faces, self.on_border(sd.closest, sd.faces)

    def match(self, points: np.ndarray, normals: np.ndarray, max_distance: float, min_cosine: float,
              hint: np.ndarray | None = None) -> Match:
        """Correspondences of source points on the target, with Amberg's rejections.

        Parameters
        ----------
        points : (N, 3) float64
            Source points (m), in the target's frame.
        normals : (N, 3) float64
            Unit source normals at them.
        max_distance : float
            Farther closest points are rejected (m).
        min_cosine : float
            Normals whose cosine is below this are rejected (a point near the back of a thin
            part, a fold reaching across a gap).
        hint : (N,) int64, optional
            The previous match's faces.
        """
        closest, distance, faces, border = self.closest(points, hint)
        normal = self.face_normals[faces]
        agree = np.einsum("ij,ij->i", normal, normals) >= min_cosine
        accepted = (distance <= max_distance) & agree & ~border & np.isfinite(distance)
        return Match(closest, distance, normal, faces, border, accepted)

    def on_border(self, closest: np.ndarray, faces: np.ndarray) -> np.ndarray:
        """(N,) bool: closest points (on ``faces``) that lie on the target's border."""
        if not self.border_edges.any():
            return np.zeros(len(faces), dtype=bool)
        bary = barycentric_coordinates(closest, self.vertices[self.faces[faces]])
        on_edge = (bary <= BORDER_BARYCENTRIC) & self.border_edges[faces]
        on_corner = (bary >= 1.0 - BORDER_BARYCENTRIC) & self.border_vertices[self.faces[faces]]
        return (on_edge | on_corner).any(axis=1)


def outer_faces(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(G, 3) int64: the faces of a target the wrap fits onto (module docstring): all of a single
    shell, the separating faces of several (all of them when none separates: a mesh with no inside).

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    """
    faces = np.asarray(faces, dtype=np.int64)
    if shell_count(faces) <= 1:
        return faces
    try:
        return faces[collision_faces(vertices, faces)]
    except InputError:  # no_inside: every face is a sheet; keep them all
        return faces


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F, 3) unit face normals (zero for a degenerate face) of ``vertices (V, 3)``, ``faces (F, 3)``."""
    corners = vertices[faces]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(cross, axis=1, keepdims=True)
    return cross / np.where(length > 0, length, 1.0)


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) unit area-weighted vertex normals (zero at a vertex no face uses).

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    """
    corners = vertices[faces]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])  # 2 * area * normal
    n = len(vertices)
    index = faces.ravel()
    summed = np.stack([np.bincount(index, weights=np.repeat(cross[:, k], 3), minlength=n) for k in range(3)], axis=1)
    length = np.linalg.norm(summed, axis=1, keepdims=True)
    return summed / np.where(length > 0, length, 1.0)


def border_features(faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """Where a mesh ends.

    Returns
    -------
    edges : (F, 3) bool
        ``[f, k]``: the edge of face ``f`` opposite corner ``k`` is held by this face alone.
    vertices : (V,) bool
        Vertices on such an edge.
    """
    table = edge_table(faces)
    # half-edge row 3 f + j runs from corner j to j + 1: the edge opposite corner k is row 3 f + (k + 1) % 3
    held_once = table.border[table.of_half_edge].reshape(-1, 3)
    edges = held_once[:, [1, 2, 0]]
    vertices = np.zeros(n_vertices, dtype=bool)
    vertices[table.ends[table.border].ravel()] = True
    return edges, vertices
