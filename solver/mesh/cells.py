"""Candidate faces per cell of space: exact closest points for points that come back.

Convention: points ``(N, 3) float64`` in meters; cells are the cubes of edge ``size`` of a
grid anchored at the mesh's lower corner, cell ``(i, j, k)`` centred at
``origin + size * (i + 1/2, j + 1/2, k + 1/2)``.

Why: a solver asks for the closest points of the same particles every iteration, and they
move little. A search down the tree (:mod:`.bvh`) visits ~20 nodes and ~10 triangles per
point (~1 us); a cell that remembers which faces can hold the closest point of any point in
it answers with a few triangle tests.

Which faces: let ``c`` be the centre of a cell, ``r`` its half-diagonal and ``u`` the
unsigned distance to the mesh. For a point ``p`` in the cell, its closest face ``f`` has
``|p - f| = u(p) <= u(c) + |p - c|``, hence ``|c - f| <= u(p) + |p - c| <= u(c) + 2 r``. The
cell keeps every face within ``u(c) + 2 r`` of ``c`` (ties included), in increasing order
of ``|c - f|``. A point scans them and stops at the first face with
``|c - f| - |p - c| >= best``: no face from there on can be closer (1-Lipschitz), so the
answer is the tree's (a face at exactly the same distance, a tie, may be another one).
A cell with more than :data:`MAX_CANDIDATES` such faces (deep inside a body, far from it)
sends its points to the tree.

Cells are filled on demand: the first query of a point in a cell not yet seen finds its
candidates (a closest-point and a ball search in the tree), later ones reuse them. A cache
belongs to one solve (:class:`~hairport.solver.adaptation.constraints.BodyDistance`), so
it holds the cells its hair visits; :data:`MAX_CACHED_CANDIDATES` bounds it (it starts
over when full).
"""

from __future__ import annotations

import math

import numpy as np

from hairport.solver.jit import kernel, parallel_kernel, prange, warms
from hairport.solver.mesh.bvh import STACK_DEPTH, TriangleTree, _faces_within, _search, _triangle_closest, build_tree

#: default cell edge (m): hair 0-2 cm from the body scans ~3-6 faces per point at 3 mm
#: (``bench/closest_point.py``); smaller cells mean more cells to fill
DEFAULT_CELL_SIZE = 3e-3

#: candidates a cell keeps at most; a cell that would need more answers by the tree
MAX_CANDIDATES = 64

#: candidates over all cells of one cache at most (12 bytes each: ~200 MB); the cache
#: starts over when a fill would pass it
MAX_CACHED_CANDIDATES = 1 << 24

#: meters by which the candidate radius is grown and the stored lower bounds lowered: far
#: above the round-off of distances between points ~1 m apart (~1e-15 m), far below any
#: spacing of faces, so rounding never drops a face that could be the closest
CELL_SLACK = 1e-10

#: cell indices span ``[-2^20, 2^20)`` on each axis (21 bits, packed in one int64 key);
#: points beyond (kilometres away) go to the tree
_AXIS_BITS = 21
_AXIS_OFFSET = 1 << (_AXIS_BITS - 1)
_AXIS_MASK = (1 << _AXIS_BITS) - 1

#: key of an empty hash slot; cell state of a point whose cell is not cached yet
_EMPTY = -1
MISSING = -2

#: the count of a packed slot value: ``begin * _COUNT_FACTOR + count + 1`` (above
#: :data:`MAX_CANDIDATES` + 1)
_COUNT_FACTOR = 1 << 10

#: cells filled per call of the fill kernel (bounds its (cells, MAX_CANDIDATES) buffers)
FILL_CHUNK = 1 << 14


class CellCache:
    """Candidate faces of the cells that queries visited (see the module docstring).

    Parameters
    ----------
    tree : TriangleTree
        Of the mesh.
    size : float
        Cell edge (m), > 0.

    Attributes
    ----------
    slots : (C, 2) int64
        Open-addressing hash table (``C`` a power of two, at most half full): per slot the
        cell's key (``-1`` empty) and ``begin * 1024 + count + 1`` of its candidates
        (``count = -1``: the cell is answered by the tree).
    candidates : (E,) int32
        Triangles in the tree's leaf order, cell after cell, the cells in Z-curve order of
        their filling batch (neighbouring cells close in memory).
    bounds : (E,) float32
        ``|c - f|`` rounded down (less :data:`CELL_SLACK`), increasing within a cell.
    """

    def __init__(self, tree: TriangleTree, size: float = DEFAULT_CELL_SIZE):
        size = float(size)
        if not (math.isfinite(size) and size > 0):
            raise ValueError(f"cell size must be finite and > 0, got {size}")
        self.tree = tree
        self.size = size
        self.origin = np.ascontiguousarray(tree.boxes[0, :3])
        self.half_diagonal = 0.5 * size * math.sqrt(3.0)
        self._clear()

    def _clear(self) -> None:
        self.slots = np.full((1 << 12, 2), _EMPTY, dtype=np.int64)
        self.n_cells = 0
        self.candidates = np.zeros(0, dtype=np.int32)
        self.bounds = np.zeros(0, dtype=np.float32)

    @property
    def n_candidates(self) -> int:
        return len(self.candidates)

    def fill(self, points: np.ndarray) -> None:
        """Find the candidates of the cells of ``points (M, 3)`` not cached yet."""
        keys = np.unique(_cell_keys(np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3),
                                    self.origin, 1.0 / self.size))
        keys = keys[keys >= 0]
        keys = keys[_lookup_all(keys, self.slots) == _EMPTY]
        keys = keys[np.argsort(_z_order(keys))]
        for start in range(0, len(keys), FILL_CHUNK):
            self._fill_keys(keys[start : start + FILL_CHUNK])

    def _fill_keys(self, keys: np.ndarray) -> None:
        tree = self.tree
        triangles = np.empty((len(keys), MAX_CANDIDATES), dtype=np.int64)
        squared = np.empty((len(keys), MAX_CANDIDATES))
        found = np.empty(len(keys), dtype=np.int64)
        _fill_kernel(keys, self.origin, self.size, self.half_diagonal, tree.boxes, tree.child, tree.first,
                     tree.count, tree.rank, tree.table, triangles, squared, found)
        kept = np.maximum(found, 0)
        if self.n_candidates + kept.sum() > MAX_CACHED_CANDIDATES:
            self._clear()
        rows = np.arange(MAX_CANDIDATES) < kept[:, None]
        begin = self.n_candidates + np.concatenate([[0], np.cumsum(kept)[:-1]])
        self.candidates = np.concatenate([self.candidates, triangles[rows].astype(np.int32)])
        self.bounds = np.concatenate([self.bounds, _lower_float32(np.sqrt(squared[rows]) - CELL_SLACK)])
        self.n_cells += len(keys)
        capacity = len(self.slots)
        if 2 * self.n_cells > capacity:
            while 2 * self.n_cells > capacity:
                capacity *= 2
            old = self.slots[self.slots[:, 0] != _EMPTY]
            self.slots = np.full((capacity, 2), _EMPTY, dtype=np.int64)
            _insert(old[:, 0], old[:, 1], self.slots)
        _insert(keys, begin * _COUNT_FACTOR + found + 1, self.slots)


def _lower_float32(values: np.ndarray) -> np.ndarray:
    """float32 values at or below ``values (E,) float64``."""
    rounded = values.astype(np.float32)
    above = rounded.astype(np.float64) > values
    rounded[above] = np.nextafter(rounded[above], np.float32(-np.inf))
    return rounded


@kernel
def _hash_slot(key, capacity):
    """First probe slot of ``key`` in a table of ``capacity`` (a power of two) slots."""
    mixed = np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)
    return np.int64(mixed >> np.uint64(40)) & (capacity - 1)


@kernel
def _lookup(key, slots):
    """The packed candidates of the cell ``key`` (see :class:`CellCache`), or ``_EMPTY``."""
    capacity = len(slots)
    slot = _hash_slot(key, capacity)
    while True:
        stored = slots[slot, 0]
        if stored == key:
            return slots[slot, 1]
        if stored == _EMPTY:
            return _EMPTY
        slot = (slot + 1) & (capacity - 1)


@kernel
def _lookup_all(keys, slots):
    out = np.empty(len(keys), dtype=np.int64)
    for i in range(len(keys)):
        out[i] = _lookup(keys[i], slots)
    return out


@kernel
def _insert(keys, values, slots):
    capacity = len(slots)
    for i in range(len(keys)):
        slot = _hash_slot(keys[i], capacity)
        while slots[slot, 0] != _EMPTY and slots[slot, 0] != keys[i]:
            slot = (slot + 1) & (capacity - 1)
        slots[slot, 0] = keys[i]
        slots[slot, 1] = values[i]


@kernel
def _z_order(keys):
    """Z-curve (Morton) codes of packed cell keys: bit ``b`` of the three axis indices
    interleaved at bits ``3 b + 2 - axis``."""
    out = np.zeros(len(keys), dtype=np.int64)
    for i in range(len(keys)):
        code = 0
        for axis in range(3):
            index = (keys[i] >> (_AXIS_BITS * (2 - axis))) & _AXIS_MASK
            for bit in range(_AXIS_BITS):
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
        key = (key << _AXIS_BITS) | (np.int64(scaled) + _AXIS_OFFSET)
    return key


@kernel
def _cell_keys(points, origin, inverse_size):
    out = np.empty(len(points), dtype=np.int64)
    for i in range(len(points)):
        out[i] = _cell_key(points[i, 0], points[i, 1], points[i, 2], origin, inverse_size)
    return out


@kernel
def _cell_center(key, origin, size, axis):
    index = ((key >> (_AXIS_BITS * (2 - axis))) & _AXIS_MASK) - _AXIS_OFFSET
    return origin[axis] + size * (index + 0.5)


@parallel_kernel
def _fill_kernel(keys, origin, size, half_diagonal, boxes, child, first, count, rank, table,
                 out_triangles, out_squared, out_found):
    for cell in prange(len(keys)):
        stack = np.empty(STACK_DEPTH, dtype=np.int64)
        stack_squared = np.empty(STACK_DEPTH)
        cx = _cell_center(keys[cell], origin, size, 0)
        cy = _cell_center(keys[cell], origin, size, 1)
        cz = _cell_center(keys[cell], origin, size, 2)
        squared = _search(cx, cy, cz, -1, boxes, child, first, count, rank, table, stack, stack_squared)[1]
        radius = math.sqrt(squared) + 2.0 * half_diagonal + CELL_SLACK
        found = _faces_within(cx, cy, cz, radius * radius, boxes, child, first, count, table, stack,
                              out_triangles[cell], out_squared[cell])
        out_found[cell] = found
        if found > 1:
            order = np.argsort(out_squared[cell, :found])
            out_triangles[cell, :found] = out_triangles[cell, :found][order]
            out_squared[cell, :found] = out_squared[cell, :found][order]


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
def _cached_search(px, py, pz, hint, origin, size, inverse_size, half_diagonal, slots, candidates, bounds,
                   boxes, child, first, count, rank, table, stack, stack_squared):
    """Nearest triangle (leaf order) by the point's cell, else by the tree:
    ``(triangle or MISSING, squared, v, w)``; MISSING when the cell is not cached yet."""
    key = _cell_key(px, py, pz, origin, inverse_size)
    if key >= 0:
        packed = _lookup(key, slots)
        if packed == _EMPTY:
            return MISSING, np.inf, 0.0, 0.0
        found = packed % _COUNT_FACTOR - 1
        if found >= 0:
            cx = _cell_center(key, origin, size, 0)
            cy = _cell_center(key, origin, size, 1)
            cz = _cell_center(key, origin, size, 2)
            ox, oy, oz = px - cx, py - cy, pz - cz
            # a point a rounding away from its cell is still within the slack of the radius;
            # anything more (never, by construction) is left to the tree
            if ox * ox + oy * oy + oz * oz <= half_diagonal * half_diagonal * (1.0 + 1e-9):
                return _scan(px, py, pz, cx, cy, cz, packed // _COUNT_FACTOR, found, candidates, bounds, table)
    return _search(px, py, pz, hint, boxes, child, first, count, rank, table, stack, stack_squared)


@warms("hairport.solver.mesh.cells")
def _warm() -> None:
    vertices = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    cache = CellCache(build_tree(vertices, faces, leaf_faces=1), size=0.25)
    cache.fill(np.array([[0.2, 0.2, 0.2], [2.0, 0.0, 0.0], [np.nan, 0.0, 0.0]]))
