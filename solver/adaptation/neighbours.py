"""Eq. 8-9: each particle's k nearest particles on other strands and their inverse-distance weights."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

#: neighbour distances are clamped to this (m) before inverting (Eq. 9)
MIN_NEIGHBOUR_DISTANCE = 1e-9
#: extra candidates asked of the k-d tree per round, to skip particles of the same strand
KNN_EXTRA_CANDIDATES = 16
#: queries per k-d tree call (bounds the candidate arrays to ~20 MB)
KNN_QUERY_CHUNK = 65536


@dataclass(frozen=True, eq=False)
class Neighbours:
    """kNN sets and weights of Eq. 8-9.

    Attributes
    ----------
    index : (N, k) int64
        Neighbour particle indices; a row's padding repeats the particle itself with weight 0.
    weight : (N, k) float64
        Normalised inverse-distance weights; rows sum to 1 (0 for a particle with no neighbour).
    """

    index: np.ndarray
    weight: np.ndarray


def knn_other_strands(
    points: np.ndarray,
    strand_of: np.ndarray,
    k: int,
    candidates: np.ndarray | None = None,
    queries: np.ndarray | None = None,
    workers: int = -1,
) -> Neighbours:
    """The ``k`` nearest particles of other strands, with Eq. 9 weights.

    Parameters
    ----------
    points : (N, 3) float64
    strand_of : (N,) int64
        Strand of each particle.
    k : int
    candidates : (N,) bool, optional
        Particles allowed as neighbours (Eq. 14: guide particles); all by default.
    queries : (Q,) int64, optional
        Particles to find neighbours for; all by default.
    workers : int
        Threads for the k-d tree query.

    Returns
    -------
    neighbours : Neighbours
        Rows for ``queries`` (or all particles).
    """
    n = len(points)
    queries = np.arange(n, dtype=np.int64) if queries is None else np.asarray(queries, dtype=np.int64)
    pool = np.arange(n, dtype=np.int64) if candidates is None else np.flatnonzero(candidates)
    index = np.repeat(queries[:, None], k, axis=1)
    distance = np.full((len(queries), k), np.inf)
    if len(pool) == 0 or k == 0:
        return Neighbours(index, np.zeros((len(queries), k)))
    tree = cKDTree(points[pool])
    # queries go in chunks so the (chunk, k + extra) candidate arrays stay small
    for first in range(0, len(queries), KNN_QUERY_CHUNK):
        todo = np.arange(first, min(first + KNN_QUERY_CHUNK, len(queries)))
        ask = k + KNN_EXTRA_CANDIDATES
        while len(todo):
            ask_now = min(ask, len(pool))
            dist, local = tree.query(points[queries[todo]], k=ask_now, workers=workers)
            dist = dist.reshape(len(todo), ask_now)
            found = pool[np.minimum(local.reshape(len(todo), ask_now), len(pool) - 1)]
            other = (strand_of[found] != strand_of[queries[todo], None]) & np.isfinite(dist)
            enough = (other.sum(axis=1) >= k) | (ask_now >= len(pool))
            rows = todo[enough]
            sel = other[enough]
            # stable order: keep the first k valid columns of each row (they are sorted by distance)
            rank = np.cumsum(sel, axis=1) - 1
            keep = sel & (rank < k)
            r, c = np.nonzero(keep)
            index[rows[r], rank[keep]] = found[enough][keep]
            distance[rows[r], rank[keep]] = dist[enough][keep]
            todo = todo[~enough]
            ask *= 2
    valid = np.isfinite(distance)
    inverse = np.where(valid, 1.0 / np.maximum(distance, MIN_NEIGHBOUR_DISTANCE), 0.0)
    total = inverse.sum(axis=1, keepdims=True)
    weight = np.divide(inverse, total, out=np.zeros_like(inverse), where=total > 0)
    return Neighbours(index, weight)


def laplacian_operator(neighbours: Neighbours, rows: np.ndarray, n: int) -> sp.csr_matrix:
    """``K`` with ``(K p)_i = sum_j w_ij (p_i - p_j)`` (Eq. 8/10).

    Parameters
    ----------
    neighbours : Neighbours
        Rows for the particles ``rows``.
    rows : (Q,) int64
        Particle of each neighbour row.
    n : int
        Total particle count (columns).

    Returns
    -------
    K : (n, n) csr_matrix
        Zero rows for particles not in ``rows``.
    """
    q, k = neighbours.index.shape
    row_ids = np.repeat(rows, k + 1)
    col_ids = np.concatenate([rows[:, None], neighbours.index], axis=1).ravel()
    values = np.concatenate([neighbours.weight.sum(axis=1, keepdims=True), -neighbours.weight], axis=1).ravel()
    return sp.csr_matrix((values, (row_ids, col_ids)), shape=(n, n))
