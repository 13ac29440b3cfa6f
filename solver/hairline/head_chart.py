"""Eq. 18-19: the head chart, a parameterised head patch whose parameters embed back onto the head."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hairport.solver.mesh.topology import corner_neighbours, vertex_faces
from hairport.solver.mesh.triangles import interpolate_barycentric
from hairport.solver.model.errors import InputError

#: a point belongs to a triangle when its barycentric coordinates are all >= -this
BARYCENTRIC_TOLERANCE = 1e-12
#: uv triangles of the chart with |signed area| below this share of the mean are refused
DEGENERATE_AREA_SHARE = 1e-14
#: locator buckets: at most this many grid cells per chart triangle
CELLS_PER_TRIANGLE = 4


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

        vertex_start, vertex_triangles, vertex_corners = vertex_faces(faces, len(vertices))
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
            neighbours=corner_neighbours(faces),
            vertex_start=vertex_start,
            vertex_triangles=vertex_triangles,
            vertex_corners=vertex_corners,
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
        weights = self.barycentric(pair_triangle, u[pair_point])
        score = weights.min(axis=1)
        keep = score >= -BARYCENTRIC_TOLERANCE
        pair_point, pair_triangle, weights, score = pair_point[keep], pair_triangle[keep], weights[keep], score[keep]
        # deepest candidate per point: sort by point, then by decreasing score
        order = np.lexsort((-score, pair_point))
        first = order[np.unique(pair_point[order], return_index=True)[1]]
        host[pair_point[first]] = pair_triangle[first]
        barycentric[pair_point[first]] = weights[first]
        return host, barycentric

    def place(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Hosts, barycentric coordinates and 3D positions of parameters (Eq. 18-19).

        Parameters
        ----------
        u : (n, 2) float64

        Returns
        -------
        host : (n,) int64
            -1 outside the chart.
        barycentric : (n, 3) float64
        x : (n, 3) float64
            NaN outside the chart.
        """
        host, barycentric = self.locate(u)
        return host, barycentric, interpolate_barycentric(self.vertices, self.faces, host, barycentric)

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
        host, _, x = self.place(u)
        if (host < 0).any():
            raise ValueError(f"{int((host < 0).sum())} parameter points lie outside the head chart")
        return x

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

    def barycentric(self, triangles: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Barycentric coordinates of parameters in given head triangles (Eq. 18).

        Parameters
        ----------
        triangles : (k,) int64
            Head triangle of each point.
        u : (k, 2) float64

        Returns
        -------
        weights : (k, 3) float64
            Of the triangle's corners; negative outside it.
        """
        local = np.einsum("kab,kb->ka", self.uv_inverse[triangles], u - self.uv[self.faces[triangles, 0]])
        return np.column_stack([1.0 - local[:, 0] - local[:, 1], local[:, 0], local[:, 1]])
