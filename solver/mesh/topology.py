"""Mesh topology over face arrays ``(F, 3) int64``: edges and adjacency (the one edge graph and
its Laplacian), sub-meshes, boundary loops, disks, subdivision.

Every edge table here comes from :func:`half_edges`: row ``3 f + j`` is face ``f``'s edge from
corner ``j`` to corner ``j + 1``, so the half-edge opposite corner ``k`` is row ``3 f + (k + 1) % 3``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from hairport.solver.model.errors import InputError

#: rounds of "add the faces around pinch vertices, fill holes" before a region is refused
MAX_DISK_REPAIRS = 4


def half_edges(faces: np.ndarray) -> np.ndarray:
    """The directed edges of every face, face by face.

    Parameters
    ----------
    faces : (F, 3) int64

    Returns
    -------
    edges : (3F, 2) int64
        Row ``3 f + j`` runs from corner ``j`` to corner ``(j + 1) % 3`` of face ``f``.
    """
    return np.asarray(faces, dtype=np.int64)[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)


def _edge_twins(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of half-edges ``(a, b)`` (rows of :func:`half_edges`) on the same undirected edge.

    On a non-manifold edge its half-edges are chained in face order, ``(h1, h2), (h2, h3)``.
    """
    edges = half_edges(faces)
    n = int(edges.max()) + 1
    key = np.minimum(edges[:, 0], edges[:, 1]) * n + np.maximum(edges[:, 0], edges[:, 1])
    order = np.argsort(key, kind="stable")
    same = key[order[1:]] == key[order[:-1]]
    return order[:-1][same], order[1:][same]


def face_adjacency(faces: np.ndarray) -> sp.csr_matrix:
    """Edge adjacency of faces.

    Parameters
    ----------
    faces : (F, 3) int64

    Returns
    -------
    adjacency : (F, F) csr_matrix of bool
        Symmetric; ``[i, j]`` when faces ``i`` and ``j`` share an edge (on a non-manifold
        edge its faces are chained in id order, which keeps them connected).
    """
    n_faces = len(faces)
    a, b = (twin // 3 for twin in _edge_twins(faces))
    data = np.ones(2 * len(a), dtype=bool)
    return sp.csr_matrix((data, (np.concatenate([a, b]), np.concatenate([b, a]))), shape=(n_faces, n_faces))


def corner_neighbours(faces: np.ndarray) -> np.ndarray:
    """The face across the edge opposite each corner.

    Parameters
    ----------
    faces : (F, 3) int64

    Returns
    -------
    neighbours : (F, 3) int64
        ``[f, k]``: the face sharing the edge from corner ``k + 1`` to ``k + 2`` of face ``f``,
        -1 on the border (on a non-manifold edge, a neighbour in the chain of
        :func:`face_adjacency`).
    """
    a, b = _edge_twins(faces)
    across = np.full(3 * len(faces), -1, dtype=np.int64)
    across[a] = b // 3
    across[b] = a // 3
    # half-edge j of a face runs from corner j to j + 1: it is opposite corner j + 2
    return across.reshape(-1, 3)[:, [1, 2, 0]]


def vertex_faces(faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The faces around each vertex, in CSR layout.

    Parameters
    ----------
    faces : (F, 3) int64
    n_vertices : int

    Returns
    -------
    start : (V + 1,) int64
        Vertex ``v``'s faces are ``faces_around[start[v]:start[v + 1]]``.
    faces_around : (3F,) int64
        Face ids, ascending per vertex.
    corners : (3F,) int64
        The vertex's corner in each of those faces.
    """
    corner_vertex = np.asarray(faces, dtype=np.int64).ravel()
    order = np.argsort(corner_vertex, kind="stable")
    start = np.zeros(n_vertices + 1, dtype=np.int64)
    np.cumsum(np.bincount(corner_vertex, minlength=n_vertices), out=start[1:])
    return start, order // 3, order % 3


def vertex_adjacency(faces: np.ndarray, n_vertices: int) -> sp.csr_matrix:
    """The mesh's edge graph.

    Parameters
    ----------
    faces : (F, 3) int64
    n_vertices : int

    Returns
    -------
    adjacency : (V, V) csr_matrix of bool
        Symmetric; ``[i, j]`` when an edge of ``faces`` joins vertices ``i`` and ``j``.
    """
    edges = half_edges(faces)
    data = np.ones(2 * len(edges), dtype=bool)
    rows = np.concatenate([edges[:, 0], edges[:, 1]])
    cols = np.concatenate([edges[:, 1], edges[:, 0]])
    return sp.csr_matrix((data, (rows, cols)), shape=(n_vertices, n_vertices))


def graph_laplacian(faces: np.ndarray, n_vertices: int) -> sp.csr_matrix:
    """The unit-weight graph Laplacian ``D - A`` of the edge graph (:func:`vertex_adjacency`).

    Parameters
    ----------
    faces : (F, 3) int64
        No face repeats a vertex.
    n_vertices : int

    Returns
    -------
    laplacian : (V, V) csr_matrix of float64
        Each vertex's neighbour count on the diagonal, -1 per edge off it; rows sum to 0.
    """
    adjacency = vertex_adjacency(faces, n_vertices).astype(np.float64)
    return (sp.diags(np.asarray(adjacency.sum(axis=1)).ravel()) - adjacency).tocsr()


def submesh(faces: np.ndarray, face_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The vertices used by some faces and the faces in local numbering.

    Parameters
    ----------
    faces : (F, 3) int64
    face_ids : (k,) int64

    Returns
    -------
    vertices : (n,) int64
        Ascending ids of the vertices used.
    triangles : (k, 3) int64
        ``faces[face_ids]`` renumbered into ``vertices``.
    """
    chosen = np.asarray(faces, dtype=np.int64)[face_ids]
    vertices, local = np.unique(chosen, return_inverse=True)
    return vertices.astype(np.int64), local.reshape(-1, 3).astype(np.int64)


def euler_characteristic(triangles: np.ndarray) -> int:
    """``V - E + F`` of a triangle mesh ``(k, 3)``, counting the vertices it uses."""
    triangles = np.asarray(triangles, dtype=np.int64)
    if len(triangles) == 0:
        return 0
    edges = np.sort(half_edges(triangles), axis=1)
    n_edges = len(np.unique(edges, axis=0))
    return len(np.unique(triangles)) - n_edges + len(triangles)


def boundary_loops(triangles: np.ndarray) -> list[np.ndarray]:
    """Ordered boundary loops of a triangle mesh, longest first.

    Parameters
    ----------
    triangles : (k, 3) int64
        Consistently oriented.

    Returns
    -------
    loops : list of (b_i,) int64
        Each loop follows the triangles' boundary half-edges (the mesh on its left seen from
        the side the triangles are counter-clockwise from); starts at its smallest vertex id.

    Raises
    ------
    InputError
        A vertex where the boundary touches itself (pinch) or an inconsistent orientation.
    """
    triangles = np.asarray(triangles, dtype=np.int64)
    if len(triangles) == 0:
        return []
    n = int(triangles.max()) + 1
    half = half_edges(triangles)
    key = half[:, 0] * n + half[:, 1]
    reverse = half[:, 1] * n + half[:, 0]
    if len(np.unique(key)) != len(key):
        raise InputError(
            "the triangles are not consistently oriented (a directed edge appears twice)", code="not_a_disk"
        )
    boundary = half[~np.isin(reverse, key)]
    if len(boundary) == 0:
        return []
    if np.bincount(boundary[:, 0], minlength=n).max() > 1:
        raise InputError("the region's boundary touches itself at a vertex (not a disk)", code="not_a_disk")
    nxt = np.full(n, -1, dtype=np.int64)
    nxt[boundary[:, 0]] = boundary[:, 1]
    unvisited = set(boundary[:, 0].tolist())
    loops = []
    while unvisited:  # a few loops, each walked once
        start = min(unvisited)
        loop = [start]
        v = int(nxt[start])
        while v != start:
            if v < 0 or len(loop) > len(boundary):
                raise InputError("the region's boundary is not a closed loop", code="not_a_disk")
            loop.append(v)
            v = int(nxt[v])
        unvisited.difference_update(loop)
        loops.append(np.asarray(loop, dtype=np.int64))
    loops.sort(key=len, reverse=True)
    return loops


def check_disk(triangles: np.ndarray, what: str = "region") -> np.ndarray:
    """The boundary loop of a triangle mesh that must be a topological disk.

    Parameters
    ----------
    triangles : (k, 3) int64
    what : str
        Name used in messages.

    Returns
    -------
    loop : (b,) int64
        As :func:`boundary_loops`.

    Raises
    ------
    InputError
        Not a disk: Euler characteristic ``V - E + F != 1`` or not exactly one boundary loop.
    """
    loops = boundary_loops(triangles)
    chi = euler_characteristic(triangles)
    if len(loops) != 1 or chi != 1:
        raise InputError(
            f"the {what} is not a disk: {len(loops)} boundary loops and Euler characteristic {chi} "
            "(a disk has 1 and 1)",
            code="not_a_disk",
        )
    return loops[0]


def is_disk(triangles: np.ndarray) -> bool:
    """Whether a triangle mesh ``(k, 3)`` is a topological disk (what :func:`check_disk` accepts)."""
    try:
        check_disk(triangles)
    except InputError:
        return False
    return True


def fill_holes(region: np.ndarray, adjacency: sp.csr_matrix) -> np.ndarray:
    """A face region with its holes filled.

    The rest of the mesh (faces outside ``region``) falls into edge-connected pieces; the
    largest is the rest of the body, every other one is a hole and joins the region.

    Parameters
    ----------
    region : (F,) bool
    adjacency : (F, F) csr_matrix
        From :func:`face_adjacency`.

    Returns
    -------
    filled : (F,) bool
    """
    outside = np.flatnonzero(~region)
    if len(outside) == 0:
        return region.copy()
    _, labels = connected_components(adjacency[outside][:, outside], directed=False)
    body = np.argmax(np.bincount(labels))
    filled = region.copy()
    filled[outside[labels != body]] = True
    return filled


def largest_piece(region: np.ndarray, adjacency: sp.csr_matrix, weight: np.ndarray) -> np.ndarray:
    """The edge-connected piece of ``region (F,) bool`` with the largest ``weight (F,)`` sum
    (ties: the most faces), as an (F,) bool mask."""
    inside = np.flatnonzero(region)
    _, labels = connected_components(adjacency[inside][:, inside], directed=False)
    score = np.bincount(labels, weights=weight[inside]) + 1e-9 * np.bincount(labels)
    piece = np.zeros_like(region)
    piece[inside[labels == np.argmax(score)]] = True
    return piece


def _pinch_vertices(faces: np.ndarray, region: np.ndarray) -> np.ndarray:
    """Ids of vertices where the region's boundary touches itself."""
    half = half_edges(faces[region])
    n = int(faces.max()) + 1
    key = half[:, 0] * n + half[:, 1]
    boundary = half[~np.isin(half[:, 1] * n + half[:, 0], key)]
    count = np.bincount(boundary[:, 0], minlength=n)
    return np.flatnonzero(count > 1)


def repair_disk(faces: np.ndarray, region: np.ndarray, adjacency: sp.csr_matrix, weight: np.ndarray,
                what: str = "region") -> np.ndarray:
    """A face region repaired toward a topological disk, unchecked (:func:`make_disk` checks).

    Keeps the edge-connected piece with the most ``weight``, fills its holes, and adds the
    faces around pinch vertices (repeated up to ``MAX_DISK_REPAIRS`` times).

    Parameters
    ----------
    faces : (F, 3) int64
    region : (F,) bool
    adjacency : (F, F) csr_matrix
        From :func:`face_adjacency`.
    weight : (F,) float64
        What the kept piece should hold most of (e.g. roots per face).
    what : str
        Name used in messages.

    Returns
    -------
    repaired : (F,) bool

    Raises
    ------
    InputError
        Empty region.
    """
    if not region.any():
        raise InputError(f"the {what} is empty", code="not_a_disk")
    disk = region
    for _ in range(MAX_DISK_REPAIRS + 1):
        disk = fill_holes(largest_piece(disk, adjacency, weight), adjacency)
        pinch = _pinch_vertices(faces, disk)
        if len(pinch) == 0:
            break
        around = np.zeros(int(faces.max()) + 1, dtype=bool)
        around[pinch] = True
        disk = disk | around[faces].any(axis=1)
    return disk


def make_disk(faces: np.ndarray, region: np.ndarray, adjacency: sp.csr_matrix, weight: np.ndarray,
              what: str = "region") -> np.ndarray:
    """A face region made a topological disk (:func:`repair_disk`, then :func:`check_disk`).

    Parameters
    ----------
    faces : (F, 3) int64
    region : (F,) bool
    adjacency : (F, F) csr_matrix
        From :func:`face_adjacency`.
    weight : (F,) float64
        What the kept piece should hold most of (e.g. roots per face).
    what : str
        Name used in messages.

    Returns
    -------
    disk : (F,) bool

    Raises
    ------
    InputError
        Empty region, or no disk after the repairs.
    """
    disk = repair_disk(faces, region, adjacency, weight, what)
    check_disk(submesh(faces, np.flatnonzero(disk))[1], what)
    return disk


def boundary_edges(triangles: np.ndarray, n_vertices: int) -> np.ndarray:
    """(k, 3) bool: whether edge ``j`` (corner ``j`` to ``j + 1``) of each triangle is on the boundary."""
    directed = half_edges(triangles).reshape(-1, 3, 2)
    key = directed[..., 0] * n_vertices + directed[..., 1]
    reverse = directed[..., 1] * n_vertices + directed[..., 0]
    return ~np.isin(key, reverse.ravel())


def subdivide(points: np.ndarray, triangles: np.ndarray, loop: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One 1-to-4 midpoint subdivision.

    Parameters
    ----------
    points : (n, 3) float64
    triangles : (k, 3) int64
    loop : (b,) int64
        An ordered boundary loop.

    Returns
    -------
    points : (n + e, 3) float64
        The old points first, then the midpoints of the ``e`` edges (not projected).
    triangles : (4k, 3) int64
        Same orientation: per old triangle ``(a, b, c)`` with midpoints ``ab, bc, ca``:
        ``(a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca)``.
    loop : (2b,) int64
        The old loop with the midpoint of each loop edge inserted after its first vertex.
    """
    n = len(points)
    half = half_edges(triangles)
    key = np.minimum(half[:, 0], half[:, 1]) * n + np.maximum(half[:, 0], half[:, 1])
    unique, inverse = np.unique(key, return_inverse=True)
    mid = (n + inverse).reshape(-1, 3)  # columns: ab, bc, ca
    ends = np.stack([unique // n, unique % n], axis=1)
    new_points = np.concatenate([points, 0.5 * (points[ends[:, 0]] + points[ends[:, 1]])])
    a, b, c = triangles.T
    ab, bc, ca = mid.T
    new_triangles = np.stack(
        [np.stack([a, ab, ca], 1), np.stack([ab, b, bc], 1), np.stack([ca, bc, c], 1), np.stack([ab, bc, ca], 1)],
        axis=1,
    ).reshape(-1, 3)
    nxt = np.roll(loop, -1)
    loop_key = np.minimum(loop, nxt) * n + np.maximum(loop, nxt)
    loop_mid = n + np.searchsorted(unique, loop_key)
    new_loop = np.stack([loop, loop_mid], axis=1).ravel()
    return new_points, new_triangles.astype(np.int64), new_loop.astype(np.int64)
