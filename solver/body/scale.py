"""Length units of inputs that do not state them, inferred from sizes, and whether a groom fits a body.

A file without units metadata (OBJ, PLY, the hair formats other than ``.npz``) may be in
meters, decimeters, centimeters or millimeters: candidates a factor 10 apart. Two sizes
decide between them:

* the roots' bounding box (the scalp): its largest extent is 0.11-0.20 m on every MakeHuman
  character and the toy, and a human scalp is 0.12-0.25 m across; the plausible range
  :data:`SCALP_EXTENT_M` is narrower than a factor 10, so at most one candidate fits it;
* the body's largest extent: a head alone (~0.2 m) up to a tall adult in a T pose
  (:data:`BODY_EXTENT_M`), which settles grooms too small to say (a few strands).

Whether a groom belongs to a body, in whatever units, is measured without units: the median
distance of its roots to the body surface as a share of the scalp's extent
(:func:`root_fit_share`): 0.00-0.03 for a groom on its own body (roots on the skin or a few
mm off it), 0.3 for one sunk 6 cm into it, above 1 for one in other units.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.units import METERS_PER_UNIT

#: plausible largest extent (m) of the roots' bounding box: a partial groom (fringe, a
#: ponytail's base) of 6 cm up to a full scalp with sideburns and nape; narrower than a factor
#: 10, so that it picks one unit
SCALP_EXTENT_M = (0.06, 0.40)
#: plausible largest extent (m) of a character mesh: a head alone to a tall adult in a T pose
BODY_EXTENT_M = (0.15, 2.6)
#: a groom fits a body when the median distance of its roots to the body surface is at most
#: this share of the scalp's extent (roots on the skin: ~0; sunk 6 cm: 0.3; other units: > 1)
FIT_MAX_SHARE = 0.5
#: a unit named as the likely one must fit at least this well (median root distance share)
CLEAR_FIT_SHARE = 0.1
#: at most this many roots (evenly spaced) are measured for the fit
FIT_SAMPLE_ROOTS = 2000
#: with fewer roots than this, or all at one point, the scalp's extent says nothing: the body's
#: extent times this share stands in for it
MIN_SCALP_ROOTS = 3
BODY_SHARE_OF_SCALP = 0.1
#: distinct rows are first looked for among this many leading rows (a groom's first roots
#: differ), before a pass over all of them
DISTINCT_PREFIX_ROWS = 64


@dataclass(frozen=True)
class UnitsGuess:
    """Units inferred from sizes, and the sizes.

    Attributes
    ----------
    units : str
    body_extent, scalp_extent : float
        Largest bounding-box extent of the body and of the roots, in file units.
    plausible : bool
        Both sizes fall in their plausible ranges in ``units``.
    """

    units: str
    body_extent: float
    scalp_extent: float
    plausible: bool

    def describe(self) -> str:
        scale = METERS_PER_UNIT[self.units]
        return (f"in {self.units} the body is {self.body_extent * scale:.2f} m and the scalp "
                f"{self.scalp_extent * scale:.2f} m across")


def largest_extent(points: np.ndarray) -> float:
    """The largest side of the bounding box of (n, 3) points (0 for none)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if not len(points):
        return 0.0
    # one reduction per column: numpy's reduction of an (n, 3) array along its first axis took
    # 17 times as long at 10^6 points (min and max are exact in any order: the same extent)
    return float(np.max([np.ptp(points[:, axis]) for axis in range(3)]))


def distinct_rows(points: np.ndarray, limit: int) -> int:
    """How many distinct rows ``points`` holds, counted up to ``limit``.

    The same count as ``min(len(np.unique(points, axis=0)), limit)`` (rows equal when every
    coordinate compares equal: ``-0.0`` equals ``0.0``, a row with a NaN equals none), in
    ``limit`` passes over the rows instead of a sort of them: the fit is measured at several
    scales of 10^6 roots, where each sort took 0.6 s.

    Parameters
    ----------
    points : (N, 3) float
    limit : int
        Small (the passes are ``limit``).

    Returns
    -------
    count : int
        At most ``limit``.
    """
    points = np.asarray(points).reshape(-1, 3)
    if len(points) > DISTINCT_PREFIX_ROWS and distinct_rows(points[:DISTINCT_PREFIX_ROWS], limit) == limit:
        return limit  # rows distinct among the first are distinct among all
    unseen = np.ones(len(points), dtype=bool)
    for count in range(limit):
        if not unseen.any():
            return count
        first = int(np.argmax(unseen))
        differs = np.zeros(len(points), dtype=bool)
        for axis in range(3):  # column by column: 8 times faster than a row-wise any
            differs |= points[:, axis] != points[first, axis]
        unseen &= differs
        unseen[first] = False  # a row with a NaN differs from itself: it counts once
    return limit


def log_outside(value: float, bounds: tuple[float, float]) -> float:
    """How far ``value`` lies outside ``bounds``, as a log ratio (0 inside)."""
    low, high = bounds
    if value <= 0:
        return np.inf
    return float(max(0.0, np.log(low / value), np.log(value / high)))


def units_from_sizes(body_vertices: np.ndarray, roots: np.ndarray) -> UnitsGuess:
    """The unit in which the body and its scalp (the roots) have plausible sizes.

    Parameters
    ----------
    body_vertices : (V, 3) float64
        In file units.
    roots : (S, 3) float64
        In the same units.

    Returns
    -------
    guess : UnitsGuess
        The unit whose sizes lie least outside :data:`SCALP_EXTENT_M` and
        :data:`BODY_EXTENT_M` (summed log ratios; ties: the scalp nearer the middle of its range).
    """
    body = largest_extent(body_vertices)
    scalp = largest_extent(roots)
    use_scalp = distinct_rows(np.asarray(roots).reshape(-1, 3), MIN_SCALP_ROOTS) >= MIN_SCALP_ROOTS and scalp > 0
    middle = np.sqrt(SCALP_EXTENT_M[0] * SCALP_EXTENT_M[1])

    def cost(units: str) -> tuple[float, float]:
        scale = METERS_PER_UNIT[units]
        scalp_cost = log_outside(scalp * scale, SCALP_EXTENT_M) if use_scalp else 0.0
        tie = abs(np.log(scalp * scale / middle)) if use_scalp else abs(np.log(body * scale))
        return scalp_cost + log_outside(body * scale, BODY_EXTENT_M), tie

    best = min(METERS_PER_UNIT, key=cost)
    return UnitsGuess(best, body, scalp, cost(best)[0] == 0.0)


def root_fit_share(query: MeshQuery, roots: np.ndarray, relative_scale: float = 1.0) -> float:
    """Median distance of the roots to the body surface, as a share of the scalp's extent.

    Parameters
    ----------
    query : MeshQuery
        Over the body, in its own units.
    roots : (S, 3) float64
        In the hair's units.
    relative_scale : float
        Body units per hair unit (the roots are multiplied by it).

    Returns
    -------
    share : float
        Without units: ~0 for roots on the skin, above 1 when the groom is not on the body.
    """
    roots = np.asarray(roots, dtype=np.float64).reshape(-1, 3) * relative_scale
    if len(roots) == 0:
        return np.inf
    step = max(1, len(roots) // FIT_SAMPLE_ROOTS)
    sample = roots[::step]
    distance = np.abs(query.signed_distance(sample).distance)
    reference = largest_extent(roots)
    if distinct_rows(roots, MIN_SCALP_ROOTS) < MIN_SCALP_ROOTS or reference <= 0:
        reference = BODY_SHARE_OF_SCALP * largest_extent(query.vertices)
    return float(np.median(distance) / reference) if reference > 0 else np.inf


def relative_fits(query: MeshQuery, roots: np.ndarray, body_units: str) -> dict[str, float]:
    """:func:`root_fit_share` of the roots read in each unit, the body in ``body_units``.

    Returns
    -------
    shares : dict
        Unit of the hair -> share.
    """
    body_scale = METERS_PER_UNIT[body_units]
    return {units: root_fit_share(query, roots, scale / body_scale) for units, scale in METERS_PER_UNIT.items()}


def best_fit(shares: dict[str, float]) -> str | None:
    """The unit that fits clearly (share at most :data:`CLEAR_FIT_SHARE`, the smallest), or None."""
    units = min(shares, key=shares.get)
    return units if shares[units] <= CLEAR_FIT_SHARE else None


def units_from_ratio(ratio: float) -> str:
    """The unit whose meters-per-unit is nearest (in log) a measured ratio of sizes."""
    return min(METERS_PER_UNIT, key=lambda units: abs(np.log(METERS_PER_UNIT[units] / ratio)))
