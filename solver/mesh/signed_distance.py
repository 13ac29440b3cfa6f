"""The signed distance of :class:`~.query.MeshQuery` in one compiled pass per point.

Convention: points ``(N, 3) float64``; ``pseudonormals (F, 7, 3) float64`` is the query's
table (:func:`~.query._pseudonormal_table`): per face, the face normal, the normals of the
edges opposite corners 0..2 and the angle-weighted normals of corners 0..2.

Per point, in parallel: the closest face and point (the point's cell's candidates when a
:class:`~.cells.CellCache` is given, else the tree of :mod:`.bvh`, seeded with a hint), the
feature the closest point lies on (face, edge, corner: the barycentric coordinates against
:data:`FEATURE_EPSILON`), the sign of the offset along that feature's pseudonormal,
the distance and the distance normal. These are the operations of the numpy reference in
:meth:`~.query.MeshQuery.signed_distance` (libigl's face, :func:`~.query._closest_on_table`,
:func:`~.query._feature_from_coordinates`), fused: no (N,) temporaries between the steps.
The inside test of a collision surface (winding numbers) stays with the query.
"""

from __future__ import annotations

import math

import numpy as np

from hairport.solver.jit import parallel_kernel, prange, warms
from hairport.solver.mesh.bvh import POINTS_PER_TASK, STACK_DEPTH, TriangleTree, _hint_array, _search, build_tree
from hairport.solver.mesh.cells import MISSING, CellCache, _cached_search

#: below this distance (m) a point counts as on the surface and the pseudonormal gives the direction
ON_SURFACE_DISTANCE = 1e-12

#: barycentric coordinate at or below which the closest point counts as on an edge or vertex
#: of its face (the pseudonormal's feature), libigl's value
FEATURE_EPSILON = 1e-12


def signed_distance(
    tree: TriangleTree,
    pseudonormals: np.ndarray,
    points: np.ndarray,
    hint: np.ndarray | None = None,
    cells: CellCache | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Signed distance by the pseudonormal of the closest feature.

    Parameters
    ----------
    tree : TriangleTree
    pseudonormals : (F, 7, 3) float64
    points : (N, 3) float64
    hint : (N,) int64, optional
        A face near each point (see :mod:`.bvh`); used where the tree is searched.
    cells : CellCache, optional
        Over the same tree; the cells of the points are filled when not cached yet.

    Returns
    -------
    distance : (N,) float64
        Negative on the back side of the closest feature; NaN for non-finite points.
    closest : (N, 3) float64
    normal : (N, 3) float64
        ``(p - closest) * sign / |p - closest|``, the pseudonormal on the surface.
    faces : (N,) int64
        0 for non-finite points.
    feature : (N,) int8
        0 inside the face, ``1 + k`` on the edge opposite corner ``k``, ``4 + k`` at corner ``k``.
    """
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    hints = _hint_array(hint, len(points))
    n = len(points)
    distance, closest, normal = np.empty(n), np.empty((n, 3)), np.empty((n, 3))
    faces, feature = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int8)
    _run(tree, pseudonormals, points, hints, cells, True, distance, closest, normal, faces, feature)
    if cells is not None:
        missing = np.flatnonzero(faces == MISSING)
        if len(missing):
            cells.fill(points[missing])
            results = (np.empty(len(missing)), np.empty((len(missing), 3)), np.empty((len(missing), 3)),
                       np.empty(len(missing), dtype=np.int64), np.empty(len(missing), dtype=np.int8))
            _run(tree, pseudonormals, points[missing], hints[missing] if len(hints) else hints, cells, False, *results)
            for out, part in zip((distance, closest, normal, faces, feature), results):
                out[missing] = part
    return distance, closest, normal, faces, feature


def _run(tree, pseudonormals, points, hints, cells, fill_missing, *outputs):
    if cells is None:
        cells = _NO_CELLS
    _signed_kernel(points, hints, pseudonormals, tree.boxes, tree.child, tree.first, tree.count, tree.faces,
                   tree.rank, tree.table, cells is not _NO_CELLS, fill_missing, cells.origin, cells.size,
                   cells.half_diagonal, cells.slots, cells.candidates, cells.bounds, *outputs)


class _NoCells:
    """Stand-in arrays for a search by the tree alone."""

    origin = np.zeros(3)
    size = 1.0
    half_diagonal = 0.0
    slots = np.full((1, 2), -1, dtype=np.int64)
    candidates = np.zeros(0, dtype=np.int32)
    bounds = np.zeros(0, dtype=np.float32)


_NO_CELLS = _NoCells()


@parallel_kernel
def _signed_kernel(points, hints, pseudonormals, boxes, child, first, count, faces, rank, table,
                   use_cells, fill_missing, origin, size, half_diagonal, slots, candidates, bounds,
                   out_distance, out_closest, out_normal, out_faces, out_feature):
    n = len(points)
    hinted = len(hints) == n
    inverse_size = 1.0 / size
    tasks = (n + POINTS_PER_TASK - 1) // POINTS_PER_TASK
    for task in prange(tasks):
        stack = np.empty(STACK_DEPTH, dtype=np.int64)
        stack_squared = np.empty(STACK_DEPTH)
        for i in range(task * POINTS_PER_TASK, min(n, (task + 1) * POINTS_PER_TASK)):
            px, py, pz = points[i, 0], points[i, 1], points[i, 2]
            t, v, w = -1, 0.0, 0.0
            if np.isfinite(px) and np.isfinite(py) and np.isfinite(pz):
                hint = hints[i] if hinted else -1
                if use_cells:
                    t, squared, v, w = _cached_search(
                        px, py, pz, hint, origin, size, inverse_size, half_diagonal, slots, candidates, bounds,
                        boxes, child, first, count, rank, table, stack, stack_squared)
                    if t == MISSING:
                        if fill_missing:
                            out_faces[i] = MISSING
                            continue
                        t, squared, v, w = _search(px, py, pz, hint, boxes, child, first, count, rank, table,
                                                   stack, stack_squared)
                else:
                    t, squared, v, w = _search(px, py, pz, hint, boxes, child, first, count, rank, table,
                                               stack, stack_squared)
            if t < 0:  # not finite, or every face degenerate
                out_distance[i] = np.nan
                for k in range(3):
                    out_closest[i, k] = out_normal[i, k] = np.nan
                out_faces[i] = 0
                out_feature[i] = 0
                continue
            face = faces[t]
            qx = table[t, 0] + v * table[t, 3] + w * table[t, 6]
            qy = table[t, 1] + v * table[t, 4] + w * table[t, 7]
            qz = table[t, 2] + v * table[t, 5] + w * table[t, 8]
            out_closest[i, 0], out_closest[i, 1], out_closest[i, 2] = qx, qy, qz
            ox, oy, oz = px - qx, py - qy, pz - qz
            u = 1.0 - v - w
            small_u, small_v, small_w = u <= FEATURE_EPSILON, v <= FEATURE_EPSILON, w <= FEATURE_EPSILON
            smalls = small_u + small_v + small_w
            if smalls == 0:
                feature = 0
            elif smalls == 1:
                feature = 1 if small_u else (2 if small_v else 3)  # the edge opposite the small coordinate
            else:
                feature = 4 if not small_u else (5 if not small_v else 6)  # the corner not small
            nx, ny, nz = pseudonormals[face, feature, 0], pseudonormals[face, feature, 1], pseudonormals[face, feature, 2]
            sign = -1.0 if ox * nx + oy * ny + oz * nz < 0.0 else 1.0
            length = math.sqrt(ox * ox + oy * oy + oz * oz)
            out_distance[i] = sign * length
            if length < ON_SURFACE_DISTANCE:
                out_normal[i, 0], out_normal[i, 1], out_normal[i, 2] = nx, ny, nz
            else:
                scale = sign / length
                out_normal[i, 0], out_normal[i, 1], out_normal[i, 2] = ox * scale, oy * scale, oz * scale
            out_faces[i] = face
            out_feature[i] = feature


@warms("hairport.solver.mesh.signed_distance")
def _warm() -> None:
    vertices = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    tree = build_tree(vertices, faces, leaf_faces=1)
    pseudonormals = np.zeros((4, 7, 3))
    pseudonormals[:, :, 2] = 1.0
    points = np.array([[0.2, 0.2, 0.2], [2.0, 0.0, 0.0], [np.nan, 0.0, 0.0]])
    signed_distance(tree, pseudonormals, points)
    signed_distance(tree, pseudonormals, points, np.array([1, 7, 0]), CellCache(tree, size=0.25))
