"""Shape carrying, beyond the paper: the anchored strands take their source shape back.

Eq. 2-3 anchor each particle on its own, so the anchored strands (Eq. 4-6 smooth only where
their Laplacian broke) follow the body's positions but not the source's directions: on the
MakeHuman pairs their mean segment angle to the source is 0.16-0.20 rad, and Eq. 11 then ties
the optimum to those directions (or, with the spacing term off, the solver slides particles
along their strands to escape them). Shape carrying replaces ``p-hat`` by the minimiser, per
strand with its root kept, of

    ``sum_s (ell / t_s)^2 || (q_b - q_a) - t_s d-bar_s ||^2 + sum_i || q_i - p-hat_i ||^2``

with ``d-bar`` the unit source directions and ``t`` the rest lengths (source lengths times the
strand's stretch, :func:`~hairport.solver.mesh.polyline.rest_lengths`): the source shape, scaled
with its strand, laid along the anchored strand and held to it over the length ``ell`` (m). Far
below ``ell`` a strand keeps its source shape, far above it the anchoring's positions. Directions
are carried unrotated: the MakeHuman bodies share one pose, and rotating them by the anchor
bone's or the surface normal's turn measured worse (``bench/fidelity.py``; docs/method.md).
A reflexive transfer is a fixed point (the source satisfies both sums exactly).

Each strand is a tridiagonal system (a Laplacian plus the identity, SPD), the same for x, y and z;
the strands lie back to back in one banded Cholesky solve.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from hairport.solver.mesh.polyline import rest_lengths
from hairport.solver.model.hair import DEGENERATE_SEGMENT_M

#: particles per banded solve (whole strands; bounds the temporaries, about 200 bytes a particle)
CARRY_CHUNK = 1 << 18

#: the default ``ell`` (m) of a retarget, measured by ``bench/fidelity.py`` over every ordered
#: MakeHuman pair and groom style (docs/fidelity.md): alone it lowers the mean segment angle on
#: all 150 (0.053 -> 0.037 rad), with the spacing term 0.043; 0.05 gave 0.043 alone, 0.2 raised
#: the inter-strand error by a fifth on fringes
CARRY_LENGTH_M = 0.1


def carry_shapes(anchored: np.ndarray, source_points: np.ndarray, offsets: np.ndarray, fixed: np.ndarray,
                 length: float) -> np.ndarray:
    """The anchored strands with their source shape carried over ``length`` (see the module's note).

    Parameters
    ----------
    anchored : (N, 3) float64
        ``p-hat`` from Eq. 2-6.
    source_points : (N, 3) float64
        ``p-bar``.
    offsets : (S+1,) int64
    fixed : (N,) bool
        Particles that keep their anchored place (roots, :attr:`~hairport.solver.model.hair.Hair.at_root`).
    length : float
        ``ell`` (m); 0 returns ``anchored`` unchanged.

    Returns
    -------
    carried : (N, 3) float64
    """
    if length <= 0:
        return anchored
    offsets = np.asarray(offsets, dtype=np.int64)
    fixed = np.asarray(fixed, dtype=bool)
    carried = np.empty((len(anchored), 3))
    first = 0
    while first < len(offsets) - 1:
        # strands are independent systems: a run of whole strands at a time gives the same rows
        stop = max(first + 1, int(np.searchsorted(offsets, offsets[first] + CARRY_CHUNK, side="right")) - 1)
        stop = min(stop, len(offsets) - 1)
        rows = slice(int(offsets[first]), int(offsets[stop]))
        carried[rows] = _carry_run(anchored[rows], source_points[rows], offsets[first:stop + 1] - offsets[first],
                                   fixed[rows], length)
        first = stop
    return carried


def _carry_run(anchored: np.ndarray, source_points: np.ndarray, offsets: np.ndarray, fixed: np.ndarray,
               length: float) -> np.ndarray:
    """:func:`carry_shapes` of a run of whole strands (its own rows and offsets)."""
    n = len(anchored)
    rest = rest_lengths(source_points, anchored, offsets)
    segment = np.flatnonzero(rest > 0)  # tips and segments of no source length carry nothing ...
    source_vector = source_points[segment + 1] - source_points[segment]
    source_length = np.linalg.norm(source_vector, axis=1)
    # ... nor do degenerate ones (no direction; their weight (ell / t)^2 reached 1e22 at 1e-12 m)
    shaped = source_length > DEGENERATE_SEGMENT_M
    segment, source_vector, source_length = segment[shaped], source_vector[shaped], source_length[shaped]
    target_vector = source_vector * (rest[segment] / source_length)[:, None]
    weight = (length / rest[segment]) ** 2
    # a segment touching a fixed particle moves its share to the right-hand side, so the matrix
    # stays symmetric: fixed rows are the identity
    diagonal = np.ones(n)
    diagonal[segment] += np.where(fixed[segment], 0.0, weight)  # a particle starts one segment at most ...
    diagonal[segment + 1] += np.where(fixed[segment + 1], 0.0, weight)  # ... and ends one
    upper = np.zeros(n)  # upper[i + 1] = A[i, i + 1]
    upper[segment + 1] = np.where(fixed[segment] | fixed[segment + 1], 0.0, -weight)
    rhs = np.array(anchored, dtype=np.float64)
    free_start, free_end = ~fixed[segment], ~fixed[segment + 1]
    rhs[segment[free_start]] -= weight[free_start, None] * target_vector[free_start]
    rhs[segment[free_end] + 1] += weight[free_end, None] * target_vector[free_end]
    into_free = fixed[segment] & free_end  # the fixed start's position pulls the next particle
    rhs[segment[into_free] + 1] += weight[into_free, None] * anchored[segment[into_free]]
    from_free = free_start & fixed[segment + 1]
    rhs[segment[from_free]] += weight[from_free, None] * anchored[segment[from_free] + 1]
    return scipy.linalg.solveh_banded(np.stack([upper, diagonal]), rhs, overwrite_ab=True, overwrite_b=True,
                                      check_finite=False)
