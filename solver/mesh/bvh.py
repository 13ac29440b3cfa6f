"""A compiled bounding volume hierarchy over triangles: exact closest points in float64.

Convention: ``vertices (V, 3) float64``, ``faces (F, 3) int64``; points ``(N, 3) float64``.
:func:`build_tree` is the setup (~10 ms for the 27k-face MakeHuman body); :func:`closest_points`
the repeated query, parallel over the points (numba's threads, :mod:`hairport.solver.jit`).

The tree
--------
Binary, top down: a node's faces are split at the median of their centroids along the
longest axis of the centroids' box, until at most :data:`LEAF_FACES` remain. Siblings are
adjacent (``child`` and ``child + 1``). Each triangle is stored once, in leaf order, as the
12 numbers Ericson's closest-point test needs (:func:`~.query._triangle_table`'s rows).

The search
----------
Depth first, nearer child first, pruning every box farther than the best squared distance
found so far: the exact minimum over all faces, as a brute-force search would find it (a
face at exactly the same distance as the one kept, a tie, may be the other one). A point
may bring a *hint*, a face it was closest to before (:attr:`~.query.SignedDistance.faces`
of an earlier query): its distance is the first upper bound, so a point that moved a little
prunes almost the whole tree from the root on. Any hint is allowed; one outside
``[0, F)`` is ignored, a wrong one only costs time.

The closest point on a triangle is Ericson's (*Real-Time Collision Detection*, 5.1.5) in the
same operations and order as the numpy reference :func:`~.query._closest_on_table`, so the
two agree to rounding. Non-finite points get NaN and face ``-1``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hairport.solver.jit import kernel, parallel_kernel, prange, warms

#: faces per leaf at most (measured on the MakeHuman body: 2-8 within 10 %, 4 the fastest)
LEAF_FACES = 4

#: entries of the search stack: the depth of a median-split tree is ``log2(F / LEAF_FACES)``
#: + 1 and the stack holds at most one entry per level plus one, so 64 covers any mesh
STACK_DEPTH = 64

#: points per parallel task (one stack allocation each; small enough to balance two threads)
POINTS_PER_TASK = 512


@dataclass(frozen=True, eq=False)
class TriangleTree:
    """The hierarchy over one mesh's triangles (see the module docstring).

    Attributes
    ----------
    boxes : (M, 6) float64
        Per node, lower corner then upper corner (m).
    child : (M,) int64
        First child of an inner node (the second is ``child + 1``), ``-1`` for a leaf.
    first : (M,) int64
        A leaf's first triangle in leaf order.
    count : (M,) int64
        A leaf's triangles (0 for inner nodes).
    faces : (F,) int64
        Face index of each triangle in leaf order.
    rank : (F,) int64
        Position in leaf order of each face (the inverse of ``faces``).
    table : (F, 12) float64
        Per triangle in leaf order: corner ``a``, ``b - a``, ``c - a``, and the Gram entries
        ``ab.ab``, ``ab.ac``, ``ac.ac``.
    """

    boxes: np.ndarray
    child: np.ndarray
    first: np.ndarray
    count: np.ndarray
    faces: np.ndarray
    rank: np.ndarray
    table: np.ndarray

    @property
    def n_faces(self) -> int:
        return len(self.faces)


def build_tree(vertices: np.ndarray, faces: np.ndarray, leaf_faces: int = LEAF_FACES) -> TriangleTree:
    """The hierarchy over the faces (at least one).

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    leaf_faces : int
        Faces per leaf at most, >= 1.
    """
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    if len(faces) == 0:
        raise ValueError("a tree needs at least one face")
    corners = vertices[faces]
    lower, upper = corners.min(axis=1), corners.max(axis=1)
    centroids = corners.mean(axis=1)
    boxes, child, first, count, order = _build(centroids, lower, upper, max(int(leaf_faces), 1))
    a = corners[:, 0]
    ab, ac = corners[:, 1] - a, corners[:, 2] - a
    gram = np.stack([np.einsum("ij,ij->i", ab, ab), np.einsum("ij,ij->i", ab, ac), np.einsum("ij,ij->i", ac, ac)], axis=1)
    table = np.ascontiguousarray(np.concatenate([a, ab, ac, gram], axis=1)[order])
    rank = np.empty(len(order), dtype=np.int64)
    rank[order] = np.arange(len(order))
    return TriangleTree(boxes, child, first, count, order, rank, table)


def closest_points(
    tree: TriangleTree, points: np.ndarray, hint: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Closest point of the mesh to each point.

    Parameters
    ----------
    tree : TriangleTree
    points : (N, 3) float64
    hint : (N,) int64, optional
        A face near each point (its previous closest face), any value; only speeds the search.

    Returns
    -------
    faces : (N,) int64
        Face holding the closest point; ``-1`` for non-finite points.
    closest : (N, 3) float64
        NaN for non-finite points.
    coordinates : (N, 2) float64
        ``(v, w)``: the closest point is ``a + v (b - a) + w (c - a)`` on its face ``(a, b, c)``.
    squared : (N,) float64
        Squared distance (m^2).
    """
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    hints = _hint_array(hint, len(points))
    n = len(points)
    faces = np.empty(n, dtype=np.int64)
    closest = np.empty((n, 3))
    coordinates = np.empty((n, 2))
    squared = np.empty(n)
    _closest_kernel(points, hints, tree.boxes, tree.child, tree.first, tree.count, tree.faces, tree.rank, tree.table,
                    faces, closest, coordinates, squared)
    return faces, closest, coordinates, squared


def _hint_array(hint: np.ndarray | None, n: int) -> np.ndarray:
    """(n,) int64 hints, or an empty array for none."""
    if hint is None:
        return np.zeros(0, dtype=np.int64)
    hint = np.ascontiguousarray(hint, dtype=np.int64).reshape(-1)
    if len(hint) != n:
        raise ValueError(f"hint must have one face per point ({n}), got {len(hint)}")
    return hint


@kernel
def _build(centroids, lower, upper, leaf_faces):
    """Top-down median split; returns (boxes, child, first, count, order)."""
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
    todo_node[0], todo_start[0], todo_stop[0] = 0, 0, n
    top = 0
    nodes = 1
    while top >= 0:
        node, start, stop = todo_node[top], todo_start[top], todo_stop[top]
        top -= 1
        for k in range(3):
            boxes[node, k] = np.inf
            boxes[node, 3 + k] = -np.inf
        low = np.full(3, np.inf)
        high = np.full(3, -np.inf)
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
        axis = 0
        for k in range(1, 3):
            if high[k] - low[k] > high[axis] - low[axis]:
                axis = k
        part = order[start:stop].copy()
        keys = np.empty(stop - start)
        for i in range(stop - start):
            keys[i] = centroids[part[i], axis]
        order[start:stop] = part[np.argsort(keys, kind="mergesort")]
        middle = (start + stop) // 2
        left = nodes
        nodes += 2
        child[node] = left
        # the right half waits on the stack below the left: depth first, at most one
        # waiting entry per level
        top += 1
        todo_node[top], todo_start[top], todo_stop[top] = left + 1, middle, stop
        top += 1
        todo_node[top], todo_start[top], todo_stop[top] = left, start, middle
    return boxes[:nodes].copy(), child[:nodes].copy(), first[:nodes].copy(), count[:nodes].copy(), order


@kernel
def _box_squared(boxes, node, px, py, pz):
    """Squared distance from the point to the node's box (0 inside)."""
    dx = max(boxes[node, 0] - px, 0.0, px - boxes[node, 3])
    dy = max(boxes[node, 1] - py, 0.0, py - boxes[node, 4])
    dz = max(boxes[node, 2] - pz, 0.0, pz - boxes[node, 5])
    return dx * dx + dy * dy + dz * dz


@kernel
def _triangle_closest(table, t, px, py, pz):
    """Ericson's closest point on triangle ``t`` of the table to the point, in the operations
    of :func:`~.query._closest_on_table`: ``(squared distance, v, w)``."""
    a0, a1, a2 = table[t, 0], table[t, 1], table[t, 2]
    b0, b1, b2 = table[t, 3], table[t, 4], table[t, 5]
    c0, c1, c2 = table[t, 6], table[t, 7], table[t, 8]
    g00, g01, g11 = table[t, 9], table[t, 10], table[t, 11]
    p0, p1, p2 = px - a0, py - a1, pz - a2
    d1 = b0 * p0 + b1 * p1 + b2 * p2
    d2 = c0 * p0 + c1 * p1 + c2 * p2
    d3, d4 = d1 - g00, d2 - g01
    d5, d6 = d1 - g01, d2 - g11
    if d1 <= 0 and d2 <= 0:  # corner a
        v, w = 0.0, 0.0
    elif d3 >= 0 and d4 <= d3:  # corner b
        v, w = 1.0, 0.0
    else:
        vc = d1 * d4 - d3 * d2
        if vc <= 0 and d1 >= 0 and d3 <= 0:  # edge ab
            v, w = d1 / (d1 - d3), 0.0
        elif d6 >= 0 and d5 <= d6:  # corner c
            v, w = 0.0, 1.0
        else:
            vb = d5 * d2 - d1 * d6
            va = d3 * d6 - d5 * d4
            e1, e2 = d4 - d3, d5 - d6
            if vb <= 0 and d2 >= 0 and d6 <= 0:  # edge ac
                v, w = 0.0, d2 / (d2 - d6)
            elif va <= 0 and e1 >= 0 and e2 >= 0:  # edge bc
                s = e1 / (e1 + e2)
                v, w = 1.0 - s, s
            else:  # inside the face
                denom = va + vb + vc
                if denom == 0:
                    denom = 1.0
                v, w = vb / denom, vc / denom
    q0 = a0 + v * b0 + w * c0
    q1 = a1 + v * b1 + w * c1
    q2 = a2 + v * b2 + w * c2
    e0, e1_, e2_ = px - q0, py - q1, pz - q2
    return e0 * e0 + e1_ * e1_ + e2_ * e2_, v, w


@kernel
def _search(px, py, pz, hint, boxes, child, first, count, rank, table, stack_node, stack_squared):
    """Nearest triangle (leaf order) to the point: ``(index or -1, squared, v, w)``."""
    best, best_t, best_v, best_w = np.inf, -1, 0.0, 0.0
    if 0 <= hint < len(rank):
        best_t = rank[hint]
        best, best_v, best_w = _triangle_closest(table, best_t, px, py, pz)
    top = 0
    stack_node[0] = 0
    stack_squared[0] = _box_squared(boxes, 0, px, py, pz)
    while top >= 0:
        node = stack_node[top]
        if stack_squared[top] >= best:
            top -= 1
            continue
        top -= 1
        c = child[node]
        if c < 0:
            for t in range(first[node], first[node] + count[node]):
                squared, v, w = _triangle_closest(table, t, px, py, pz)
                if squared < best:
                    best, best_t, best_v, best_w = squared, t, v, w
            continue
        near_squared = _box_squared(boxes, c, px, py, pz)
        far_squared = _box_squared(boxes, c + 1, px, py, pz)
        near, far = c, c + 1
        if far_squared < near_squared:
            near, far = far, near
            near_squared, far_squared = far_squared, near_squared
        if far_squared < best:
            top += 1
            stack_node[top], stack_squared[top] = far, far_squared
        if near_squared < best:
            top += 1
            stack_node[top], stack_squared[top] = near, near_squared
    return best_t, best, best_v, best_w


@kernel
def _faces_within(px, py, pz, radius_squared, boxes, child, first, count, table, stack, out_triangles, out_squared):
    """Triangles (leaf order) within ``sqrt(radius_squared)`` of the point and their squared
    distances, into the outputs; returns how many, or ``-1`` if more than fit."""
    found = 0
    top = 0
    stack[0] = 0
    while top >= 0:
        node = stack[top]
        top -= 1
        if _box_squared(boxes, node, px, py, pz) > radius_squared:
            continue
        c = child[node]
        if c >= 0:
            top += 1
            stack[top] = c + 1
            top += 1
            stack[top] = c
            continue
        for t in range(first[node], first[node] + count[node]):
            squared = _triangle_closest(table, t, px, py, pz)[0]
            if squared <= radius_squared:
                if found == len(out_triangles):
                    return -1
                out_triangles[found], out_squared[found] = t, squared
                found += 1
    return found


@parallel_kernel
def _closest_kernel(points, hints, boxes, child, first, count, faces, rank, table,
                    out_faces, out_closest, out_coordinates, out_squared):
    n = len(points)
    hinted = len(hints) == n
    tasks = (n + POINTS_PER_TASK - 1) // POINTS_PER_TASK
    for task in prange(tasks):
        stack_node = np.empty(STACK_DEPTH, dtype=np.int64)
        stack_squared = np.empty(STACK_DEPTH)
        for i in range(task * POINTS_PER_TASK, min(n, (task + 1) * POINTS_PER_TASK)):
            px, py, pz = points[i, 0], points[i, 1], points[i, 2]
            if not (np.isfinite(px) and np.isfinite(py) and np.isfinite(pz)):
                out_faces[i] = -1
                out_closest[i, 0] = out_closest[i, 1] = out_closest[i, 2] = np.nan
                out_coordinates[i, 0] = out_coordinates[i, 1] = np.nan
                out_squared[i] = np.nan
                continue
            hint = hints[i] if hinted else -1
            t, squared, v, w = _search(px, py, pz, hint, boxes, child, first, count, rank, table,
                                       stack_node, stack_squared)
            if t < 0:  # every triangle degenerate (NaN distances)
                out_faces[i] = -1
                out_closest[i, 0] = out_closest[i, 1] = out_closest[i, 2] = np.nan
                out_coordinates[i, 0] = out_coordinates[i, 1] = np.nan
                out_squared[i] = np.nan
                continue
            out_faces[i] = faces[t]
            out_coordinates[i, 0], out_coordinates[i, 1] = v, w
            for k in range(3):
                out_closest[i, k] = table[t, k] + v * table[t, 3 + k] + w * table[t, 6 + k]
            out_squared[i] = squared


@warms("hairport.solver.mesh.bvh")
def _warm() -> None:
    vertices = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    tree = build_tree(vertices, faces, leaf_faces=1)
    points = np.array([[0.2, 0.2, 0.2], [2.0, 0.0, 0.0]])
    closest_points(tree, points)
    closest_points(tree, points, np.array([1, 7]))
