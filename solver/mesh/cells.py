"""Candidate faces per cell of space: exact closest points for points that come back.

Convention: points ``(N, 3) float64`` in meters; cells are the cubes of edge ``size`` of a
grid anchored at the mesh's lower corner, cell ``(i, j, k)`` centred at
``origin + size * (i + 1/2, j + 1/2, k + 1/2)``.

Why: a solver asks for the closest points of the same particles every iteration, and they
move little. A search down the tree (:mod:`.bvh`) visits ~25 nodes and ~10 triangles per
point (~1 us); a cell that remembers which faces can hold the closest point of any point in
it answers with 3-4 triangle tests (2-4x faster, ``bench/closest_point.py``).

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
candidates (one nearest-first search of the tree whose reach shrinks with the nearest face
found, ~3 us), later ones reuse them. A cache
belongs to one solve (:class:`~hairport.solver.adaptation.problem.constraints.BodyDistance`), so
it holds the cells its hair visits; :data:`MAX_CACHED_CANDIDATES` bounds it (it starts
over when full). The kernels are in :mod:`.closest_kernels`.
"""

from __future__ import annotations

import math

import numpy as np

from hairport.solver.mesh.bvh import TriangleTree
from hairport.solver.mesh.closest_kernels import (
    CELL_SLACK,
    COUNT_FACTOR,
    EMPTY,
    cell_keys,
    fill_cells,
    insert_cells,
    lookup_all,
    z_order,
)

#: default cell edge (m): at 3 mm a point scans 2.7 faces on a groom's particles within 2 cm
#: of the MakeHuman body, 3.8 on a 10^5 retarget's queries (9-11 candidates per cell);
#: smaller cells scan fewer but need more filling, larger the reverse (2-5 mm measured
#: within 10 % of one another on that retarget's queries)
DEFAULT_CELL_SIZE = 3e-3

#: candidates a cell keeps at most (below :data:`~.closest_kernels.COUNT_FACTOR` - 1); a cell
#: that would need more answers by the tree
MAX_CANDIDATES = 64

#: candidates over all cells of one cache at most (8 bytes each: 64 MiB; the particles of a
#: 10^6 "long" groom within 2 cm of the body fill 0.53 M, a 10^5 retarget's fine level 0.6 M);
#: the cache starts over when a fill would pass it
MAX_CACHED_CANDIDATES = 1 << 23

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
        their filling batch (neighbouring cells close in memory); a view of a buffer that
        grows by doubling.
    bounds : (E,) float32
        ``|c - f|`` rounded down (less :data:`~.closest_kernels.CELL_SLACK`), increasing within a cell.
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
        self.slots = np.full((1 << 12, 2), EMPTY, dtype=np.int64)
        self.n_cells = 0
        self.n_candidates = 0
        self._candidates = np.zeros(1 << 12, dtype=np.int32)
        self._bounds = np.zeros(1 << 12, dtype=np.float32)

    @property
    def candidates(self) -> np.ndarray:
        return self._candidates[: self.n_candidates]

    @property
    def bounds(self) -> np.ndarray:
        return self._bounds[: self.n_candidates]

    @property
    def nbytes(self) -> int:
        """Bytes the cache holds (its buffers' capacity)."""
        return self.slots.nbytes + self._candidates.nbytes + self._bounds.nbytes

    def fill(self, points: np.ndarray) -> None:
        """Find the candidates of the cells of ``points (M, 3)`` not cached yet."""
        keys = np.unique(cell_keys(np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3),
                                    self.origin, 1.0 / self.size))
        keys = keys[keys >= 0]
        keys = keys[lookup_all(keys, self.slots) == EMPTY]
        keys = keys[np.argsort(z_order(keys))]
        for start in range(0, len(keys), FILL_CHUNK):
            self._fill_keys(keys[start : start + FILL_CHUNK])

    def _fill_keys(self, keys: np.ndarray) -> None:
        tree = self.tree
        triangles = np.empty((len(keys), MAX_CANDIDATES), dtype=np.int64)
        squared = np.empty((len(keys), MAX_CANDIDATES))
        found = np.empty(len(keys), dtype=np.int64)
        fill_cells(keys, self.origin, self.size, self.half_diagonal, tree.boxes, tree.child, tree.first,
                     tree.count, tree.rank, tree.table, triangles, squared, found)
        kept = np.maximum(found, 0)
        if self.n_candidates + kept.sum() > MAX_CACHED_CANDIDATES:
            self._clear()
        rows = np.arange(MAX_CANDIDATES) < kept[:, None]
        begin = self.n_candidates + np.cumsum(kept) - kept
        end = self.n_candidates + int(kept.sum())
        if end > len(self._candidates):
            capacity = max(end, 2 * len(self._candidates))
            self._candidates = np.concatenate([self.candidates, np.zeros(capacity - self.n_candidates, np.int32)])
            self._bounds = np.concatenate([self.bounds, np.zeros(capacity - self.n_candidates, np.float32)])
        self._candidates[self.n_candidates : end] = triangles[rows]
        self._bounds[self.n_candidates : end] = _lower_float32(np.sqrt(squared[rows]) - CELL_SLACK)
        self.n_candidates = end
        self.n_cells += len(keys)
        capacity = len(self.slots)
        if 2 * self.n_cells > capacity:
            while 2 * self.n_cells > capacity:
                capacity *= 2
            old = self.slots[self.slots[:, 0] != EMPTY]
            self.slots = np.full((capacity, 2), EMPTY, dtype=np.int64)
            # contiguous columns: the kernel's one compiled (and warmed) signature
            insert_cells(np.ascontiguousarray(old[:, 0]), np.ascontiguousarray(old[:, 1]), self.slots)
        insert_cells(keys, begin * COUNT_FACTOR + found + 1, self.slots)


def _lower_float32(values: np.ndarray) -> np.ndarray:
    """float32 values at or below ``values (E,) float64``."""
    rounded = values.astype(np.float32)
    above = rounded.astype(np.float64) > values
    rounded[above] = np.nextafter(rounded[above], np.float32(-np.inf))
    return rounded
