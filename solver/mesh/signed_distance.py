"""The signed distance of :class:`~.query.MeshQuery` in one compiled pass per point.

Convention: points ``(N, 3) float64``; ``pseudonormals (F, 7, 3) float64`` is the query's
table (:func:`~.query._pseudonormal_table`): per face, the face normal, the normals of the
edges opposite corners 0..2 and the angle-weighted normals of corners 0..2.

Per point, in parallel: the closest face and point (the point's cell's candidates when a
:class:`~.cells.CellCache` is given, else the tree of :mod:`.bvh`, seeded with a hint), the
feature the closest point lies on (face, edge, corner: the barycentric coordinates against
:data:`~.closest_kernels.FEATURE_EPSILON`), the sign of the offset along that feature's pseudonormal,
the distance and the distance normal. These are the operations of the numpy reference in
:meth:`~.query.MeshQuery.signed_distance` (libigl's face, :func:`~.query._closest_on_table`,
:func:`~.query._feature_from_coordinates`), fused: no (N,) temporaries between the steps.
The inside test of a collision surface (winding numbers) stays with the query. The kernel
is :func:`.closest_kernels.signed_kernel`.
"""

from __future__ import annotations

import numpy as np

from hairport.solver.mesh.bvh import TriangleTree, hint_array
from hairport.solver.mesh.cells import CellCache
from hairport.solver.mesh.closest_kernels import MISSING, signed_kernel


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
    hints = hint_array(hint, len(points))
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
    signed_kernel(points, hints, pseudonormals, tree.boxes, tree.child, tree.first, tree.count, tree.faces,
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
