"""Which part of the source is fitted, and how the rest follows.

The hair needs the body only near it: :func:`hair_region` keeps the source vertices within
reach of the hair's particles. The wrap fits that region (:func:`region_mesh`: the faces with
all three corners in it) and moves every other vertex by the harmonic extension of the
region's displacement (:func:`follow`): smooth, exact on the region's border, fading to the
start's similarity far from it, at the cost of one scalar Laplacian solve instead of a
fourfold larger fitting system.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.spatial import cKDTree

from hairport.solver.mesh.shells import edge_table
from hairport.solver.mesh.topology import graph_laplacian, submesh

#: the Laplacian's shift in :func:`follow` (its diagonal is the vertex degree, ~6): keeps the
#: solve definite on pieces of the body the region does not touch, whose displacement then
#: decays to zero, and changes a connected piece's harmonic extension by ~1e-9 relative
FOLLOW_SHIFT = 1e-9


def hair_region(source_vertices: np.ndarray, source_faces: np.ndarray, hair_points: np.ndarray,
                reach_m: float) -> np.ndarray:
    """(V,) bool: source vertices within ``reach_m`` of a hair particle, closed over faces.

    A face with two of its corners in reach brings in the third, so that the region's border
    runs along whole faces and no vertex is held by a single edge.

    Parameters
    ----------
    source_vertices : (V, 3) float64
        Meters.
    source_faces : (F, 3) int64
    hair_points : (P, 3) float64
        The hair's particles (m), roots included.
    reach_m : float
        Meters; e.g. the longest strand's length for a region any strand could swing over,
        or the solver's contact band for the body the hair touches as it lies.
    """
    points = np.asarray(hair_points, dtype=np.float64).reshape(-1, 3)
    vertices = np.asarray(source_vertices, dtype=np.float64)
    if len(points) == 0:
        return np.zeros(len(vertices), dtype=bool)
    distance, _ = cKDTree(points).query(vertices, distance_upper_bound=reach_m)
    region = np.isfinite(distance)
    faces = np.asarray(source_faces, dtype=np.int64)
    inside = region[faces].sum(axis=1) >= 2
    region[faces[inside].ravel()] = True
    return region


def region_mesh(faces: np.ndarray, region: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The sub-mesh the wrap fits: faces with all corners in ``region``.

    Parameters
    ----------
    faces : (F, 3) int64
    region : (V,) bool

    Returns
    -------
    vertices : (n,) int64
        Source ids of the sub-mesh's vertices (ascending; region vertices on no kept face are left out).
    triangles : (t, 3) int64
        Its faces in local ids.
    edges : (m, 2) int64
        Its undirected edges, local ids, each once.
    """
    kept = np.flatnonzero(region[faces].all(axis=1))
    vertices, triangles = submesh(faces, kept)
    return vertices, triangles, edge_table(triangles).ends


def follow(start: np.ndarray, faces: np.ndarray, fitted: np.ndarray, fitted_positions: np.ndarray) -> np.ndarray:
    """Positions of all vertices: the fitted ones as fitted, the others carried along smoothly.

    The displacement from ``start`` is harmonic (graph Laplacian) over the vertices not fitted,
    equal to the fitted displacement on the fitted ones.

    Parameters
    ----------
    start : (V, 3) float64
        Every source vertex after the start's similarity (m).
    faces : (F, 3) int64
    fitted : (n,) int64
        Ids of the fitted vertices.
    fitted_positions : (n, 3) float64
        Where they went (m).

    Returns
    -------
    positions : (V, 3) float64
    """
    n = len(start)
    out = np.array(start, dtype=np.float64, copy=True)
    out[fitted] = fitted_positions
    free = np.ones(n, dtype=bool)
    free[fitted] = False
    if not free.any() or len(fitted) == 0:
        return out
    laplacian = graph_laplacian(faces, n).tocsr()
    free_ids = np.flatnonzero(free)
    l_ff = laplacian[free_ids][:, free_ids] + FOLLOW_SHIFT * sp.identity(len(free_ids), format="csr")
    l_fb = laplacian[free_ids][:, fitted]
    displacement = fitted_positions - start[fitted]
    solved = spla.splu(l_ff.tocsc()).solve(-(l_fb @ displacement))
    out[free_ids] = start[free_ids] + solved
    return out
