"""Eq. 8-9: each particle's k nearest particles on other strands and their inverse-distance weights.

The search is linear in memory for any strand layout. :func:`knn_other_strands` asks a
compiled k-d tree (:mod:`.kdtree`) that skips the query's own strand while it searches, so
one search per particle gives the exact answer. A particle that meets more than
:data:`KNN_MAX_ROUND_CANDIDATES` particles of its own strand before it has found ``k`` others
(a long strand with no neighbour near: candidate rounds once took 4.3 GB for one
10,000-point strand) goes instead to an exact search that never sees its own strand: the
strands are split in halves recursively, and each half's particles query a tree of the
other half's, so every particle meets every other strand once, in ``log2(S)`` levels of
trees whose sizes add up to the pool per level.

:func:`knn_other_strands_reference`, the tested reference, finds the same sets with scipy's
``cKDTree``: most particles find ``k`` particles of other strands among a few dozen nearest
candidates (rounds that double the candidates while some are missing), long strands that
miss go to the exact search. The compiled tree was 2-3x faster on the MakeHuman long groom
at 10^6 particles (full sets: 5.5 s against 16 s on a loaded machine), with equal results.

A particle may find fewer than ``k`` neighbours (the pool holds fewer particles of other
strands, or none: a groom of one strand). Eq. 9's weights are normalised over the
neighbours found; a row without any has weight 0 and adds no Eq. 10 term.

A neighbour at distance 0 (a duplicate strand, :mod:`hairport.solver.model.degenerate`) is no
singularity: the distances are clamped (:data:`MIN_NEIGHBOUR_DISTANCE`) before they are inverted
and the weights normalised, so such a neighbour takes (almost) its row's whole weight and every
weight stays in [0, 1]. Collapsed strands (all their points at the root) are left out of the sets
of a whole hairstyle (:func:`knn_shaped_strands`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from hairport.solver.adaptation.source.kdtree import build_tree, query_tree
from hairport.solver.jit import parallel_kernel, prange, warms
from hairport.solver.model.degenerate import groom_size
from hairport.solver.model.hair import Hair

#: neighbour distances are clamped to this (m) before inverting (Eq. 9)
MIN_NEIGHBOUR_DISTANCE = 1e-9
#: extra candidates asked of the k-d tree in the reference's first round, to skip particles of the same strand
KNN_EXTRA_CANDIDATES = 16
#: queries per k-d tree call (bounds the gathered query points and, in the reference's first
#: round, the candidate arrays to ~20 MB)
KNN_QUERY_CHUNK = 65536
#: candidate entries (rows x candidates) per k-d tree call in every round: the first round's
#: size at the default k = 5, so later rounds, with more candidates, take fewer rows per call
KNN_CANDIDATE_BUDGET = KNN_QUERY_CHUNK * (5 + KNN_EXTRA_CANDIDATES)
#: a particle that meets more particles of its own strand than this before it has found k
#: others (the reference: whose strand holds more pool particles than this, less k, and whose
#: first round missed) takes the exact other-strand search: the tree's and the rounds' cost
#: grows with the strand's length, the exact search's does not. Strands of ordinary grooms (up
#: to a few hundred particles) stay below it
KNN_MAX_ROUND_CANDIDATES = 512


#: a strand farther than this many groom sizes (:func:`~hairport.solver.model.degenerate.groom_size`:
#: the roots' spread plus a typical strand length, 0.1-0.5 m on a head) from every particle of other
#: strands has no Eq. 10 rows (:func:`_isolated_rows`). Ordinary strands stay far inside it: on the
#: MakeHuman and toy grooms (300-3,000 strands, every style, all strands, 40 and 5 guides) no particle's
#: nearest neighbour lay farther than 0.23 m; a threshold relative to the spacing would not do (the
#: largest nearest distance reached 34 times the median on dense grooms)
ISOLATED_SIZES = 2.0

#: storage of the neighbour indices: particle counts stay far below 2^31 (the readers cap them
#: at tens of millions), and the index array is the largest one a hairstyle keeps
NEIGHBOUR_INDEX_DTYPE = np.int32


@dataclass(frozen=True, eq=False)
class Neighbours:
    """kNN sets and weights of Eq. 8-9.

    Attributes
    ----------
    index : (N, k) int32
        Neighbour particle indices; a row's padding repeats the particle itself with weight 0.
    weight : (N, k) float64
        Normalised inverse-distance weights; rows sum to 1 (0 for a particle with no neighbour).
    """

    index: np.ndarray
    weight: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "index", np.asarray(self.index, dtype=NEIGHBOUR_INDEX_DTYPE))
        object.__setattr__(self, "weight", np.asarray(self.weight, dtype=np.float64))


def knn_other_strands(
    points: np.ndarray,
    strand_of: np.ndarray,
    k: int,
    candidates: np.ndarray | None = None,
    queries: np.ndarray | None = None,
    workers: int = -1,
    reach: float = np.inf,
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
    reach : float
        The rows of a strand none of whose rows has a neighbour within this have none
        (:func:`_isolated_rows`; ``inf``: every row keeps its neighbours).

    Returns
    -------
    neighbours : Neighbours
        Rows for ``queries`` (or all particles); fewer than ``k`` neighbours where the pool
        holds fewer particles of other strands (padding: the particle itself, weight 0).
    """
    n = len(points)
    strand_of = np.asarray(strand_of, dtype=np.int64)
    queries = np.arange(n, dtype=np.int64) if queries is None else np.asarray(queries, dtype=np.int64)
    pool = np.arange(n, dtype=np.int64) if candidates is None else np.flatnonzero(candidates)
    index = np.repeat(queries[:, None].astype(NEIGHBOUR_INDEX_DTYPE), k, axis=1)
    distance = np.full((len(queries), k), np.inf)
    if len(pool) == 0 or k == 0 or len(queries) == 0:
        return Neighbours(index, np.zeros((len(queries), k)))
    if candidates is None:  # the whole hairstyle: no gathered copies (the tree keeps its own, in tree order)
        tree = build_tree(points, pool, strand_of)
    else:
        tree = build_tree(points[pool], pool, strand_of[pool])
    complete = np.empty(len(queries), dtype=bool)
    for first in range(0, len(queries), KNN_QUERY_CHUNK):  # bounds the gathered query points
        rows = slice(first, first + KNN_QUERY_CHUNK)
        complete[rows] = query_tree(tree, points[queries[rows]], strand_of[queries[rows]], index[rows],
                                    distance[rows], KNN_MAX_ROUND_CANDIDATES)
    hard = np.flatnonzero(~complete)  # met more than KNN_MAX_ROUND_CANDIDATES of their own strand
    if len(hard):
        index[hard] = queries[hard, None]
        index[hard], distance[hard] = _other_strand_search(points, strand_of, pool, queries[hard], k, workers)
    return Neighbours(index, _inverse_distance_weights(_isolated_rows(index, distance, queries, strand_of, reach)))


def knn_shaped_strands(hair: Hair, k: int, candidates: np.ndarray | None = None,
                       reach: float | None = None) -> Neighbours:
    """Eq. 8-9 over the strands of ``hair`` but its collapsed ones (:attr:`~hairport.solver.model.hair.Hair.collapsed`),
    isolated strands without neighbours (:func:`_isolated_rows`).

    A collapsed strand is carried on its root, not solved: it is nobody's neighbour and has none (rows
    of weight 0), so the other strands' sets are those of the groom without it (its particles, fixed
    at a root far from theirs, pulled them by up to 1.7 cm through Eq. 10 in the coupled solve of the toy pair).

    Parameters
    ----------
    hair : Hair
    k : int
    candidates : (N,) bool, optional
        Particles allowed as neighbours (all by default); a collapsed strand's never are.
    reach : float, optional
        :func:`neighbour_reach` of the whole groom (``hair``'s by default; a groom's guides take the groom's).

    Returns
    -------
    neighbours : Neighbours
        One row per particle of ``hair``.
    """
    reach = neighbour_reach(hair) if reach is None else reach
    still = np.repeat(hair.collapsed, hair.counts)
    if not still.any():
        return knn_other_strands(hair.points, hair.strand_of, k, candidates, reach=reach)
    pool = ~still if candidates is None else (np.asarray(candidates, dtype=bool) & ~still)
    shaped = np.flatnonzero(~still)
    found = knn_other_strands(hair.points, hair.strand_of, k, candidates=pool, queries=shaped, reach=reach)
    index = np.repeat(np.arange(hair.n_particles, dtype=NEIGHBOUR_INDEX_DTYPE)[:, None], k, axis=1)
    weight = np.zeros((hair.n_particles, k))
    index[shaped], weight[shaped] = found.index, found.weight
    return Neighbours(index, weight)


def knn_other_strands_reference(
    points: np.ndarray,
    strand_of: np.ndarray,
    k: int,
    candidates: np.ndarray | None = None,
    queries: np.ndarray | None = None,
    workers: int = -1,
    reach: float = np.inf,
) -> Neighbours:
    """:func:`knn_other_strands` by scipy's k-d tree and rounds of candidates (module
    docstring): the reference the compiled tree is tested against (same parameters and results)."""
    n = len(points)
    strand_of = np.asarray(strand_of, dtype=np.int64)
    queries = np.arange(n, dtype=np.int64) if queries is None else np.asarray(queries, dtype=np.int64)
    pool = np.arange(n, dtype=np.int64) if candidates is None else np.flatnonzero(candidates)
    index = np.repeat(queries[:, None].astype(NEIGHBOUR_INDEX_DTYPE), k, axis=1)
    distance = np.full((len(queries), k), np.inf)
    if len(pool) == 0 or k == 0 or len(queries) == 0:
        return Neighbours(index, np.zeros((len(queries), k)))
    tree = cKDTree(points[pool])
    own = np.bincount(strand_of[pool], minlength=int(strand_of.max()) + 1)[strand_of[queries]]
    # only after missing neighbours in the first round does a particle go to the exact search
    if not own.any():  # no query's strand in the pool (Eq. 14: normal particles, guide particles)
        _nearest_in_pool(points, tree, pool, queries, k, workers, index, distance)
        return Neighbours(index, _inverse_distance_weights(_isolated_rows(index, distance, queries, strand_of, reach)))
    long_strand = own + k > KNN_MAX_ROUND_CANDIDATES
    todo = np.arange(len(queries))
    ask = k + KNN_EXTRA_CANDIDATES
    exact: list[np.ndarray] = []
    first_round = True
    while len(todo):
        ask_now = min(ask, len(pool))
        missing = []
        rows_per_call = max(1, KNN_CANDIDATE_BUDGET // ask_now)
        for first in range(0, len(todo), rows_per_call):
            rows = todo[first : first + rows_per_call]
            missing.append(_round(points, strand_of, tree, pool, queries, rows, k, ask_now, workers, index, distance))
        todo = np.concatenate(missing)
        if first_round:
            exact.append(todo[long_strand[todo]])
            todo = todo[~long_strand[todo]]
            first_round = False
        ask *= 2
    hard = np.concatenate(exact)
    if len(hard):
        index[hard], distance[hard] = _other_strand_search(points, strand_of, pool, queries[hard], k, workers)
    return Neighbours(index, _inverse_distance_weights(_isolated_rows(index, distance, queries, strand_of, reach)))


def _isolated_rows(index: np.ndarray, distance: np.ndarray, queries: np.ndarray, strand_of: np.ndarray,
                   reach: float) -> np.ndarray:
    """Empty (in place: the padding of a row without neighbours) the rows of the strands none of whose rows
    has a neighbour within ``reach``: strands away from every other.

    Eq. 10 keeps a particle's offset to its neighbours; a strand far from every other (a strand moved away
    from the groom, a damaged file's points in a heap at the origin) has offsets of metres, and its rows
    pulled the strands they name (a copy moved 1.5 m away moved them 11 cm in the coupled solve). Such a
    strand is retargeted by its own terms. Nobody names it back: it is far from them too. A strand that
    comes near the others anywhere keeps every row (a long strand among short ones reaches far from them
    with its tip, as hair does).

    Parameters
    ----------
    index : (Q, k) int
    distance : (Q, k) float64
        ``inf`` for padding.
    queries : (Q,) int64
        The particle of each row.
    strand_of : (N,) int64
    reach : float

    Returns
    -------
    distance : (Q, k) float64
        ``distance`` itself.
    """
    if not np.isfinite(reach) or len(distance) == 0:
        return distance
    nearest = distance.min(axis=1)
    strand = strand_of[queries]
    closest = np.full(int(strand.max()) + 1, np.inf)
    np.minimum.at(closest, strand, nearest)
    far = np.flatnonzero(np.isfinite(nearest) & (closest[strand] > reach))
    index[far] = queries[far, None]
    distance[far] = np.inf
    return distance


def neighbour_reach(hair: Hair) -> float:
    """How far (m) a strand may lie from every other before it has no neighbours: :data:`ISOLATED_SIZES` groom
    sizes (``inf`` for a groom without a size)."""
    size, _ = groom_size(hair.points, hair.offsets) if hair.n_strands else (0.0, None)
    return ISOLATED_SIZES * size if size > 0 else np.inf


def _inverse_distance_weights(distance: np.ndarray) -> np.ndarray:
    """Eq. 9 from ``(Q, k)`` neighbour distances (``inf``: padding), in place (no ``(Q, k)`` temporaries).

    Returns
    -------
    weight : (Q, k) float64
        ``distance``'s memory: normalised inverse distances, 0 for the padding (1/inf) and
        for a row without any neighbour.
    """
    weight = np.maximum(distance, MIN_NEIGHBOUR_DISTANCE, out=distance)
    np.divide(1.0, weight, out=weight)
    total = weight.sum(axis=1, keepdims=True)
    np.divide(weight, total, out=weight, where=total > 0)
    return weight


def _nearest_in_pool(points: np.ndarray, tree: cKDTree, pool: np.ndarray, queries: np.ndarray, k: int, workers: int,
                     index: np.ndarray, distance: np.ndarray) -> None:
    """The ``k`` nearest pool particles of every query, none of whose strands is in the pool
    (so all are of other strands): fills ``index`` and ``distance`` (``(Q, k)``, in place);
    the columns beyond the pool's size keep their padding."""
    ask = min(k, len(pool))
    rows_per_call = max(1, KNN_CANDIDATE_BUDGET // ask)
    for first in range(0, len(queries), rows_per_call):
        rows = slice(first, first + rows_per_call)
        dist, local = tree.query(points[queries[rows]], k=ask, workers=workers)
        index[rows, :ask] = pool[local.reshape(-1, ask)]
        distance[rows, :ask] = dist.reshape(-1, ask)


def _round(
    points: np.ndarray,
    strand_of: np.ndarray,
    tree: cKDTree,
    pool: np.ndarray,
    queries: np.ndarray,
    rows: np.ndarray,
    k: int,
    ask: int,
    workers: int,
    index: np.ndarray,
    distance: np.ndarray,
) -> np.ndarray:
    """One k-d tree call for ``rows`` of ``queries`` with ``ask`` candidates.

    Fills ``index`` and ``distance`` (``(Q, k)``, in place) for the rows that found ``k``
    particles of other strands (or saw the whole pool).

    Returns
    -------
    missing : (M,) int64
        The rows that did not.
    """
    dist, local = tree.query(points[queries[rows]], k=ask, workers=workers)
    dist = dist.reshape(len(rows), ask)
    found = pool[np.minimum(local.reshape(len(rows), ask), len(pool) - 1)]
    other = (strand_of[found] != strand_of[queries[rows], None]) & np.isfinite(dist)
    enough = (other.sum(axis=1) >= k) | (ask >= len(pool))
    done = rows[enough]
    sel = other[enough]
    # stable order: keep the first k valid columns of each row (they are sorted by distance)
    rank = np.cumsum(sel, axis=1) - 1
    keep = sel & (rank < k)
    r, c = np.nonzero(keep)
    index[done[r], rank[keep]] = found[enough][keep]
    distance[done[r], rank[keep]] = dist[enough][keep]
    return rows[~enough]


def _other_strand_search(
    points: np.ndarray, strand_of: np.ndarray, pool: np.ndarray, queries: np.ndarray, k: int, workers: int
) -> tuple[np.ndarray, np.ndarray]:
    """Exact ``k`` nearest pool particles of other strands, never looking at a query's own strand.

    The strand ids are halved recursively; at each split the queries of one half query a
    tree of the other half's pool particles, and the ``k`` best so far are kept. Memory:
    ``O(Q k)`` for the results plus one tree of at most the pool.

    Parameters
    ----------
    points : (N, 3) float64
    strand_of : (N,) int64
    pool : (P,) int64
        Particles allowed as neighbours.
    queries : (Q,) int64
    k : int
    workers : int

    Returns
    -------
    index : (Q, k) int64
        Neighbours sorted by distance; the query itself where fewer than ``k`` exist.
    distance : (Q, k) float64
        ``inf`` for the padding.
    """
    order = np.argsort(strand_of[pool], kind="stable")
    pool = pool[order]
    pool_strand = strand_of[pool]
    query_strand = strand_of[queries]
    best_index = np.repeat(queries[:, None], k, axis=1)
    best_distance = np.full((len(queries), k), np.inf)
    lowest = int(min(pool_strand[0], query_strand.min()))
    highest = int(max(pool_strand[-1], query_strand.max())) + 1
    # (first strand, end strand, query rows whose strand is in that range)
    stack = [(lowest, highest, np.arange(len(queries)))]
    while stack:
        lo, hi, rows = stack.pop()
        if hi - lo < 2 or len(rows) == 0:
            continue
        mid = (lo + hi) // 2
        left = rows[query_strand[rows] < mid]
        right = rows[query_strand[rows] >= mid]
        for side, first, end in ((left, mid, hi), (right, lo, mid)):
            a, b = np.searchsorted(pool_strand, [first, end])
            if len(side) == 0 or a == b:
                continue
            ask = min(k, int(b - a))
            dist, local = cKDTree(points[pool[a:b]]).query(points[queries[side]], k=ask, workers=workers)
            dist = dist.reshape(len(side), ask)
            found = pool[a:b][local.reshape(len(side), ask)]
            merged_distance = np.concatenate([best_distance[side], dist], axis=1)
            merged_index = np.concatenate([best_index[side], found], axis=1)
            best = np.argsort(merged_distance, axis=1, kind="stable")[:, :k]
            best_distance[side] = np.take_along_axis(merged_distance, best, axis=1)
            best_index[side] = np.take_along_axis(merged_index, best, axis=1)
        stack.append((lo, mid, left))
        stack.append((mid, hi, right))
    return best_index, best_distance


def neighbour_average(neighbours: Neighbours, points: np.ndarray) -> np.ndarray:
    """Each row's weighted sum of its neighbours' positions, ``sum_j w_ij p_j`` (Eq. 10/14),
    without the ``(Q, k, 3)`` gather (compiled; :func:`neighbour_average_reference`).

    Parameters
    ----------
    neighbours : Neighbours
        ``Q`` rows.
    points : (N, 3) float64
        Positions the indices point into.

    Returns
    -------
    average : (Q, 3) float64
    """
    out = np.empty((len(neighbours.index), 3))
    _neighbour_average_kernel(np.ascontiguousarray(neighbours.index), np.ascontiguousarray(neighbours.weight),
                              np.ascontiguousarray(points, dtype=np.float64), out)
    return out


def neighbour_average_reference(neighbours: Neighbours, points: np.ndarray) -> np.ndarray:
    """:func:`neighbour_average` in numpy (gathers ``(Q, k, 3)``): the tested reference."""
    return np.einsum("nk,nkd->nd", neighbours.weight, points[neighbours.index])


@parallel_kernel
def _neighbour_average_kernel(index, weight, points, out):
    for i in prange(index.shape[0]):
        x = y = z = 0.0
        for j in range(index.shape[1]):
            w, p = weight[i, j], index[i, j]
            x += w * points[p, 0]
            y += w * points[p, 1]
            z += w * points[p, 2]
        out[i, 0], out[i, 1], out[i, 2] = x, y, z


@warms
def _warm() -> None:
    for dtype in (np.int32, np.int64):
        _neighbour_average_kernel(np.zeros((1, 2), dtype), np.ones((1, 2)), np.ones((1, 3)), np.empty((1, 3)))


def laplacian_operator(neighbours: Neighbours, rows: np.ndarray, n: int) -> sp.csr_matrix:
    """``K`` with ``(K p)_i = sum_j w_ij (p_i - p_j)`` (Eq. 8/10).

    Parameters
    ----------
    neighbours : Neighbours
        Rows for the particles ``rows``; rows with fewer neighbours carry zero weights.
    rows : (Q,) int64
        Particle of each neighbour row.
    n : int
        Total particle count (columns).

    Returns
    -------
    K : (n, n) csr_matrix
        Zero rows for particles not in ``rows`` and for particles without neighbours.
    """
    q, k = neighbours.index.shape
    row_ids = np.repeat(rows, k + 1)
    col_ids = np.concatenate([rows[:, None], neighbours.index], axis=1).ravel()
    values = np.concatenate([neighbours.weight.sum(axis=1, keepdims=True), -neighbours.weight], axis=1).ravel()
    return sp.csr_matrix((values, (row_ids, col_ids)), shape=(n, n))
