"""The normal equations of optimal-step non-rigid ICP (Amberg, Romdhani & Vetter 2007), on a fixed pattern.

Every source vertex ``i`` carries an affine map ``X_i`` (4 x 3, acting on the homogeneous
row ``v_i = (x, y, z, 1)``), stacked into ``X (4n, 3)``. One step minimises

    E(X) = ||W (D X - U)||^2 + alpha^2 ||(M kron G) X||^2 + beta^2 ||D_L X - U_L||^2 + eps ||X - X_0||^2

with ``D (n, 4n)`` holding ``v_i`` in vertex ``i``'s block, ``W`` the data weights, ``U (n, 3)``
the closest target points, ``M`` the edge-vertex incidence of the source, ``G = diag(1, 1, 1,
gamma)`` (how much a change of translation costs against one of the linear part), ``D_L``
the landmark rows (barycentric combinations of ``v``) and ``U_L`` their target points; the
tiny ridge ``eps`` towards the previous ``X_0`` keeps the matrix definite where nothing else
holds a vertex (a piece of the region with no data and no landmark). Its normal equations
``A X = B`` have one matrix

    A = alpha^2 (L kron G^2) + D^T W^2 D + beta^2 D_L^T D_L + eps I

(``L = M^T M`` the graph Laplacian) for the three columns of ``X``. ``A``'s pattern does not
depend on ``alpha``, ``W`` or ``beta`` (the 4 x 4 diagonal blocks, the diagonal of the
off-diagonal blocks on the edges, the landmarks' blocks), so :class:`AmbergSystem` lays it
out once (:func:`_pattern`) and each assembly is one ``bincount`` into it: a factorisation
that keeps its symbolic analysis (:mod:`.factor`) gets the same pattern every time.

Coordinates are normalised (the region's centroid removed, divided by its RMS radius) so
that ``alpha`` and ``gamma`` mean the same for a head in meters or in centimetres.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

#: the ridge towards the previous transforms, against the data entries (~1 in normalised
#: coordinates): small enough to change no fitted vertex measurably, large enough that a
#: vertex held by nothing else keeps its place instead of making ``A`` singular
RIDGE = 1e-8


class AmbergSystem:
    """The normal equations over a fixed source mesh (see the module docstring).

    Parameters
    ----------
    points : (n, 3) float64
        Source vertices, normalised coordinates.
    edges : (m, 2) int64
        Undirected edges of the source mesh, each once.
    gamma : float
        Weight of the translation part in the stiffness term.
    landmark_corners : (k, c) int64, optional
        Vertices of each landmark's barycentric combination (``c`` = 3 for a point on a
        face; repeated corners with zero weight are allowed).
    landmark_weights : (k, c) float64, optional
        Their barycentric weights.
    """

    def __init__(self, points: np.ndarray, edges: np.ndarray, gamma: float,
                 landmark_corners: np.ndarray | None = None, landmark_weights: np.ndarray | None = None):
        self.n = len(points)
        self.homogeneous = np.concatenate([points, np.ones((self.n, 1))], axis=1)
        self.edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
        self.corners = np.zeros((0, 3), np.int64) if landmark_corners is None else np.asarray(landmark_corners, np.int64)
        self.bary = np.zeros((0, 3)) if landmark_weights is None else np.asarray(landmark_weights, np.float64)
        g2 = np.array([1.0, 1.0, 1.0, gamma * gamma])
        rows, cols, self._stiffness = _stiffness_entries(self.n, self.edges, g2)
        data_rows, data_cols, _ = _block_entries(np.arange(self.n), np.arange(self.n))
        lm_rows, lm_cols, self._landmark = self._landmark_entries()
        diag = np.arange(4 * self.n)
        self._parts = (len(rows), len(data_rows), len(lm_rows))
        self.slot, self.indices, self.indptr = _pattern(np.concatenate([rows, data_rows, lm_rows, diag]),
                                                        np.concatenate([cols, data_cols, lm_cols, diag]), 4 * self.n)
        # the data entries of vertex i: w_i^2 v_i v_i^T, row-major over the 4 x 4 block
        self._outer = np.einsum("ia,ib->iab", self.homogeneous, self.homogeneous).reshape(-1)

    def _landmark_entries(self):
        """Rows, columns and values of ``D_L^T D_L`` (before ``beta^2``)."""
        k, c = self.corners.shape
        if k == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
        ci, cj = np.repeat(self.corners, c, axis=1).ravel(), np.tile(self.corners, (1, c)).ravel()
        wi, wj = np.repeat(self.bary, c, axis=1).ravel(), np.tile(self.bary, (1, c)).ravel()
        rows, cols, pairs = _block_entries(ci, cj)
        vi, vj = self.homogeneous[ci], self.homogeneous[cj]
        values = (wi * wj)[:, None, None] * np.einsum("pa,pb->pab", vi, vj)
        return rows, cols, values.reshape(-1)

    @property
    def nnz(self) -> int:
        """Stored entries of ``A`` (both triangles)."""
        return len(self.indices)

    def matrix(self, alpha: float, weights: np.ndarray, beta: float = 0.0) -> sp.csc_matrix:
        """``A`` (4n, 4n) for stiffness ``alpha``, data weights ``weights (n,)`` and landmark weight ``beta``."""
        values = np.concatenate([
            alpha * alpha * self._stiffness,
            np.repeat(weights * weights, 16) * self._outer,
            beta * beta * self._landmark,
            np.full(4 * self.n, RIDGE),
        ])
        data = np.bincount(self.slot, weights=values, minlength=len(self.indices))
        return sp.csc_matrix((data, self.indices, self.indptr), shape=(4 * self.n, 4 * self.n))

    def rhs(self, weights: np.ndarray, targets: np.ndarray, previous: np.ndarray, beta: float = 0.0,
            landmark_targets: np.ndarray | None = None) -> np.ndarray:
        """``B (4n, 3)``: data targets ``targets (n, 3)`` with ``weights (n,)``, the ridge's
        ``previous (4n, 3)`` transforms, and landmark targets ``(k, 3)`` with weight ``beta``."""
        b = (weights * weights)[:, None, None] * self.homogeneous[:, :, None] * targets[:, None, :]
        b = b.reshape(-1, 3) + RIDGE * previous
        if beta > 0 and len(self.corners):
            k, c = self.corners.shape
            contribution = (beta * beta * self.bary.reshape(-1, 1, 1) * self.homogeneous[self.corners.ravel()][:, :, None]
                            * np.repeat(landmark_targets, c, axis=0)[:, None, :]).reshape(-1, 3)
            rows = (4 * self.corners.ravel()[:, None] + np.arange(4)).ravel()
            b += np.stack([np.bincount(rows, weights=contribution[:, j], minlength=4 * self.n) for j in range(3)], axis=1)
        return b

    def positions(self, transforms: np.ndarray) -> np.ndarray:
        """(n, 3) ``D X``: each vertex moved by its transform ``transforms (4n, 3)``."""
        return np.einsum("ia,iab->ib", self.homogeneous, transforms.reshape(self.n, 4, 3))

    def landmark_positions(self, transforms: np.ndarray) -> np.ndarray:
        """(k, 3) ``D_L X``: the landmarks moved with the transforms."""
        moved = self.positions(transforms)
        return np.einsum("kc,kcj->kj", self.bary, moved[self.corners])

    def identity(self) -> np.ndarray:
        """(4n, 3) transforms that move nothing."""
        return np.tile(np.vstack([np.eye(3), np.zeros((1, 3))]), (self.n, 1))


def _stiffness_entries(n: int, edges: np.ndarray, g2: np.ndarray):
    """Rows, columns and values of ``L kron diag(g2)`` (before ``alpha^2``)."""
    degree = np.bincount(edges.ravel(), minlength=n).astype(np.float64)
    k = np.arange(4)
    diag_rows = (4 * np.arange(n)[:, None] + k).ravel()
    diag_values = (degree[:, None] * g2).ravel()
    i, j = edges[:, 0], edges[:, 1]
    off_rows = np.concatenate([(4 * i[:, None] + k).ravel(), (4 * j[:, None] + k).ravel()])
    off_cols = np.concatenate([(4 * j[:, None] + k).ravel(), (4 * i[:, None] + k).ravel()])
    off_values = -np.tile(g2, 2 * len(edges))
    return (np.concatenate([diag_rows, off_rows]), np.concatenate([diag_rows, off_cols]),
            np.concatenate([diag_values, off_values]))


def _block_entries(ci: np.ndarray, cj: np.ndarray):
    """Rows and columns of the full 4 x 4 blocks ``(ci[p], cj[p])``, row-major per block."""
    a = np.repeat(np.arange(4), 4)
    b = np.tile(np.arange(4), 4)
    rows = (4 * np.asarray(ci)[:, None] + a).ravel()
    cols = (4 * np.asarray(cj)[:, None] + b).ravel()
    return rows, cols, len(ci)


def _pattern(rows: np.ndarray, cols: np.ndarray, size: int):
    """The CSC pattern of the entries ``(rows, cols)`` (duplicates merged).

    Returns
    -------
    slot : (K,) int64
        Where each entry's value is added in the CSC data array.
    indices, indptr : int32 arrays
        The CSC pattern, rows ascending within each column.
    """
    keys = cols.astype(np.int64) * size + rows
    unique, slot = np.unique(keys, return_inverse=True)
    indices = (unique % size).astype(np.int32)
    indptr = np.zeros(size + 1, dtype=np.int32)
    np.cumsum(np.bincount(unique // size, minlength=size), out=indptr[1:])
    return slot.reshape(-1), indices, indptr
