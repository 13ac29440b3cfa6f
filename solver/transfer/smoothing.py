"""Eq. 4-6: smoothing the anchored strands where their shape broke (restoring the source Laplacian)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from hairport.solver.mesh.polyline import MIN_SEGMENT_LENGTH

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
    inv = 1.0 / np.maximum(lengths, MIN_SEGMENT_LENGTH)
    is_end = np.zeros(n, dtype=bool)
    is_end[offsets[:-1]] = True
    is_end[offsets[1:] - 1] = True
    interior = np.flatnonzero(~is_end)
    rows = np.repeat(interior, 3)
    cols = (interior[:, None] + np.array([-1, 0, 1])).ravel()
    vals = np.stack([inv[interior - 1], -(inv[interior - 1] + inv[interior]), inv[interior]], axis=1).ravel()
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))


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
        u = np.flatnonzero(unsmooth)
        d = np.flatnonzero(~unsmooth)
        L_uu = L[u][:, u].tocsc()
        rhs = source_features[u] - L[u][:, d] @ anchored[d]
        smoothed = anchored.copy()
        smoothed[u] = spla.splu(L_uu).solve(np.ascontiguousarray(rhs))
        grown = unsmooth | discrepancy(smoothed)
        if (grown == unsmooth).all():
            break
        unsmooth = grown
    return smoothed, used
