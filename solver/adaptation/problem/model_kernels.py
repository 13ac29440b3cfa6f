"""Compiled Newton model of Eq. 1 per strand (:func:`.strand_problem.newton_system` is the numpy reference).

:func:`assemble_strand` builds one strand's strand-banded blocks and gradient with a diagonal ``K``: the fine
level's per-strand QPs use it (:mod:`..fine.strand_kernels`); :func:`assemble_strands` runs it over all strands
of a coupled problem, whose ``K`` terms are then added by sparse products (:func:`.strand_problem.compiled_newton_system`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from hairport.solver.adaptation.problem.spacing import band_excess
from hairport.solver.jit import kernel, parallel_kernel, prange, warms


@kernel
def cross(a0, a1, a2, b0, b1, b2):
    """``a x b`` of two vectors given by their components."""
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@kernel
def normal_to(v0, v1, v2):
    """A vector normal to ``v``: ``v x e_k`` with ``k`` its smallest component (numpy's argmin: the first on ties)."""
    k = 0
    if abs(v1) < abs(v0):
        k = 1
    if abs(v2) < abs(v1 if k == 1 else v0):
        k = 2
    if k == 0:
        return cross(v0, v1, v2, 1.0, 0.0, 0.0)
    if k == 1:
        return cross(v0, v1, v2, 0.0, 1.0, 0.0)
    return cross(v0, v1, v2, 0.0, 0.0, 1.0)


@kernel
def _clamped_block(u0, u1, u2, d0, d1, d2, floor, parallel_sine, out):
    """:func:`clamped_direction_hessian` on components (no array is allocated)."""
    c = u0 * d0 + u1 * d1 + u2 * d2
    e0, e1, e2 = d0 - c * u0, d1 - c * u1, d2 - c * u2
    s = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    if s < parallel_sine:
        e0, e1, e2 = normal_to(u0, u1, u2)
    e_norm = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    if e_norm > 0:  # 0 only where u and d both are (a welded segment at zero length, never assembled)
        e0, e1, e2 = e0 / e_norm, e1 / e_norm, e2 / e_norm
    w0, w1, w2 = cross(u0, u1, u2, e0, e1, e2)
    low = 0.5 * (c - np.sqrt(c * c + 4.0 * s * s))
    q0, q1, q2 = s * u0 + low * e0, s * u1 + low * e1, s * u2 + low * e2
    q_norm = np.sqrt(q0 * q0 + q1 * q1 + q2 * q2)
    if q_norm > 0:
        q0, q1, q2 = q0 / q_norm, q1 / q_norm, q2 / q_norm
    else:
        q0, q1, q2 = e0, e1, e2
    raise_low = max(low, -floor) - low
    raise_w = max(c, -floor) - c
    u = (u0, u1, u2)
    d = (d0, d1, d2)
    q = (q0, q1, q2)
    w = (w0, w1, w2)
    for a in range(3):
        for b in range(3):
            identity = 1.0 if a == b else 0.0
            exact = (u[a] * d[b] + u[b] * d[a]) + c * (identity - 3.0 * u[a] * u[b])
            out[a, b] = (exact + raise_low * q[a] * q[b]) + raise_w * w[a] * w[b]


@kernel
def clamped_direction_hessian(unit, direction, floor, parallel_sine, out):
    """One block of :func:`.energies.clamped_direction_hessians`.

    Parameters
    ----------
    unit, direction : (3,) float64
        ``u`` and ``d``.
    floor : float
        Eigenvalues below ``-floor`` are raised to it.
    parallel_sine : float
        :data:`.energies.PARALLEL_SINE`.
    out : (3, 3) float64
        Receives the block.
    """
    _clamped_block(unit[0], unit[1], unit[2], direction[0], direction[1], direction[2], floor, parallel_sine, out)


@kernel
def assemble_strand(first, count, points, source_directions, initial, pull_weight, features, gamma, rest_lengths,
                    alpha, beta, spacing, spacing_low, spacing_high, damping, min_length, weld_length, curvature_share,
                    parallel_sine, diagonal, upper, gradient):
    """One strand's Newton model of Eq. 1 and the spacing term (:func:`.strand_problem.newton_system` with
    ``K = diag(pull_weight)``).

    Parameters
    ----------
    first, count : int
        The strand's first particle and particle count.
    points, source_directions, initial, features : (N, 3) float64
        The chunk's arrays.
    pull_weight, gamma : (N,) float64
    rest_lengths : (N,) float64
        The spacing term's rest lengths (0: no term; unread, and any length, when ``spacing`` is 0).
    alpha, beta, spacing : float
        Eq. 1's weights and the spacing term's.
    spacing_low, spacing_high : float
        The spacing term's free band of ``l / t`` (:func:`.spacing.band_excess`).
    damping : float
        The strand's radial damping.
    min_length, weld_length, curvature_share, parallel_sine : float
        :data:`.polyline.MIN_SEGMENT_LENGTH`, :data:`.energies.WELD_LENGTH_M` (the spring of a welded
        segment: one whose source direction is 0), :data:`.energies.NEGATIVE_CURVATURE_SHARE`,
        :data:`.energies.PARALLEL_SINE`.
    diagonal, upper : (count, 3, 3) float64
        Receive the blocks (``upper[i]``: particles ``i, i+1``; the last one zero).
    gradient : (count, 3) float64
        Receives the gradient.
    """
    diagonal[:] = 0.0
    upper[:] = 0.0
    gradient[:] = 0.0
    block = np.empty((3, 3))
    for j in range(count - 1):
        i = first + j
        e0 = points[i + 1, 0] - points[i, 0]
        e1 = points[i + 1, 1] - points[i, 1]
        e2 = points[i + 1, 2] - points[i, 2]
        d = (source_directions[i, 0], source_directions[i, 1], source_directions[i, 2])
        if d[0] == 0.0 and d[1] == 0.0 and d[2] == 0.0:  # welded: || e ||^2 / w^2 (.energies.shape_values)
            stiffness = 2.0 / (weld_length * weld_length)
            e = (e0, e1, e2)
            for a in range(3):
                diagonal[j, a, a] += stiffness
                diagonal[j + 1, a, a] += stiffness
                upper[j, a, a] = -stiffness
                gradient[j, a] -= stiffness * e[a]
                gradient[j + 1, a] += stiffness * e[a]
            continue
        length = max(np.sqrt(e0 * e0 + e1 * e1 + e2 * e2), min_length)
        unit = (e0 / length, e1 / length, e2 / length)
        cosine = unit[0] * d[0] + unit[1] * d[1] + unit[2] * d[2]
        floor = curvature_share * beta * min(gamma[i], gamma[i + 1]) * length**2
        _clamped_block(unit[0], unit[1], unit[2], d[0], d[1], d[2], floor, parallel_sine, block)
        rest = rest_lengths[i] if spacing != 0.0 else 0.0  # unread without the term (may be a stub)
        radial, tangential, pull = 0.0, 0.0, 0.0  # the spacing term's Hessian and gradient factors
        if rest > 0.0:
            excess = band_excess(length / rest, spacing_low, spacing_high)
            if excess != 0.0:
                tangential = 2.0 * spacing * (max(excess, 0.0) / (rest * length))
                radial = 2.0 * spacing / (rest * rest) - tangential
                pull = 2.0 * spacing * (excess / rest)
        for a in range(3):
            for b in range(3):
                value = 2.0 * (block[a, b] + damping * unit[a] * unit[b]) / length**2
                value += radial * unit[a] * unit[b] + (tangential if a == b else 0.0)
                diagonal[j, a, b] += value
                diagonal[j + 1, a, b] += value
                upper[j, a, b] = -value
            shape_residual = 2.0 * ((unit[a] * cosine - d[a]) / length) + pull * unit[a]
            gradient[j, a] -= shape_residual
            gradient[j + 1, a] += shape_residual
    for j in range(count):
        i = first + j
        w = pull_weight[i]
        g = gamma[i]
        stiffness = 2.0 * alpha * (w * g * w) + 2.0 * beta * g
        for a in range(3):
            diagonal[j, a, a] += stiffness
            gradient[j, a] += 2.0 * alpha * (w * (g * (w * points[i, a] - features[i, a])))
            gradient[j, a] += 2.0 * beta * g * (points[i, a] - initial[i, a])


@parallel_kernel
def assemble_strands(offsets, points, source_directions, initial, gamma, rest_lengths, beta, spacing, spacing_low,
                     spacing_high, damping, min_length, weld_length, curvature_share, parallel_sine, diagonal, upper,
                     gradient):
    """:func:`assemble_strand` of every strand with no pull (``K`` = 0), a strand per ``prange`` iteration.

    Parameters
    ----------
    offsets : (S+1,) int64
    points, source_directions, initial : (N, 3) float64
    gamma, rest_lengths : (N,) float64
    beta, spacing, spacing_low, spacing_high, min_length, weld_length, curvature_share, parallel_sine : float
    damping : (S,) float64
        Each strand's radial damping.
    diagonal, upper : (N, 3, 3) float64
    gradient : (N, 3) float64
        Receive the blocks and the gradient.
    """
    n = len(points)
    no_pull = np.zeros(n)
    for s in prange(len(offsets) - 1):
        first, stop = offsets[s], offsets[s + 1]
        assemble_strand(first, stop - first, points, source_directions, initial, no_pull, points, gamma,
                        rest_lengths, 0.0, beta, spacing, spacing_low, spacing_high, damping[s], min_length,
                        weld_length, curvature_share, parallel_sine, diagonal[first:stop], upper[first:stop],
                        gradient[first:stop])


class WarmStrands(NamedTuple):
    """Two tiny strands (3 and 2 particles, rooted, the first touching the body) the per-strand kernels'
    warmers run on: ``offsets (3,) int64``, ``points (5, 3)``, ``fixed (5,) bool``, ``distance (5,)``."""

    offsets: np.ndarray
    points: np.ndarray
    fixed: np.ndarray
    distance: np.ndarray


def warm_strands() -> WarmStrands:
    """:class:`WarmStrands`, new arrays."""
    return WarmStrands(np.array([0, 3, 5], dtype=np.int64),
                       np.array([[0.0, 0.0, 0.0], [0.0, -0.004, 0.0], [0.001, -0.008, 0.0],
                                 [0.01, 0.0, 0.0], [0.01, -0.004, 0.001]]),
                       np.array([True, False, False, True, False]), np.array([0.0, 1e-4, np.inf, 0.0, np.inf]))


@warms
def _warm() -> None:
    """:func:`warm_strands` through :func:`assemble_strands`."""
    offsets, points, _, _ = warm_strands()
    n = len(points)
    assemble_strands(offsets, points, np.tile([0.0, -1.0, 0.0], (n, 1)), points, np.ones(n), np.full(n, 0.004),
                     1e3, 1.0, 0.9, 1.1, np.ones(2), 1e-9, 1e-6, 0.2, 1e-12, np.zeros((n, 3, 3)), np.zeros((n, 3, 3)),
                     np.zeros((n, 3)))
