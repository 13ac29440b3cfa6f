"""The compiled kernels of the closest-point queries: tree search, cell caches, the fused signed distance.

All of them live in this one module (the tree's build, which no kernel here calls, is
:mod:`.bvh_build`'s) because numba's on-disk cache (``cache=True``,
:mod:`hairport.solver.jit`) keys a kernel on its own file only: a kernel that calls a kernel
of another file keeps that callee's machine code from when it was compiled, and would
silently run a stale copy after the other file changes. The Python around them is in
:mod:`.bvh` (the tree), :mod:`.cells` (the cell cache) and :mod:`.signed_distance` (the
fused query); the numpy reference is :meth:`.query.MeshQuery.signed_distance` with libigl's
face search.

Conventions: float64 math, int64 indices; a triangle ``t`` is a row of the tree's ``table``
(corner ``a``, ``b - a``, ``c - a``, Gram entries ``ab.ab``, ``ab.ac``, ``ac.ac``) in the
tree's leaf order; a point's result on it is ``(squared distance, v, w)`` with the closest
point ``a + v (b - a) + w (c - a)``. Each parallel kernel splits its points into tasks of
:data:`POINTS_PER_TASK` (one search stack each).
"""

from __future__ import annotations

import math

import numpy as np

from hairport.solver.jit import kernel, parallel_kernel, prange, warms
from hairport.solver.mesh.bvh_build import STACK_DEPTH, build_nodes

#: points per parallel task (one stack allocation each; small enough to balance two threads)
POINTS_PER_TASK = 512

#: below this distance (m) a point counts as on the surface and the pseudonormal gives the direction
ON_SURFACE_DISTANCE = 1e-12

#: barycentric coordinate at or below which the closest point counts as on an edge or vertex
#: of its face (the pseudonormal's feature), libigl's value
FEATURE_EPSILON = 1e-12

#: meters by which a cell's candidate radius is grown and its stored lower bounds lowered:
#: far above the round-off of distances between points ~1 m apart (~1e-15 m), far below any
#: spacing of faces, so rounding never drops a face that could be the closest
CELL_SLACK = 1e-10

#: cell indices span ``[-2^20, 2^20)`` on each axis (21 bits each, packed in one int64 key);
#: points beyond (kilometres away) go to the tree
AXIS_BITS = 21
_AXIS_OFFSET = 1 << (AXIS_BITS - 1)
_AXIS_MASK = (1 << AXIS_BITS) - 1

#: key of an empty hash slot, and what a lookup of an unknown cell returns
EMPTY = -1
#: the triangle of a point whose cell is not cached yet
MISSING = -2
#: the triangle of a point whose cell sends it to the tree
BY_TREE = -3

#: a packed slot value is ``begin * COUNT_FACTOR + count + 1``: the cell's first candidate,
#: and how many it has (``-1``: the cell is answered by the tree); above the most candidates
#: a cell keeps, plus one
COUNT_FACTOR = 1 << 10


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


@parallel_kernel
def closest_kernel(points, hints, boxes, child, first, count, faces, rank, table,
                    out_faces, out_closest, out_coordinates, out_squared):
    """Per point (parallel): the face holding its closest point (``-1`` if not finite), the point,
    its ``(v, w)`` and squared distance, into the outputs (see :func:`.bvh.closest_points`)."""
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


@kernel
def _hash_slot(key, capacity):
    """First probe slot of ``key`` in a table of ``capacity`` (a power of two) slots."""
    mixed = np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)
    return np.int64(mixed >> np.uint64(40)) & (capacity - 1)


@kernel
def _lookup(key, slots):
    """The packed candidates of the cell ``key`` (see :class:`CellCache`), or ``EMPTY``."""
    capacity = len(slots)
    slot = _hash_slot(key, capacity)
    while True:
        stored = slots[slot, 0]
        if stored == key:
            return slots[slot, 1]
        if stored == EMPTY:
            return EMPTY
        slot = (slot + 1) & (capacity - 1)


@kernel
def lookup_all(keys, slots):
    """:func:`_lookup` of each key."""
    out = np.empty(len(keys), dtype=np.int64)
    for i in range(len(keys)):
        out[i] = _lookup(keys[i], slots)
    return out


@kernel
def insert_cells(keys, values, slots):
    """Store ``values[i]`` under ``keys[i]`` (linear probing; the table must have room)."""
    capacity = len(slots)
    for i in range(len(keys)):
        slot = _hash_slot(keys[i], capacity)
        while slots[slot, 0] != EMPTY and slots[slot, 0] != keys[i]:
            slot = (slot + 1) & (capacity - 1)
        slots[slot, 0] = keys[i]
        slots[slot, 1] = values[i]


@kernel
def z_order(keys):
    """Z-curve (Morton) codes of packed cell keys: bit ``b`` of the three axis indices
    interleaved at bits ``3 b + 2 - axis``."""
    out = np.zeros(len(keys), dtype=np.int64)
    for i in range(len(keys)):
        code = 0
        for axis in range(3):
            index = (keys[i] >> (AXIS_BITS * (2 - axis))) & _AXIS_MASK
            for bit in range(AXIS_BITS):
                code |= ((index >> bit) & 1) << (3 * bit + 2 - axis)
        out[i] = code
    return out


@kernel
def _cell_key(px, py, pz, origin, inverse_size):
    """Packed key of the point's cell, or -1 when it is out of the keys' range or not finite."""
    key = 0
    for value, corner in ((px, origin[0]), (py, origin[1]), (pz, origin[2])):
        scaled = np.floor((value - corner) * inverse_size)  # a float: NaN stays NaN
        if not (-_AXIS_OFFSET <= scaled < _AXIS_OFFSET):  # also False for NaN
            return -1
        key = (key << AXIS_BITS) | (np.int64(scaled) + _AXIS_OFFSET)
    return key


@kernel
def cell_keys(points, origin, inverse_size):
    """:func:`_cell_key` of each point."""
    out = np.empty(len(points), dtype=np.int64)
    for i in range(len(points)):
        out[i] = _cell_key(points[i, 0], points[i, 1], points[i, 2], origin, inverse_size)
    return out


@kernel
def _cell_center(key, origin, size, axis):
    index = ((key >> (AXIS_BITS * (2 - axis))) & _AXIS_MASK) - _AXIS_OFFSET
    return origin[axis] + size * (index + 0.5)


@kernel
def _candidates(cx, cy, cz, reach, boxes, child, first, count, table, stack, stack_squared, out_triangles,
                out_squared):
    """Triangles (leaf order) within ``u + reach`` of the point, ``u`` its distance to the mesh,
    with their squared distances, into the outputs; returns how many, or ``-1`` if more than fit.

    One search, nearer child first: the reach is measured from the nearest triangle found so
    far, so it shrinks to ``u + reach`` as the search goes and prunes like a closest-point
    search; entries beyond the final reach are dropped at the end."""
    capacity = len(out_triangles)
    found = 0
    best, limit = np.inf, np.inf  # squared: the nearest so far, and (its distance + reach)^2
    top = 0
    stack[0] = 0
    stack_squared[0] = _box_squared(boxes, 0, cx, cy, cz)
    while top >= 0:
        node, box = stack[top], stack_squared[top]
        top -= 1
        if box > limit:
            continue
        c = child[node]
        if c < 0:
            for t in range(first[node], first[node] + count[node]):
                squared = _triangle_closest(table, t, cx, cy, cz)[0]
                if squared < best:
                    best = squared
                    limit = (math.sqrt(squared) + reach) ** 2
                if squared <= limit:
                    if found == capacity:
                        found = _within(found, limit, out_triangles, out_squared)
                        if found == capacity:
                            return -1
                    out_triangles[found], out_squared[found] = t, squared
                    found += 1
            continue
        near_squared = _box_squared(boxes, c, cx, cy, cz)
        far_squared = _box_squared(boxes, c + 1, cx, cy, cz)
        near, far = c, c + 1
        if far_squared < near_squared:
            near, far = far, near
            near_squared, far_squared = far_squared, near_squared
        if far_squared <= limit:
            top += 1
            stack[top], stack_squared[top] = far, far_squared
        if near_squared <= limit:
            top += 1
            stack[top], stack_squared[top] = near, near_squared
    return _within(found, limit, out_triangles, out_squared)


@kernel
def _within(found, limit, out_triangles, out_squared):
    """Keep the first ``found`` entries with a squared distance at most ``limit``, in order; how many."""
    kept = 0
    for e in range(found):
        if out_squared[e] <= limit:
            out_triangles[kept], out_squared[kept] = out_triangles[e], out_squared[e]
            kept += 1
    return kept


@kernel
def _sort_pairs(keys, values, n):
    """Sort the first ``n`` ``keys`` increasing, ``values`` alongside (insertion sort: a cell's
    few candidates)."""
    for i in range(1, n):
        key, value = keys[i], values[i]
        j = i - 1
        while j >= 0 and keys[j] > key:
            keys[j + 1], values[j + 1] = keys[j], values[j]
            j -= 1
        keys[j + 1], values[j + 1] = key, value


@parallel_kernel
def fill_cells(keys, origin, size, half_diagonal, boxes, child, first, count, rank, table,
               out_triangles, out_squared, out_found):
    """Candidates of the cells ``keys``: every triangle within ``u(c) + 2 r`` (plus
    :data:`CELL_SLACK`) of the cell's centre ``c``, in increasing distance (see :mod:`.cells`)."""
    reach = 2.0 * half_diagonal + CELL_SLACK
    for cell in prange(len(keys)):
        stack = np.empty(STACK_DEPTH, dtype=np.int64)
        stack_squared = np.empty(STACK_DEPTH)
        cx = _cell_center(keys[cell], origin, size, 0)
        cy = _cell_center(keys[cell], origin, size, 1)
        cz = _cell_center(keys[cell], origin, size, 2)
        found = _candidates(cx, cy, cz, reach, boxes, child, first, count, table, stack, stack_squared,
                            out_triangles[cell], out_squared[cell])
        out_found[cell] = found
        _sort_pairs(out_squared[cell], out_triangles[cell], found)


@kernel
def _scan(px, py, pz, cx, cy, cz, begin, found, candidates, bounds, table):
    """Nearest of a cell's candidates: ``(triangle in leaf order, squared, v, w)``."""
    ox, oy, oz = px - cx, py - cy, pz - cz
    away = math.sqrt(ox * ox + oy * oy + oz * oz)
    best, best_t, best_v, best_w = np.inf, -1, 0.0, 0.0
    best_distance = np.inf
    for e in range(begin, begin + found):
        if bounds[e] - away >= best_distance:
            break
        t = candidates[e]
        squared, v, w = _triangle_closest(table, t, px, py, pz)
        if squared < best:
            best, best_t, best_v, best_w = squared, t, v, w
            best_distance = math.sqrt(squared)
    return best_t, best, best_v, best_w


@kernel
def _cached_scan(px, py, pz, origin, size, inverse_size, half_diagonal, slots, candidates, bounds, table):
    """Nearest triangle (leaf order) by the point's cell: ``(triangle, squared, v, w)``, with
    the triangle :data:`MISSING` when the cell is not cached yet and :data:`BY_TREE` when the
    cell (or the point) is left to the tree."""
    key = _cell_key(px, py, pz, origin, inverse_size)
    if key < 0:
        return BY_TREE, np.inf, 0.0, 0.0
    packed = _lookup(key, slots)
    if packed == EMPTY:
        return MISSING, np.inf, 0.0, 0.0
    found = packed % COUNT_FACTOR - 1
    if found < 0:
        return BY_TREE, np.inf, 0.0, 0.0
    cx = _cell_center(key, origin, size, 0)
    cy = _cell_center(key, origin, size, 1)
    cz = _cell_center(key, origin, size, 2)
    ox, oy, oz = px - cx, py - cy, pz - cz
    # a point a rounding away from its cell is still within the slack of the radius;
    # anything more (never, by construction) is left to the tree
    if ox * ox + oy * oy + oz * oz > half_diagonal * half_diagonal * (1.0 + 1e-9):
        return BY_TREE, np.inf, 0.0, 0.0
    return _scan(px, py, pz, cx, cy, cz, packed // COUNT_FACTOR, found, candidates, bounds, table)


@parallel_kernel
def signed_kernel(points, hints, pseudonormals, boxes, child, first, count, faces, rank, table,
                   use_cells, fill_missing, origin, size, half_diagonal, slots, candidates, bounds,
                   out_distance, out_closest, out_normal, out_faces, out_feature):
    """Per point (parallel): the signed distance by the pseudonormal of the closest feature
    (see :func:`.signed_distance.signed_distance`), the closest face from the cells when
    ``use_cells`` (a point whose cell is not cached yet gets face :data:`MISSING` and nothing
    else when ``fill_missing``, else the tree's answer), from the tree otherwise."""
    n = len(points)
    hinted = len(hints) == n
    inverse_size = 1.0 / size
    tasks = (n + POINTS_PER_TASK - 1) // POINTS_PER_TASK
    for task in prange(tasks):
        stack = np.empty(STACK_DEPTH, dtype=np.int64)
        stack_squared = np.empty(STACK_DEPTH)
        for i in range(task * POINTS_PER_TASK, min(n, (task + 1) * POINTS_PER_TASK)):
            px, py, pz = points[i, 0], points[i, 1], points[i, 2]
            t, v, w = -1, 0.0, 0.0
            if np.isfinite(px) and np.isfinite(py) and np.isfinite(pz):
                t = BY_TREE
                if use_cells:
                    t, squared, v, w = _cached_scan(px, py, pz, origin, size, inverse_size, half_diagonal, slots,
                                                    candidates, bounds, table)
                    if t == MISSING and fill_missing:
                        out_faces[i] = MISSING
                        continue
                if t < 0:  # one search per point written once: the kernel compiles faster
                    hint = hints[i] if hinted else -1
                    t, squared, v, w = _search(px, py, pz, hint, boxes, child, first, count, rank, table,
                                               stack, stack_squared)
            if t < 0:  # not finite, or every face degenerate
                out_distance[i] = np.nan
                for k in range(3):
                    out_closest[i, k] = out_normal[i, k] = np.nan
                out_faces[i] = 0
                out_feature[i] = 0
                continue
            face = faces[t]
            qx = table[t, 0] + v * table[t, 3] + w * table[t, 6]
            qy = table[t, 1] + v * table[t, 4] + w * table[t, 7]
            qz = table[t, 2] + v * table[t, 5] + w * table[t, 8]
            out_closest[i, 0], out_closest[i, 1], out_closest[i, 2] = qx, qy, qz
            ox, oy, oz = px - qx, py - qy, pz - qz
            u = 1.0 - v - w
            small_u, small_v, small_w = u <= FEATURE_EPSILON, v <= FEATURE_EPSILON, w <= FEATURE_EPSILON
            smalls = small_u + small_v + small_w
            if smalls == 0:
                feature = 0
            elif smalls == 1:
                feature = 1 if small_u else (2 if small_v else 3)  # the edge opposite the small coordinate
            else:
                feature = 4 if not small_u else (5 if not small_v else 6)  # the corner not small
            nx, ny, nz = pseudonormals[face, feature, 0], pseudonormals[face, feature, 1], pseudonormals[face, feature, 2]
            sign = -1.0 if ox * nx + oy * ny + oz * nz < 0.0 else 1.0
            length = math.sqrt(ox * ox + oy * oy + oz * oz)
            out_distance[i] = sign * length
            if length < ON_SURFACE_DISTANCE:
                out_normal[i, 0], out_normal[i, 1], out_normal[i, 2] = nx, ny, nz
            else:
                scale = sign / length
                out_normal[i, 0], out_normal[i, 1], out_normal[i, 2] = ox * scale, oy * scale, oz * scale
            out_faces[i] = face
            out_feature[i] = feature


@warms
def _warm() -> None:
    # a tetrahedron, a tree of one face per leaf, every kernel on two points and a NaN
    vertices = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    corners = vertices[np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])]
    boxes, child, first, count, order = build_nodes(corners.mean(axis=1), corners.min(axis=1), corners.max(axis=1), 1)
    ab, ac = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    gram = np.stack([(ab * ab).sum(1), (ab * ac).sum(1), (ac * ac).sum(1)], axis=1)
    table = np.ascontiguousarray(np.concatenate([corners[:, 0], ab, ac, gram], axis=1)[order])
    rank = np.argsort(order)
    points = np.array([[0.2, 0.2, 0.2], [2.0, 0.0, 0.0], [np.nan, 0.0, 0.0]])
    hints = np.array([1, 7, 0])
    n = len(points)
    out = (np.empty(n, dtype=np.int64), np.empty((n, 3)), np.empty((n, 2)), np.empty(n))
    closest_kernel(points, hints, boxes, child, first, count, order, rank, table, *out)
    origin, size, half_diagonal = boxes[0, :3].copy(), 0.25, 0.125 * math.sqrt(3.0)
    keys = cell_keys(points, origin, 1.0 / size)
    keys = keys[keys >= 0]
    keys = keys[np.argsort(z_order(keys))]
    triangles, squared, found = np.empty((len(keys), 4), dtype=np.int64), np.empty((len(keys), 4)), np.empty(len(keys), dtype=np.int64)
    fill_cells(keys, origin, size, half_diagonal, boxes, child, first, count, rank, table, triangles, squared, found)
    kept = np.maximum(found, 0)
    begin = np.cumsum(kept) - kept
    slots = np.full((8, 2), EMPTY, dtype=np.int64)
    insert_cells(keys, begin * COUNT_FACTOR + found + 1, slots)
    lookup_all(keys, slots)
    rows = np.arange(4) < kept[:, None]
    candidates, bounds = triangles[rows].astype(np.int32), np.sqrt(squared[rows]).astype(np.float32)
    pseudonormals = np.zeros((4, 7, 3))
    pseudonormals[:, :, 2] = 1.0
    signed = (np.empty(n), np.empty((n, 3)), np.empty((n, 3)), np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int8))
    for use_cells, fill_missing in ((False, False), (True, True), (True, False)):
        signed_kernel(points, hints, pseudonormals, boxes, child, first, count, order, rank, table, use_cells,
                      fill_missing, origin, size, half_diagonal, slots, candidates, bounds, *signed)
