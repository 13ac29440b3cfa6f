"""Eq. 12-13: roots fixed, every other particle kept ``eps_c`` outside the target body.

The one owner of what both QP backends (:mod:`.active_set`, :mod:`.osqp_backend`) do with
the constraints of Sec. 4.6:

* Eq. 12, roots held fixed: they are no unknowns of the QP (:func:`free_coordinates`,
  :func:`pinned_coordinates`);
* Eq. 13 linearised at the iterate ``p``: ``<n_i, d_i> >= eps_c - s_i`` for every free
  particle near the body or inside it at any depth, with ``s_i`` its signed distance and
  ``n_i`` the distance normal (:func:`linearised_clearance`; the broad phase
  :class:`BodyDistance` says which); the sign is the body's inside test
  (:mod:`hairport.solver.mesh.collision`), so the half-space of a particle inside pushes it out;
* the l1 clearance violation of the line search's merit (:func:`clearance_violation`);
* the push-out of particles short of the clearance when the iteration cap stops the loop
  (:func:`push_out_short`): the result never breaks Eq. 13;
* the line search's distances without a query where a bound suffices (:class:`QueryAnchors`).

Convention: particles ``(N, 3) float64`` in meters; ``fixed (N,) bool`` marks the roots.
"""

from __future__ import annotations

import copy

import numpy as np

from hairport.solver.mesh.clearance import push_out
from hairport.solver.mesh.distance_grid import DistanceGrid
from hairport.solver.mesh.query import MeshQuery

_NOT_MADE = object()



class BodyDistance:
    """Signed distance to the target for the particles that can be near it or are inside it.

    Without a broad phase every particle gets an exact query. With a distance grid over the
    body, a particle gets one when it may be within ``band`` of the surface (the grid's lower
    bound of ``|distance|``) or when it may be inside: the grid proves it (a certain
    negative sign), cannot say (a closed body's grid is unsure only next to the surface), or,
    on a body whose grid knows no sign (an open one), the winding number says so
    (:attr:`~hairport.solver.mesh.query.MeshQuery.inside_test`). So every particle inside the body
    gets its Eq. 13 constraint whatever its depth. The others are far outside: distance
    ``inf``, a zero normal, and no constraint.

    The exact queries go through a cell cache of the query (:meth:`.MeshQuery.cell_cache`,
    :mod:`hairport.solver.mesh.cells`), kept for the life of this object: a solve asks about
    the same region every iteration, and a point in a cell seen before is answered from the
    cell's few candidate faces (the same result, but for ties).
    """

    def __init__(self, query: MeshQuery, band: float = np.inf, grid: DistanceGrid | None = None):
        self.query = query
        self.band = band
        self.grid = grid
        self._cells = _NOT_MADE  # the query's cell cache (None if its face search has none), made on the first call
        #: (N,) float64 or None: each particle's clearance beyond ``eps_c`` (m), see :meth:`with_margin`
        self.margin: np.ndarray | None = None

    def with_margin(self, margin: np.ndarray) -> "BodyDistance":
        """This distance less a clearance of each particle's own: ``margin (N,) float64`` (m, >= 0, below
        ``band``), over the particles of the solve it serves.

        A solve that keeps ``distance >= eps_c`` then keeps particle ``i`` at ``eps_c + margin[i]``
        from the body (:mod:`hairport.solver.adaptation.segments`). The shifted distance stays
        1-Lipschitz for each particle, so the line search's bounds (:class:`QueryAnchors`) hold. Its
        calls must say which particles they ask about (``rows``). The cell cache is shared.
        """
        if self._cells is _NOT_MADE:
            self._cells = self.query.cell_cache()
        shifted = copy.copy(self)
        shifted.margin = np.asarray(margin, dtype=np.float64)
        return shifted

    def _signed_distance(self, points: np.ndarray):
        if self._cells is _NOT_MADE:
            self._cells = self.query.cell_cache()
        return self.query.signed_distance(points, cells=self._cells)

    def __call__(self, points: np.ndarray, rows: np.ndarray | slice | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``points (N, 3)`` -> distance ``(N,)``, normal ``(N, 3)``, near ``(N,) bool``.

        ``rows``: the solve's particles these points are (indices or a slice; all of them, in order, when
        omitted); read only with a :meth:`with_margin`.
        """
        distance, normal, near = self._distance(points)
        if self.margin is not None:
            margin = self.margin if rows is None else self.margin[rows]
            if len(margin) != len(points):
                raise ValueError(f"{len(points)} points asked about with {len(margin)} particles' margins")
            distance = distance - margin
        return distance, normal, near

    def _distance(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = len(points)
        if self.grid is None:
            sd = self._signed_distance(points)
            return sd.distance, sd.normal, np.ones(n, dtype=bool)
        bound, sign = self.grid.bound_and_sign(points)
        near = (bound < self.band) | (sign < 0)
        unknown = np.flatnonzero(~near & (sign == 0))
        if len(unknown):
            # at least ``band`` from the surface: the winding number alone decides (a plain
            # query over an open mesh has none: all of them are queried)
            test = self.query.inside_test
            near[unknown] = True if test is None else test.inside(points[unknown])
        distance = np.full(n, np.inf)
        normal = np.zeros((n, 3))
        if near.any():
            sd = self._signed_distance(points[near])
            distance[near] = sd.distance
            normal[near] = sd.normal
        return distance, normal, near


def fixed_coordinates(fixed: np.ndarray) -> np.ndarray:
    """Eq. 12: every coordinate of a root is held where it is (a QP step is zero there).

    Parameters
    ----------
    fixed : (N,) bool

    Returns
    -------
    pinned : (N, 3) bool
        A new array.
    """
    return np.repeat(np.asarray(fixed, dtype=bool)[:, None], 3, axis=1)


def free_coordinates(fixed: np.ndarray) -> np.ndarray:
    """Eq. 12 for a QP whose unknowns are the free coordinates only.

    Parameters
    ----------
    fixed : (N,) bool

    Returns
    -------
    columns : (3 F,) int64
        Their indices ``3 i + c`` in a particle-major ``(3 N,)`` vector, ascending (``F`` free particles).
    """
    return np.flatnonzero(~fixed_coordinates(fixed).ravel())


def linearised_clearance(
    distance: np.ndarray, eps_c: float, fixed: np.ndarray | None = None, near: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 13 linearised at the iterate: a step ``d`` keeps ``<n_i, d_i> >= eps_c - s_i``.

    With the closest point and normal frozen at the iterate, Eq. 13's ``<p_i + d_i - q_i, n_i> >= eps_c``
    is this half-space on particle ``i``'s step (``s_i = <p_i - q_i, n_i>``); a particle already
    inside has ``s_i < 0`` and must move out by more than ``eps_c``. Roots carry none (Eq. 12),
    nor do particles the broad phase puts far from the body.

    Parameters
    ----------
    distance : (N,) float64
        ``s_i``, signed distance to the target (m).
    eps_c : float
        Clearance (m).
    fixed : (N,) bool, optional
        Roots; none by default.
    near : (N,) bool, optional
        Particles that can be near the body (:class:`BodyDistance`); all by default.

    Returns
    -------
    constrained : (N,) bool
        Particles with a half-space: free and near.
    lower : (N,) float64
        ``eps_c - s_i`` (m).
    """
    constrained = np.ones(len(distance), dtype=bool) if near is None else np.asarray(near, dtype=bool)
    if fixed is not None:
        constrained = constrained & ~fixed
    return constrained, eps_c - distance


def clearance_violation(distance: np.ndarray, eps_c: float, fixed: np.ndarray | None = None) -> np.ndarray:
    """Per particle, how far (m) it is short of Eq. 13's clearance: the l1 term of the line search's merit.

    Parameters
    ----------
    distance : (N,) float64
        Signed distance to the target (m); ``inf`` for particles far from it.
    eps_c : float
    fixed : (N,) bool, optional
        Roots, which are never short (Eq. 12).

    Returns
    -------
    violation : (N,) float64
        ``max(eps_c - distance, 0)``, 0 at roots.
    """
    short = np.maximum(eps_c - distance, 0.0)
    return short if fixed is None else np.where(fixed, 0.0, short)


def push_out_short(
    points: np.ndarray, fixed: np.ndarray, distance: np.ndarray, query: MeshQuery, eps_c: float, tolerance: float,
    margin: np.ndarray | None = None,
) -> tuple[np.ndarray, int]:
    """Eq. 13 made to hold when the iteration cap stopped the loop.

    A loop stopped by its cap, possibly after a shortened step, may leave some free particle
    short of its clearance: then every free particle closer than ``eps_c`` goes out along the
    distance normal (:func:`~hairport.solver.mesh.clearance.push_out`); the result never breaks Eq. 13.

    Parameters
    ----------
    points : (N, 3) float64
    fixed : (N,) bool
    distance : (N,) float64
        Signed distance of ``points`` to the target (m); rows of fixed particles unused.
    query : MeshQuery
        The target body.
    eps_c : float
    tolerance : float
        A particle counts as short below ``eps_c - tolerance`` (m).
    margin : (N,) float64, optional
        Each particle's clearance beyond ``eps_c`` (:meth:`BodyDistance.with_margin`; ``distance`` is
        then less it too).

    Returns
    -------
    points : (N, 3) float64
        ``points`` itself when no particle is short, else a new array.
    pushed : int
        Particles that were short.
    """
    pushed = int(np.sum((distance < eps_c - tolerance) & ~fixed))
    if pushed:
        points = push_out(points, fixed, query, eps_c if margin is None else eps_c + margin)
    return points, pushed


class QueryAnchors:
    """Each particle's last exact distance query, to bound its distance at a trial point without one.

    The signed distance is 1-Lipschitz: a point ``x`` at ``delta`` from the anchor ``a`` of its
    particle (where the query gave ``s``) has distance at least ``s - delta``. Where that bound
    is at least ``eps_c + margin`` the line search asks no query: the merit's clearance
    violation is 0 there, and the iterate keeps the bound as its distance with the anchor's
    normal (``bounded``). Such a particle's Eq. 13 half-space in the next QP is slack by more
    than ``margin``, as the exact one is; when the QP's step of every bounded particle stays
    shorter than its slack (``distance - eps_c``), both half-spaces are inactive at that step and
    it is the exact QP's solution too (a convex QP's KKT point does not depend on inactive
    constraints). A strand with a step that reaches the slack gets exact queries for its bounded
    particles and its QP solved again (:func:`reaching`). Particles the broad phase put far from
    the body (``near`` False, distance ``inf``) are always asked again.

    Parameters
    ----------
    points : (N, 3) float64
        The positions of the first query ...
    distance : (N,) float64
    normal : (N, 3) float64
    near : (N,) bool
        ... and its results (:class:`BodyDistance`); copied.

    Attributes
    ----------
    bounded : (N,) bool
        Particles whose iterate's distance is a bound, not a query.
    """

    def __init__(self, points: np.ndarray, distance: np.ndarray, normal: np.ndarray, near: np.ndarray):
        self.points = np.array(points, dtype=np.float64)
        self.distance = np.array(distance, dtype=np.float64)
        self.normal = np.array(normal, dtype=np.float64)
        self.near = np.array(near, dtype=bool)
        self.bounded = np.zeros(len(self.points), dtype=bool)

    def trial_distance(self, distance: BodyDistance, moved: np.ndarray, particles: np.ndarray, eps_c: float,
                       margin: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Distances at the trial points ``moved (T, 3)`` of ``particles (T,) int64``.

        Returns
        -------
        distance : (T,) float64
            Exact where queried, else the bound ``s - delta``.
        normal : (T, 3) float64
            The query's, else the anchor's.
        near : (T,) bool
        queried : (T,) bool
            Which points got an exact query.
        """
        delta = np.sqrt(np.sum((moved - self.points[particles]) ** 2, axis=1))
        bound = self.distance[particles] - delta
        queried = ~(self.near[particles] & (bound >= eps_c + margin))
        d = np.where(queried, np.inf, bound)
        nrm = self.normal[particles].copy()
        nr = ~queried
        if queried.any():
            d[queried], nrm[queried], nr[queried] = distance(moved[queried], particles[queried])
        return d, nrm, nr, queried

    def commit(self, particles: np.ndarray, points: np.ndarray, distance: np.ndarray, normal: np.ndarray,
               near: np.ndarray, queried: np.ndarray) -> None:
        """``particles (T,)`` move to ``points (T, 3)``: the anchors of the ``queried (T,)`` ones
        with them (exact there), the others become bounded."""
        asked = particles[queried]
        self.points[asked] = points[queried]
        self.distance[asked] = distance[queried]
        self.normal[asked] = normal[queried]
        self.near[asked] = near[queried]
        self.bounded[particles] = ~queried

    def refresh(self, distance: BodyDistance, particles: np.ndarray,
                points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Exact queries of ``particles (T,)`` at their iterate ``points (T, 3)``, committed: ``(distance, normal, near)``."""
        d, nrm, nr = distance(points, particles)
        self.commit(particles, points, d, nrm, nr, np.ones(len(particles), dtype=bool))
        return d, nrm, nr


def reaching(step: np.ndarray, distance: np.ndarray, bounded: np.ndarray, eps_c: float) -> np.ndarray:
    """Bounded particles (:class:`QueryAnchors`) whose QP step ``(N, 3)`` is at least their slack ``distance - eps_c``: ``(N,) bool``."""
    length = np.sqrt(np.sum(step * step, axis=1))
    return bounded & (length >= distance - eps_c)
