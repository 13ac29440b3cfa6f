"""Inside or outside a body given as triangles, closed or open: the generalized winding number.

What "inside" means
-------------------
A point ``p`` is inside the body when its generalized winding number (Jacobson, Kavan and
Sorkine-Hornung 2013)

    w(p) = 1/(4 pi) * sum over faces of the signed solid angle the face subtends at p

exceeds :data:`INSIDE_WINDING` (1/2). Faces are taken counter-clockwise seen from outside.

* **Closed meshes** (every edge has as many faces running along it one way as the other):
  ``w`` is an integer off the surface, 1 inside a shell and 0 outside, so this is the
  ordinary inside. Where shells overlap or nest (an eyeball or teeth inside the head, a body
  whose arm passes into its torso) ``w`` is 2 or more: inside too, the union of the shells.
* **Open meshes** (a bust cut at the chest, a head cut at the neck, open eye sockets): ``w``
  still jumps by 1 across the surface, and varies smoothly across each hole. The body is
  closed at a hole by the surface where ``w = 1/2``, which spans the hole's rim: for a flat
  cut exactly the flat piece of the cut's plane inside the rim (the bust closed by its cut),
  for a curved rim a smooth film across it. Non-manifold flaps inside the body (a third face
  on an edge) leave the inside as it is.

Near the surface the winding number is exact (libigl evaluates nearby triangles exactly
and far ones by a Barnes-Hut expansion whose error is below 0.006 on the MakeHuman body,
irrelevant next to the 1/2 threshold wherever ``w`` is an integer).

The surface hair collides with
------------------------------
Only the faces that separate inside from outside can be touched from outside: those whose
front side is outside and back side inside (:func:`exit_faces`). The others (an eyeball
inside the head, the part of one shell inside another, a flap inside the body) are inside
the body on both sides, and pushing a particle across one of them does not bring it out.
For a single closed shell without self-intersections every face separates.

Convention: ``vertices (V, 3) float64``, ``faces (F, 3) int64``, points ``(N, 3) float64``.
"""

from __future__ import annotations

from dataclasses import dataclass

import igl
import numpy as np

from hairport.solver.mesh.shells import edge_table, shell_labels
from hairport.solver.mesh.topology import half_edges

#: a point is inside where the winding number exceeds this (1 inside a closed shell, 0 outside)
INSIDE_WINDING = 0.5
#: libigl's default Barnes-Hut accuracy scale: the winding number's error stays below 0.006 on the MakeHuman body
WINDING_ACCURACY = 2.0
#: :func:`exit_faces` first probes at this accuracy scale, ~4 times faster next to the surface: on the MakeHuman
#: heavy male its error at the probes is at most 0.13, against 0.006 at :data:`WINDING_ACCURACY` ...
PROBE_ACCURACY = 1.0
#: ... and a probe whose first value is within this of a threshold (the inside's 1/2, or -1/2 for a face turned
#: inward) is probed again at :data:`WINDING_ACCURACY`: twice the error measured at :data:`PROBE_ACCURACY`
PROBE_MARGIN = 0.25
#: :func:`exit_faces` probes each face's two sides this far from its centroid, as a fraction of
#: the mesh's bounding-box diagonal (2 um on a 2 m body): below any gap between two parts of a
#: body, far above round-off
SIDE_PROBE = 1e-6


class WindingNumber:
    """Generalized winding number of points against one triangle mesh (fast, libigl's BVH).

    The tree is built on the first call (~15 ms for the 27k-face MakeHuman body; ~0.6 us per
    point then, on 2 cores, about a quarter of a closest-point query), and rebuilt after
    unpickling.

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        self._tree = None

    def __getstate__(self):
        state = self.__dict__.copy()
        state["_tree"] = None  # native, does not pickle
        return state

    def __call__(self, points: np.ndarray, accuracy: float = WINDING_ACCURACY) -> np.ndarray:
        """``points (N, 3)`` -> ``w (N,) float64`` (NaN for non-finite points); ``accuracy``: libigl's
        Barnes-Hut accuracy scale (a cluster is expanded only beyond this many of its radii)."""
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        w = np.full(len(points), np.nan)
        finite = np.isfinite(points).all(axis=1)
        if len(self.faces) == 0:
            w[finite] = 0.0
            return w
        if finite.any():
            if self._tree is None:
                self._tree = igl.FastWindingNumberBVH()
                self._tree.init(self.vertices, self.faces)
            w[finite] = self._tree.winding_number(np.ascontiguousarray(points[finite]), accuracy)
        return w

    def inside(self, points: np.ndarray) -> np.ndarray:
        """(N,) bool: ``w > INSIDE_WINDING`` (False for non-finite points)."""
        return self(points) > INSIDE_WINDING


def manifold_closed(faces: np.ndarray) -> bool:
    """Whether every edge is shared by exactly two faces that run along it in opposite
    directions (closed, edge-manifold, consistently oriented).

    Parameters
    ----------
    faces : (F, 3) int64
    """
    return len(faces) > 0 and bool(edge_table(faces).manifold.all())


def closed_cycle(faces: np.ndarray) -> bool:
    """Whether every edge has as many faces running along it one way as the other: then the
    winding number is an integer off the surface, and inside/outside changes only across it
    (also for several shells, nested or overlapping, and non-manifold edges).

    Parameters
    ----------
    faces : (F, 3) int64
    """
    if len(faces) == 0:
        return False
    half = half_edges(faces)
    way = np.where(half[:, 0] < half[:, 1], 1.0, -1.0)
    edges = edge_table(faces)
    return bool(np.all(np.bincount(edges.of_half_edge, weights=way, minlength=len(edges.count)) == 0))


def shell_count(faces: np.ndarray) -> int:
    """Shells of the mesh (:func:`.shells.shell_labels`: pieces joined across manifold edges).

    Parameters
    ----------
    faces : (F, 3) int64
    """
    return int(shell_labels(faces).max()) + 1 if len(faces) else 0


def exit_faces(vertices: np.ndarray, faces: np.ndarray, winding: WindingNumber) -> np.ndarray:
    """The faces that separate inside from outside (see the module docstring).

    Each face is probed at its centroid, :data:`SIDE_PROBE` of the bounding-box diagonal
    off it on either side: it separates when its back side is inside and its front side
    outside. A face crossed by another part of the body is classified by its centroid. On a
    closed body (:func:`closed_cycle`) the winding number is an integer off the surface and
    rises by exactly one from a face's front to its back, so the front probe alone decides
    (the face separates where it is 0): half the queries, and the near-surface queries are
    the expensive ones (~5 us each on the MakeHuman body, ~1 us at :data:`PROBE_ACCURACY`).

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    winding : WindingNumber
        Over the whole body (``vertices``, ``faces``).

    Returns
    -------
    separating : (F,) bool
        False for faces of zero area.
    """
    if len(faces) == 0:
        return np.zeros(0, dtype=bool)
    corners = np.asarray(vertices, dtype=np.float64)[faces]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(cross, axis=1)
    normal = cross / np.where(length > 0, length, 1.0)[:, None]
    centroid = corners.mean(axis=1)
    step = SIDE_PROBE * float(np.linalg.norm(np.ptp(np.asarray(vertices), axis=0)))
    if closed_cycle(faces):
        front = _probed(winding, centroid + step * normal)
        return (length > 0) & (np.abs(front) < INSIDE_WINDING)
    w = _probed(winding, np.concatenate([centroid + step * normal, centroid - step * normal]))
    front, back = w[: len(faces)], w[len(faces):]
    return (length > 0) & (front < INSIDE_WINDING) & (back > INSIDE_WINDING)


def _probed(winding: WindingNumber, points: np.ndarray) -> np.ndarray:
    """``w (N,)`` at probe points ``(N, 3)``, exact enough to tell which side of +-1/2 each is on: fast first
    (:data:`PROBE_ACCURACY`), again at :data:`WINDING_ACCURACY` where that was within :data:`PROBE_MARGIN` of +-1/2."""
    w = winding(points, PROBE_ACCURACY)
    unsure = np.flatnonzero(np.abs(np.abs(w) - INSIDE_WINDING) < PROBE_MARGIN)
    if len(unsure):
        w[unsure] = winding(points[unsure])
    return w


def manifold_features(faces: np.ndarray) -> np.ndarray:
    """Which features of each face lie where the surface is a closed manifold: an edge shared
    by exactly two faces running along it in opposite directions, a vertex all of whose
    edges are such. There the side given by the feature's pseudonormal is the side of the
    surface (Baerentzen and Aanaes 2005 need no more than that neighbourhood).

    Parameters
    ----------
    faces : (F, 3) int64

    Returns
    -------
    manifold : (F, 7) bool
        Columns as :meth:`~.query.MeshQuery`'s features: ``0`` the face (always), ``1 + k``
        the edge opposite corner ``k``, ``4 + k`` corner ``k``.
    """
    faces = np.asarray(faces, dtype=np.int64)
    out = np.ones((len(faces), 7), dtype=bool)
    if len(faces) == 0:
        return out
    edges = edge_table(faces)
    half_good = edges.manifold[edges.of_half_edge]
    bad_vertex = np.zeros(int(faces.max()) + 1, dtype=bool)
    bad_vertex[half_edges(faces)[~half_good].ravel()] = True
    # half-edge 3 f + j runs from corner j to j + 1: it is the edge opposite corner j + 2
    out[:, 1:4] = half_good.reshape(-1, 3)[:, [1, 2, 0]]
    out[:, 4:7] = ~bad_vertex[faces]
    return out


@dataclass(frozen=True, eq=False)
class InsideTest:
    """How a :class:`~hairport.solver.mesh.query.MeshQuery` over a body's separating faces
    (:func:`.collision.collision_query`) signs its distances.

    Attributes
    ----------
    winding : WindingNumber
        Over the whole body.
    closed : bool
        Inside and outside change only across the query's surface (no open cut): a distance
        grid may take a sign as certain in a ball free of the surface.
    manifold : (F, 7) bool, optional
        None: every sign is the pseudonormal's (a single closed shell whose faces all
        separate, where it is exact). Else the features of the query's faces where the
        surface is a closed manifold (:func:`manifold_features`): a point closest to one takes
        the pseudonormal's side when the body is closed, or when it lies within the query's
        near band of the surface (libigl evaluates the winding number in single precision:
        within ~1e-7 of the coordinates' size of a face its answer is noise); every other
        point takes the winding number's.
    """

    winding: WindingNumber
    closed: bool
    manifold: np.ndarray | None = None

    def inside(self, points: np.ndarray) -> np.ndarray:
        """(N,) bool by the winding number alone: for points away from the surface
        (see :attr:`manifold`), such as a broad phase's far ones."""
        return self.winding.inside(points)
