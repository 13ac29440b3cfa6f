"""A compiled bounding volume hierarchy over triangles: exact closest points in float64.

Convention: ``vertices (V, 3) float64``, ``faces (F, 3) int64``; points ``(N, 3) float64``.
:func:`build_tree` is the setup (~50-80 ms of CPU for the 27k-face MakeHuman body; libigl's
AABB ~35-50 ms); :func:`closest_points` the repeated query, parallel over the points
(numba's threads, :mod:`hairport.solver.jit`).

The tree
--------
Binary, top down: a node's faces are split by the surface area heuristic over binned
centroids (:func:`.bvh_build.build_nodes`; 20 % less CPU per query than median splits
on hair near the MakeHuman body and on far points), until at most :data:`LEAF_FACES` remain.
Siblings are adjacent (``child`` and ``child + 1``). Each triangle is stored once, in leaf order, as the
12 numbers Ericson's closest-point test needs (:func:`~.query._triangle_table`'s rows).

The search
----------
Depth first, nearer child first, pruning every box farther than the best squared distance
found so far: the exact minimum over all faces, as a brute-force search would find it (a
face at exactly the same distance as the one kept, a tie, may be the other one). A point
may bring a *hint*, a face it was closest to before (:attr:`~.query.SignedDistance.faces`
of an earlier query): its distance is the first upper bound. It saves little (~10 % on hair
near the body, ``bench/closest_point.py``): the search still goes down ~13 levels to the
leaves around the point; :mod:`.cells` is the fast path for points that come back. Any
hint is allowed; one outside ``[0, F)`` is ignored, a wrong one only costs time.

The closest point on a triangle is Ericson's (*Real-Time Collision Detection*, 5.1.5) in the
same operations and order as the numpy reference :func:`~.query._closest_on_table`, so the
two agree to rounding. Non-finite points get NaN and face ``-1``. The kernels are in
:mod:`.closest_kernels`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hairport.solver.mesh.bvh_build import build_nodes, refit_boxes
from hairport.solver.mesh.closest_kernels import closest_kernel

#: faces per leaf at most (measured on the MakeHuman body: 2 and 4 the fastest, 1 and 8 ~10 % slower)
LEAF_FACES = 4


@dataclass(frozen=True, eq=False)
class TriangleTree:
    """The hierarchy over one mesh's triangles (see the module docstring).

    Attributes
    ----------
    boxes : (M, 6) float64
        Per node, lower corner then upper corner (m).
    child : (M,) int64
        First child of an inner node (the second is ``child + 1``), ``-1`` for a leaf.
    first : (M,) int64
        A leaf's first triangle in leaf order.
    count : (M,) int64
        A leaf's triangles (0 for inner nodes).
    faces : (F,) int64
        Face index of each triangle in leaf order.
    rank : (F,) int64
        Position in leaf order of each face (the inverse of ``faces``).
    table : (F, 12) float64
        Per triangle in leaf order: corner ``a``, ``b - a``, ``c - a``, and the Gram entries
        ``ab.ab``, ``ab.ac``, ``ac.ac``.
    built_area : float
        :func:`node_area` when the nodes were last split (:func:`build_tree`); a refit tree
        (:func:`refit_tree`) keeps its build's.
    """

    boxes: np.ndarray
    child: np.ndarray
    first: np.ndarray
    count: np.ndarray
    faces: np.ndarray
    rank: np.ndarray
    table: np.ndarray
    built_area: float = float("nan")

    @property
    def n_faces(self) -> int:
        return len(self.faces)


def build_tree(vertices: np.ndarray, faces: np.ndarray, leaf_faces: int = LEAF_FACES) -> TriangleTree:
    """The hierarchy over the faces (at least one).

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    leaf_faces : int
        Faces per leaf at most, >= 1.
    """
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    if len(faces) == 0:
        raise ValueError("a tree needs at least one face")
    corners = vertices[faces]
    lower, upper = corners.min(axis=1), corners.max(axis=1)
    centroids = corners.mean(axis=1)
    boxes, child, first, count, order = build_nodes(centroids, lower, upper, max(int(leaf_faces), 1))
    rank = np.empty(len(order), dtype=np.int64)
    rank[order] = np.arange(len(order))
    return TriangleTree(boxes, child, first, count, order, rank, _leaf_table(corners[order]), node_area(boxes))


def refit_tree(tree: TriangleTree, vertices: np.ndarray, faces: np.ndarray) -> TriangleTree:
    """The tree over the same faces moved to ``vertices (V, 3) float64``: its nodes, leaves and
    leaf order kept, their boxes grown or shrunk around the moved triangles (a few ms against
    ~50-80 ms for a build on the MakeHuman body). Exact for any motion; a large one leaves boxes
    that overlap more than a fresh split's, so searches slow down (:func:`node_area` tells).

    Parameters
    ----------
    tree : TriangleTree
        Built over ``faces`` (``faces (F, 3) int64``).
    """
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    if len(faces) != tree.n_faces:
        raise ValueError(f"a tree over {tree.n_faces} faces refit to {len(faces)}")
    corners = vertices[faces[tree.faces]]
    boxes = refit_boxes(tree.child, tree.first, tree.count, corners.min(axis=1), corners.max(axis=1))
    return TriangleTree(boxes, tree.child, tree.first, tree.count, tree.faces, tree.rank, _leaf_table(corners),
                        tree.built_area)


def node_area(boxes: np.ndarray) -> float:
    """Half the surface area of every node's box, summed (m^2; ``boxes (M, 6) float64``): the
    surface area heuristic's estimate of a search's cost, up to a factor."""
    extent = boxes[:, 3:] - boxes[:, :3]
    return float(np.sum(extent[:, 0] * extent[:, 1] + extent[:, 1] * extent[:, 2] + extent[:, 2] * extent[:, 0]))


def _refit_boxes_reference(child: np.ndarray, first: np.ndarray, count: np.ndarray, lower: np.ndarray,
                           upper: np.ndarray) -> np.ndarray:
    """:func:`.bvh_build.refit_boxes` in numpy, a level at a time from the deepest: the tested reference."""
    parent = np.full(len(child), -1, dtype=np.int64)
    inner = np.flatnonzero(child >= 0)
    parent[child[inner]] = parent[child[inner] + 1] = inner
    depth = np.zeros(len(child), dtype=np.int64)
    for node in range(1, len(child)):  # a parent comes before its children
        depth[node] = depth[parent[node]] + 1
    boxes = np.empty((len(child), 6))
    leaves = np.flatnonzero(child < 0)
    leaves = leaves[np.argsort(first[leaves])]  # the leaves' runs tile the leaf order
    boxes[leaves, :3] = np.minimum.reduceat(lower, first[leaves])
    boxes[leaves, 3:] = np.maximum.reduceat(upper, first[leaves])
    for level in range(depth.max(), -1, -1):
        nodes = inner[depth[inner] == level]
        boxes[nodes, :3] = np.minimum(boxes[child[nodes], :3], boxes[child[nodes] + 1, :3])
        boxes[nodes, 3:] = np.maximum(boxes[child[nodes], 3:], boxes[child[nodes] + 1, 3:])
    return boxes


def _leaf_table(corners: np.ndarray) -> np.ndarray:
    """(F, 12) float64 :attr:`TriangleTree.table` of triangles ``(F, 3, 3)`` in leaf order."""
    a = corners[:, 0]
    ab, ac = corners[:, 1] - a, corners[:, 2] - a
    gram = np.stack([np.einsum("ij,ij->i", ab, ab), np.einsum("ij,ij->i", ab, ac), np.einsum("ij,ij->i", ac, ac)], axis=1)
    return np.ascontiguousarray(np.concatenate([a, ab, ac, gram], axis=1))


def closest_points(
    tree: TriangleTree, points: np.ndarray, hint: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Closest point of the mesh to each point.

    Parameters
    ----------
    tree : TriangleTree
    points : (N, 3) float64
    hint : (N,) int64, optional
        A face near each point (its previous closest face), any value; only speeds the search.

    Returns
    -------
    faces : (N,) int64
        Face holding the closest point; ``-1`` for non-finite points.
    closest : (N, 3) float64
        NaN for non-finite points.
    coordinates : (N, 2) float64
        ``(v, w)``: the closest point is ``a + v (b - a) + w (c - a)`` on its face ``(a, b, c)``.
    squared : (N,) float64
        Squared distance (m^2).
    """
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    hints = hint_array(hint, len(points))
    n = len(points)
    faces = np.empty(n, dtype=np.int64)
    closest = np.empty((n, 3))
    coordinates = np.empty((n, 2))
    squared = np.empty(n)
    closest_kernel(points, hints, tree.boxes, tree.child, tree.first, tree.count, tree.faces, tree.rank, tree.table,
                    faces, closest, coordinates, squared)
    return faces, closest, coordinates, squared


def hint_array(hint: np.ndarray | None, n: int) -> np.ndarray:
    """(n,) int64 hints, or an empty array for none."""
    if hint is None:
        return np.zeros(0, dtype=np.int64)
    hint = np.ascontiguousarray(hint, dtype=np.int64).reshape(-1)
    if len(hint) != n:
        raise ValueError(f"hint must have one face per point ({n}), got {len(hint)}")
    return hint
