"""Exact k nearest neighbours by a compiled k-d tree, skipping each query's own group (Eq. 8-9, Eq. 14).

The inter-strand kNN asks, for up to millions of particles, the ``k`` nearest particles of
*other* strands. scipy's ``cKDTree`` answers the plain kNN; the strand filter then needs
extra candidates and rounds (:mod:`.neighbours`). This tree does both at once: a particle of
the query's own strand is skipped while searching, so one search gives the exact answer,
and the search runs compiled and in parallel over queries (measured on the MakeHuman
"long" grooms: ``bench/preprocess.py``).

The tree: points split at the median of their widest axis, level by level, down to leaves
of at most :data:`LEAF_SIZE` points (implicit heap layout: node ``i`` has children
``2i + 1`` and ``2i + 2``). A query descends depth first, nearer side first, and skips a
subtree whose splitting plane lies farther than its current ``k``-th distance. Distances are
``sqrt(dx^2 + dy^2 + dz^2)`` summed in axis order (as ``cKDTree`` sums them); among equal
distances the point met first is kept first.

A query meeting more than ``max_skipped`` points of its own group before it has ``k``
others (a long strand far from the rest) gives up; its caller takes the exact search of
:mod:`.neighbours` for it, whose cost does not grow with the strand's length.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hairport.solver.jit import kernel, parallel_kernel, prange, warms

#: at most this many points per leaf
LEAF_SIZE = 8
#: deepest descent a query's stack holds (a tree over 2^40 points would be deeper)
MAX_DEPTH = 48
#: queries per block of the parallel loop (each block allocates its scratch once)
QUERY_BLOCK = 256
#: storage of the points' ids and groups (particle and strand indices stay far below 2^31)
ID_DTYPE = np.int32


@dataclass(frozen=True, eq=False)
class KdTree:
    """A k-d tree over ``P`` points (:func:`build_tree`).

    Attributes
    ----------
    points : (P, 3) float64
        The points in tree order (each leaf's points contiguous).
    ids : (P,) int32
        What each point in tree order stands for (the caller's index).
    groups : (P,) int32
        Each point's group (its strand), in tree order.
    start, end : (M,) int64
        Each node's range of points.
    axis : (M,) int64
        Splitting axis, ``-1`` for a leaf.
    split : (M,) float64
        Splitting coordinate: the left child holds the points before the median, which lie
        at or below it, the right child the others, at or above it.
    """

    points: np.ndarray
    ids: np.ndarray
    groups: np.ndarray
    start: np.ndarray
    end: np.ndarray
    axis: np.ndarray
    split: np.ndarray


def build_tree(points: np.ndarray, ids: np.ndarray, groups: np.ndarray) -> KdTree:
    """Build the tree.

    Parameters
    ----------
    points : (P, 3) float64
    ids : (P,) int64
        Reported for each found point.
    groups : (P,) int64
        A query skips the points of its own group.
    """
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    count = len(points)
    depth = 0
    while -(-count // (1 << depth)) > LEAF_SIZE:  # halving: a node of depth d holds at most ceil(P / 2^d)
        depth += 1
    nodes = (1 << (depth + 1)) - 1
    order = np.arange(count, dtype=np.int64)
    start = np.zeros(nodes, dtype=np.int64)
    end = np.zeros(nodes, dtype=np.int64)
    axis = np.full(nodes, -1, dtype=np.int64)
    split = np.zeros(nodes)
    end[0] = count
    for level in range(depth):
        _split_level(points, order, start, end, axis, split, (1 << level) - 1, (1 << (level + 1)) - 1)
    return KdTree(np.ascontiguousarray(points[order]), np.ascontiguousarray(np.asarray(ids)[order], dtype=ID_DTYPE),
                  np.ascontiguousarray(np.asarray(groups)[order], dtype=ID_DTYPE), start, end, axis, split)


def query_tree(tree: KdTree, queries: np.ndarray, groups: np.ndarray, index: np.ndarray, distance: np.ndarray,
               max_skipped: int) -> np.ndarray:
    """The ``k`` nearest tree points of other groups of every query.

    Parameters
    ----------
    tree : KdTree
    queries : (Q, 3) float64
    groups : (Q,) int64
        Each query's group.
    index : (Q, k) integer array
        Receives the found points' ids, nearest first, in the columns up to the number found
        (the rest untouched).
    distance : (Q, k) float64
        Receives their distances; ``inf`` in the columns not found.
    max_skipped : int
        A query that meets more points of its own group than this gives up.

    Returns
    -------
    complete : (Q,) bool
        False where the query gave up (its rows are then not meaningful).
    """
    complete = np.empty(len(queries), dtype=bool)
    _query(tree.points, tree.ids, tree.groups, tree.start, tree.end, tree.axis, tree.split,
           np.ascontiguousarray(queries, dtype=np.float64), np.ascontiguousarray(groups, dtype=np.int64),
           int(max_skipped), index, distance, complete)
    return complete


@parallel_kernel
def _split_level(points, order, start, end, axis, split, first, last):
    for node in prange(first, last):
        lo, hi = start[node], end[node]
        widest, spread = 0, -1.0
        for d in range(3):
            low, high = np.inf, -np.inf
            for i in range(lo, hi):
                value = points[order[i], d]
                low = min(low, value)
                high = max(high, value)
            if high - low > spread:
                widest, spread = d, high - low
        middle = (lo + hi) // 2
        if hi > lo:
            _select(points, order, lo, hi, middle, widest)
            split[node] = points[order[middle], widest]
        axis[node] = widest
        start[2 * node + 1], end[2 * node + 1] = lo, middle
        start[2 * node + 2], end[2 * node + 2] = middle, hi


@kernel
def _select(points, order, lo, hi, nth, d):
    """Reorder ``order[lo:hi]`` so that position ``nth`` holds the point it would hold sorted
    by coordinate ``d``, with no larger one before it and no smaller one after it (quickselect)."""
    left, right = lo, hi - 1
    while right > left:
        mid = (left + right) // 2
        a, b, c = points[order[left], d], points[order[mid], d], points[order[right], d]
        pivot = max(min(a, b), min(max(a, b), c))  # median of three
        i, j = left, right
        while i <= j:
            while points[order[i], d] < pivot:
                i += 1
            while points[order[j], d] > pivot:
                j -= 1
            if i <= j:
                order[i], order[j] = order[j], order[i]
                i += 1
                j -= 1
        if nth <= j:
            right = j
        elif nth >= i:
            left = i
        else:
            return


@parallel_kernel
def _query(points, ids, groups, start, end, axis, split, queries, query_groups, max_skipped, index, distance,
           complete):
    k = distance.shape[1]
    blocks = (queries.shape[0] + QUERY_BLOCK - 1) // QUERY_BLOCK
    for block in prange(blocks):
        # scratch once per block of queries (an allocation per query costs as much as its search)
        best = np.empty(k)  # squared distances, ascending
        found = np.empty(k, dtype=np.int64)
        stack_node = np.empty(MAX_DEPTH + 1, dtype=np.int64)
        stack_bound = np.empty(MAX_DEPTH + 1)
        for q in range(block * QUERY_BLOCK, min(queries.shape[0], (block + 1) * QUERY_BLOCK)):
            complete[q] = _search(points, ids, groups, start, end, axis, split, queries[q, 0], queries[q, 1],
                                  queries[q, 2], query_groups[q], max_skipped, best, found, stack_node, stack_bound)
            for j in range(k):
                if best[j] < np.inf:
                    index[q, j] = ids[found[j]]
                    distance[q, j] = np.sqrt(best[j])
                else:
                    distance[q, j] = np.inf


@kernel
def _search(points, ids, groups, start, end, axis, split, qx, qy, qz, own, max_skipped, best, found, stack_node,
            stack_bound):
    """One query: fills ``best`` (squared distances, ascending, inf where none) and ``found``
    (tree positions); False when it gave up."""
    k = best.shape[0]
    best[:] = np.inf
    stack_node[0], stack_bound[0] = 0, 0.0
    top = 1
    skipped = 0
    while top > 0:
        top -= 1
        node, bound = stack_node[top], stack_bound[top]
        if bound > best[k - 1]:
            continue
        if axis[node] < 0 or 2 * node + 1 >= axis.shape[0]:
            for i in range(start[node], end[node]):
                if groups[i] == own:
                    skipped += 1
                    if skipped > max_skipped and best[k - 1] == np.inf:
                        return False
                    continue
                dx, dy, dz = points[i, 0] - qx, points[i, 1] - qy, points[i, 2] - qz
                d2 = dx * dx + dy * dy + dz * dz
                if d2 < best[k - 1]:
                    j = k - 1
                    while j > 0 and best[j - 1] > d2:
                        best[j] = best[j - 1]
                        found[j] = found[j - 1]
                        j -= 1
                    best[j] = d2
                    found[j] = i
            continue
        a = axis[node]
        offset = (qx if a == 0 else qy if a == 1 else qz) - split[node]
        near, far = (2 * node + 1, 2 * node + 2) if offset < 0.0 else (2 * node + 2, 2 * node + 1)
        stack_node[top], stack_bound[top] = far, max(bound, offset * offset)
        stack_node[top + 1], stack_bound[top + 1] = near, bound
        top += 2
    return True


@warms
def _warm() -> None:
    points = np.random.default_rng(0).random((40, 3))
    tree = build_tree(points, np.arange(40), np.arange(40) // 4)
    for dtype in (np.int32, np.int64):
        query_tree(tree, points[:3], np.arange(3), np.zeros((3, 2), dtype), np.empty((3, 2)), 10)
