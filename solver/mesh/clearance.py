"""Pushing points out of a body to a clearance along the distance normal: every particle closer
than the clearance (:func:`push_out`, the baselines' ``+pushout`` and the solvers' cap), or the
particles inside the body (:func:`push_inside_out`, the final check of :mod:`.penetration`)."""

from __future__ import annotations

import numpy as np

from hairport.solver.mesh.query import MeshQuery

#: push-out rounds at most (a pushed particle may come close to another part of the body)
MAX_PUSH_ROUNDS = 5
#: a particle within this distance (m) below the clearance counts as clear: a pushed particle
#: lands at the clearance up to round-off, and must not be pushed again every round for it
PUSH_TOLERANCE = 1e-10
#: rounds of :func:`push_inside_out`, each with half the clearance of the one before: a
#: particle that the full clearance puts into another part of the body (across a gap
#: narrower than it) lands in the gap a round later; the last round's clearance is 1/32 of it
INSIDE_PUSH_ROUNDS = 6
#: below this distance (m) from its closest point a particle goes out along the surface normal
ON_SURFACE = 1e-12


def push_out(points: np.ndarray, is_root: np.ndarray, query: MeshQuery, clearance: float | np.ndarray) -> np.ndarray:
    """Move non-root particles closer than ``clearance`` to the body out to exactly ``clearance``.

    A particle ``p`` with signed distance ``d < clearance`` (less :data:`PUSH_TOLERANCE`) goes
    to ``p + (clearance - d) n`` along the distance normal ``n`` (outward; it also pushes out
    particles inside). Moved particles are checked again, for at most :data:`MAX_PUSH_ROUNDS` rounds, since a moved
    particle may come close to another part of the body. Particles are independent: strands
    may stretch; nothing keeps segment lengths.

    Parameters
    ----------
    points : (N, 3) float64
    is_root : (N,) bool
        Roots are never moved.
    query : MeshQuery
        Over the target body.
    clearance : float or (N,) float64
        Meters, >= 0 (each particle's own, or one for all).

    Returns
    -------
    points : (N, 3) float64
        A new array.
    """
    out = np.array(points, dtype=np.float64, copy=True).reshape(-1, 3)
    each = np.broadcast_to(np.asarray(clearance, dtype=np.float64), (len(out),))
    active = np.flatnonzero(~np.asarray(is_root, dtype=bool))
    for _ in range(MAX_PUSH_ROUNDS):
        if active.size == 0:
            break
        sd = query.signed_distance(out[active])
        close = sd.distance < each[active] - PUSH_TOLERANCE
        if not close.any():
            break
        active = active[close]
        out[active] += (each[active] - sd.distance[close])[:, None] * sd.normal[close]
    return out


def push_inside_out(
    points: np.ndarray, rows: np.ndarray, query: MeshQuery, clearance: float, runs: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Move particles that are inside the body out, to a clearance beyond its surface.

    A particle inside goes through its closest point ``q`` on the body's surface to
    ``q + c u``, ``u`` the unit vector from it to ``q`` (the surface normal at ``q`` when it is
    on the surface): straight out by the shortest way. Particles still inside
    (:meth:`~.query.MeshQuery.inside`: a gap narrower than ``c`` put them into another part of
    the body) go again with half the clearance, for :data:`INSIDE_PUSH_ROUNDS` rounds.
    Particles are independent; nothing keeps segment lengths.

    Parameters
    ----------
    points : (N, 3) float64
    rows : (K,) int64
        The particles inside (never roots).
    query : MeshQuery
        The body (its collision surface, :func:`.collision.collision_query`).
    clearance : float
        Meters, >= 0: the first round's.
    runs : (N,) int64, optional
        Each particle's run of welded particles (:func:`.segment_crossing.weld_runs`): the rows of one run
        move as one, by the push of its first row (pushed apart, particles a rounding apart at an edge of
        the body could land on two faces, a weld broken by up to the clearance).

    Returns
    -------
    points : (N, 3) float64
        A new array.
    inside : (J,) int64
        The rows still inside after the last round (none on success).
    """
    rows = np.asarray(rows, dtype=np.int64)
    if runs is not None and rows.size:
        run_of = np.asarray(runs)[rows]
        _, first, slot = np.unique(run_of, return_index=True, return_inverse=True)
        leaders = rows[first]
        pushed, left = push_inside_out(points, leaders, query, clearance)
        out = np.array(points, dtype=np.float64, copy=True).reshape(-1, 3)
        out[rows] += (pushed[leaders] - out[leaders])[slot]
        return out, rows[np.isin(run_of, run_of[first][np.isin(leaders, left)])]
    out = np.array(points, dtype=np.float64, copy=True).reshape(-1, 3)
    c = float(clearance)
    for _ in range(INSIDE_PUSH_ROUNDS):
        if rows.size == 0:
            break
        sd = query.signed_distance(out[rows])
        offset = sd.closest - out[rows]
        length = np.linalg.norm(offset, axis=1)
        away = np.where((length > ON_SURFACE)[:, None], offset / np.maximum(length, ON_SURFACE)[:, None], sd.normal)
        out[rows] = sd.closest + c * away
        rows = rows[query.inside(out[rows])]
        c *= 0.5
    return out, rows
