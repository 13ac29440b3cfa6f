"""Compiled per-strand kernels of the uncoupled active-set loop (Eq. 14's fine level): the Newton model and its QP.

When ``K`` is diagonal every strand is its own problem (:mod:`.active_set`).
:func:`newton_qp_steps` does one strand's QP of an outer iteration in one pass over its
particles, a strand per ``prange`` iteration, with scratch arrays of the strand's size only:
Eq. 1's Newton model (:func:`.model_kernels.assemble_strand`, as :func:`.strand_problem.newton_system`:
Eq. 7's clamped exact blocks, Eq. 10's diagonal pull, Eq. 11, the radial damping), its
rotation into the contact frames of the constrained particles (:func:`contact_frame`,
:func:`rotate_strand`, as :class:`.contact_qp.Frames`), the primal-dual active-set rounds
(:func:`active_set_qp`, as :func:`.contact_qp.solve_qp`), each a banded Cholesky solve of
the pinned system (:mod:`.band_kernels`), then the step, the strand's merit penalty (its own
running maximum of the multipliers) and the model's predicted change. The line search's
kernels are :mod:`.line_search_kernels`'.

The numpy functions named above are the tested references. Strands are CSR runs
(``offsets (S+1,) int64``) of a chunk's particle arrays. Every setting the kernels read is
an argument: numba's on-disk cache does not notice a changed constant of another module.
"""

from __future__ import annotations

import numpy as np

from hairport.solver.adaptation.fine.band_kernels import (
    BAND_REACH,
    band_cholesky,
    band_solve,
    block_matvec,
    pinned_band,
)
from hairport.solver.adaptation.problem.model_kernels import assemble_strand, cross, normal_to, warm_strands
from hairport.solver.jit import kernel, parallel_kernel, prange, warms


@kernel
def contact_frame(normal, frame):
    """The rotation ``(3, 3)`` whose columns are the unit ``normal (3,)`` and two tangents (:func:`.contact_qp.normal_frames`)."""
    n0, n1, n2 = normal[0], normal[1], normal[2]
    t0, t1, t2 = normal_to(n0, n1, n2)
    t_norm = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    t0, t1, t2 = t0 / t_norm, t1 / t_norm, t2 / t_norm
    b0, b1, b2 = cross(n0, n1, n2, t0, t1, t2)
    frame[0, 0], frame[1, 0], frame[2, 0] = n0, n1, n2
    frame[0, 1], frame[1, 1], frame[2, 1] = t0, t1, t2
    frame[0, 2], frame[1, 2], frame[2, 2] = b0, b1, b2


@kernel
def _left_transposed(frame, block, out):
    """``out = frame^T block``."""
    for a in range(3):
        for b in range(3):
            out[a, b] = frame[0, a] * block[0, b] + frame[1, a] * block[1, b] + frame[2, a] * block[2, b]


@kernel
def _right(block, frame, out):
    """``out = block frame``."""
    for a in range(3):
        for b in range(3):
            out[a, b] = block[a, 0] * frame[0, b] + block[a, 1] * frame[1, b] + block[a, 2] * frame[2, b]


@kernel
def rotate_strand(rotated, frames, diagonal, upper, gradient):
    """``R^T H R`` and ``R^T g`` in place, ``R_i`` = ``frames[i]`` where ``rotated[i]`` (identity elsewhere).

    Parameters
    ----------
    rotated : (m,) bool
    frames : (m, 3, 3) float64
    diagonal, upper : (m, 3, 3) float64
    gradient : (m, 3) float64
    """
    m = len(rotated)
    work = np.empty((3, 3))
    for i in range(m):
        if rotated[i]:
            _left_transposed(frames[i], diagonal[i], work)
            _right(work, frames[i], diagonal[i])
            g0, g1, g2 = gradient[i, 0], gradient[i, 1], gradient[i, 2]
            for a in range(3):
                gradient[i, a] = frames[i, 0, a] * g0 + frames[i, 1, a] * g1 + frames[i, 2, a] * g2
        if i + 1 < m:
            if rotated[i]:
                _left_transposed(frames[i], upper[i], work)
                upper[i] = work
            if rotated[i + 1]:
                _right(upper[i], frames[i + 1], work)
                upper[i] = work


@kernel
def active_set_qp(diagonal, upper, gradient, fixed, constrained, lower, active, max_rounds, step, multipliers):
    """:func:`.contact_qp.solve_qp` of one strand, in its contact frames (rotated ``H'``, ``g'``).

    Parameters
    ----------
    diagonal, upper : (m, 3, 3) float64
        ``R^T H R``.
    gradient : (m, 3) float64
        ``R^T g``.
    fixed, constrained : (m,) bool
    lower : (m,) float64
        ``eps_c - s_i`` (rows of unconstrained particles unused).
    active : (m,) bool
        The previous active set in, this one's out.
    max_rounds : int
    step : (m, 3) float64
        Receives ``y`` (the step in the contact frames).
    multipliers : (m,) float64
        Receives the multipliers (0 off the active set).

    Returns
    -------
    rounds : int
        Active-set rounds, or -1 if a pinned system was not positive definite.
    """
    m = len(fixed)
    pinned = np.empty((m, 3), dtype=np.bool_)
    values = np.zeros(m)
    for i in range(m):
        pinned[i, 1] = fixed[i]
        pinned[i, 2] = fixed[i]
        active[i] = active[i] and constrained[i] and not fixed[i]
        if constrained[i]:
            values[i] = lower[i]
    band = np.empty((3 * m, BAND_REACH + 1))
    start = np.zeros(m)  # the pinned first unknowns' values: only they are nonzero in the pinned start
    rhs = np.empty(3 * m)
    rounds = 0
    for rounds in range(1, max_rounds + 1):
        for i in range(m):
            pinned[i, 0] = fixed[i] or active[i]
            start[i] = values[i] if pinned[i, 0] else 0.0
        # rhs = -g - H start on the free unknowns (start has a first component only)
        for i in range(m):
            for a in range(3):
                if pinned[i, a]:
                    rhs[3 * i + a] = 0.0
                    continue
                product = diagonal[i, a, 0] * start[i]
                if i + 1 < m:
                    product += upper[i, a, 0] * start[i + 1]
                if i > 0:
                    product += upper[i - 1, 0, a] * start[i - 1]
                rhs[3 * i + a] = -gradient[i, a] - product
        pinned_band(diagonal, upper, pinned, band)
        if not band_cholesky(band):
            return -1
        band_solve(band, rhs)
        for i in range(m):
            step[i, 0] = start[i] + (0.0 if pinned[i, 0] else rhs[3 * i])
            for a in range(1, 3):
                step[i, a] = 0.0 if pinned[i, a] else rhs[3 * i + a]
        changed = False
        for i in range(m):
            if active[i]:  # (H y + g) of the first unknown
                product = diagonal[i, 0, 0] * step[i, 0] + diagonal[i, 0, 1] * step[i, 1] + diagonal[i, 0, 2] * step[i, 2]
                if i + 1 < m:
                    product += upper[i, 0, 0] * step[i + 1, 0] + upper[i, 0, 1] * step[i + 1, 1] + upper[i, 0, 2] * step[i + 1, 2]
                if i > 0:
                    product += upper[i - 1, 0, 0] * step[i - 1, 0] + upper[i - 1, 1, 0] * step[i - 1, 1] + upper[i - 1, 2, 0] * step[i - 1, 2]
                multipliers[i] = product + gradient[i, 0]
            else:
                multipliers[i] = 0.0
            next_active = (constrained[i] and not fixed[i]
                           and multipliers[i] + diagonal[i, 0, 0] * (values[i] - step[i, 0]) > 0)
            if next_active != active[i]:
                changed = True
                active[i] = next_active
        if not changed:
            break
    return rounds


@parallel_kernel
def newton_qp_steps(strands, offsets, points, distance, normal, near, source_directions, initial, pull_weight,
                    features, gamma, rest_lengths, fixed, alpha, beta, spacing, spacing_low, spacing_high, eps_c, damping,
                    penalty, active, step, rounds, predicted, min_length, weld_length, curvature_share, parallel_sine,
                    penalty_factor, max_rounds):
    """One outer iteration's QP of every listed strand: the step, the raised merit penalty, the model's change.

    Parameters
    ----------
    strands : (T,) int64
        Strands to step (the open ones).
    offsets : (S+1,) int64
    points, normal : (N, 3) float64
        The iterate and the distance normals.
    distance : (N,) float64
        Signed distance (``inf`` far from the body).
    near : (N,) bool
        Particles that get a linearised Eq. 13 half-space (:func:`.constraints.linearised_clearance`).
    source_directions, initial, features : (N, 3) float64
    pull_weight, gamma, rest_lengths : (N,) float64
    fixed : (N,) bool
    alpha, beta, spacing, spacing_low, spacing_high, eps_c : float
    damping : (S,) float64
        Radial damping per strand.
    penalty : (S,) float64
        Each strand's merit penalty, raised in place to ``penalty_factor`` times its largest multiplier.
    active : (N,) bool
        Active constraints, updated in place.
    step : (N, 3) float64
        Receives the listed strands' steps.
    rounds : (T,) int64
        Receives the active-set rounds (-1: a pinned system was not positive definite).
    predicted : (T,) float64
        Receives the quadratic model's change along the step.
    min_length, weld_length, curvature_share, parallel_sine, penalty_factor : float
    max_rounds : int
    """
    for t in prange(len(strands)):
        s = strands[t]
        first = offsets[s]
        count = offsets[s + 1] - first
        diagonal = np.empty((count, 3, 3))
        upper = np.empty((count, 3, 3))
        gradient = np.empty((count, 3))
        assemble_strand(first, count, points, source_directions, initial, pull_weight, features, gamma, rest_lengths,
                        alpha, beta, spacing, spacing_low, spacing_high, damping[s], min_length, weld_length,
                        curvature_share, parallel_sine, diagonal, upper, gradient)
        constrained = np.empty(count, dtype=np.bool_)
        frames = np.empty((count, 3, 3))
        lower = np.empty(count)
        for j in range(count):
            i = first + j
            constrained[j] = near[i] and not fixed[i]
            lower[j] = eps_c - distance[i]
            if constrained[j]:
                contact_frame(normal[i], frames[j])
        rotate_strand(constrained, frames, diagonal, upper, gradient)
        local_active = active[first:first + count].copy()
        y = np.empty((count, 3))
        multipliers = np.empty(count)
        rounds[t] = active_set_qp(diagonal, upper, gradient, fixed[first:first + count], constrained, lower,
                                  local_active, max_rounds, y, multipliers)
        product = np.empty((count, 3))
        block_matvec(diagonal, upper, y, product)
        change = 0.0
        largest = 0.0
        for j in range(count):
            i = first + j
            active[i] = local_active[j]
            largest = max(largest, abs(multipliers[j]))
            for a in range(3):
                change += y[j, a] * (gradient[j, a] + 0.5 * product[j, a])
            if constrained[j]:
                for a in range(3):
                    step[i, a] = frames[j, a, 0] * y[j, 0] + frames[j, a, 1] * y[j, 1] + frames[j, a, 2] * y[j, 2]
            else:
                for a in range(3):
                    step[i, a] = y[j, a]
        predicted[t] = change
        penalty[s] = max(penalty[s], penalty_factor * largest)


@warms
def _warm() -> None:
    """:func:`.model_kernels.warm_strands` through every kernel."""
    offsets, points, fixed, distance = warm_strands()
    n = len(points)
    directions = np.tile([0.0, -1.0, 0.0], (n, 1))
    normal = np.zeros((n, 3))
    normal[:, 0] = 1.0
    near = np.isfinite(distance)
    newton_qp_steps(np.arange(2, dtype=np.int64), offsets, points, distance, normal, near, directions, points,
                    np.ones(n), points, np.ones(n), np.full(n, 0.004), fixed, 3e3, 1e3, 1.0, 0.9, 1.1, 5e-4, np.ones(2), np.zeros(2),
                    np.zeros(n, dtype=np.bool_), np.zeros((n, 3)), np.zeros(2, dtype=np.int64), np.zeros(2),
                    1e-9, 1e-6, 0.2, 1e-12, 2.0, 50)
