"""Section 7.5's alternatives to the embedded membrane for hair-root relocation (harmonic, 2D and 3D
thin-plate RBF displacements).

Convention: the scalp is a triangle mesh with rest positions ``rest (n, 3) float64``
(meters) on the head, ``triangles (m, 3) int64`` and rest parameters ``u_rest (n, 2)
float64`` in the head's parameterization (uv units, :mod:`hairport.solver.mesh.parameterization`). The
hairline is pinned: ``fixed (n,) bool`` marks its vertices and ``u_fixed (k, 2) float64``
(``x_fixed (k, 3)`` in 3D) gives their new places, in the order of
``np.flatnonzero(fixed)``. Every method returns the new place of every vertex, the fixed
ones exactly at their targets.

The paper (Section 7.5, Figures 13 and 16, Table 3) compares the membrane of Eq. 15
(:func:`.newton.relocate`) with three models of how the scalp's interior follows the
hairline:

``harmonic`` (:func:`harmonic_displacement`)
    The displacement ``u - u_rest`` is harmonic on the parameterized scalp mesh: the
    cotangent Laplacian of the *uv* triangles, Dirichlet values on the fixed vertices ("the
    same boundary conditions as our embedded membrane"). The weights come from the uv
    triangles, so the result depends on the parameterization (Figure 16, LSCM vs ARAP).
``rbf2d`` (:func:`rbf_displacement_2d`)
    A thin-plate-spline RBF interpolation of the 2D displacement in uv, fitted to the
    fixed vertices' displacements and to zero displacements at a sparse set of interior
    vertices (:func:`interior_seeds`).
``rbf3d`` (:func:`rbf_displacement_3d`, Figure 13d)
    The same in 3D on the rest positions; the displaced vertices leave the head and the
    caller reprojects them onto it.

The thin-plate splines use SciPy's :class:`~scipy.interpolate.RBFInterpolator` with its
default degree-1 polynomial term, so they reproduce affine displacement fields exactly.

Bad input raises :class:`~hairport.solver.model.errors.InputError` with ``code="bad_relocation"`` (:mod:`.checks`).
"""

from __future__ import annotations

import igl
import numpy as np
import scipy.sparse.linalg as spla
from scipy.interpolate import RBFInterpolator
from scipy.sparse.csgraph import connected_components, dijkstra

from hairport.solver.hairline.checks import check_pins, check_points, check_triangles, index_array, refuse
from hairport.solver.mesh.topology import vertex_adjacency

#: interior vertices pinned at zero displacement by the RBF alternatives. The paper only
#: says "a sparse set"; a dozen spread over the scalp's core (the vertices at least half
#: the deepest hop distance from the hairline) keeps the crown from drifting with the
#: hairline while leaving the band between hairline and core free to absorb the motion;
#: many more would turn the field into a step between a moved hairline and a pinned core
RBF_INTERIOR_SEEDS = 12
#: radial basis function of both RBF alternatives (Section 7.5: "TPS")
RBF_KERNEL = "thin_plate_spline"
#: a scalp vertex belongs to the core sampled by :func:`interior_seeds` when its hop
#: distance from the boundary loop is at least this share of the largest one
CORE_DEPTH_SHARE = 0.5
def harmonic_displacement(
    u_rest: np.ndarray, triangles: np.ndarray, fixed: np.ndarray, u_fixed: np.ndarray
) -> np.ndarray:
    """The hairline motion extended harmonically over the parameterized scalp (Section 7.5).

    Solves ``L d = 0`` on the free vertices with ``d = u_fixed - u_rest[fixed]`` on the
    fixed ones, ``L`` the cotangent Laplacian of the scalp's *uv* triangles
    (``igl.cotmatrix`` takes the ``(n, 2)`` parameters directly), and returns
    ``u_rest + d``. Harmonic fields reproduce affine ones, so a hairline moved by an affine
    map of the plane moves every vertex by it (cotangent weights are exact for linear
    functions). Vertices of scalp pieces holding no fixed
    vertex (and vertices in no triangle) keep ``d = 0``.

    Parameters
    ----------
    u_rest : (n, 2) float64
        Rest parameters of the scalp vertices (uv units).
    triangles : (m, 3) int64
        Scalp triangles, none degenerate in uv.
    fixed : (n,) bool
        The pinned (hairline) vertices.
    u_fixed : (k, 2) float64
        Their new parameters, ``k = fixed.sum()``, in the order of ``np.flatnonzero(fixed)``.

    Returns
    -------
    u : (n, 2) float64
        New parameters; ``u[fixed] == u_fixed`` exactly.

    Raises
    ------
    InputError
        Bad shapes or ids, non-finite values, degenerate uv triangles or a singular system.
    """
    source = "harmonic_displacement"
    u_rest = check_points(u_rest, 2, "u_rest", source)
    n = len(u_rest)
    triangles = check_triangles(triangles, n, source)
    if len(triangles) == 0:
        raise refuse("the scalp has no triangles", source)
    fixed, u_fixed = check_pins(fixed, u_fixed, n, 2, source)

    _, piece = connected_components(vertex_adjacency(triangles, n), directed=False)
    anchored = np.bincount(piece, weights=fixed.astype(np.float64)) > 0
    free = anchored[piece] & ~fixed
    displacement = np.zeros((n, 2))
    displacement[fixed] = u_fixed - u_rest[fixed]
    if free.any():
        laplacian = igl.cotmatrix(np.ascontiguousarray(u_rest), triangles).tocsr()
        if not np.isfinite(laplacian.data).all():
            raise refuse("the scalp has degenerate triangles in uv (infinite cotangent weights)", source)
        rows = laplacian[free]
        rhs = -(rows[:, fixed] @ displacement[fixed])
        try:
            factor = spla.splu(rows[:, free].tocsc())
        except RuntimeError as error:
            raise refuse(f"the cotangent Laplacian of the free vertices is singular ({error})", source) from None
        displacement[free] = factor.solve(rhs)
        if not np.isfinite(displacement).all():
            raise refuse("the harmonic solve gave non-finite displacements", source)
    u = u_rest + displacement
    u[fixed] = u_fixed
    return u


def _rbf_displacement(points: np.ndarray, fixed, targets, seeds, source: str) -> np.ndarray:
    """TPS interpolation of ``targets - points[fixed]`` and zero at ``seeds``, applied to ``points``."""
    n, dim = points.shape
    fixed, targets = check_pins(fixed, targets, n, dim, source)
    seeds = index_array(seeds, 1, "seeds", source)
    if seeds.size and (seeds.min() < 0 or seeds.max() >= n):
        raise refuse(f"seeds index vertices outside 0 .. {n - 1}", source)
    seeds = np.unique(seeds)
    if fixed[seeds].any():
        raise refuse(f"seeds {seeds[fixed[seeds]][:5].tolist()} are fixed vertices", source)
    data = np.concatenate([np.flatnonzero(fixed), seeds])
    if len(data) < dim + 1:
        raise refuse(f"a thin-plate spline in {dim}D needs at least {dim + 1} fixed vertices and seeds, "
                      f"got {len(data)}", source)
    values = np.zeros((len(data), dim))
    values[: int(fixed.sum())] = targets - points[fixed]
    out = points.copy()
    out[fixed] = targets
    rest = np.ones(n, dtype=bool)
    rest[data] = False
    if rest.any():
        try:
            field = RBFInterpolator(points[data], values, kernel=RBF_KERNEL)
        except np.linalg.LinAlgError as error:
            raise refuse(f"the thin-plate spline's system is singular (fixed vertices and seeds "
                          f"collinear/coplanar or repeated?): {error}", source) from None
        out[rest] = points[rest] + field(points[rest])
    return out


def rbf_displacement_2d(
    u_rest: np.ndarray, fixed: np.ndarray, u_fixed: np.ndarray, seeds: np.ndarray
) -> np.ndarray:
    """Thin-plate-spline interpolation of the hairline motion in the parameterization (Section 7.5).

    The data are the fixed vertices with their prescribed displacements and the seeds with
    zero displacement; every other vertex moves by the interpolated field.

    Parameters
    ----------
    u_rest : (n, 2) float64
        Rest parameters of the scalp vertices (uv units).
    fixed : (n,) bool
        The pinned (hairline) vertices.
    u_fixed : (k, 2) float64
        Their new parameters, ``k = fixed.sum()``, in the order of ``np.flatnonzero(fixed)``.
    seeds : (s,) int64
        Interior vertices held at zero displacement (:func:`interior_seeds`); not fixed.

    Returns
    -------
    u : (n, 2) float64
        New parameters; ``u[fixed] == u_fixed`` and ``u[seeds] == u_rest[seeds]`` exactly.

    Raises
    ------
    InputError
        Bad shapes or ids, non-finite values, seeds that are fixed, fewer than 3 data
        points or a singular system (collinear or repeated data points).
    """
    u_rest = check_points(u_rest, 2, "u_rest", "rbf_displacement_2d")
    return _rbf_displacement(u_rest, fixed, u_fixed, seeds, "rbf_displacement_2d")


def rbf_displacement_3d(
    rest: np.ndarray, fixed: np.ndarray, x_fixed: np.ndarray, seeds: np.ndarray
) -> np.ndarray:
    """Thin-plate-spline interpolation of the hairline motion in 3D (Section 7.5, Figure 13d).

    As :func:`rbf_displacement_2d` on the rest positions with 3D displacements. The result
    is off the head in general; the caller reprojects it.

    Parameters
    ----------
    rest : (n, 3) float64
        Rest positions of the scalp vertices (m).
    fixed : (n,) bool
        The pinned (hairline) vertices.
    x_fixed : (k, 3) float64
        Their new positions (m), ``k = fixed.sum()``, in the order of ``np.flatnonzero(fixed)``.
    seeds : (s,) int64
        Interior vertices held at zero displacement (:func:`interior_seeds`); not fixed.

    Returns
    -------
    x : (n, 3) float64
        Displaced positions (m); ``x[fixed] == x_fixed`` and ``x[seeds] == rest[seeds]`` exactly.

    Raises
    ------
    InputError
        Bad shapes or ids, non-finite values, seeds that are fixed, fewer than 4 data
        points or a singular system (coplanar or repeated data points).
    """
    rest = check_points(rest, 3, "rest", "rbf_displacement_3d")
    return _rbf_displacement(rest, fixed, x_fixed, seeds, "rbf_displacement_3d")


def interior_seeds(
    triangles: np.ndarray, boundary: np.ndarray, rest: np.ndarray, count: int = RBF_INTERIOR_SEEDS
) -> np.ndarray:
    """A sparse, well-spread set of interior scalp vertices to hold still (Section 7.5).

    The candidates are the scalp's core: vertices whose edge-hop distance from the
    boundary loop is at least :data:`CORE_DEPTH_SHARE` of the largest one (vertices not
    connected to the boundary are left out). Farthest-point sampling in 3D (Euclidean on
    ``rest``) picks ``count`` of them, starting from the deepest core vertex (lowest id
    among ties; later ties also go to the lowest id), so the result is deterministic.

    Parameters
    ----------
    triangles : (m, 3) int64
        Scalp triangles.
    boundary : (b,) int64
        The boundary loop's vertices (any order).
    rest : (n, 3) float64
        Rest positions of the scalp vertices (m).
    count : int
        How many to pick; all candidates when there are fewer.

    Returns
    -------
    seeds : (s,) int64
        Ascending vertex ids, ``s = min(count, candidates)``; empty when no vertex is off
        the boundary.

    Raises
    ------
    InputError
        Bad shapes or ids, an empty boundary or a negative count.
    """
    source = "interior_seeds"
    rest = check_points(rest, 3, "rest", source)
    n = len(rest)
    triangles = check_triangles(triangles, n, source)
    boundary = index_array(boundary, 1, "boundary", source)
    if boundary.size == 0:
        raise refuse("the boundary loop is empty", source)
    if boundary.min() < 0 or boundary.max() >= n:
        raise refuse(f"boundary indexes vertices outside 0 .. {n - 1}", source)
    if not isinstance(count, (int, np.integer)) or count < 0:
        raise refuse(f"count must be a non-negative integer, got {count!r}", source)
    count = int(count)

    hops = dijkstra(vertex_adjacency(triangles, n), directed=False, indices=np.unique(boundary),
                    unweighted=True, min_only=True)
    reached = np.isfinite(hops)
    deepest = hops[reached].max()
    if deepest == 0 or count == 0:
        return np.zeros(0, dtype=np.int64)
    core = np.flatnonzero(reached & (hops >= CORE_DEPTH_SHARE * deepest))
    if len(core) <= count:
        return core
    points = rest[core]
    picked = np.zeros(len(core), dtype=bool)
    first = int(np.argmax(hops[core]))
    picked[first] = True
    gap = np.linalg.norm(points - points[first], axis=1)
    for _ in range(count - 1):
        nxt = int(np.argmax(np.where(picked, -np.inf, gap)))
        picked[nxt] = True
        gap = np.minimum(gap, np.linalg.norm(points - points[nxt], axis=1))
    return core[picked]
