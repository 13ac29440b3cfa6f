"""Compiled kernels of the uncoupled loop's line search (:mod:`.fine_solve`): trial points, commits (the merits
are :mod:`~hairport.solver.adaptation.problem.merit_kernels`').

* :func:`gather_trial_points`: the trial points ``p + fraction * step`` of the strands still
  backtracking, packed back to back for one batched distance query;
* :func:`commit_trial_points`: the accepted ones written back with their step length and
  clearance, and :func:`strand_clearances`: the clearance of strands that stay;
* :func:`bound_trial_distances`, :func:`commit_anchors`, :func:`reaching_strands`: the trial
  points' distance bounds from each particle's last exact query, the anchors moved, and the
  strands whose QP step reaches a bounded particle's slack (:class:`.constraints.QueryAnchors`,
  their numpy reference).

A "packed" array holds the rows of a list of strands back to back (``packed_offsets (T+1,)
int64``). These kernels are serial: a few passes over memory cost less than waking a second
thread, whose barrier on a busy machine can wait a scheduler quantum (measured at 10^5
particles on two shared cores: 0.2 s in all serial, 2-3 s in parallel).
"""

from __future__ import annotations

import numpy as np

from hairport.solver.adaptation.problem.model_kernels import warm_strands
from hairport.solver.jit import kernel, warms


@kernel
def gather_trial_points(strands, offsets, packed_offsets, points, step, fraction, fixed, moved, free):
    """The listed strands' trial points ``p + fraction * step``, packed.

    Parameters
    ----------
    strands : (T,) int64
    offsets : (S+1,) int64
    packed_offsets : (T+1,) int64
    points, step : (N, 3) float64
    fraction : (T,) float64
        Step length per listed strand.
    fixed : (N,) bool
    moved : (P, 3) float64
        Receives the trial points.
    free : (P,) bool
        Receives ``~fixed`` of those rows.
    """
    for t in range(len(strands)):
        first = offsets[strands[t]]
        for j in range(packed_offsets[t + 1] - packed_offsets[t]):
            r = packed_offsets[t] + j
            for a in range(3):
                moved[r, a] = points[first + j, a] + fraction[t] * step[first + j, a]
            free[r] = not fixed[first + j]


@kernel
def commit_trial_points(strands, offsets, packed_offsets, take, moved, moved_distance, moved_normal, moved_near,
                        fixed, eps_c, points, distance, normal, near, max_step, shortfall, min_clearance):
    """Write the trial points of the strands that ``take (T,) bool`` says into the chunk's arrays.

    Parameters
    ----------
    strands : (T,) int64
    offsets : (S+1,) int64
    packed_offsets : (T+1,) int64
    take : (T,) bool
    moved, moved_normal : (P, 3) float64
    moved_distance : (P,) float64
    moved_near : (P,) bool
    fixed : (N,) bool
    eps_c : float
    points, normal : (N, 3) float64
    distance : (N,) float64
    near : (N,) bool
        Updated in place for the taken strands.
    max_step, shortfall, min_clearance : (T,) float64
        Receive, per taken strand, the longest particle move (m), the largest ``eps_c - distance``
        of a free particle (-inf without one), and the smallest distance of a free particle (inf without one).
    """
    for t in range(len(strands)):
        if not take[t]:
            continue
        first = offsets[strands[t]]
        longest = 0.0
        short = -np.inf
        closest = np.inf
        for j in range(packed_offsets[t + 1] - packed_offsets[t]):
            r = packed_offsets[t] + j
            i = first + j
            e0 = moved[r, 0] - points[i, 0]
            e1 = moved[r, 1] - points[i, 1]
            e2 = moved[r, 2] - points[i, 2]
            longest = max(longest, np.sqrt(e0 * e0 + e1 * e1 + e2 * e2))
            if not fixed[i]:
                short = max(short, eps_c - moved_distance[r])
                closest = min(closest, moved_distance[r])
            for a in range(3):
                points[i, a] = moved[r, a]
                normal[i, a] = moved_normal[r, a]
            distance[i] = moved_distance[r]
            near[i] = moved_near[r]
        max_step[t] = longest
        shortfall[t] = short
        min_clearance[t] = closest


@kernel
def bound_trial_distances(strands, offsets, packed_offsets, moved, anchor_points, anchor_distance, anchor_normal,
                          anchor_near, least, distance, normal, near, queried):
    """Per packed trial point: the bound ``s - delta`` from its particle's anchor where it is at least ``least``, else a query is due.

    Parameters
    ----------
    strands : (T,) int64
    offsets : (S+1,) int64
    packed_offsets : (T+1,) int64
    moved : (P, 3) float64
        Packed trial points.
    anchor_points, anchor_normal : (N, 3) float64
    anchor_distance : (N,) float64
    anchor_near : (N,) bool
        Each particle's last exact query (:class:`.constraints.QueryAnchors`).
    least : float
        ``eps_c + margin`` (m).
    distance, normal, near, queried : (P,), (P, 3), (P,), (P,)
        Receive the bound, the anchor's normal and True where the bound suffices, and
        ``queried`` True (the others left as they are) where an exact query is due.
    """
    for t in range(len(strands)):
        first = offsets[strands[t]]
        for j in range(packed_offsets[t + 1] - packed_offsets[t]):
            r = packed_offsets[t] + j
            i = first + j
            e0 = moved[r, 0] - anchor_points[i, 0]
            e1 = moved[r, 1] - anchor_points[i, 1]
            e2 = moved[r, 2] - anchor_points[i, 2]
            bound = anchor_distance[i] - np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
            if anchor_near[i] and bound >= least:
                queried[r] = False
                distance[r] = bound
                near[r] = True
                for a in range(3):
                    normal[r, a] = anchor_normal[i, a]
            else:
                queried[r] = True


@kernel
def commit_anchors(strands, offsets, packed_offsets, take, queried, moved, moved_distance, moved_normal, moved_near,
                   anchor_points, anchor_distance, anchor_normal, anchor_near, bounded):
    """The strands that ``take (T,) bool`` says moved to their trial points: the anchors of the
    exactly ``queried`` ones move with them, the others become ``bounded (N,) bool``."""
    for t in range(len(strands)):
        if not take[t]:
            continue
        first = offsets[strands[t]]
        for j in range(packed_offsets[t + 1] - packed_offsets[t]):
            r = packed_offsets[t] + j
            i = first + j
            bounded[i] = not queried[r]
            if queried[r]:
                for a in range(3):
                    anchor_points[i, a] = moved[r, a]
                    anchor_normal[i, a] = moved_normal[r, a]
                anchor_distance[i] = moved_distance[r]
                anchor_near[i] = moved_near[r]


@kernel
def reaching_strands(strands, offsets, step, distance, bounded, eps_c, hit):
    """Per listed strand ``(T,)``: does the step of a bounded particle reach its slack ``distance - eps_c``
    (:func:`.constraints.reaching`)? Into ``hit (T,) bool``."""
    for t in range(len(strands)):
        reached = False
        for i in range(offsets[strands[t]], offsets[strands[t] + 1]):
            if bounded[i]:
                length = np.sqrt(step[i, 0] * step[i, 0] + step[i, 1] * step[i, 1] + step[i, 2] * step[i, 2])
                if length >= distance[i] - eps_c:
                    reached = True
        hit[t] = reached


@kernel
def strand_clearances(strands, offsets, distance, fixed, eps_c, shortfall, clearance):
    """Per listed strand ``(T,) int64``: the largest ``eps_c - distance`` of a free particle (-inf without one)
    into ``shortfall (T,)``, and the smallest distance of a free particle (inf without one) into ``clearance (T,)``."""
    for t in range(len(strands)):
        short = -np.inf
        closest = np.inf
        for i in range(offsets[strands[t]], offsets[strands[t] + 1]):
            if not fixed[i]:
                short = max(short, eps_c - distance[i])
                closest = min(closest, distance[i])
        shortfall[t] = short
        clearance[t] = closest


@warms
def _warm() -> None:
    """:func:`.model_kernels.warm_strands` through every kernel."""
    offsets, points, fixed, distance = warm_strands()
    n = len(points)
    normal = np.zeros((n, 3))
    normal[:, 0] = 1.0
    near = np.isfinite(distance)
    strands = np.arange(2, dtype=np.int64)
    moved, free = np.empty((n, 3)), np.empty(n, dtype=np.bool_)
    gather_trial_points(strands, offsets, offsets, points, np.zeros((n, 3)), np.ones(2), fixed, moved, free)
    commit_trial_points(strands, offsets, offsets, np.ones(2, dtype=np.bool_), moved, distance, normal, near, fixed,
                        5e-4, points.copy(), distance.copy(), normal.copy(), near.copy(), np.zeros(2), np.zeros(2),
                        np.zeros(2))
    strand_clearances(strands, offsets, distance, fixed, 5e-4, np.zeros(2), np.zeros(2))
    queried = np.empty(n, dtype=np.bool_)
    bound_trial_distances(strands, offsets, offsets, moved, points, distance, normal, near, 2.5e-3, distance.copy(),
                          normal.copy(), near.copy(), queried)
    bounded = np.zeros(n, dtype=np.bool_)
    commit_anchors(strands, offsets, offsets, np.ones(2, dtype=np.bool_), queried, moved, distance, normal, near,
                   points.copy(), distance.copy(), normal.copy(), near.copy(), bounded)
    reaching_strands(strands, offsets, np.zeros((n, 3)), distance, bounded, 5e-4, np.zeros(2, dtype=np.bool_))
