"""The final penetration check: no result is reported with a hair particle inside the body.

Every method that claims a penetration-free result (the solvers, the baselines with
``+pushout``) ends here (:func:`resolve_penetration`): the non-root particles inside the
body are counted by its inside test (the winding number, :mod:`.inside`, the same test as
the penetration metrics); any found are pushed out (:func:`.clearance.push_inside_out`) and
reported; if some are still inside after that, the result is refused with
:class:`~hairport.solver.model.errors.PenetrationRemaining` (code ``penetration_remaining``).

Convention: particles ``(N, 3) float64`` in meters.
"""

from __future__ import annotations

import numpy as np

from hairport.solver.mesh.clearance import push_inside_out
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.errors import PenetrationRemaining


def inside_depths(points: np.ndarray, is_root: np.ndarray, query: MeshQuery) -> tuple[np.ndarray, np.ndarray]:
    """The non-root particles inside the body and how deep (m) they are.

    Parameters
    ----------
    points : (N, 3) float64
    is_root : (N,) bool
    query : MeshQuery
        The body (its collision surface: the sign of its distance is the inside test).

    Returns
    -------
    rows : (K,) int64
        Particles inside, ascending.
    depth : (K,) float64
        Their distance to the body's surface (m).
    """
    free = np.flatnonzero(~np.asarray(is_root, dtype=bool))
    distance = query.signed_distance(points[free]).distance if len(free) else np.zeros(0)
    inside = distance < 0.0
    return free[inside], -distance[inside]


def resolve_penetration(
    points: np.ndarray, is_root: np.ndarray, query: MeshQuery, clearance: float, body: str | None = None
) -> tuple[np.ndarray, dict]:
    """Push out the particles a method left inside the body, or refuse the result.

    Parameters
    ----------
    points : (N, 3) float64
        A method's result.
    is_root : (N,) bool
        Roots (on the surface by Eq. 12) are not checked.
    query : MeshQuery
        The body's collision surface (:func:`.collision.collision_query`).
    clearance : float
        Meters: where pushed particles land beyond the surface (``eps_c``).
    body : str, optional
        The body's name, for the error.

    Returns
    -------
    points : (N, 3) float64
        ``points`` itself when none was inside, else a new array.
    resolved : dict
        ``particles``: how many were inside and were pushed out; ``deepest_m``: the deepest of
        them (0 when none).

    Raises
    ------
    PenetrationRemaining
        Some particles are still inside after the push-out.
    """
    rows, depth = inside_depths(points, is_root, query)
    resolved = {"particles": int(len(rows)), "deepest_m": float(depth.max(initial=0.0))}
    if len(rows) == 0:
        return points, resolved
    pushed, left = push_inside_out(points, rows, query, clearance)
    if len(left):
        raise PenetrationRemaining(
            f"{len(left):,} of the {len(rows):,} hair particles the method left inside the target body (deepest "
            f"{1e3 * resolved['deepest_m']:.2f} mm) are still inside after pushing them out (the first: particle "
            f"{left[0]}); no penetration-free result was found",
            body,
        )
    return pushed, resolved
