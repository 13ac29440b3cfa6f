"""Skin weights derived from the geometry when a file has none.

Skin weights are a sparse ``(V, B)`` matrix whose column ``b`` belongs to bone ``b``; every
vertex row with a positive sum sums to 1 and a vertex without any weight keeps an all-zero
row (:func:`~hairport.solver.model.character.normalise_weight_rows`, with the model: the file
readers normalise what they read without loading this module's mesh queries). A character
whose skeleton comes without weights (a sidecar without ``weights``) gets them from
:func:`derive_skin_weights`: each vertex goes to the nearest bone that "sees" it, then a few
steps of uniform-Laplacian smoothing blend the weights across bone borders.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from hairport.solver.mesh.polyline import closest_points_on_segments
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.mesh.topology import vertex_adjacency
from hairport.solver.model.character import Skeleton, normalise_weight_rows

#: how many nearest bones per vertex are tested for visibility
VISIBILITY_CANDIDATES = 4
#: a bone sees a vertex if the ray from the bone hits the mesh no earlier than
#: ``distance - (VISIBILITY_TOLERANCE + VISIBILITY_RELATIVE_TOLERANCE * distance)`` (m, -)
VISIBILITY_TOLERANCE = 1e-5
VISIBILITY_RELATIVE_TOLERANCE = 1e-3
#: default number of uniform-Laplacian smoothing steps, and the step size (unitless)
DEFAULT_WEIGHT_SMOOTHING = 2
WEIGHT_SMOOTHING_STEP = 0.5
#: derived weights below this are dropped after smoothing (then rows are renormalised)
MIN_DERIVED_WEIGHT = 1e-3
#: (vertex, bone) pairs evaluated at once when deriving weights (bounds memory, ~100 MB)
DERIVE_CHUNK_PAIRS = 1 << 22


def derive_skin_weights(
    vertices: np.ndarray,
    faces: np.ndarray,
    skeleton: Skeleton,
    *,
    smoothing: int = DEFAULT_WEIGHT_SMOOTHING,
    query: MeshQuery | None = None,
) -> sp.csr_matrix:
    """Skin weights from the geometry: nearest visible bone, then Laplacian smoothing.

    Each vertex first gets weight 1 for the nearest bone segment that "sees" it: among its
    :data:`VISIBILITY_CANDIDATES` nearest bones, the nearest one whose ray from the closest
    point on the segment towards the vertex meets the mesh no earlier than the vertex itself
    (up to :data:`VISIBILITY_TOLERANCE`); if none does, the nearest bone. This keeps, e.g.,
    a vertex of the upper arm from going to a spine bone that is nearer through the armpit.
    Then ``smoothing`` steps ``W <- (1 - s) W + s D^-1 A W`` with the uniform graph
    Laplacian of the mesh edges (``A`` adjacency, ``D`` degrees, ``s`` =
    :data:`WEIGHT_SMOOTHING_STEP`) blend the weights across bone borders; weights below
    :data:`MIN_DERIVED_WEIGHT` are then dropped and every row renormalised to sum 1.

    Parameters
    ----------
    vertices : (V, 3) float64
        Meters.
    faces : (F, 3) int64
    skeleton : Skeleton
    smoothing : int
        Number of smoothing steps (0: hard weights).
    query : MeshQuery, optional
        A prebuilt query structure over the same mesh.

    Returns
    -------
    weights : (V, B) scipy.sparse.csr_matrix
        Non-negative, rows sum to 1.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    n_vertices, n_bones = len(vertices), skeleton.n_bones
    if n_bones == 0:
        return sp.csr_matrix((n_vertices, 0))
    query = query or MeshQuery(vertices, faces)
    bone = nearest_visible_bones(vertices, skeleton, query)
    weights = sp.csr_matrix((np.ones(n_vertices), (np.arange(n_vertices), bone)), shape=(n_vertices, n_bones))
    if smoothing > 0:
        weights = smooth_weights(weights, faces, smoothing)
    return weights


def nearest_visible_bones(vertices: np.ndarray, skeleton: Skeleton, query: MeshQuery) -> np.ndarray:
    """The bone of each vertex before smoothing (see :func:`derive_skin_weights`).

    Parameters
    ----------
    vertices : (V, 3) float64
    skeleton : Skeleton
        With at least one bone.
    query : MeshQuery
        Over the mesh of ``vertices``.

    Returns
    -------
    bone : (V,) int64
        The nearest bone that sees the vertex, else the nearest bone.
    """
    n_vertices, n_bones = len(vertices), skeleton.n_bones
    n_candidates = min(VISIBILITY_CANDIDATES, n_bones)
    chunk = max(1, DERIVE_CHUNK_PAIRS // n_bones)
    bone = np.empty(n_vertices, dtype=np.int64)
    for start in range(0, n_vertices, chunk):
        points = vertices[start : start + chunk]
        _, closest = closest_points_on_segments(points, skeleton.heads, skeleton.tails)
        offset = points[:, None, :] - closest
        distance = np.linalg.norm(offset, axis=2)
        order = np.argsort(distance, axis=1, kind="stable")[:, :n_candidates]
        rows = np.arange(len(points))[:, None]
        cand_distance = distance[rows, order]
        cand_origin = closest[rows, order]
        cand_offset = offset[rows, order]
        visible = cand_distance <= VISIBILITY_TOLERANCE
        cast = ~visible
        if cast.any():
            hits = query.first_hits(cand_origin[cast], cand_offset[cast])
            allowed = cand_distance[cast] * (1.0 - VISIBILITY_RELATIVE_TOLERANCE) - VISIBILITY_TOLERANCE
            visible[cast] = ~hits.hit | (hits.distance >= allowed)
        first_visible = np.argmax(visible, axis=1)
        first_visible[~visible.any(axis=1)] = 0
        bone[start : start + chunk] = order[np.arange(len(points)), first_visible]
    return bone


def smooth_weights(weights: sp.csr_matrix, faces: np.ndarray, steps: int) -> sp.csr_matrix:
    """``steps`` uniform-Laplacian smoothing steps, then pruning and row renormalisation.

    Parameters
    ----------
    weights : (V, B) scipy.sparse.csr_matrix
    faces : (F, 3) int64
        The mesh whose edges join the vertices; a vertex on no edge keeps its row.
    steps : int

    Returns
    -------
    weights : (V, B) scipy.sparse.csr_matrix
        Entries below :data:`MIN_DERIVED_WEIGHT` dropped, rows with a positive sum
        summing to 1.
    """
    n_vertices = weights.shape[0]
    adjacency = vertex_adjacency(faces, n_vertices).astype(np.float64)
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    isolated = degree == 0
    inv_degree = np.where(isolated, 0.0, 1.0 / np.where(isolated, 1.0, degree))
    average = sp.diags(inv_degree) @ adjacency + sp.diags(isolated.astype(np.float64))
    step = sp.csr_matrix(
        (1.0 - WEIGHT_SMOOTHING_STEP) * sp.identity(n_vertices) + WEIGHT_SMOOTHING_STEP * average
    )
    for _ in range(steps):
        weights = step @ weights
    weights = sp.csr_matrix(weights)
    weights.data[weights.data < MIN_DERIVED_WEIGHT] = 0.0
    weights.eliminate_zeros()
    return normalise_weight_rows(weights)
