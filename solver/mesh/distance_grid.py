"""A conservative broad phase for distance queries: a signed distance grid over a mesh.

Convention: points are ``(N, 3) float64`` in meters; the grid is axis-aligned with cubic
cells of edge ``spacing`` (m), node ``(i, j, k)`` at ``origin + spacing * (i, j, k)``; node
values are signed distances (m, negative inside) computed by :meth:`.query.MeshQuery.signed_distance`,
exact (float64, libigl's AABB) at every node closer to the surface than the grid's
``exact_band``. Beyond ``exact_band`` a node holds a value of the right sign whose
magnitude is at least ``exact_band`` and at most the exact ``|distance|`` (a certified lower
bound; with ``exact_band=inf`` every node is exact).

Why: hair has up to 10^7 particles and most of them hang far from the body, while an exact
closest-point query costs ~1-10 us per point. :func:`near_mask` finds, for the cost of a few
gathers per point, the particles that *may* be within a band of the surface; only those need
the exact query. It never misses one (``True`` is the conservative answer).

The bound
---------
The unsigned distance ``u = |d|`` to any set is 1-Lipschitz: ``u(p) >= u(c) - |p - c|`` for
every node ``c``, and a stored value ``|v(c)| <= u(c)`` keeps that true. :meth:`DistanceGrid.lower_bound`
takes the largest of these over the 8 corners of the cell holding the point (the nearest
node is one of them, so it is never looser than the nearest-node bound), clamped at 0. For
a point inside the box where the corner values are exact, the bound is within
``2 * |p - nearest node| <= spacing * sqrt(3)`` of ``|d(p)|`` (reached only next to the
medial axis, where ``|d|`` has a ridge); next to a flat surface it is within ~0.69 spacing
(the worst case over cell positions and directions, found numerically). Points outside the
box use their projection onto the box (see :meth:`DistanceGrid.lower_bound`).

Build cost and the narrow band
------------------------------
An exact query costs ~9 us per node on the ~27k-face MakeHuman body for nodes spread over
its bounding box (far points visit many tree nodes): the 9 M nodes at 5 mm took ~80 s.
:meth:`DistanceGrid.build` therefore builds coarse to fine (~1 M exact queries, ~5 s on
that body; ``bench/distance_grid.py``): the coarsest grid is
exact; every finer node first gets a lower bound and a certain sign from the coarser grid,
and only nodes whose bound is below the band are queried exactly, the others keep the
bound. No node with ``|d| < exact_band`` is skipped (its bound is ``<= |d|``), so
:func:`near_mask` with ``band <= exact_band - spacing * sqrt(3)`` returns exactly what it
would on the fully exact grid (a far corner's stored value is still ``>= exact_band``).

Signs (:meth:`DistanceGrid.sign_where_certain`) hold where inside and outside change only
across the surface: a closed body (:attr:`.query.MeshQuery.closed`, also a collision
surface with extra shells, :mod:`.collision`). Over an open body (a bust cut at the chest)
inside also changes across the film closing the cut, where no surface is: the grid then
knows no sign (0 everywhere). The lower bound holds for any mesh.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hairport.solver.jit import kernel, parallel_kernel, prange, warms
from hairport.solver.mesh.query import MeshQuery

#: default grid spacing (m): edge of the cubic cells
DEFAULT_GRID_SPACING = 5e-3
#: default margin (m) by which the grid box extends the mesh's bounding box on every side;
#: points outside the box are bounded by their distance to it, so a margin above the band
#: (plus a cell diagonal) lets them all be excluded without an exact query
DEFAULT_GRID_MARGIN = 2e-2
#: default node cap (2^24 nodes, 128 MiB of float64 values); above it the spacing grows
MAX_GRID_NODES = 1 << 24
#: default distance (m) within which node values are exact; beyond, a certified lower bound
#: of the right sign (see the module docstring); ``inf`` for a fully exact grid
DEFAULT_EXACT_BAND = 2.5e-2
#: a grid of at most this many nodes is queried exactly at every node (the coarsest level)
COARSEST_NODES = 4096
#: nodes per MeshQuery.signed_distance call during the build (bounds the build's memory)
BUILD_CHUNK = 1 << 20
#: a sign counts as certain only where the lower bound exceeds this (m): far above the
#: round-off of the bound (~1e-16 m per meter of coordinates), far below any physical scale
SIGN_MARGIN = 1e-9
#: points per block in the numpy reference of the lower-bound evaluation (bounds its
#: temporaries, ~20 arrays of this size)
EVAL_CHUNK = 1 << 17

_SQRT3 = math.sqrt(3.0)


@dataclass(frozen=True, eq=False)
class DistanceGrid:
    """Signed distance at the nodes of an axis-aligned grid over a mesh (see the module docstring).

    Attributes
    ----------
    origin : (3,) float64
        Position (m) of node ``(0, 0, 0)``, the box's lower corner.
    spacing : float
        Cell edge (m), > 0.
    values : (nx, ny, nz) float64
        Signed distance (m, negative inside) at the nodes; each axis has at least 2 nodes.
        The box spans ``origin`` to ``origin + spacing * (shape - 1)`` (:attr:`upper`) and
        contains the mesh.
    exact_band : float
        Values with ``|v| < exact_band`` are exact; the others are lower bounds of the right
        sign with ``exact_band <= |v| <= |d|``. ``inf``: all exact.
    covers_mesh : bool
        Whether the box contains the whole mesh. A grid built over a region (the space the
        hair can reach) may not: points outside its box then get the bound 0 and an unknown
        sign, so the exact query decides for them.
    closed : bool
        Whether inside and outside change only across the surface (the query's
        :attr:`~.query.MeshQuery.closed`); if not, :meth:`sign_where_certain` knows no sign.
    """

    origin: np.ndarray
    spacing: float
    values: np.ndarray
    exact_band: float = field(default=math.inf)
    covers_mesh: bool = True
    closed: bool = True

    def __post_init__(self) -> None:
        origin = np.ascontiguousarray(self.origin, dtype=np.float64).reshape(3)
        values = np.ascontiguousarray(self.values, dtype=np.float64)
        spacing = float(self.spacing)
        if not (math.isfinite(spacing) and spacing > 0):
            raise ValueError(f"spacing must be finite and > 0, got {spacing}")
        if values.ndim != 3 or min(values.shape) < 2:
            raise ValueError(f"values must be (nx, ny, nz) with every axis >= 2, got shape {values.shape}")
        object.__setattr__(self, "origin", origin)
        object.__setattr__(self, "values", values)
        object.__setattr__(self, "spacing", spacing)
        object.__setattr__(self, "exact_band", float(self.exact_band))

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.values.shape

    @property
    def upper(self) -> np.ndarray:
        """(3,) float64: position (m) of the last node, the box's upper corner."""
        return self.origin + self.spacing * (np.array(self.values.shape, dtype=np.float64) - 1.0)

    @classmethod
    def build(
        cls,
        query: MeshQuery,
        spacing: float = DEFAULT_GRID_SPACING,
        margin: float = DEFAULT_GRID_MARGIN,
        max_nodes: int = MAX_GRID_NODES,
        exact_band: float = DEFAULT_EXACT_BAND,
        region: tuple[np.ndarray, np.ndarray] | None = None,
        near: np.ndarray | None = None,
        reach: float = math.inf,
    ) -> "DistanceGrid":
        """Grid over ``query``'s mesh: its vertices' bounding box grown by ``margin`` on every side.

        With ``region = (lo, hi)`` (two ``(3,)`` corners, m) the grid covers only that box's
        intersection with the mesh's: a hairstyle needs distances where its particles can
        go, not at the feet (the whole MakeHuman body at 5 mm takes ~4 s, the head and
        shoulders a fraction of it).

        Parameters
        ----------
        query : MeshQuery
            Of the (closed, for the signs) mesh.
        spacing : float
            Requested cell edge (m), > 0. If the box would need more than ``max_nodes`` nodes
            at this spacing, the spacing grows to the smallest one at which it fits, and the
            grid's ``spacing`` attribute says which one was used.
        margin : float
            Meters, >= 0.
        max_nodes : int
            At least 8.
        exact_band : float
            Meters, > 0: nodes with ``|d| < exact_band`` are exact, the others hold a
            certified lower bound of the right sign (coarse-to-fine build, far cheaper);
            ``inf`` queries every node exactly. :func:`near_mask` with ``band <= exact_band
            - spacing * sqrt(3)`` gives the same answer as on the fully exact grid.
        near : (P, 3) float64, optional
            With ``reach``: only the nodes within ``reach`` (m) of these points (a solve's first iterate, when its
            particles will not go far) are queried; the other nodes keep their coarser level's certified bound, so
            a point far from them is sent to the exact query more often, never answered wrongly. Every node
            within ``exact_band`` and ``reach`` is exact (:meth:`lower_bound` as on the full grid there).
        """
        spacing, margin, exact_band = float(spacing), float(margin), float(exact_band)
        if not (math.isfinite(spacing) and spacing > 0):
            raise ValueError(f"spacing must be finite and > 0, got {spacing}")
        if not (math.isfinite(margin) and margin >= 0):
            raise ValueError(f"margin must be finite and >= 0, got {margin}")
        if max_nodes < 8:
            raise ValueError(f"max_nodes must be at least 8, got {max_nodes}")
        if not exact_band > 0:
            raise ValueError(f"exact_band must be > 0, got {exact_band}")
        if len(query.vertices) == 0:
            raise ValueError("the mesh has no vertices")
        lo = query.vertices.min(axis=0) - margin
        hi = query.vertices.max(axis=0) + margin
        covers_mesh = True
        if region is not None:
            region_lo = np.asarray(region[0], dtype=np.float64).reshape(3)
            region_hi = np.asarray(region[1], dtype=np.float64).reshape(3)
            if not (np.isfinite(region_lo).all() and np.isfinite(region_hi).all()):
                raise ValueError("region corners must be finite")
            covers_mesh = bool(np.all(region_lo <= lo) and np.all(region_hi >= hi))
            lo, hi = np.maximum(lo, region_lo), np.minimum(hi, region_hi)
            if np.any(hi - lo <= spacing):
                # the region misses the mesh's box (or barely touches it): a minimal grid
                # there; every point outside it is checked exactly
                hi = np.maximum(hi, lo + 2 * spacing)
        spacing, shape = _fit_spacing(lo, hi, spacing, max_nodes)
        if near is not None:
            near = np.asarray(near, dtype=np.float64).reshape(-1, 3)
            near = near[np.isfinite(near).all(axis=1)]
            reach = float(reach)
            if not reach >= 0:
                raise ValueError(f"reach must be >= 0, got {reach}")
        values = _node_values(query, lo, spacing, shape, exact_band, near if math.isfinite(reach) else None, reach)
        return cls(lo, spacing, values, exact_band, covers_mesh, query.closed)

    def lower_bound(self, points: np.ndarray) -> np.ndarray:
        """A lower bound of ``|signed distance|`` at each point.

        Parameters
        ----------
        points : (N, 3) float64

        Returns
        -------
        bound : (N,) float64
            ``0 <= bound <= |d(p)|`` (0 for non-finite points). Inside the box: the largest
            ``|v(c)| - |p - c|`` over the corners ``c`` of the point's cell, clamped at 0
            (1-Lipschitz, see the module docstring). Outside the box:
            ``sqrt(dist(p, box)^2 + bound(p')^2)`` with ``p'`` the closest point of the box.

        Why the outside bound holds: the box ``B`` is convex and contains the mesh (it
        contains the vertices' bounding box, hence every triangle), so the closest surface
        point ``q`` of ``p`` lies in ``B``. ``p'``, the projection of ``p`` onto ``B``,
        satisfies ``(p - p') . (q - p') <= 0`` for every ``q`` in ``B``, hence
        ``|p - q|^2 = |p - p'|^2 + |p' - q|^2 - 2 (p - p') . (q - p') >= |p - p'|^2 + |p' - q|^2``;
        and ``|p' - q| >= |d(p')| >= bound(p')`` since ``q`` is on the surface. So
        ``|d(p)| = |p - q| >= sqrt(|p - p'|^2 + bound(p')^2)``, which is at least the
        distance to the box.
        """
        return self._evaluate(points, want_sign=False)[0]

    def sign_where_certain(self, points: np.ndarray) -> np.ndarray:
        """(N,) int8: +1 (outside) / -1 (inside) where the grid proves the sign, 0 where unknown.

        Inside the box the sign is certain when the best corner ``c`` of :meth:`lower_bound`
        has ``|v(c)| > |p - c|`` (by more than :data:`SIGN_MARGIN`, for round-off): the ball of
        radius ``|d(c)| >= |v(c)|`` around ``c`` holds no surface point, so the segment from
        ``c`` to ``p`` does not cross the surface and ``p`` has the sign of ``c``. Points outside the box are outside the (closed) mesh: +1.
        Points on or next to the surface get 0; every point gets 0 on a grid that is not
        :attr:`closed`.
        """
        return self._evaluate(points, want_sign=True)[1]

    def bound_and_sign(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`lower_bound` and :meth:`sign_where_certain` in one pass: ``(N,) float64``, ``(N,) int8``."""
        return self._evaluate(points, want_sign=True)

    def _evaluate(self, points: np.ndarray, want_sign: bool) -> tuple[np.ndarray, np.ndarray | None]:
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        bound = np.empty(len(points))
        sign = np.empty(len(points), dtype=np.int8)
        _bound_and_sign_kernel(self.values.reshape(-1), self.values.shape[0], self.values.shape[1],
                               self.values.shape[2], self.origin, self.spacing, points, self.covers_mesh,
                               self.closed, bound, sign)
        return bound, (sign if want_sign else None)

    def _evaluate_reference(self, points: np.ndarray, want_sign: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """:meth:`_evaluate` in numpy, block by block: the tested reference of the kernel."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        bound = np.empty(len(points))
        sign = np.empty(len(points), dtype=np.int8) if want_sign else None
        for start in range(0, len(points), EVAL_CHUNK):
            block = slice(start, start + EVAL_CHUNK)
            b, s = _bound_and_sign(self.values, self.origin, self.spacing, points[block], want_sign)
            if not self.covers_mesh:
                block_points = points[block]
                outside = np.any((block_points < self.origin) | (block_points > self.upper), axis=1)
                b[outside] = 0.0
                if want_sign:
                    s[outside] = 0
            bound[block] = b
            if want_sign:
                sign[block] = s if self.closed else 0
        return bound, sign


def near_mask(grid: DistanceGrid, points: np.ndarray, band: float) -> np.ndarray:
    """(N,) bool: points whose |signed distance| may be < band (True is conservative).

    ``True`` where ``grid.lower_bound(points) < band``: every point with ``|d| < band`` is in
    the mask; a point outside it is certainly at least ``band`` (m) from the surface.
    """
    return grid.lower_bound(points) < band


def _grid_shape(lo: np.ndarray, hi: np.ndarray, spacing) -> np.ndarray:
    """Nodes per axis, at least 2, so that the last node ``lo + spacing * (n - 1) >= hi`` up
    to 1e-12 of ``hi - lo`` (a quotient a few ulps above an integer gets no extra node; any
    margin covers the difference). ``spacing`` may be a (K,) array: then (K, 3)."""
    spacing = np.asarray(spacing, dtype=np.float64)[..., None]
    cells = (hi - lo) / spacing
    return (np.maximum(np.ceil(cells * (1.0 - 1e-12)), 1.0) + 1.0).astype(np.int64)


def _fit_spacing(lo: np.ndarray, hi: np.ndarray, spacing: float, max_nodes: int) -> tuple[float, tuple[int, int, int]]:
    """The smallest spacing >= ``spacing`` whose box over ``[lo, hi]`` has at most
    ``max_nodes`` nodes, and that box's shape.

    The node count only drops where ``extent / spacing`` crosses an integer, so after growing
    the spacing by the cube root of the excess until the box fits, the answer is the first
    fitting one among those crossings between the last spacing too fine and the fitting one.
    """
    shape = _grid_shape(lo, hi, spacing)
    if math.prod(shape.tolist()) <= max_nodes:
        return spacing, tuple(shape.tolist())
    too_fine, fits = spacing, spacing
    while math.prod(_grid_shape(lo, hi, fits).tolist()) > max_nodes:
        too_fine = fits
        fits = fits * max((math.prod(_grid_shape(lo, hi, fits).tolist()) / max_nodes) ** (1.0 / 3.0), 1.0 + 1e-6)
    extent = hi - lo
    candidates = [np.array([fits])]
    for e in extent[extent > 0]:
        k = np.arange(max(math.floor(e / fits), 1), math.ceil(e / too_fine) + 1, dtype=np.float64)
        candidates.append(e / k)  # k cells cover e
    candidates = np.concatenate(candidates)
    candidates = np.unique(candidates[(candidates > too_fine) & (candidates <= fits)])
    counts = np.prod(_grid_shape(lo, hi, candidates).astype(np.float64), axis=-1)
    best = float(candidates[np.argmax(counts <= max_nodes)])  # sorted: the first that fits
    return best, tuple(_grid_shape(lo, hi, best).tolist())


def _node_positions(origin: np.ndarray, spacing: float, shape: tuple[int, int, int], flat: np.ndarray) -> np.ndarray:
    """(K, 3) positions of the nodes with C-order flat indices ``flat``."""
    i, j, k = np.unravel_index(flat, shape)
    return origin + spacing * np.stack([i, j, k], axis=1).astype(np.float64)


def _exact_values(query: MeshQuery, origin, spacing, shape, flat: np.ndarray) -> np.ndarray:
    """Exact signed distance at the nodes ``flat``, in chunks of :data:`BUILD_CHUNK`."""
    out = np.empty(len(flat))
    for start in range(0, len(flat), BUILD_CHUNK):
        block = flat[start : start + BUILD_CHUNK]
        out[start : start + len(block)] = query.signed_distance(_node_positions(origin, spacing, shape, block)).distance
    return out


def _node_values(query: MeshQuery, origin, spacing, shape, exact_band, near: np.ndarray | None = None,
                 reach: float = math.inf) -> np.ndarray:
    """(nx, ny, nz) node values, exact within ``exact_band`` (and within ``reach`` of the points ``near``
    ``(P, 3)`` when given), else certified lower bounds.

    Coarse to fine: the grid with twice the spacing (nodes at the even indices, covering at
    least this box) gives every node here a lower bound and, where that is positive, a
    certain sign (:func:`_refine`); only nodes whose bound is below ``exact_band`` are
    queried. The coarser grid is built with a band, and a reach, larger by its cell diagonal,
    so that its own truncated nodes do not force extra queries here.
    """
    n = math.prod(shape)
    if n <= COARSEST_NODES or not math.isfinite(exact_band):
        return _exact_values(query, origin, spacing, shape, np.arange(n)).reshape(shape)
    coarse_shape = tuple(s // 2 + 1 for s in shape)
    widen = 2.0 * spacing * _SQRT3
    coarse = _node_values(query, origin, 2.0 * spacing, coarse_shape, exact_band + widen, near, reach + widen)
    values = _refine(coarse, spacing, shape)
    flat = values.reshape(-1)
    wanted = np.abs(flat) < exact_band
    if near is not None:
        wanted &= _nodes_near(origin, spacing, shape, near, reach).reshape(-1)
    todo = np.flatnonzero(wanted)
    flat[todo] = _exact_values(query, origin, spacing, shape, todo)
    return values


def _nodes_near(origin: np.ndarray, spacing: float, shape: tuple[int, int, int], points: np.ndarray,
                reach: float) -> np.ndarray:
    """``(nx, ny, nz) bool``: every node within ``reach`` (m) of a point ``(P, 3)`` (and some up to a cell
    diagonal farther): the corners of each point's cell, grown by ``ceil(reach / spacing)`` nodes along each axis
    (a point outside the box marks the cell it is nearest to)."""
    from scipy.ndimage import maximum_filter

    top = np.array(shape, dtype=np.int64) - 1
    cells = np.clip(np.floor((points - origin) * (1.0 / spacing)), 0, top).astype(np.int64)
    marked = np.zeros(shape, dtype=np.uint8)
    marked.reshape(-1)[(cells[:, 0] * shape[1] + cells[:, 1]) * shape[2] + cells[:, 2]] = 1
    # node n is near when a marked cell c has n - 1 - grow <= c <= n + grow: an even window, which scipy
    # places at [n - size // 2, n + size // 2 - 1]
    grow = int(math.ceil(reach / spacing))
    return maximum_filter(marked, size=2 * grow + 2, mode="constant").astype(bool)


def _refine(coarse: np.ndarray, spacing: float, shape: tuple[int, int, int]) -> np.ndarray:
    """Signed lower bounds at the nodes of the grid of spacing ``spacing`` and ``shape`` from
    the grid ``coarse`` of twice the spacing with the same origin (values exact or certified).

    A fine node with even index on every axis is a coarse node: its value is copied. Along
    an axis where its index is odd it lies halfway between two coarse nodes, so with ``k``
    odd axes it is at distance ``spacing * sqrt(k)`` from ``2^k`` coarse nodes; its bound is
    the largest ``|v|`` among them minus that distance (1-Lipschitz), with that node's sign
    when positive (the segment to it does not cross the surface), else 0. Slices only.
    """
    values = np.empty(shape)
    for parity in range(8):
        odd = [(parity >> (2 - axis)) & 1 for axis in range(3)]
        # per axis, the coarse index ranges of the neighbours: one (even) or two (odd)
        ranges = []
        for axis in range(3):
            n = shape[axis]
            if odd[axis]:
                m = n // 2
                ranges.append([slice(0, m), slice(1, m + 1)])
            else:
                ranges.append([slice(0, (n + 1) // 2)])
        best = None
        for sx in ranges[0]:
            for sy in ranges[1]:
                for sz in ranges[2]:
                    v = coarse[sx, sy, sz]
                    if best is None:
                        best, best_value = np.abs(v), v
                    else:
                        magnitude = np.abs(v)
                        better = magnitude > best
                        best = np.where(better, magnitude, best)
                        best_value = np.where(better, v, best_value)
        bound = best - spacing * math.sqrt(sum(odd))
        target = values[odd[0] :: 2, odd[1] :: 2, odd[2] :: 2]
        target[...] = np.where(bound > SIGN_MARGIN, np.copysign(bound, best_value), 0.0)
    return values


def _bound_and_sign(values: np.ndarray, origin: np.ndarray, spacing: float, points: np.ndarray, want_sign: bool = True):
    """Lower bound of ``|d|`` and certain sign (0 if unknown, None if not ``want_sign``) at
    ``points`` (one block)."""
    nx, ny, nz = values.shape
    flat_values = values.reshape(-1)
    finite = np.isfinite(points).all(axis=1)
    if not finite.all():
        points = np.where(finite[:, None], points, origin)
    away_sq = np.zeros(len(points))
    lower_sq, upper_sq, cells = [], [], []
    for axis, n in enumerate((nx, ny, nz)):
        x = points[:, axis]
        top = origin[axis] + spacing * (n - 1)
        inside = np.minimum(np.maximum(x, origin[axis]), top)  # p', the projection onto the box
        away_sq += (x - inside) ** 2
        t = (inside - origin[axis]) * (1.0 / spacing)
        cell = np.minimum(t.astype(np.intp), n - 2)  # t >= 0: truncation is floor
        frac = t - cell  # in [0, 1]: position in the cell, in cells
        cells.append(cell)
        lower_sq.append((frac * spacing) ** 2)  # squared offset (m^2) to the lower corner plane
        upper_sq.append(((1.0 - frac) * spacing) ** 2)
    base = (cells[0] * ny + cells[1]) * nz + cells[2]

    best = np.full(len(points), -np.inf)
    best_value = np.zeros(len(points)) if want_sign else None
    for corner in range(8):
        bits = ((corner >> 2) & 1, (corner >> 1) & 1, corner & 1)
        v = flat_values[base + (bits[0] * ny * nz + bits[1] * nz + bits[2])] if corner else flat_values[base]
        dist_sq = (upper_sq if bits[0] else lower_sq)[0] + (upper_sq if bits[1] else lower_sq)[1]
        dist_sq += (upper_sq if bits[2] else lower_sq)[2]
        candidate = np.abs(v)
        candidate -= np.sqrt(dist_sq, out=dist_sq)
        if want_sign:
            better = candidate > best
            best = np.where(better, candidate, best)
            best_value = np.where(better, v, best_value)
        else:
            np.maximum(best, candidate, out=best)

    certain = best > SIGN_MARGIN
    bound = np.maximum(best, 0.0)
    outside = away_sq > 0.0
    bound = np.where(outside, np.sqrt(away_sq + bound * bound), bound)
    sign = None
    if want_sign:
        sign = np.where(outside, 1, np.where(certain, np.sign(best_value), 0)).astype(np.int8)
    if not finite.all():
        bound[~finite] = 0.0
        if want_sign:
            sign[~finite] = 0
    return bound, sign


@kernel
def _along_axis(x, start, n, spacing, inverse):
    """One axis of :func:`_bound_and_sign`: ``(squared distance to the box, cell, squared offsets
    to the cell's lower and upper corner planes, outside the box)``."""
    top = start + spacing * (n - 1)
    inside = min(max(x, start), top)  # p', the projection onto the box
    t = (inside - start) * inverse
    cell = min(int(t), n - 2)  # t >= 0: truncation is floor
    frac = t - cell
    return (x - inside) ** 2, cell, (frac * spacing) ** 2, ((1.0 - frac) * spacing) ** 2, x < start or x > top


@parallel_kernel
def _bound_and_sign_kernel(values, nx, ny, nz, origin, spacing, points, covers_mesh, closed, out_bound, out_sign):
    """:func:`_bound_and_sign` point by point, in its operations, with :meth:`DistanceGrid._evaluate_reference`'s
    handling of a grid that does not cover the mesh or is not closed; ``values`` flat (C order)."""
    inverse = 1.0 / spacing
    for i in prange(len(points)):
        x0, x1, x2 = points[i, 0], points[i, 1], points[i, 2]
        if not (np.isfinite(x0) and np.isfinite(x1) and np.isfinite(x2)):
            out_bound[i], out_sign[i] = 0.0, 0
            continue
        away0, c0, low0, up0, out0 = _along_axis(x0, origin[0], nx, spacing, inverse)
        away1, c1, low1, up1, out1 = _along_axis(x1, origin[1], ny, spacing, inverse)
        away2, c2, low2, up2, out2 = _along_axis(x2, origin[2], nz, spacing, inverse)
        if (out0 or out1 or out2) and not covers_mesh:
            out_bound[i], out_sign[i] = 0.0, 0
            continue
        away_sq = 0.0 + away0
        away_sq += away1
        away_sq += away2
        base = (c0 * ny + c1) * nz + c2
        best, best_value = -np.inf, 0.0
        for corner in range(8):
            b0, b1, b2 = (corner >> 2) & 1, (corner >> 1) & 1, corner & 1
            v = values[base + (b0 * ny * nz + b1 * nz + b2)]
            dist_sq = (up0 if b0 else low0) + (up1 if b1 else low1)
            dist_sq += up2 if b2 else low2
            candidate = abs(v) - np.sqrt(dist_sq)
            if candidate > best:
                best, best_value = candidate, v
        bound = max(best, 0.0)
        if away_sq > 0.0:
            out_bound[i] = np.sqrt(away_sq + bound * bound)
            sign = 1
        else:
            out_bound[i] = bound
            sign = (1 if best_value > 0 else (-1 if best_value < 0 else 0)) if best > SIGN_MARGIN else 0
        out_sign[i] = sign if closed else 0


@warms
def _warm() -> None:
    values = np.arange(8, dtype=np.float64).reshape(2, 2, 2) - 3.5
    points = np.array([[0.5, 0.5, 0.5], [3.0, 0.0, 0.0], [np.nan, 0.0, 0.0]])
    bound, sign = np.empty(3), np.empty(3, dtype=np.int8)
    _bound_and_sign_kernel(values.reshape(-1), 2, 2, 2, np.zeros(3), 1.0, points, True, True, bound, sign)
