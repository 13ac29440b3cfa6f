"""The compiled build of the closest-point queries' bounding volume hierarchy (:mod:`.bvh`).

The tree is split by the surface area heuristic (binned) for its first :data:`SAH_DEPTH`
levels and at the median below. No kernel of :mod:`.closest_kernels` calls these (numba's
on-disk cache keys a kernel on its own file only, see there): the build runs once per mesh,
the searches on the tree it returns.
"""

from __future__ import annotations

import numpy as np

from hairport.solver.jit import kernel, warms

#: levels of the tree split by the surface area heuristic, the ones below at the median
SAH_DEPTH = 64

#: bins per axis of the surface area heuristic
SAH_BINS = 16

#: entries of a search stack: it holds at most one entry per level plus one, and a tree has
#: at most ``SAH_DEPTH + log2(F)`` levels (< 96 for any int32 face count)
STACK_DEPTH = 128


@kernel
def build_nodes(centroids, lower, upper, leaf_faces):
    """The tree over triangles with centroid, lower and upper corners ``(F, 3)``, top down:
    ``(boxes, child, first, count, order)`` as :class:`.bvh.TriangleTree`'s.

    A node of more than ``leaf_faces`` triangles is split by the surface area heuristic
    over :data:`SAH_BINS` bins of its centroids' extent per axis (the split with the least
    ``area(left) * n(left) + area(right) * n(right)``); below :data:`SAH_DEPTH` levels, or
    where no bin boundary separates the centroids, at the median along the longest axis,
    which bounds the depth by ``SAH_DEPTH + log2(F)``."""
    n = len(centroids)
    capacity = 2 * n
    boxes = np.empty((capacity, 6))
    child = np.full(capacity, -1, dtype=np.int64)
    first = np.zeros(capacity, dtype=np.int64)
    count = np.zeros(capacity, dtype=np.int64)
    order = np.arange(n)
    todo_node = np.empty(STACK_DEPTH * 2, dtype=np.int64)
    todo_start = np.empty(STACK_DEPTH * 2, dtype=np.int64)
    todo_stop = np.empty(STACK_DEPTH * 2, dtype=np.int64)
    todo_depth = np.empty(STACK_DEPTH * 2, dtype=np.int64)
    todo_node[0], todo_start[0], todo_stop[0], todo_depth[0] = 0, 0, n, 0
    top = 0
    nodes = 1
    low = np.empty(3)
    high = np.empty(3)
    work = (np.zeros(SAH_BINS, dtype=np.int64), np.empty((SAH_BINS, 3)), np.empty((SAH_BINS, 3)), np.empty(SAH_BINS),
            np.empty(3), np.empty(3))
    while top >= 0:
        node, start, stop, depth = todo_node[top], todo_start[top], todo_stop[top], todo_depth[top]
        top -= 1
        for k in range(3):
            boxes[node, k], boxes[node, 3 + k] = np.inf, -np.inf
            low[k], high[k] = np.inf, -np.inf
        for i in range(start, stop):
            f = order[i]
            for k in range(3):
                boxes[node, k] = min(boxes[node, k], lower[f, k])
                boxes[node, 3 + k] = max(boxes[node, 3 + k], upper[f, k])
                low[k] = min(low[k], centroids[f, k])
                high[k] = max(high[k], centroids[f, k])
        if stop - start <= leaf_faces:
            first[node], count[node] = start, stop - start
            continue
        middle = -1
        if depth < SAH_DEPTH:
            axis, split = _sah_split(centroids, lower, upper, order, start, stop, low, high, *work)
            if axis >= 0:
                middle = _partition(centroids, order, start, stop, axis, low[axis], high[axis], split)
        if middle <= start or middle >= stop:
            axis = 0
            for k in range(1, 3):
                if high[k] - low[k] > high[axis] - low[axis]:
                    axis = k
            middle = (start + stop) // 2
            _select(centroids, order, start, stop, axis, middle)
        left = nodes
        nodes += 2
        child[node] = left
        # the right part waits on the stack below the left: depth first, at most one
        # waiting entry per level
        top += 1
        todo_node[top], todo_start[top], todo_stop[top], todo_depth[top] = left + 1, middle, stop, depth + 1
        top += 1
        todo_node[top], todo_start[top], todo_stop[top], todo_depth[top] = left, start, middle, depth + 1
    return boxes[:nodes].copy(), child[:nodes].copy(), first[:nodes].copy(), count[:nodes].copy(), order


@kernel
def refit_boxes(child, first, count, lower, upper):
    """The boxes ``(M, 6)`` of a built tree's nodes (``child``, ``first``, ``count`` as
    :class:`.bvh.TriangleTree`'s) around triangles whose lower and upper corners in leaf order
    are ``lower``, ``upper`` ``(F, 3)``: a leaf's around its triangles, an inner node's around
    its two children. Children come after their parent (the build numbers them so), so one
    pass from the last node to the first sees every child before its parent."""
    boxes = np.empty((len(child), 6))
    for node in range(len(child) - 1, -1, -1):
        if child[node] < 0:
            for k in range(3):
                boxes[node, k], boxes[node, 3 + k] = np.inf, -np.inf
            for i in range(first[node], first[node] + count[node]):
                for k in range(3):
                    boxes[node, k] = min(boxes[node, k], lower[i, k])
                    boxes[node, 3 + k] = max(boxes[node, 3 + k], upper[i, k])
        else:
            left, right = child[node], child[node] + 1
            for k in range(3):
                boxes[node, k] = min(boxes[left, k], boxes[right, k])
                boxes[node, 3 + k] = max(boxes[left, 3 + k], boxes[right, 3 + k])
    return boxes


@kernel
def _select(centroids, order, start, stop, axis, middle):
    """Reorder ``order[start:stop]`` so that no centroid before ``middle`` lies above, and none
    after it below, the one at ``middle`` along ``axis`` (Hoare's selection)."""
    lo, hi = start, stop - 1
    while lo < hi:
        pivot = centroids[order[(lo + hi) // 2], axis]
        i, j = lo, hi
        while i <= j:
            while centroids[order[i], axis] < pivot:
                i += 1
            while centroids[order[j], axis] > pivot:
                j -= 1
            if i <= j:
                order[i], order[j] = order[j], order[i]
                i += 1
                j -= 1
        if middle <= j:
            hi = j
        elif middle >= i:
            lo = i
        else:
            break


@kernel
def _bin_of(value, low, high):
    return min(int((value - low) / (high - low) * SAH_BINS), SAH_BINS - 1)


@kernel
def _half_area(lo, hi):
    """Half the surface area of a box (0 for an empty one)."""
    d0, d1, d2 = hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]
    return d0 * d1 + d1 * d2 + d2 * d0 if d0 >= 0 else 0.0


@kernel
def _sah_split(centroids, lower, upper, order, start, stop, low, high, counts, bin_low, bin_high, left_cost, lo, hi):
    """``(axis, first bin of the right part)`` of the cheapest binned split, ``(-1, -1)`` if none;
    the arrays after ``high`` are work space: ``(SAH_BINS,)`` int64, two ``(SAH_BINS, 3)``,
    ``(SAH_BINS,)``, two ``(3,)`` float64."""
    best_cost, best_axis, best_split = np.inf, -1, -1
    for axis in range(3):
        if not high[axis] > low[axis]:
            continue
        counts[:] = 0
        bin_low[:] = np.inf
        bin_high[:] = -np.inf
        for i in range(start, stop):
            f = order[i]
            b = _bin_of(centroids[f, axis], low[axis], high[axis])
            counts[b] += 1
            for k in range(3):
                bin_low[b, k] = min(bin_low[b, k], lower[f, k])
                bin_high[b, k] = max(bin_high[b, k], upper[f, k])
        lo[:] = np.inf
        hi[:] = -np.inf
        total = 0
        for b in range(SAH_BINS - 1):  # left part: bins 0..b
            total += counts[b]
            for k in range(3):
                lo[k], hi[k] = min(lo[k], bin_low[b, k]), max(hi[k], bin_high[b, k])
            left_cost[b] = _half_area(lo, hi) * total
        lo[:] = np.inf
        hi[:] = -np.inf
        total = 0
        for b in range(SAH_BINS - 1, 0, -1):  # right part: bins b..
            total += counts[b]
            for k in range(3):
                lo[k], hi[k] = min(lo[k], bin_low[b, k]), max(hi[k], bin_high[b, k])
            if total == 0 or total == stop - start:
                continue
            cost = left_cost[b - 1] + _half_area(lo, hi) * total
            if cost < best_cost:
                best_cost, best_axis, best_split = cost, axis, b
    return best_axis, best_split


@kernel
def _partition(centroids, order, start, stop, axis, low, high, split):
    """Reorder ``order[start:stop]`` so the triangles in bins below ``split`` come first; the
    index of the first of the others."""
    i, j = start, stop - 1
    while i <= j:
        if _bin_of(centroids[order[i], axis], low, high) < split:
            i += 1
        else:
            order[i], order[j] = order[j], order[i]
            j -= 1
    return i


@warms
def _warm() -> None:
    # a tetrahedron's four faces, one per leaf
    vertices = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    corners = vertices[np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])]
    _, child, first, count, order = build_nodes(corners.mean(axis=1), corners.min(axis=1), corners.max(axis=1), 1)
    refit_boxes(child, first, count, corners.min(axis=1)[order], corners.max(axis=1)[order])
