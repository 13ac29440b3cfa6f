"""The surface hair collides with: the boundary of the body's inside, for any mesh.

:func:`collision_query` builds the :class:`~.query.MeshQuery` that the solvers' Eq. 13, the
push-outs, the final penetration check and the penetration metrics use. Inside and outside
are the winding number's (:mod:`.inside`): correct at any depth, for closed and for open
bodies (a bust cut at the chest is closed by its cut), for extra shells (eyes, teeth) and
overlapping parts. Distances, closest points and normals are to the faces that separate
inside from outside (:func:`.inside.exit_faces`): a particle inside is sent to the nearest
place where it can leave the body, never across an eyeball's back into the eyeball.

Signs: on a closed body (no open cut) inside changes only across the separating faces, so
a point whose closest point lies on a face, or on an edge or vertex where those faces form a
closed manifold, takes the pseudonormal's sign (exact there, and free); only points closest
to the rim of a removed face (where a shell pokes through the skin, where the body crosses
itself) are counted by the winding number. MakeHuman bodies cross themselves in 0 to 20
faces (the male shapes at the lips, the female and child shapes at the toes): few particles
if any. On an open body every point farther from the
surface than :data:`~.query.NEAR_SURFACE` of its size is counted (~0.6 us each, a quarter of
a closest-point query): across the film over a hole inside changes with no face to say so.
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict

import numpy as np

from hairport.solver.mesh.inside import (
    InsideTest,
    WindingNumber,
    closed_cycle,
    exit_faces,
    manifold_closed,
    manifold_features,
    shell_count,
)
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.errors import InputError

#: collision queries kept for reuse, per thread (one retarget job per target, a benchmark's
#: many methods); per thread because a query builds its trees lazily, unguarded
CACHED_BODIES = 4

_LOCAL = threading.local()


def body_key(vertices: np.ndarray, faces: np.ndarray) -> str:
    """The content digest of a body (``vertices (V, 3) float64``, ``faces (F, 3) int64``): 32 hex characters."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    return hashlib.blake2b(vertices.tobytes() + b"|" + faces.tobytes(), digest_size=16).hexdigest()


def collision_faces(vertices: np.ndarray, faces: np.ndarray, name: str | None = None,
                    winding: WindingNumber | None = None) -> np.ndarray:
    """``(F,) bool``: the faces that separate the body's inside from outside (the expensive part of
    :func:`collision_query`: a winding number beside each face, :func:`.inside.exit_faces`). ``no_inside`` when there
    are none. ``winding``: the body's, when the caller keeps one (its tree is built once)."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    separating = exit_faces(vertices, faces, WindingNumber(vertices, faces) if winding is None else winding)
    if not separating.any():
        raise InputError(
            "the body encloses no volume: no face has the body behind it (are its faces oriented inward?)",
            name, "no_inside",
        )
    return separating


def collision_query(vertices: np.ndarray, faces: np.ndarray, name: str | None = None,
                    separating: np.ndarray | None = None, moved_from: MeshQuery | None = None) -> MeshQuery:
    """The collision surface of a body and its inside test.

    Finding the separating faces takes a winding number beside each face (~0.1 s on the closed
    27k-face MakeHuman body, two per face on an open body): the last :data:`CACHED_BODIES` bodies' queries are kept,
    by content, and shared within a thread.

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
        Counter-clockwise seen from outside.
    name : str, optional
        The body's name, for the error.
    separating : (F,) bool, optional
        :func:`collision_faces` of this body, when kept from an earlier build (another process's).
    moved_from : MeshQuery, optional
        The collision query of this mesh at other vertices (a sequence's previous frame): where its surface is
        the same faces, the new query is it moved (:meth:`~.query.MeshQuery.moved`: what depends on the faces
        alone kept, the face search refit); the separating faces are found anew all the same.

    Returns
    -------
    query : MeshQuery
        Over the separating faces; its signed distance and ``query.inside`` give the body's
        inside, ``query.inside_test.winding`` the winding number of all the faces, and
        ``query.closed`` whether inside changes only across the surface (no open cut).

    Raises
    ------
    InputError
        ``no_inside``: no face has the body's inside behind it (no faces, or faces that all
        look inward), so nothing could be kept out of it.
    """
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    key = hashlib.blake2b(vertices.tobytes() + b"|" + faces.tobytes(), digest_size=16).digest()
    cache = _LOCAL.__dict__.setdefault("bodies", OrderedDict())
    if key in cache:
        cache.move_to_end(key)
        return cache[key]
    if separating is not None and np.shape(separating) != (len(faces),):
        raise ValueError(f"separating faces of shape {np.shape(separating)} for a body of {len(faces)} faces")
    query = _build(vertices, faces, name, separating, moved_from)
    cache[key] = query
    while len(cache) > CACHED_BODIES:
        cache.popitem(last=False)
    return query


def forget_bodies() -> None:
    """Drop the collision queries this thread keeps (:func:`collision_query`): the next query of any body is built
    anew (a benchmark's cold retarget of a body a warm frame just queried)."""
    _LOCAL.__dict__.pop("bodies", None)


def _build(vertices: np.ndarray, faces: np.ndarray, name: str | None, separating: np.ndarray | None,
           moved_from: MeshQuery | None) -> MeshQuery:
    winding = WindingNumber(vertices, faces)
    if separating is None:
        separating = collision_faces(vertices, faces, name, winding)  # the inside test then reuses its tree
    separating = np.asarray(separating, dtype=bool)
    surface = faces[separating]
    if _same_surface(moved_from, faces, surface):
        # closedness and the manifold features depend on the faces alone
        kept = moved_from.inside_test
        return moved_from.moved(vertices, InsideTest(winding, closed=kept.closed, manifold=kept.manifold))
    if separating.all() and manifold_closed(faces) and shell_count(faces) == 1:
        inside = InsideTest(winding, closed=True)
    else:
        inside = InsideTest(winding, closed=closed_cycle(faces), manifold=manifold_features(surface))
    return MeshQuery(vertices, surface, inside=inside)


def _same_surface(query: MeshQuery | None, faces: np.ndarray, surface: np.ndarray) -> bool:
    """Whether ``query`` is a collision query of a body with these ``faces (F, 3)`` whose surface is ``surface``."""
    return (query is not None and query.inside_test is not None
            and np.array_equal(query.inside_test.winding.faces, faces) and np.array_equal(query.faces, surface))
