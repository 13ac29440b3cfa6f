"""Compiled merits of the active-set loop's line search: Eq. 1 plus a clearance penalty, per strand.

:func:`strand_merit` is one strand's :func:`.strand_problem.group_energies` (the numpy reference) with a
diagonal ``K`` (each particle pulled by ``pull_weight`` towards ``features``); a coupled ``K`` is the
same with ``pull_weight`` 0 and ``features`` the residual ``K p - L-bar`` at the points (:func:`strand_energies`).
Both levels' line searches use them: the fine level's strands (:mod:`..fine.fine_solve`) and the coupled
guides' per-strand merits (:mod:`..coupled.numpy_level`).
"""

from __future__ import annotations

import numpy as np

from hairport.solver.adaptation.problem.model_kernels import warm_strands
from hairport.solver.adaptation.problem.spacing import band_excess
from hairport.solver.jit import kernel, warms


@kernel
def strand_merit(first, count, points, distance, rows, source_directions, initial, pull_weight, features, gamma,
                 rest_lengths, fixed, alpha, beta, spacing, spacing_low, spacing_high, penalty, eps_c,
                 min_length, weld_length) -> float:
    """One strand's merit: Eq. 1 and the spacing term plus ``penalty`` times its clearance short of ``eps_c``
    (:func:`.strand_problem.group_energies`).

    Parameters
    ----------
    first, count : int
        The strand's first particle in the chunk's arrays and its particle count.
    points : (P, 3) float64
        Positions, the strand's at rows ``rows + j`` (the chunk's, or packed trial points).
    distance : (P,) float64
        Signed distances of those rows.
    rows : int
        The strand's first row in ``points`` and ``distance``.
    source_directions, initial, features : (N, 3) float64
    pull_weight, gamma, rest_lengths : (N,) float64
    fixed : (N,) bool
    alpha, beta, spacing, spacing_low, spacing_high, penalty, eps_c : float
    min_length, weld_length : float
        :data:`.polyline.MIN_SEGMENT_LENGTH`, :data:`.energies.WELD_LENGTH_M` (the spring of a welded
        segment: one whose source direction is 0).
    """
    total = 0.0
    for j in range(count):
        i = first + j
        r = rows + j
        value = 0.0
        if j + 1 < count:
            e0 = points[r + 1, 0] - points[r, 0]
            e1 = points[r + 1, 1] - points[r, 1]
            e2 = points[r + 1, 2] - points[r, 2]
            d = source_directions[i]
            if d[0] == 0.0 and d[1] == 0.0 and d[2] == 0.0:  # welded: || e ||^2 / w^2, no spacing term
                value = (e0 * e0 + e1 * e1 + e2 * e2) / (weld_length * weld_length)
            else:
                length = max(np.sqrt(e0 * e0 + e1 * e1 + e2 * e2), min_length)
                value = (e0 / length - d[0]) ** 2 + (e1 / length - d[1]) ** 2 + (e2 / length - d[2]) ** 2
                rest = rest_lengths[i] if spacing != 0.0 else 0.0  # unread without the term (may be a stub)
                if rest > 0.0:
                    value += spacing * band_excess(length / rest, spacing_low, spacing_high) ** 2
        w = pull_weight[i]
        inter = 0.0
        body = 0.0
        for a in range(3):
            inter += (w * points[r, a] - features[i, a]) ** 2
            body += (points[r, a] - initial[i, a]) ** 2
        value += alpha * gamma[i] * inter
        value += beta * gamma[i] * body
        if penalty > 0 and not fixed[i]:
            value += penalty * max(eps_c - distance[r], 0.0)
        total += value
    return total



@kernel
def strand_merits(strands, offsets, first_rows, positions, distance, source_directions, initial, pull_weight,
                  features, gamma, rest_lengths, fixed, alpha, beta, spacing, spacing_low, spacing_high, penalty, eps_c,
                  min_length, weld_length, merit):
    """The merit (:func:`strand_merit`) of each listed strand, at the iterate or at packed trial points.

    Parameters
    ----------
    strands : (T,) int64
    offsets : (S+1,) int64
    first_rows : (T,) int64
        Where each listed strand's rows start in ``positions`` and ``distance``: ``offsets[strands]``
        for the chunk's arrays, ``packed_offsets[:-1]`` for packed ones.
    positions : (P, 3) float64
    distance : (P,) float64
    source_directions, initial, features : (N, 3) float64
    pull_weight, gamma, rest_lengths : (N,) float64
    fixed : (N,) bool
    alpha, beta, spacing, spacing_low, spacing_high, eps_c, min_length, weld_length : float
    penalty : (S,) float64
        Each strand's clearance penalty.
    merit : (T,) float64
        Receives the merits.
    """
    for t in range(len(strands)):
        s = strands[t]
        merit[t] = strand_merit(offsets[s], offsets[s + 1] - offsets[s], positions, distance, first_rows[t],
                                source_directions, initial, pull_weight, features, gamma, rest_lengths, fixed,
                                alpha, beta, spacing, spacing_low, spacing_high, penalty[s], eps_c, min_length,
                                weld_length)


@warms
def _warm() -> None:
    """:func:`.model_kernels.warm_strands` through :func:`strand_merits`."""
    offsets, points, fixed, distance = warm_strands()
    n = len(points)
    strand_merits(np.arange(2, dtype=np.int64), offsets, offsets[:-1], points, distance,
                  np.tile([0.0, -1.0, 0.0], (n, 1)), points, np.ones(n), points, np.ones(n), np.full(n, 0.004), fixed,
                  3e3, 1e3, 1.0, 0.9, 1.1, np.ones(2), 5e-4, 1e-9, 1e-6, np.zeros(2))
