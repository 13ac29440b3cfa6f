"""Eq. 4-6: smoothing the anchored strands where their shape broke (restoring the source Laplacian)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from hairport.solver.jit import parallel_kernel, prange, warms
from hairport.solver.model.hair import DEGENERATE_SEGMENT_M

#: Eq. 6's epsilon_s: Laplacian discrepancy (unitless, Eq. 5 divides by lengths)
SMOOTHING_EPS = 0.3
#: rounds of re-evaluating the unsmooth set on the smoothed strands
SMOOTHING_ROUNDS = 5
#: particles per block when the unsmooth set is evaluated (bounds its temporaries)
SMOOTHING_CHUNK = 1 << 18


def strand_laplacian(points: np.ndarray, offsets: np.ndarray) -> sp.csr_matrix:
    """Per-strand Laplacian of Eq. 5, weighted by the lengths of ``points``' segments.

    Interior particle ``i``: ``(f[i+1]-f[i])/l[i] - (f[i]-f[i-1])/l[i-1]``. Roots and tips
    have empty rows: Eq. 5 is not defined there, and they stay Dirichlet in Eq. 4 (a
    one-sided tip row lets the strand end drift with the source's orientation: on the
    MakeHuman pair it put 137 particles inside the jaw instead of 7).

    Parameters
    ----------
    points : (N, 3) float64
        Positions defining the segment lengths (the source ``p-bar``).
    offsets : (S+1,) int64

    Returns
    -------
    L : (N, N) csr_matrix
    """
    n = len(points)
    lengths = np.linalg.norm(np.diff(points, axis=0), axis=1)  # (N-1,), includes fake cross-strand gaps
    # a degenerate segment (repeated points) weighs 1 / DEGENERATE_SEGMENT_M, the length the solve's
    # weld uses: it keeps its two particles together
    inv = 1.0 / np.maximum(lengths, DEGENERATE_SEGMENT_M)
    is_end = np.zeros(n, dtype=bool)
    is_end[offsets[:-1]] = True
    is_end[offsets[1:] - 1] = True
    interior = np.flatnonzero(~is_end)
    # CSR straight away (rows sorted, three sorted columns each, no duplicates): what the
    # (row, column) triplets converted to, without their (3N,) int64 arrays
    indptr = np.zeros(n + 1, dtype=np.int32 if 3 * n < np.iinfo(np.int32).max else np.int64)
    np.cumsum(3 * ~is_end, out=indptr[1:])
    cols = (interior[:, None] + np.array([-1, 0, 1])).astype(indptr.dtype).ravel()
    vals = np.stack([inv[interior - 1], -(inv[interior - 1] + inv[interior]), inv[interior]], axis=1).ravel()
    return sp.csr_matrix((vals, cols, indptr), shape=(n, n))


def smooth_strands(
    anchored: np.ndarray,
    source_points: np.ndarray,
    offsets: np.ndarray,
    eps_s: float = SMOOTHING_EPS,
    rounds: int = SMOOTHING_ROUNDS,
    laplacian: sp.csr_matrix | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Adaptive Poisson smoothing (Eq. 4-6, DESIGN.md's reading).

    On the unsmooth set ``I_u`` the source Laplacian is restored, every other particle (and
    always the root) keeps its anchored position.

    Parameters
    ----------
    anchored : (N, 3) float64
        ``p~`` from :func:`place_anchors`.
    source_points : (N, 3) float64
        ``p-bar``.
    offsets : (S+1,) int64
    eps_s : float
    rounds : int
        Re-evaluations of ``I_u`` on the smoothed result.
    laplacian : (N, N) csr_matrix, optional
        Precomputed :func:`strand_laplacian` of ``source_points``.

    Returns
    -------
    smoothed : (N, 3) float64
        ``p^``.
    unsmooth : (N,) bool
        The final ``I_u``.
    """
    L = laplacian if laplacian is not None else strand_laplacian(source_points, offsets)
    source_features = L @ source_points
    has_row = np.diff(L.indptr) > 0

    def discrepancy(p: np.ndarray) -> np.ndarray:
        # a block of rows at a time: the same sums, without (N, 3) temporaries
        far = np.empty(len(p), dtype=bool)
        for start in range(0, len(p), SMOOTHING_CHUNK):
            rows = slice(start, start + SMOOTHING_CHUNK)
            far[rows] = np.linalg.norm(L[rows] @ p - source_features[rows], axis=1) > eps_s
        return has_row & far

    unsmooth = discrepancy(anchored)
    smoothed = anchored
    used = np.zeros_like(unsmooth)
    for _ in range(max(rounds, 1)):
        if not unsmooth.any():
            break
        used = unsmooth
        smoothed = restore_laplacian(L, anchored, source_features, np.flatnonzero(unsmooth))
        grown = unsmooth | discrepancy(smoothed)
        if (grown == unsmooth).all():
            break
        unsmooth = grown
    return smoothed, used


def restore_laplacian(L: sp.csr_matrix, anchored: np.ndarray, source_features: np.ndarray,
                      unsmooth: np.ndarray) -> np.ndarray:
    """Eq. 4 on one unsmooth set: ``(L p)_i = L-bar_i`` for ``i`` in it, every other particle anchored.

    ``L`` is a strand Laplacian (:func:`strand_laplacian`): an unsmooth particle's row couples
    it with its two strand neighbours only, so the system falls apart into runs of consecutive
    unsmooth particles, each a tridiagonal system between two anchored particles, solved by
    elimination along the run (compiled, parallel over runs). Equal to the sparse LU solve of
    the whole set (:func:`restore_laplacian_reference`) to rounding (1e-12 m on the MakeHuman
    grooms, tested).

    Parameters
    ----------
    L : (N, N) csr_matrix
    anchored : (N, 3) float64
    source_features : (N, 3) float64
        ``L-bar = L p-bar``.
    unsmooth : (U,) int64
        Ascending particles with a row in ``L`` (no roots or tips).

    Returns
    -------
    smoothed : (N, 3) float64
    """
    rows = np.diff(L.indptr)[unsmooth]
    if len(unsmooth) and not (rows == 3).all():  # not a strand Laplacian's interior rows
        return restore_laplacian_reference(L, anchored, source_features, unsmooth)
    breaks = np.flatnonzero(np.diff(unsmooth) != 1) + 1
    run_first = np.concatenate([[0], breaks]).astype(np.int64)  # positions in ``unsmooth``
    run_end = np.concatenate([breaks, [len(unsmooth)]]).astype(np.int64)
    smoothed = np.array(anchored, dtype=np.float64, order="C")
    _solve_runs(L.indptr, L.data, np.ascontiguousarray(unsmooth, dtype=np.int64), run_first, run_end,
                np.ascontiguousarray(source_features, dtype=np.float64), smoothed,
                np.empty(len(unsmooth)), np.empty((len(unsmooth), 3)))
    return smoothed


def restore_laplacian_reference(L: sp.csr_matrix, anchored: np.ndarray, source_features: np.ndarray,
                                unsmooth: np.ndarray) -> np.ndarray:
    """:func:`restore_laplacian` by a sparse LU solve of the whole set: the tested reference."""
    d = np.flatnonzero(np.isin(np.arange(len(anchored)), unsmooth, invert=True))
    L_uu = L[unsmooth][:, unsmooth].tocsc()
    rhs = source_features[unsmooth] - L[unsmooth][:, d] @ anchored[d]
    smoothed = anchored.copy()
    smoothed[unsmooth] = spla.splu(L_uu).solve(np.ascontiguousarray(rhs))
    return smoothed


@parallel_kernel
def _solve_runs(indptr, data, unsmooth, run_first, run_end, source_features, points, ratio, value):
    """Thomas elimination per run; ``points`` holds the anchored positions and receives the run's
    solution; ``ratio (U,)`` and ``value (U, 3)`` are scratch, a run using its own positions."""
    for r in prange(run_first.shape[0]):
        first, end = run_first[r], run_end[r]
        for j in range(first, end):
            i = unsmooth[j]
            k = indptr[i]
            lower, diagonal, upper = data[k], data[k + 1], data[k + 2]
            if j > first:
                diagonal -= lower * ratio[j - 1]
            ratio[j] = upper / diagonal
            for c in range(3):
                right = source_features[i, c]
                if j == first:  # the anchored particle before the run
                    right -= lower * points[i - 1, c]
                else:
                    right -= lower * value[j - 1, c]
                if j == end - 1:  # and the one after it
                    right -= upper * points[i + 1, c]
                value[j, c] = right / diagonal
        last = unsmooth[end - 1]
        for c in range(3):
            points[last, c] = value[end - 1, c]
        for j in range(end - 2, first - 1, -1):
            for c in range(3):
                points[unsmooth[j], c] = value[j, c] - ratio[j] * points[unsmooth[j + 1], c]


@warms
def _warm() -> None:
    points = np.array([[0.0, 0.0, 0.0], [0.0, -0.01, 0.001], [0.0, -0.02, 0.0]])
    restore_laplacian(strand_laplacian(points, np.array([0, 3])), points, np.zeros((3, 3)), np.array([1]))
