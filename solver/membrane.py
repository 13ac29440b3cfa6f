"""The scalp as a neo-Hookean membrane embedded in the head surface (Section 6.1, Eq. 15-19).

Convention: the head surface H is a triangle mesh ``head_vertices (h, 3) float64`` in
meters with ``head_faces (g, 3) int64`` and a 2D parameterisation ``head_uv (h, 2)
float64`` (a disk patch: injective, every triangle of positive signed area in uv), wrapped
in a :class:`HeadChart`. The scalp S is a separate triangle mesh with rest positions
``rest (n, 3)`` (meters) and ``triangles (m, 3) int64``, wrapped in a :class:`Membrane`.
Each deformed scalp vertex lives on H and is described by its parameter ``u (n, 2)`` in
uv units; its 3D position is the barycentric interpolation over its *host* triangle of H
(Eq. 18-19), so inside a host ``x`` is affine in ``u`` with the constant 3x2 Jacobian
``[X1 - X0 | X2 - X0] [u1 - u0 | u2 - u0]^-1``. Parameter vectors of length ``2n`` are
vertex-major (u0x u0y u1x u1y ...).

Energy (Eq. 15): ``E(u) = sum_t A_t psi(F_t)`` with ``F_t = d_t D_t^-1`` (3x2, Eq. 16-17)
and the neo-Hookean membrane density ``psi = mu/2 (tr C - 2) - mu ln J + lam/2 (ln J)^2``,
``C = F^T F``, ``J = sqrt(det C)``. Its derivatives in ``F`` (``G = F C^-1``, the
pseudo-inverse transpose of ``F``; ``Q = I - F C^-1 F^T`` the projector on the normal of
the deformed triangle)::

    P = dpsi/dF           = mu F + (lam ln J - mu) G
    dP_ia / dF_jb         = mu d_ij d_ab + lam G_ia G_jb
                            + (lam ln J - mu) (Q_ij Cinv_ab - G_ib G_ja)

The derivatives in ``u`` follow by the chain rule through ``F = sum_k x_k B_k``
(``B = [[-1, -1], [1, 0], [0, 1]] D^-1``) and the per-vertex Jacobians of the hosts
(``x`` affine in ``u`` while the hosts stay). ``lam`` is the membrane (plane-stress) Lame
parameter ``E nu / (1 - nu^2)``.

The energy is finite for a triangle flipped *on* the surface (``J`` only sees areas), so
:func:`relocate` keeps every scalp triangle's signed area in uv of its starting sign. As
``x(u)`` is only piecewise affine, ``E(u)`` has kinks along the head's edges, where a
stretched scalp's minimiser often puts vertices; :func:`relocate` treats them as an
active set (see there).

Since ``mu`` and ``lam`` are both proportional to Young's modulus for a fixed Poisson
ratio, ``E(u)`` scales linearly with it and its minimiser does not depend on it: any
positive value works (:data:`DEFAULT_YOUNG`); the stopping tests are scale-free.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .errors import InputError

#: Young's modulus (Pa); the minimiser of Eq. 15 does not depend on it (the energy is
#: linear in it at a fixed Poisson ratio), only the energy values reported do
DEFAULT_YOUNG = 1.0
#: Poisson ratio (dimensionless) of the scalp membrane, in-plane (plane stress). The paper
#: gives none. Root density is roots per area, so the membrane should resist area change
#: more than shape change: a nearly incompressible 0.45 (rubber-like) lowered Table 3's
#: average L1 over 8 grooms from 0.043 / 0.040 (nu = 0.3) to 0.041 / 0.035 (straight /
#: widow's peak), with the same L-infinity
DEFAULT_POISSON = 0.45
#: a point belongs to a triangle when its barycentric coordinates are all >= -this
BARYCENTRIC_TOLERANCE = 1e-12
#: uv triangles of the chart with |signed area| below this share of the mean are refused
DEGENERATE_AREA_SHARE = 1e-14
#: locator buckets: at most this many grid cells per chart triangle
CELLS_PER_TRIANGLE = 4
#: default Newton stopping tolerance on the largest parameter step (uv units); harmonic
#: disk maps span about one uv unit
DEFAULT_STEP_TOLERANCE = 1e-9
#: stop also when the squared Newton decrement ``-g . d`` falls below this share of
#: ``mu * (total rest area)`` (dimensionless; near the round-off of the energy itself)
DECREMENT_TOLERANCE = 1e-15
#: default relative energy decrease of one accepted step below which a stage has stalled
#: (converged): on the piecewise-linear head, vertices that reach a head edge make the
#: step test wait for ever shorter kink-limited steps that no longer change the energy
DEFAULT_ENERGY_TOLERANCE = 1e-7
#: a step cut below this fraction by the line search (a vertex meeting a head edge or the
#: fold barrier) ends the stage once it lowers the energy by less than SHORT_STEP_TOLERANCE
#: of it: such steps repeat at the same fraction for dozens of iterations, moving vertices
#: by micrometres
SHORT_STEP = 0.125
SHORT_STEP_TOLERANCE = 1e-6
#: the same for the intermediate load stages, whose results only start the next stage
STAGE_ENERGY_TOLERANCE = 1e-5
#: default cap on Newton iterations (all load stages together)
DEFAULT_MAX_ITERATIONS = 100
#: step halvings tried by the backtracking line search before giving up
MAX_BACKTRACKS = 40
#: Armijo sufficient-decrease constant (dimensionless)
ARMIJO = 1e-4
#: the free block of the projected Hessian is shifted by this share of its largest
#: diagonal entry (the PSD projection may leave it singular)
REGULARISATION_SHARE = 1e-10
#: diagonal shift of the unit-weight graph Laplacian (neighbour counts, ~6) in the
#: harmonic start, so that scalp pieces with no fixed vertex get zero motion
HARMONIC_SHIFT = 1e-12
#: a scalp triangle whose uv area falls below this share of its starting one meets the fold
#: barrier of :func:`fold_barrier`
FOLD_THRESHOLD = 0.1
#: weight of the fold barrier per triangle, in units of ``mu * A_t``: the barrier only grows
#: like a logarithm, and at 1 a triangle folded to 1e-4 of its uv area costs less than
#: the same triangle compressed three-fold in 3D
FOLD_STIFFNESS = 1000.0
#: boundary-motion fractions below this are not split further (load stepping, relocate)
MIN_LOAD_FRACTION = 1.0 / 1024.0


# ----------------------------------------------------------------------------------------
# head chart
# ----------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class HeadChart:
    """The head surface with its uv parameterisation and a bucket-grid point locator.

    Attributes
    ----------
    vertices : (h, 3) float64
        Head vertices (m).
    faces : (g, 3) int64
        Head triangles, positive signed area in uv.
    uv : (h, 2) float64
        Parameters of the head vertices (uv units).
    uv_inverse : (g, 2, 2) float64
        ``[u1 - u0 | u2 - u0]^-1`` per triangle (Eq. 19).
    jacobian : (g, 3, 2) float64
        ``dx/du`` inside each triangle (Eq. 18-19).
    origin : (2,) float64
        Lower corner of the bucket grid (uv).
    cell_size : float
        Side of a bucket (uv units).
    grid_shape : (2,) int64
        Buckets along u and v.
    cell_start : (cells + 1,) int64
        CSR offsets into ``cell_triangles`` per bucket (bucket id ``i * grid_shape[1] + j``).
    cell_triangles : (K,) int64
        Triangles whose uv bounding box meets each bucket.
    neighbours : (g, 3) int64
        Triangle across the edge opposite each corner, -1 on the chart's border.
    vertex_start : (h + 1,) int64
        CSR offsets into ``vertex_triangles`` per head vertex.
    vertex_triangles, vertex_corners : (3g,) int64
        Triangles around each head vertex and the vertex's corner in each.
    """

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    uv_inverse: np.ndarray = field(repr=False)
    jacobian: np.ndarray = field(repr=False)
    origin: np.ndarray = field(repr=False)
    cell_size: float = field(repr=False)
    grid_shape: np.ndarray = field(repr=False)
    cell_start: np.ndarray = field(repr=False)
    cell_triangles: np.ndarray = field(repr=False)
    neighbours: np.ndarray = field(repr=False)
    vertex_start: np.ndarray = field(repr=False)
    vertex_triangles: np.ndarray = field(repr=False)
    vertex_corners: np.ndarray = field(repr=False)

    @classmethod
    def build(cls, vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray) -> "HeadChart":
        """Precompute the per-triangle maps and the bucket grid.

        Parameters
        ----------
        vertices : (h, 3) float64
        faces : (g, 3) int
        uv : (h, 2) float64

        Raises
        ------
        InputError
            On bad shapes, non-finite values or a uv triangle that is degenerate or
            negatively oriented.
        """
        vertices = np.asarray(vertices, dtype=np.float64)
        faces = np.asarray(faces, dtype=np.int64)
        uv = np.asarray(uv, dtype=np.float64)
        if vertices.ndim != 2 or vertices.shape[1] != 3 or uv.shape != (len(vertices), 2):
            raise InputError("head vertices must be (h, 3) and uv (h, 2)", "head_chart")
        if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
            raise InputError("head faces must be a non-empty (g, 3) array", "head_chart")
        if faces.min() < 0 or faces.max() >= len(vertices):
            raise InputError("head faces index missing vertices", "head_chart")
        if not (np.isfinite(vertices).all() and np.isfinite(uv).all()):
            raise InputError("head vertices or uv are not finite", "head_chart", code="non_finite")
        corners = uv[faces]  # (g, 3, 2)
        edges = np.stack([corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]], axis=2)  # (g, 2, 2)
        det = edges[:, 0, 0] * edges[:, 1, 1] - edges[:, 0, 1] * edges[:, 1, 0]
        if (det <= DEGENERATE_AREA_SHARE * np.abs(det).mean()).any():
            raise InputError("the uv parameterisation has degenerate or flipped triangles", "head_chart")
        uv_inverse = np.stack(
            [np.stack([edges[:, 1, 1], -edges[:, 0, 1]], axis=1), np.stack([-edges[:, 1, 0], edges[:, 0, 0]], axis=1)],
            axis=1,
        ) / det[:, None, None]
        X = vertices[faces]
        spatial = np.stack([X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]], axis=2)  # (g, 3, 2)
        jacobian = spatial @ uv_inverse

        # uniform bucket grid over the triangles' uv bounding boxes
        low = corners.min(axis=1)
        high = corners.max(axis=1)
        origin = uv.min(axis=0)
        extent = np.maximum(uv.max(axis=0) - origin, np.finfo(float).tiny)
        cell_size = float(np.mean(np.max(high - low, axis=1)))
        cell_size = max(cell_size, float(np.sqrt(extent[0] * extent[1] / (CELLS_PER_TRIANGLE * len(faces)))))
        grid_shape = np.maximum(np.ceil(extent / cell_size).astype(np.int64), 1)
        pad = 1e-9 * cell_size
        first = np.clip(np.floor((low - pad - origin) / cell_size).astype(np.int64), 0, grid_shape - 1)
        last = np.clip(np.floor((high + pad - origin) / cell_size).astype(np.int64), 0, grid_shape - 1)
        span = last - first + 1  # (g, 2)
        count = span[:, 0] * span[:, 1]
        owner = np.repeat(np.arange(len(faces)), count)
        offset = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
        ci = first[owner, 0] + offset // span[owner, 1]
        cj = first[owner, 1] + offset % span[owner, 1]
        cell = ci * grid_shape[1] + cj
        order = np.argsort(cell, kind="stable")
        cell_start = np.zeros(int(grid_shape.prod()) + 1, dtype=np.int64)
        np.cumsum(np.bincount(cell, minlength=int(grid_shape.prod())), out=cell_start[1:])

        # edge adjacency: the edge opposite corner k joins corners k+1 and k+2
        g = len(faces)
        ends = np.stack([faces[:, [1, 2, 0]], faces[:, [2, 0, 1]]], axis=2).reshape(-1, 2)  # (3g, 2)
        key = np.sort(ends, axis=1)
        key = key[:, 0] * len(vertices) + key[:, 1]
        order_e = np.argsort(key, kind="stable")
        same = key[order_e[1:]] == key[order_e[:-1]]
        a, b = order_e[:-1][same], order_e[1:][same]
        neighbours = np.full(3 * g, -1, dtype=np.int64)
        neighbours[a] = b // 3
        neighbours[b] = a // 3
        # triangles around each vertex
        corner_vertex = faces.ravel()
        order_v = np.argsort(corner_vertex, kind="stable")
        vertex_start = np.zeros(len(vertices) + 1, dtype=np.int64)
        np.cumsum(np.bincount(corner_vertex, minlength=len(vertices)), out=vertex_start[1:])
        return cls(
            vertices=vertices,
            faces=faces,
            uv=uv,
            uv_inverse=uv_inverse,
            jacobian=jacobian,
            origin=origin,
            cell_size=cell_size,
            grid_shape=grid_shape,
            cell_start=cell_start,
            cell_triangles=owner[order],
            neighbours=neighbours.reshape(g, 3),
            vertex_start=vertex_start,
            vertex_triangles=order_v // 3,
            vertex_corners=order_v % 3,
        )

    def locate(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Host triangles and barycentric coordinates of parameters.

        Among several candidate triangles (a point on an edge) the one where the point is
        deepest inside (largest smallest barycentric coordinate) is chosen.

        Parameters
        ----------
        u : (n, 2) float64

        Returns
        -------
        host : (n,) int64
            Head triangle containing each point, -1 outside the chart.
        barycentric : (n, 3) float64
            Weights of the host's corners (NaN outside the chart).
        """
        u = np.asarray(u, dtype=np.float64).reshape(-1, 2)
        n = len(u)
        host = np.full(n, -1, dtype=np.int64)
        barycentric = np.full((n, 3), np.nan)
        cell2 = np.floor((u - self.origin) / self.cell_size)
        # a point on the grid's upper border belongs to the last bucket
        cell2 = np.where(cell2 == self.grid_shape, self.grid_shape - 1, cell2)
        in_grid = np.isfinite(cell2).all(axis=1) & (cell2 >= 0).all(axis=1) & (cell2 < self.grid_shape).all(axis=1)
        points = np.flatnonzero(in_grid)
        if len(points) == 0:
            return host, barycentric
        cell = cell2[points, 0].astype(np.int64) * self.grid_shape[1] + cell2[points, 1].astype(np.int64)
        start = self.cell_start[cell]
        count = self.cell_start[cell + 1] - start
        pair_point = np.repeat(points, count)
        pair_triangle = self.cell_triangles[
            np.repeat(start, count) + np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
        ]
        weights = self._barycentric(pair_triangle, u[pair_point])
        score = weights.min(axis=1)
        keep = score >= -BARYCENTRIC_TOLERANCE
        pair_point, pair_triangle, weights, score = pair_point[keep], pair_triangle[keep], weights[keep], score[keep]
        # deepest candidate per point: sort by point, then by decreasing score
        order = np.lexsort((-score, pair_point))
        first = order[np.unique(pair_point[order], return_index=True)[1]]
        host[pair_point[first]] = pair_triangle[first]
        barycentric[pair_point[first]] = weights[first]
        return host, barycentric

    def embed(self, u: np.ndarray) -> np.ndarray:
        """3D positions on the head of parameters (Eq. 18-19).

        Parameters
        ----------
        u : (n, 2) float64

        Returns
        -------
        x : (n, 3) float64

        Raises
        ------
        ValueError
            If a point lies outside the chart.
        """
        host, barycentric = self.locate(u)
        if (host < 0).any():
            raise ValueError(f"{int((host < 0).sum())} parameter points lie outside the head chart")
        return np.einsum("nk,nkc->nc", barycentric, self.vertices[self.faces[host]])

    def jacobians(self, host: np.ndarray) -> np.ndarray:
        """``dx/du`` of host triangles, ``[X1-X0 | X2-X0] [u1-u0 | u2-u0]^-1``.

        Parameters
        ----------
        host : (n,) int64
            Head triangle indices (>= 0).

        Returns
        -------
        jacobian : (n, 3, 2) float64
        """
        return self.jacobian[np.asarray(host, dtype=np.int64)]

    def _barycentric(self, triangles: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``(k, 3)`` barycentric coordinates of ``u (k, 2)`` in head ``triangles (k,)``."""
        local = np.einsum("kab,kb->ka", self.uv_inverse[triangles], u - self.uv[self.faces[triangles, 0]])
        return np.column_stack([1.0 - local[:, 0] - local[:, 1], local[:, 0], local[:, 1]])


# ----------------------------------------------------------------------------------------
# membrane
# ----------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Membrane:
    """The undeformed scalp (Eq. 16) and its material.

    Attributes
    ----------
    rest : (n, 3) float64
        Rest positions (m).
    triangles : (m, 3) int64
    rest_inverse : (m, 2, 2) float64
        ``D^-1`` of Eq. 16.
    areas : (m,) float64
        Rest areas ``A_t`` (m^2).
    mu, lam : float
        Lame parameters (Pa); ``lam`` is the membrane (plane-stress) one,
        ``E nu / (1 - nu^2)``, so that a small in-plane pull contracts sideways by ``nu``.
    """

    rest: np.ndarray
    triangles: np.ndarray
    rest_inverse: np.ndarray
    areas: np.ndarray
    mu: float
    lam: float

    @classmethod
    def build(
        cls, rest: np.ndarray, triangles: np.ndarray, young: float = DEFAULT_YOUNG, poisson: float = DEFAULT_POISSON
    ) -> "Membrane":
        """Rest shape matrices and areas of the scalp.

        Parameters
        ----------
        rest : (n, 3) float64
        triangles : (m, 3) int
        young : float
            Young's modulus (Pa, > 0).
        poisson : float
            Poisson ratio in (-1, 1).

        Raises
        ------
        InputError
            On bad shapes, bad material or degenerate rest triangles.
        """
        rest = np.asarray(rest, dtype=np.float64)
        triangles = np.asarray(triangles, dtype=np.int64)
        if rest.ndim != 2 or rest.shape[1] != 3 or triangles.ndim != 2 or triangles.shape[1] != 3:
            raise InputError("scalp rest must be (n, 3) and triangles (m, 3)", "membrane")
        if len(triangles) and (triangles.min() < 0 or triangles.max() >= len(rest)):
            raise InputError("scalp triangles index missing vertices", "membrane")
        if not np.isfinite(rest).all():
            raise InputError("scalp rest positions are not finite", "membrane", code="non_finite")
        if not (young > 0 and -1.0 < poisson < 1.0):
            raise InputError("need young > 0 and -1 < poisson < 1", "membrane")
        X = rest[triangles]
        e1 = X[:, 1] - X[:, 0]
        e2 = X[:, 2] - X[:, 0]
        length = np.linalg.norm(e1, axis=1)
        twice_area = np.linalg.norm(np.cross(e2, e1), axis=1)
        if (length <= 0).any() or (twice_area <= 0).any():
            raise InputError("the scalp has degenerate rest triangles", "membrane")
        a = length
        b = np.einsum("ij,ij->i", e2, e1) / length
        c = twice_area / length
        # D = [[a, b], [0, c]] (Eq. 16), D^-1 = [[1/a, -b/(a c)], [0, 1/c]]
        rest_inverse = np.zeros((len(triangles), 2, 2))
        rest_inverse[:, 0, 0] = 1.0 / a
        rest_inverse[:, 0, 1] = -b / (a * c)
        rest_inverse[:, 1, 1] = 1.0 / c
        mu = young / (2.0 * (1.0 + poisson))
        lam = young * poisson / (1.0 - poisson * poisson)
        return cls(rest, triangles, rest_inverse, 0.5 * twice_area, float(mu), float(lam))


#: Lame parameters (Pa) of DEFAULT_YOUNG and DEFAULT_POISSON, as Membrane.build sets them
DEFAULT_MU = DEFAULT_YOUNG / (2.0 * (1.0 + DEFAULT_POISSON))
DEFAULT_LAM = DEFAULT_YOUNG * DEFAULT_POISSON / (1.0 - DEFAULT_POISSON**2)

#: d = x_corners^T @ CORNER_EDGES: the two edge vectors of a triangle from its corners
CORNER_EDGES = np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]])


def deformation_gradients(membrane: Membrane, x: np.ndarray) -> np.ndarray:
    """``F = d D^-1`` per scalp triangle (Eq. 16-17).

    Parameters
    ----------
    membrane : Membrane
    x : (n, 3) float64
        Deformed positions (m).

    Returns
    -------
    F : (m, 3, 2) float64
    """
    X = np.asarray(x, dtype=np.float64)[membrane.triangles]  # (m, 3 corners, 3)
    d = np.stack([X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]], axis=2)
    return d @ membrane.rest_inverse


def _invariants(F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``C = F^T F (m, 2, 2)``, ``det C (m,)``, ``C^-1`` (inf-free where det C > 0) and ``G = F C^-1``."""
    C = np.einsum("mia,mib->mab", F, F)
    det = C[:, 0, 0] * C[:, 1, 1] - C[:, 0, 1] * C[:, 1, 0]
    safe = np.where(det > 0, det, 1.0)
    Cinv = np.stack([np.stack([C[:, 1, 1], -C[:, 0, 1]], axis=1), np.stack([-C[:, 1, 0], C[:, 0, 0]], axis=1)], axis=1)
    Cinv = Cinv / safe[:, None, None]
    return C, det, Cinv, F @ Cinv


def energy_density(F: np.ndarray, mu: float | None = None, lam: float | None = None) -> np.ndarray:
    """``psi(F) = mu/2 (tr C - 2) - mu ln J + lam/2 (ln J)^2``, +inf where ``J <= 0`` or non-finite.

    Parameters
    ----------
    F : (m, 3, 2) float64
        Deformation gradients.
    mu, lam : float, optional
        Lame parameters (Pa); default those of ``Membrane.build`` with
        :data:`DEFAULT_YOUNG` and :data:`DEFAULT_POISSON`.

    Returns
    -------
    psi : (m,) float64 (Pa, i.e. J/m^2)
    """
    mu = DEFAULT_MU if mu is None else mu
    lam = DEFAULT_LAM if lam is None else lam
    C, det, _, _ = _invariants(np.asarray(F, dtype=np.float64))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        log_j = 0.5 * np.log(np.where(det > 0, det, 1.0))
        psi = 0.5 * mu * (C[:, 0, 0] + C[:, 1, 1] - 2.0) - mu * log_j + 0.5 * lam * log_j * log_j
    return np.where((det > 0) & np.isfinite(psi), psi, np.inf)


def _first_piola(F: np.ndarray, mu: float, lam: float) -> tuple[np.ndarray, tuple]:
    """``P = dpsi/dF (m, 3, 2)`` and the pieces the Hessian reuses."""
    C, det, Cinv, G = _invariants(F)
    log_j = 0.5 * np.log(np.where(det > 0, det, 1.0))
    s = lam * log_j - mu
    return mu * F + s[:, None, None] * G, (Cinv, G, s)


def _corner_weights(membrane: Membrane) -> np.ndarray:
    """``B = CORNER_EDGES D^-1 (m, 3, 2)``: ``F_ia = sum_k x_ki B_ka``."""
    return CORNER_EDGES[None] @ membrane.rest_inverse


def _position_hessians(F: np.ndarray, B: np.ndarray, areas: np.ndarray, mu: float, lam: float) -> np.ndarray:
    """``A_t d^2 psi / dx_ki dx_lj`` per triangle, ``(m, 3, 3, 3, 3)`` indexed ``[t, k, i, l, j]``.

    With ``W = B G^T`` (``W_ki = sum_a B_ka G_ia``), ``Q = I - F G^T`` and ``s = lam ln J - mu``
    the contraction of ``dP/dF`` (module docstring) with ``B`` on both sides is
    ``mu (B B^T)_kl d_ij + lam W_ki W_lj + s (B C^-1 B^T)_kl Q_ij - s W_kj W_li``.
    """
    _, (Cinv, G, s) = _first_piola(F, mu, lam)
    W = B @ np.transpose(G, (0, 2, 1))  # (m, k, i)
    BBt = B @ np.transpose(B, (0, 2, 1))
    BCB = B @ Cinv @ np.transpose(B, (0, 2, 1))
    Q = np.eye(3)[None] - F @ np.transpose(G, (0, 2, 1))
    s5 = s[:, None, None, None, None]
    # broadcast outer products: [t, k, i, l, j]
    H = (mu * BBt)[:, :, None, :, None] * np.eye(3)[None, None, :, None, :]
    H = H + lam * W[:, :, :, None, None] * W[:, None, None, :, :]
    H += s5 * (BCB[:, :, None, :, None] * Q[:, None, :, None, :])
    H -= s5 * (W[:, :, None, None, :] * np.transpose(W, (0, 2, 1))[:, None, :, :, None])
    return areas[:, None, None, None, None] * H


def _project_psd(H: np.ndarray) -> np.ndarray:
    """Symmetric ``(m, d, d)`` blocks with negative eigenvalues set to 0."""
    H = 0.5 * (H + np.transpose(H, (0, 2, 1)))
    w, V = np.linalg.eigh(H)
    return (V * np.maximum(w, 0.0)[:, None, :]) @ np.transpose(V, (0, 2, 1))


def _position_gradients(membrane: Membrane, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``F (m, 3, 2)`` and ``dE/dx (n, 3)`` at deformed positions ``x (n, 3)``."""
    F = deformation_gradients(membrane, x)
    P, _ = _first_piola(F, membrane.mu, membrane.lam)
    gx = membrane.areas[:, None, None] * np.einsum("tia,tka->tki", P, _corner_weights(membrane))  # (m, 3, 3)
    flat = membrane.triangles.ravel()
    n = len(x)
    return F, np.column_stack([np.bincount(flat, gx[:, :, c].ravel(), minlength=n) for c in range(3)])


def _parameter_blocks(membrane: Membrane, F: np.ndarray, M: np.ndarray) -> np.ndarray:
    """Exact per-triangle Hessians ``(m, 6, 6)`` in the corners' parameters: ``J^T H_x J``
    with the block-diagonal ``J (m, 9, 6)`` of the corners' Jacobians ``M (n, 3, 2)``."""
    m = len(membrane.triangles)
    H = _position_hessians(F, _corner_weights(membrane), membrane.areas, membrane.mu, membrane.lam).reshape(m, 9, 9)
    J = np.zeros((m, 3, 3, 3, 2))  # [t, k, i, l, a]: corner k's row i, corner l's column a
    Mt = M[membrane.triangles]  # (m, 3, 3, 2)
    for k in range(3):
        J[:, k, :, k, :] = Mt[:, k]
    J = J.reshape(m, 9, 6)
    return np.transpose(J, (0, 2, 1)) @ H @ J


def _assemble_blocks(triangles: np.ndarray, blocks: np.ndarray, n: int) -> sp.csr_matrix:
    """``(2n, 2n)`` matrix from per-triangle ``(m, 6, 6)`` blocks over the corners' parameters."""
    m = len(triangles)
    dof = (2 * triangles[:, :, None] + np.arange(2)[None, None, :]).reshape(m, 6)
    rows = np.repeat(dof, 6, axis=1).ravel()
    cols = np.tile(dof, (1, 6)).ravel()
    return sp.coo_matrix((blocks.ravel(), (rows, cols)), shape=(2 * n, 2 * n)).tocsr()


def _assemble_hessian(membrane: Membrane, F: np.ndarray, M: np.ndarray, project: bool) -> sp.csr_matrix:
    """``(2n, 2n)`` Hessian in u from per-triangle blocks and per-vertex ``M (n, 3, 2)``;
    ``project`` clamps each triangle's 6x6 block in its corners' parameters to PSD."""
    blocks = _parameter_blocks(membrane, F, M)
    return _assemble_blocks(membrane.triangles, _project_psd(blocks) if project else blocks, len(M))


def _shifted_solve(H: sp.spmatrix, rhs: np.ndarray) -> np.ndarray:
    """``(H + shift I)^-1 rhs`` for a square sparse ``H``: the shift is
    :data:`REGULARISATION_SHARE` of its largest diagonal entry, as a projected Hessian may be
    singular."""
    shift = REGULARISATION_SHARE * max(float(np.abs(H.diagonal()).max()), np.finfo(float).tiny)
    return np.atleast_1d(spla.spsolve((H + shift * sp.identity(H.shape[0])).tocsc(), rhs))


def _located(chart: HeadChart, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hosts and 3D positions of ``u``; ``ValueError`` outside the chart."""
    host, barycentric = chart.locate(u)
    if (host < 0).any():
        raise ValueError(f"{int((host < 0).sum())} scalp vertices lie outside the head chart")
    return host, np.einsum("nk,nkc->nc", barycentric, chart.vertices[chart.faces[host]])


def membrane_energy(membrane: Membrane, chart: HeadChart, u: np.ndarray) -> float:
    """``sum_t A_t psi(F_t)`` (Eq. 15) with ``x = chart.embed(u)``, in J (+inf if degenerate).

    Parameters
    ----------
    membrane : Membrane
    chart : HeadChart
    u : (n, 2) float64
        Parameters of the scalp vertices; all inside the chart (else ``ValueError``).
    """
    x = chart.embed(u)
    return float(membrane.areas @ energy_density(deformation_gradients(membrane, x), membrane.mu, membrane.lam))


def membrane_gradient(membrane: Membrane, chart: HeadChart, u: np.ndarray) -> np.ndarray:
    """``dE/du (n, 2)`` with every vertex kept in its current host (x affine in u there).

    Parameters
    ----------
    membrane : Membrane
    chart : HeadChart
    u : (n, 2) float64

    Returns
    -------
    gradient : (n, 2) float64 (J per uv unit)
    """
    host, x = _located(chart, u)
    _, gx = _position_gradients(membrane, x)
    return np.einsum("nia,ni->na", chart.jacobians(host), gx)


def membrane_hessian(membrane: Membrane, chart: HeadChart, u: np.ndarray, project: bool = True) -> sp.csr_matrix:
    """``d^2E/du^2 (2n, 2n)``, vertex-major, hosts fixed.

    Each triangle's ``9x9`` Hessian in its corners' 3D positions is mapped to the corners'
    parameters by the per-vertex Jacobians (``J^T H J``, ``6x6``), then (when ``project``)
    made positive semi-definite by clamping its eigenvalues at 0 (the projection acts on
    the unknowns themselves), and assembled.

    Parameters
    ----------
    membrane : Membrane
    chart : HeadChart
    u : (n, 2) float64
    project : bool
        Clamp the per-triangle Hessians (projected Newton) or keep them exact.

    Returns
    -------
    hessian : (2n, 2n) scipy.sparse.csr_matrix
    """
    host, x = _located(chart, u)
    return _assemble_hessian(membrane, deformation_gradients(membrane, x), chart.jacobians(host), project)


#: d(2 * signed uv area) / d u as a constant (6, 6) Hessian over a triangle's corner
#: parameters (vertex-major): twice the area is ``(u1 - u0) x (u2 - u0)``
_AREA_HESSIAN = np.zeros((6, 6))
for _k in range(3):
    _AREA_HESSIAN[2 * _k, 2 * ((_k + 1) % 3) + 1] = 1.0  # d/du_{k,x} of (u_{k+1,y} - u_{k+2,y})
    _AREA_HESSIAN[2 * _k, 2 * ((_k + 2) % 3) + 1] = -1.0
    _AREA_HESSIAN[2 * _k + 1, 2 * ((_k + 2) % 3)] = 1.0  # d/du_{k,y} of (u_{k+2,x} - u_{k+1,x})
    _AREA_HESSIAN[2 * _k + 1, 2 * ((_k + 1) % 3)] = -1.0
_AREA_HESSIAN *= 0.5


def fold_barrier(
    triangles: np.ndarray, u: np.ndarray, rest_uv_areas: np.ndarray, weights: np.ndarray,
    threshold: float = FOLD_THRESHOLD,
) -> tuple[float, np.ndarray, np.ndarray]:
    """A barrier against folding the scalp over the head, in the parameterization.

    Eq. 15's ``J`` measures a deformed triangle's 3D area, which a triangle folded across a
    bend of the piecewise-flat head keeps (its corners are not collinear in 3D even where
    they are in uv): near a fold the membrane feels little resistance. Each triangle whose
    uv area ratio ``r = a / a_0`` to its starting one is below ``r^ = threshold`` adds
    ``w_t b(r)`` with the C2 log barrier ``b(r) = -(r - r^)^2 ln(r / r^)`` (zero with its
    first two derivatives at ``r^``, infinite at 0). Above the threshold, i.e. away from
    ten-fold compressions, it is exactly zero and the result is Eq. 15's.

    Parameters
    ----------
    triangles : (m, 3) int64
    u : (n, 2) float64
    rest_uv_areas : (m,) float64
        Positive signed uv areas at the start.
    weights : (m,) float64
        ``w_t`` (J), e.g. ``mu * A_t``.
    threshold : float

    Returns
    -------
    energy : float
        ``+inf`` if a triangle has ``r <= 0``.
    gradient : (n, 2) float64
    blocks : (m, 6, 6) float64
        Per-triangle Hessians over the corners' parameters (zero where inactive).
    """
    n, m = len(u), len(triangles)
    ratio = signed_uv_areas(triangles, u) / rest_uv_areas
    gradient = np.zeros((n, 2))
    blocks = np.zeros((m, 6, 6))
    active = np.flatnonzero(ratio < threshold)
    if len(active) == 0:
        return 0.0, gradient, blocks
    r = ratio[active]
    if (r <= 0).any():
        return np.inf, gradient, blocks
    log = np.log(r / threshold)
    gap = r - threshold
    energy = float(np.sum(weights[active] * -(gap**2) * log))
    db = -2.0 * gap * log - gap**2 / r
    d2b = -2.0 * log - 4.0 * gap / r + gap**2 / r**2
    U = u[triangles[active]]  # (a, 3, 2)
    nxt, prv = U[:, [1, 2, 0]], U[:, [2, 0, 1]]
    # d(signed area)/du_k = 0.5 (u_{k+1,y} - u_{k+2,y}, u_{k+2,x} - u_{k+1,x})
    d_area = 0.5 * np.stack([nxt[..., 1] - prv[..., 1], prv[..., 0] - nxt[..., 0]], axis=2).reshape(-1, 6)
    d_ratio = d_area / rest_uv_areas[active, None]
    w = weights[active]
    per_corner = ((w * db)[:, None] * d_ratio).reshape(-1, 3, 2)
    for c in range(2):
        gradient[:, c] = np.bincount(triangles[active].ravel(), per_corner[..., c].ravel(), minlength=n)
    blocks[active] = (w * d2b)[:, None, None] * d_ratio[:, :, None] * d_ratio[:, None, :] + (
        (w * db) / rest_uv_areas[active])[:, None, None] * _AREA_HESSIAN[None]
    return energy, gradient, blocks


def signed_uv_areas(triangles: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Signed areas ``(m,)`` of the scalp triangles in the parameter plane (uv units^2)."""
    U = np.asarray(u, dtype=np.float64)[triangles]
    e1 = U[:, 1] - U[:, 0]
    e2 = U[:, 2] - U[:, 0]
    return 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


# ----------------------------------------------------------------------------------------
# relocation (projected Newton)
# ----------------------------------------------------------------------------------------

#: a scalp vertex whose barycentric coordinate in its host is below this lies on the
#: host's edge (one small coordinate) or vertex (two): where the piecewise-linear head
#: bends, the energy has a kink there (see :func:`relocate`)
KINK_BARYCENTRIC = 1e-10
#: a free vertex this close (barycentric) to a head edge or vertex where both sides go
#: uphill is moved onto it when that lowers the energy (Newton would otherwise approach
#: the kink by ever shorter steps)
SNAP_BARYCENTRIC = 1e-6
#: a vertex's activity: free in its host (2 unknowns), held on a head edge (1) or at a
#: head vertex (0)
FREE, ON_EDGE, AT_VERTEX = 0, 1, 2


@dataclass
class RelocationReport:
    """What :func:`relocate` did.

    Attributes
    ----------
    iterations : int
        Accepted Newton steps, all load stages together.
    converged : bool
        The last stage met the tolerance with the boundary at its target.
    energy : list of float
        Energy (J) at the start of each stage and after every accepted step (moving
        vertices onto kinks between steps only lowers it and is not listed).
    step_sizes : list of float
        Line-search fraction of every accepted step.
    seconds : float
    stages : int
        Load stages (1 unless the boundary motion had to be split to keep triangles unflipped).
    start : list of str
        How each stage's start was made: ``"pinned"`` (free vertices left in place) or
        ``"harmonic"`` (the boundary motion extended to the free vertices by a uniform
        graph-Laplacian solve, used when pinning alone flips triangles).
    held : list of int
        Per Newton iteration, the free vertices held on a head edge or vertex (a kink of
        the energy where both sides go uphill).
    exact_steps : int
        Accepted steps that used the exact instead of the projected Hessian (``polish``).
    stop : str
        Why the last stage stopped: ``"step"`` (largest step below the tolerance),
        ``"decrement"`` (Newton decrement at round-off), ``"energy"`` (a step lowered the
        energy by less than the relative tolerance), ``"short_steps"`` (a step the line
        search cut below :data:`SHORT_STEP` lowered it by less than
        :data:`SHORT_STEP_TOLERANCE`), ``"line_search"`` (no admissible
        descent along the Newton direction) or ``"iterations"``.
    """

    iterations: int = 0
    converged: bool = False
    energy: list[float] = field(default_factory=list)
    step_sizes: list[float] = field(default_factory=list)
    seconds: float = 0.0
    stages: int = 0
    start: list[str] = field(default_factory=list)
    held: list[int] = field(default_factory=list)
    exact_steps: int = 0
    stop: str = ""


def _uniform_laplacian(triangles: np.ndarray, n: int) -> sp.csr_matrix:
    """Graph Laplacian ``(n, n)`` of the scalp's edges, unit weights."""
    edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    edges = np.unique(np.sort(edges, axis=1), axis=0)
    A = sp.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    A = (A + A.T).tocsr()
    return (sp.diags(np.asarray(A.sum(axis=1)).ravel()) - A).tocsr()


def _activity(
    chart: HeadChart,
    host: np.ndarray,
    barycentric: np.ndarray,
    gx: np.ndarray,
    free: np.ndarray,
    reach: float = KINK_BARYCENTRIC,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Which free vertices sit in a kink of the energy, and which host to differentiate in.

    A vertex on a head edge with both one-sided derivatives across the edge >= 0 is held
    on the edge (``ON_EDGE``, moving along ``tangent``); otherwise it is differentiated in
    the side of steeper descent. A vertex at a head vertex with no descent direction into
    any incident triangle is held there (``AT_VERTEX``); otherwise it is differentiated in
    the incident triangle of steepest descent. Vertices within ``reach`` (barycentric) of
    an edge or vertex are tested as if on it; if held, ``snapped`` puts them on it.

    Parameters
    ----------
    chart : HeadChart
    host : (n,) int64
    barycentric : (n, 3) float64
    gx : (n, 3) float64
        ``dE/dx`` per scalp vertex.
    free : (n,) bool
    reach : float
        Barycentric distance counted as on an edge or vertex.

    Returns
    -------
    host : (n,) int64
        Host to use for the Jacobians.
    mode : (n,) int8
        ``FREE``, ``ON_EDGE`` or ``AT_VERTEX``.
    tangent : (n, 2) float64
        Unit uv direction of the holding edge (``ON_EDGE`` rows), else 0.
    snapped : (n, 2) float64
        Parameters with the held vertices moved exactly onto their edge or vertex.
    """
    n = len(host)
    host = host.copy()
    mode = np.zeros(n, dtype=np.int8)
    tangent = np.zeros((n, 2))
    faces, uv = chart.faces, chart.uv
    snapped = np.einsum("nk,nkc->nc", barycentric, uv[faces[host]])
    small = barycentric < reach
    on = barycentric < KINK_BARYCENTRIC
    count = small.sum(axis=1)

    # on an edge: the corner k with the small coordinate faces it
    idx = np.flatnonzero(free & (count == 1))
    if len(idx):
        t = host[idx]
        k = np.argmax(small[idx], axis=1)
        c1 = faces[t, (k + 1) % 3]
        c2 = faces[t, (k + 2) % 3]
        edge = uv[c2] - uv[c1]
        unit = edge / np.linalg.norm(edge, axis=1, keepdims=True)
        normal = np.column_stack([-unit[:, 1], unit[:, 0]])
        normal *= np.sign(np.einsum("ij,ij->i", normal, uv[faces[t, k]] - uv[c1]))[:, None]  # into t
        slope_in = np.einsum("nia,ni,na->n", chart.jacobian[t], gx[idx], normal)
        other = chart.neighbours[t, k]
        has_other = other >= 0
        slope_out = np.where(
            has_other, -np.einsum("nia,ni,na->n", chart.jacobian[np.maximum(other, 0)], gx[idx], normal), np.inf
        )
        held = (slope_in >= 0) & (slope_out >= 0)
        mode[idx[held]] = ON_EDGE
        tangent[idx[held]] = unit[held]
        w = barycentric[idx[held]].copy()
        w[np.arange(len(w)), k[held]] = 0.0
        w /= w.sum(axis=1, keepdims=True)
        snapped[idx[held]] = np.einsum("nk,nkc->nc", w, uv[faces[t[held]]])
        switch = ~held & (slope_out < slope_in) & on[idx].any(axis=1)
        host[idx[switch]] = other[switch]

    # at a head vertex: test every incident triangle's cone
    idx = np.flatnonzero(free & (count >= 2))
    if len(idx):
        vertex = faces[host[idx], np.argmax(barycentric[idx], axis=1)]
        start = chart.vertex_start[vertex]
        fan = chart.vertex_start[vertex + 1] - start
        owner = np.repeat(np.arange(len(idx)), fan)
        pick = np.repeat(start, fan) + np.arange(fan.sum()) - np.repeat(np.cumsum(fan) - fan, fan)
        t = chart.vertex_triangles[pick]
        k = chart.vertex_corners[pick]
        e1 = uv[faces[t, (k + 1) % 3]] - uv[vertex[owner]]
        e2 = uv[faces[t, (k + 2) % 3]] - uv[vertex[owner]]
        g = np.einsum("pia,pi->pa", chart.jacobian[t], gx[idx[owner]])
        d1 = np.einsum("pa,pa->p", g, e1) / np.linalg.norm(e1, axis=1)
        d2 = np.einsum("pa,pa->p", g, e2) / np.linalg.norm(e2, axis=1)
        # -g inside the cone of (e1, e2): steepest descent -|g| is available there
        det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        a = (-g[:, 0] * e2[:, 1] + g[:, 1] * e2[:, 0]) / det
        b = (-e1[:, 0] * g[:, 1] + e1[:, 1] * g[:, 0]) / det
        score = np.where((a >= 0) & (b >= 0), -np.linalg.norm(g, axis=1), np.minimum(d1, d2))
        uphill = np.bincount(owner, (np.minimum(d1, d2) < 0).astype(float), minlength=len(idx)) == 0
        mode[idx[uphill]] = AT_VERTEX
        snapped[idx[uphill]] = uv[vertex[uphill]]
        order = np.lexsort((score, owner))
        best = order[np.unique(owner[order], return_index=True)[1]]
        switch = ~uphill & (on[idx].sum(axis=1) >= 2)
        host[idx[switch]] = t[best][switch]
    return host, mode, tangent, snapped


def relocate(
    membrane: Membrane,
    chart: HeadChart,
    u_start: np.ndarray,
    fixed: np.ndarray,
    u_fixed: np.ndarray,
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
    tolerance: float = DEFAULT_STEP_TOLERANCE,
    polish: bool = True,
    energy_tolerance: float = DEFAULT_ENERGY_TOLERANCE,
) -> tuple[np.ndarray, RelocationReport]:
    """Minimise Eq. 15 over the free scalp parameters with the hairline pinned (projected Newton).

    Each iteration solves ``(H + shift I) d = -g`` on the free unknowns with the projected
    Hessian of :func:`membrane_hessian` (Teran et al. 2005) and backtracks (halving, at
    most :data:`MAX_BACKTRACKS`) until the trial point keeps every vertex inside the chart,
    every scalp triangle's signed uv area of its sign in ``u_start``, and satisfies Armijo;
    hosts are located anew at every evaluation. Stops when the largest vertex step
    ``|d|`` is below ``tolerance``, the squared Newton decrement ``-g . d`` below
    :data:`DECREMENT_TOLERANCE` ``* mu * sum A_t``, or an accepted step lowered the energy
    by less than ``energy_tolerance`` of it (:data:`STAGE_ENERGY_TOLERANCE` at least for
    intermediate load stages); :attr:`RelocationReport.stop` says which.

    Kinks: ``x(u)`` is only piecewise affine, so ``E(u)`` has kinks along the head's edges
    (in uv). Where the head bends, a stretched membrane's minimiser often puts vertices
    exactly on an edge, where the gradient does not vanish and plain Newton stalls with
    ever smaller steps. Hence (an active set over the kinks): the line search lands
    exactly on the first edge a vertex would cross before halving past it; a vertex on an
    edge whose both sides go uphill is held on the edge for that iteration (its one
    unknown is the position along the edge), and one at a head vertex with no downhill
    direction is held there; the others are differentiated in their downhill side. The
    holds are re-decided every iteration, so a converged result is a stationary point of
    the piecewise-smooth energy.

    The energy minimised is Eq. 15 plus :func:`fold_barrier` (zero unless a triangle is
    compressed ten-fold in uv), which keeps triangles from folding across the head's bends.

    The fixed vertices are first set to ``u_fixed``. If that flips a triangle, the boundary
    motion is extended to the free vertices harmonically; if that flips too, the motion is
    applied in load stages (halved until a stage starts unflipped, each solved to
    convergence); ``u[fixed] == u_fixed`` unless ``max_iterations`` ran out first.

    Parameters
    ----------
    membrane : Membrane
    chart : HeadChart
    u_start : (n, 2) float64
        Starting parameters, inside the chart, no degenerate scalp triangle in uv.
    fixed : (n,) bool
        Hairline (Dirichlet) vertices.
    u_fixed : (k, 2) float64
        Their target parameters, ``k = fixed.sum()``, in the order of ``flatnonzero(fixed)``.
    max_iterations : int
        Newton steps, all stages together.
    tolerance : float
        Largest vertex step (uv units) counted as converged.
    energy_tolerance : float
        Relative energy decrease of a step counted as converged.
    polish : bool
        After a full projected step, first try the exact Hessian's full step (kept only if
        it is a descent direction, admissible and passes Armijo). Near a minimiser with
        compressed triangles the per-triangle clamp stays active and projected Newton
        converges only linearly (a contraction of about 0.25 per step measured on a 20 %
        push of a 10x10 sheet); the exact steps restore quadratic convergence.

    Returns
    -------
    u : (n, 2) float64
    report : RelocationReport

    Raises
    ------
    InputError
        On bad shapes, points outside the chart, degenerate starting triangles or a
        boundary motion that cannot be reached without flipping.
    """
    began = time.perf_counter()
    u_start = np.asarray(u_start, dtype=np.float64)
    fixed = np.asarray(fixed, dtype=bool)
    u_fixed = np.asarray(u_fixed, dtype=np.float64).reshape(-1, 2)
    n = len(membrane.rest)
    if u_start.shape != (n, 2) or fixed.shape != (n,) or len(u_fixed) != fixed.sum():
        raise InputError("need u_start (n, 2), fixed (n,) and u_fixed (fixed.sum(), 2)", "relocate")
    if (chart.locate(u_start)[0] < 0).any() or (chart.locate(u_fixed)[0] < 0).any():
        raise InputError("starting or hairline parameters lie outside the head chart", "relocate")
    orientation = np.sign(signed_uv_areas(membrane.triangles, u_start))
    if (orientation == 0).any():
        raise InputError("the scalp has degenerate triangles in uv at the start", "relocate")

    report = RelocationReport()
    free = ~fixed
    oriented = np.where((orientation < 0)[:, None], membrane.triangles[:, [0, 2, 1]], membrane.triangles)
    rest_uv = signed_uv_areas(oriented, u_start)
    barrier_weights = FOLD_STIFFNESS * membrane.mu * membrane.areas
    energy_scale = membrane.mu * float(membrane.areas.sum())
    laplacian = None

    def admissible(u: np.ndarray) -> float | None:
        """Energy at ``u`` if inside the chart and unflipped, else None."""
        if (chart.locate(u)[0] < 0).any():
            return None
        if (signed_uv_areas(membrane.triangles, u) * orientation <= 0).any():
            return None
        energy = membrane_energy(membrane, chart, u) + barrier(u)[0]
        return energy if np.isfinite(energy) else None

    def barrier(u: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        return fold_barrier(oriented, u, rest_uv, barrier_weights)

    def derivatives(u: np.ndarray, F: np.ndarray, gx: np.ndarray, M: np.ndarray, exact: bool):
        """``dE/du (2n,)`` of Eq. 15 plus the fold barrier, its projected Hessian and (if
        ``exact``) its exact one, ``(2n, 2n)``, at deformation gradients ``F`` and position
        gradients ``gx`` with host Jacobians ``M``."""
        _, fold_gradient, fold_blocks = barrier(u)
        g = (np.einsum("nia,ni->na", M, gx) + fold_gradient).ravel()
        blocks = _parameter_blocks(membrane, F, M)
        projected = (_assemble_blocks(membrane.triangles, _project_psd(blocks), n)
                     + _assemble_blocks(oriented, _project_psd(fold_blocks), n))
        if not exact:
            return g, projected, None
        return g, projected, _assemble_blocks(membrane.triangles, blocks, n) + _assemble_blocks(oriented, fold_blocks, n)

    def elastic_start(u: np.ndarray, target: np.ndarray) -> np.ndarray | None:
        """One Newton step of Eq. 15 with the hairline moved to ``target`` (an inhomogeneous
        Dirichlet step): the free vertices follow the boundary motion as the linearised
        membrane does, at the current hosts."""
        host, barycentric = chart.locate(u)
        x = np.einsum("nk,nkc->nc", barycentric, chart.vertices[chart.faces[host]])
        F, gx = _position_gradients(membrane, x)
        g, H, _ = derivatives(u, F, gx, chart.jacobians(host), exact=False)
        free2, fixed2 = np.repeat(free, 2), np.repeat(fixed, 2)
        rhs = -(g[free2] + H[free2][:, fixed2] @ (target - u[fixed]).ravel())
        step = _shifted_solve(H[free2][:, free2], rhs)
        if not np.isfinite(step).all():
            return None
        extended = u.copy()
        extended[fixed] = target
        extended[free] += step.reshape(-1, 2)
        return extended

    def stage_start(u: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, float, str] | None:
        nonlocal laplacian
        pinned = u.copy()
        pinned[fixed] = target
        energy = admissible(pinned)
        if energy is not None:
            return pinned, energy, "pinned"
        extended = elastic_start(u, target)
        energy = None if extended is None else admissible(extended)
        if energy is not None:
            return extended, energy, "elastic"
        if laplacian is None:
            laplacian = _uniform_laplacian(membrane.triangles, n)
        # a shift keeps components without a pinned vertex (zero motion) solvable
        L_ff = (laplacian[free][:, free] + HARMONIC_SHIFT * sp.identity(int(free.sum()))).tocsc()
        motion = np.zeros((n, 2))
        motion[fixed] = target - u[fixed]
        motion[free] = spla.spsolve(L_ff, -(laplacian[free][:, fixed] @ motion[fixed])).reshape(-1, 2)
        extended = u + motion
        energy = admissible(extended)
        if energy is not None:
            return extended, energy, "harmonic"
        return None

    def linearise(u: np.ndarray, energy: float, exact: bool):
        """Snapped ``u`` and its energy, reduced gradient, projected (and exact) reduced
        Hessians, basis, hosts and the count of held vertices."""
        host, barycentric = chart.locate(u)
        x = np.einsum("nk,nkc->nc", barycentric, chart.vertices[chart.faces[host]])
        F, gx = _position_gradients(membrane, x)
        _, mode, _, snapped = _activity(chart, host, barycentric, gx, free, SNAP_BARYCENTRIC)
        if (mode != FREE).any() and not np.array_equal(snapped, u):
            snapped_energy = admissible(snapped)
            if snapped_energy is not None and snapped_energy <= energy:
                u, energy = snapped, snapped_energy
                host, barycentric = chart.locate(u)
                x = np.einsum("nk,nkc->nc", barycentric, chart.vertices[chart.faces[host]])
                F, gx = _position_gradients(membrane, x)
        host, mode, tangent, _ = _activity(chart, host, barycentric, gx, free)
        M = chart.jacobians(host)
        # basis of the unknowns: 2 per free vertex, 1 (along the edge) per edge-held one
        loose = np.flatnonzero(free & (mode == FREE))
        edged = np.flatnonzero(free & (mode == ON_EDGE))
        first = 2 * np.arange(len(loose))
        rows = np.concatenate([2 * loose, 2 * loose + 1, 2 * edged, 2 * edged + 1])
        cols = np.concatenate([first, first + 1] + [2 * len(loose) + np.arange(len(edged))] * 2)
        vals = np.concatenate([np.ones(2 * len(loose)), tangent[edged, 0], tangent[edged, 1]])
        T = sp.csr_matrix((vals, (rows, cols)), shape=(2 * n, 2 * len(loose) + len(edged)))
        g, projected, exact_hessian = derivatives(u, F, gx, M, exact)
        gr = T.T @ g
        hessians = [(T.T @ H @ T).tocsc() for H in (projected, exact_hessian) if H is not None]
        return u, energy, gr, hessians, T, host, int((free & (mode != FREE)).sum())

    def direction(u: np.ndarray, gr: np.ndarray, Hr: sp.csc_matrix, T: sp.csr_matrix, host: np.ndarray):
        """Step ``(n, 2)``, squared decrement and the first fraction at which a vertex leaves its host."""
        if Hr.shape[0] == 0:  # every free vertex held at a head vertex
            return np.zeros((n, 2)), 0.0, np.inf
        z = _shifted_solve(Hr, -gr)
        d = (T @ z).reshape(n, 2)
        weights = chart._barycentric(host, u)
        local = np.einsum("nab,nb->na", chart.uv_inverse[host], d)
        rate = np.column_stack([-local.sum(axis=1), local])
        crossing = (weights > KINK_BARYCENTRIC) & (rate < 0)
        first_kink = float(np.where(crossing, weights / np.where(crossing, -rate, 1.0), np.inf).min())
        return d, float(-gr @ z), first_kink

    def small(d: np.ndarray, decrement2: float) -> bool:
        if np.sqrt((d**2).sum(axis=1)).max() < tolerance:
            report.stop = "step"
            return True
        if decrement2 < DECREMENT_TOLERANCE * energy_scale:
            report.stop = "decrement"
            return True
        return False

    def finish(u: np.ndarray, energy: float, d: np.ndarray) -> tuple[np.ndarray, float]:
        """Take the last step when it is not below the tolerance: the decrement stopped the
        loop because Armijo can no longer be told from round-off; keep the step if it is
        admissible and does not raise the energy."""
        if np.sqrt((d**2).sum(axis=1)).max() < tolerance:
            return u, energy
        trial_energy = admissible(u + d)
        if trial_energy is None or trial_energy > energy:
            return u, energy
        report.iterations += 1
        report.energy.append(trial_energy)
        report.step_sizes.append(1.0)
        return u + d, trial_energy

    u = u_start.copy()
    base = u_start[fixed]
    reached = 0.0
    converged = False
    while True:
        fraction = 1.0
        while True:
            target = u_fixed if fraction == 1.0 else base + fraction * (u_fixed - base)
            started = stage_start(u, target)
            if started is not None:
                break
            fraction = 0.5 * (reached + fraction)
            if fraction - reached < MIN_LOAD_FRACTION:
                raise InputError(
                    f"the hairline edit is too drastic for this scalp: beyond {100 * reached:.0f} % of the "
                    "hairline's motion the scalp would fold over itself on the head; use a smaller amount "
                    "or a curve closer to the current hairline", "relocate", "hairline_too_far")
        u, energy, how = started
        reached = fraction
        report.stages += 1
        report.start.append(how)
        report.energy.append(energy)
        converged = not free.any()
        full_step = False
        stall = energy_tolerance if reached >= 1.0 else max(energy_tolerance, STAGE_ENERGY_TOLERANCE)
        report.stop = "step" if converged else "iterations"

        def stalled(before: float, after: float) -> bool:
            return before - after <= stall * abs(before)

        while not converged and report.iterations < max_iterations:
            exact = polish and full_step
            u, energy, gr, hessians, T, host, held = linearise(u, energy, exact)
            report.held.append(held)
            if exact:
                # the exact Hessian's full step, taken only if it is an admissible Armijo descent
                d, decrement2, _ = direction(u, gr, hessians[1], T, host)
                if decrement2 > 0:
                    if small(d, decrement2):
                        u, energy = finish(u, energy, d)
                        converged = True
                        break
                    trial_energy = admissible(u + d)
                    if trial_energy is not None and trial_energy <= energy - ARMIJO * decrement2:
                        converged = stalled(energy, trial_energy)
                        u, energy = u + d, trial_energy
                        report.iterations += 1
                        report.energy.append(energy)
                        report.step_sizes.append(1.0)
                        report.exact_steps += 1
                        if converged:
                            report.stop = "energy"
                        continue
            d, decrement2, first_kink = direction(u, gr, hessians[0], T, host)
            if small(d, decrement2):
                u, energy = finish(u, energy, d)
                converged = True
                break
            alpha = 1.0
            accepted = None
            for _ in range(MAX_BACKTRACKS + 1):
                trial = u + alpha * d
                trial_energy = admissible(trial)
                if trial_energy is not None and trial_energy <= energy - ARMIJO * alpha * decrement2:
                    accepted = trial
                    break
                # land on the first kink rather than halving past it
                alpha = first_kink if 0.5 * alpha <= first_kink < alpha else 0.5 * alpha
            if accepted is None:
                report.stop = "line_search"
                break
            converged = stalled(energy, trial_energy)
            if converged:
                report.stop = "energy"
            elif alpha < SHORT_STEP and energy - trial_energy <= SHORT_STEP_TOLERANCE * abs(energy):
                converged = True
                report.stop = "short_steps"
            u, energy = accepted, trial_energy
            full_step = alpha == 1.0
            report.iterations += 1
            report.energy.append(energy)
            report.step_sizes.append(alpha)
        if reached >= 1.0 or report.iterations >= max_iterations:
            break
    report.converged = converged and reached >= 1.0
    report.seconds = time.perf_counter() - began
    return u, report
