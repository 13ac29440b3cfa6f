"""Pushing points out of a closed body to a clearance along the distance normal."""

from __future__ import annotations

import numpy as np

from hairport.solver.mesh.query import MeshQuery

#: push-out rounds at most (a pushed particle may come close to another part of the body)
MAX_PUSH_ROUNDS = 5
#: a particle within this distance (m) below the clearance counts as clear: a pushed particle
#: lands at the clearance up to round-off, and must not be pushed again every round for it
PUSH_TOLERANCE = 1e-10


def push_out(points: np.ndarray, is_root: np.ndarray, query: MeshQuery, clearance: float) -> np.ndarray:
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
    clearance : float
        Meters, >= 0.

    Returns
    -------
    points : (N, 3) float64
        A new array.
    """
    out = np.array(points, dtype=np.float64, copy=True).reshape(-1, 3)
    active = np.flatnonzero(~np.asarray(is_root, dtype=bool))
    for _ in range(MAX_PUSH_ROUNDS):
        if active.size == 0:
            break
        sd = query.signed_distance(out[active])
        close = sd.distance < clearance - PUSH_TOLERANCE
        if not close.any():
            break
        active = active[close]
        out[active] += (clearance - sd.distance[close])[:, None] * sd.normal[close]
    return out
