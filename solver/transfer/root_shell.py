"""Roots on the skin: roots whose closest point lies on another piece of the mesh move onto the skin.

A character mesh may carry eyes, teeth, lashes or stray faces on non-manifold edges as
separate shells (:mod:`~hairport.solver.mesh.shells`). A root a few millimetres off the skin
can be closer to one of them (a fringe root above a lash, a root over a fin) than to the
skin it grows from. The skin is the shell that holds most roots; a root anchored elsewhere
is anchored to its closest point on that shell instead, when that holds at least
:data:`~hairport.solver.mesh.shells.MIN_ROOT_SHELL_SHARE` of the roots (otherwise the roots
are spread over several pieces on purpose, and stay).
"""

from __future__ import annotations

import numpy as np

from hairport.solver.mesh.query import MeshQuery, SignedDistance
from hairport.solver.mesh.shells import MIN_ROOT_SHELL_SHARE, shell_labels


def snap_roots_to_skin(query: MeshQuery, points: np.ndarray, surface: SignedDistance,
                      is_root: np.ndarray) -> tuple[SignedDistance, int]:
    """The closest-point results with every root's on the shell that holds most roots.

    Parameters
    ----------
    query : MeshQuery
        Over the whole mesh.
    points : (N, 3) float64
        Hair particles.
    surface : SignedDistance
        ``query.signed_distance`` of all N particles.
    is_root : (N,) bool

    Returns
    -------
    surface : SignedDistance
        The same, with the rows of the roots that lay on another shell replaced by their
        closest point on the roots' shell (``faces`` still the whole mesh's ids).
    moved : int
        Roots moved onto the roots' shell.
    """
    roots = np.flatnonzero(is_root)
    if len(roots) == 0:
        return surface, 0
    labels = shell_labels(query.faces)
    on = labels[surface.faces[roots]]
    count = np.bincount(on)
    skin = int(np.argmax(count))
    off = roots[on != skin]
    if len(off) == 0 or count[skin] < MIN_ROOT_SHELL_SHARE * len(roots):
        return surface, 0
    skin_faces = np.flatnonzero(labels == skin)
    found = MeshQuery(query.vertices, query.faces[skin_faces]).signed_distance(points[off])
    snapped = surface.take(np.arange(len(surface.faces)))  # a copy
    snapped.distance[off] = found.distance
    snapped.closest[off] = found.closest
    snapped.normal[off] = found.normal
    snapped.faces[off] = skin_faces[found.faces]
    return snapped, int(len(off))

