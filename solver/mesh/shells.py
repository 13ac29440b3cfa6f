"""The separate pieces (shells) of a character mesh, its border and its non-manifold edges.

Game and scan characters carry eyes, teeth, tongue and lashes in the body's mesh as separate
shells, are often cut open (a bust at the chest, the eye sockets) and may hold a few
non-manifold edges (three or more faces on one edge, or two faces that disagree in
orientation). The hairline edit works on the one *skin shell* that carries the roots
(:func:`root_shell`); these functions find it and describe what is wrong where a region of
it cannot be a disk (:func:`explain_not_disk`), in the user's terms.

A shell is a connected component of the faces joined across *manifold* edges: edges held by
exactly two faces, in opposite directions. A non-manifold edge joins nothing, so a fin
hanging on an edge, or a face flipped against its neighbours, falls apart from the skin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra

from hairport.solver.mesh.topology import half_edges
from hairport.solver.model.errors import InputError

#: the roots' shell must hold at least this share of the roots; below it the roots are spread
#: over several pieces of the mesh and no one scalp holds them
MIN_ROOT_SHELL_SHARE = 0.9


@dataclass(frozen=True, eq=False)
class EdgeTable:
    """The undirected edges of a triangle mesh and how many faces hold each.

    Attributes
    ----------
    ends : (E, 2) int64
        Vertex ids, the smaller first, ascending by ``(a, b)``.
    of_half_edge : (3F,) int64
        The edge of each half-edge of :func:`~hairport.solver.mesh.topology.half_edges`.
    count : (E,) int64
        Faces holding each edge.
    manifold : (E,) bool
        Held by exactly two faces in opposite directions.
    """

    ends: np.ndarray
    of_half_edge: np.ndarray
    count: np.ndarray
    manifold: np.ndarray

    @property
    def border(self) -> np.ndarray:
        """(E,) bool: edges held by one face."""
        return self.count == 1


def edge_table(faces: np.ndarray) -> EdgeTable:
    """The edges of ``faces (F, 3) int64`` with their face counts (see :class:`EdgeTable`)."""
    half = half_edges(faces)
    n = int(half.max()) + 1 if len(half) else 1
    low, high = np.minimum(half[:, 0], half[:, 1]), np.maximum(half[:, 0], half[:, 1])
    keys, inverse, count = np.unique(low * n + high, return_inverse=True, return_counts=True)
    forward = np.bincount(inverse, weights=(half[:, 0] < half[:, 1]).astype(np.float64), minlength=len(keys))
    manifold = (count == 2) & (forward == 1)
    ends = np.stack([keys // n, keys % n], axis=1).astype(np.int64)
    return EdgeTable(ends, inverse.astype(np.int64), count.astype(np.int64), manifold)


def manifold_face_adjacency(faces: np.ndarray, edges: EdgeTable | None = None) -> sp.csr_matrix:
    """(F, F) csr_matrix of bool: faces joined across a manifold edge (symmetric)."""
    edges = edges or edge_table(faces)
    joined = edges.manifold[edges.of_half_edge]
    order = np.argsort(edges.of_half_edge[joined], kind="stable")
    pairs = (np.flatnonzero(joined)[order] // 3).reshape(-1, 2)
    n = len(faces)
    data = np.ones(2 * len(pairs), dtype=bool)
    return sp.csr_matrix((data, (np.concatenate([pairs[:, 0], pairs[:, 1]]),
                                 np.concatenate([pairs[:, 1], pairs[:, 0]]))), shape=(n, n))


def shell_labels(faces: np.ndarray, edges: EdgeTable | None = None) -> np.ndarray:
    """(F,) int64: the shell of each face (components across manifold edges), numbered from 0."""
    _, labels = connected_components(manifold_face_adjacency(faces, edges), directed=False)
    return labels.astype(np.int64)


def vertex_components(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """(V,) int64: connected components of the edge graph (vertices no face uses are each their own)."""
    half = half_edges(faces)
    graph = sp.csr_matrix((np.ones(len(half), dtype=bool), (half[:, 0], half[:, 1])), shape=(n_vertices, n_vertices))
    return connected_components(graph, directed=False)[1].astype(np.int64)


def root_shell(faces: np.ndarray, root_faces: np.ndarray, name: str | None = None) -> np.ndarray:
    """The shell that carries the roots.

    Parameters
    ----------
    faces : (F, 3) int64
    root_faces : (S,) int64
        The face holding each root (S >= 1).
    name : str, optional
        The character, for messages.

    Returns
    -------
    shell : (F,) bool
        The faces of the shell holding the most roots.

    Raises
    ------
    InputError
        ``roots_on_several_pieces``: that shell holds less than :data:`MIN_ROOT_SHELL_SHARE`
        of the roots.
    """
    labels = shell_labels(faces)
    per_shell = np.bincount(labels[root_faces], minlength=int(labels.max()) + 1)
    best = int(np.argmax(per_shell))
    share = per_shell[best] / len(root_faces)
    if share < MIN_ROOT_SHELL_SHARE:
        sizes = np.bincount(labels)
        order = np.argsort(-per_shell)[: np.count_nonzero(per_shell)]
        parts = ", ".join(f"{per_shell[k]} on a piece of {sizes[k]} faces" for k in order[:3])
        raise InputError(
            f"the roots lie on {len(order)} separate pieces of the mesh ({parts}); a hairline edit needs "
            f"at least {100 * MIN_ROOT_SHELL_SHARE:g}% of the roots on one connected piece of skin (join the "
            "pieces in the mesh, or edit the groom without a hairline edit)",
            name, "roots_on_several_pieces")
    return labels == best


def _near(vertices: np.ndarray | None, ids: np.ndarray) -> str:
    if vertices is None or len(ids) == 0:
        return ""
    return f" near {np.round(vertices[ids].mean(axis=0), 3).tolist()}"


def explain_not_disk(
    faces: np.ndarray,
    region: np.ndarray,
    shell: np.ndarray,
    what: str,
    vertices: np.ndarray | None = None,
    name: str | None = None,
) -> InputError | None:
    """Why a region of a shell is not a disk, in the user's terms, or None when the mesh is
    not to blame (then the caller's own message stands).

    Parameters
    ----------
    faces : (F, 3) int64
        The whole mesh.
    region : (F,) bool
        The region that should have been a disk (inside ``shell``).
    shell : (F,) bool
        The shell it lies on.
    what : str
        ``"scalp"``, ``"head patch"``, ...
    vertices : (V, 3) float64, optional
        For the place in the message.
    name : str, optional
        The character, for messages.

    Returns
    -------
    error : InputError or None
        ``mesh_hole`` when the region's border has more than one loop and a loop runs
        entirely along the border of the mesh (edges of the shell held by one face): the
        region surrounds a gap in the mesh; ``not_manifold`` when edges inside the region
        are held by more than two faces, or by two that disagree in orientation.
    """
    region_edges = edge_table(faces[region])
    border = region_edges.ends[region_edges.border]
    if len(border):
        shell_edges = edge_table(faces[shell])
        n = int(faces.max()) + 1
        mesh_border = shell_edges.ends[shell_edges.border]
        on_mesh = np.isin(border[:, 0] * n + border[:, 1], mesh_border[:, 0] * n + mesh_border[:, 1])
        loops = _border_loop_labels(border)
        n_loops = int(loops.max()) + 1
        length = np.bincount(loops, minlength=n_loops)
        along_mesh = np.bincount(loops, weights=on_mesh, minlength=n_loops) == length
        if n_loops > 1 and along_mesh.any():
            if along_mesh.all():
                along_mesh[np.argmax(length)] = False  # the longest is the outline
            ids = np.unique(border[along_mesh[loops]].ravel())
            return InputError(
                f"the {what} under the roots has a hole: it surrounds a gap in the mesh ({len(ids)} border "
                f"vertices{_near(vertices, ids)}); close the gap in the mesh or keep the roots off it",
                name, "mesh_hole")
    bad = ~region_edges.border & ~region_edges.manifold
    if bad.any():
        ids = np.unique(region_edges.ends[bad].ravel())
        return InputError(
            f"the mesh is not manifold inside the {what}: {int(bad.sum())} edges are held by more than two "
            f"faces or by two faces of opposite orientation{_near(vertices, ids)}; repair the mesh there",
            name, "not_manifold")
    return None


def _border_loop_labels(border: np.ndarray) -> np.ndarray:
    """(b,) int64: which connected loop of border edges ``border (b, 2)`` each edge is on (0, 1, ...)."""
    n = int(border.max()) + 1
    graph = sp.csr_matrix((np.ones(len(border), dtype=bool), (border[:, 0], border[:, 1])), shape=(n, n))
    labels = connected_components(graph, directed=False)[1]
    return np.unique(labels[border[:, 0]], return_inverse=True)[1].astype(np.int64)


def shell_of(faces: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """(F,) bool: the shells holding any face of ``seed (F,) bool``."""
    labels = shell_labels(faces)
    return np.isin(labels, np.unique(labels[seed]))


def border_vertices(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """(V,) bool: vertices on an edge held by one face of ``faces (F, 3)`` (the mesh's border)."""
    edges = edge_table(faces)
    border = np.zeros(n_vertices, dtype=bool)
    border[edges.ends[edges.border].ravel()] = True
    return border


def edge_distance(vertices: np.ndarray, faces: np.ndarray, sources: np.ndarray) -> np.ndarray:
    """Shortest distance (m) along the edges of ``faces (F, 3)`` from any vertex of ``sources (V,) bool``.

    Returns
    -------
    distance : (V,) float64
        0 on the sources, ``inf`` where no path reaches (or no source is given).
    """
    n = len(vertices)
    if not sources.any():
        return np.full(n, np.inf)
    edges = edge_table(faces).ends
    length = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)
    length = np.maximum(length, np.finfo(float).tiny)  # an explicit zero would drop the edge
    graph = sp.csr_matrix((length, (edges[:, 0], edges[:, 1])), shape=(n, n))
    return dijkstra(graph, directed=False, indices=np.flatnonzero(sources), min_only=True)
