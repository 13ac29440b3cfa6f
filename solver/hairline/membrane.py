"""The scalp as a neo-Hookean membrane embedded in the head surface (Section 6.1, Eq. 15-17): its
energy and its derivatives in the scalp parameters.

Convention: the head surface H is a triangle mesh ``head_vertices (h, 3) float64`` in
meters with ``head_faces (g, 3) int64`` and a 2D parameterisation ``head_uv (h, 2)
float64`` (a disk patch: injective, every triangle of positive signed area in uv), wrapped
in a :class:`.head_chart.HeadChart`. The scalp S is a separate triangle mesh with rest positions
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
:func:`.newton.relocate` keeps every scalp triangle's signed area in uv of its starting sign. As
``x(u)`` is only piecewise affine, ``E(u)`` has kinks along the head's edges, where a
stretched scalp's minimiser often puts vertices; :func:`.newton.relocate` treats them as an
active set (:mod:`.kinks`) and adds :mod:`.fold_barrier` against triangles folding across the
head's bends.

Since ``mu`` and ``lam`` are both proportional to Young's modulus for a fixed Poisson
ratio, ``E(u)`` scales linearly with it and its minimiser does not depend on it: any
positive value works (:data:`DEFAULT_YOUNG`); the stopping tests are scale-free.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from hairport.solver.hairline.head_chart import HeadChart
from hairport.solver.mesh.areas import triangle_areas
from hairport.solver.model.errors import InputError

#: Young's modulus (Pa); the minimiser of Eq. 15 does not depend on it (the energy is
#: linear in it at a fixed Poisson ratio), only the energy values reported do
DEFAULT_YOUNG = 1.0
#: Poisson ratio (dimensionless) of the scalp membrane, in-plane (plane stress). The paper
#: gives none. Root density is roots per area, so the membrane should resist area change
#: more than shape change: a nearly incompressible 0.45 (rubber-like) lowered Table 3's
#: average L1 over 8 grooms from 0.043 / 0.040 (nu = 0.3) to 0.041 / 0.035 (straight /
#: widow's peak), with the same L-infinity
DEFAULT_POISSON = 0.45


#: the free block of the projected Hessian is shifted by this share of its largest
#: diagonal entry (the PSD projection may leave it singular)
REGULARISATION_SHARE = 1e-10


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
        areas = triangle_areas(rest, triangles)
        if (length <= 0).any() or (areas <= 0).any():
            raise InputError("the scalp has degenerate rest triangles", "membrane")
        a = length
        b = np.einsum("ij,ij->i", e2, e1) / length
        c = 2.0 * areas / length
        # D = [[a, b], [0, c]] (Eq. 16), D^-1 = [[1/a, -b/(a c)], [0, 1/c]]
        rest_inverse = np.zeros((len(triangles), 2, 2))
        rest_inverse[:, 0, 0] = 1.0 / a
        rest_inverse[:, 0, 1] = -b / (a * c)
        rest_inverse[:, 1, 1] = 1.0 / c
        mu = young / (2.0 * (1.0 + poisson))
        lam = young * poisson / (1.0 - poisson * poisson)
        return cls(rest, triangles, rest_inverse, areas, float(mu), float(lam))


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


def project_psd(H: np.ndarray) -> np.ndarray:
    """Per-block projection onto the positive semi-definite matrices (projected Newton).

    Parameters
    ----------
    H : (m, d, d) float64
        Blocks, symmetrised before the projection.

    Returns
    -------
    projected : (m, d, d) float64
        Each block with its negative eigenvalues set to 0.
    """
    H = 0.5 * (H + np.transpose(H, (0, 2, 1)))
    w, V = np.linalg.eigh(H)
    return (V * np.maximum(w, 0.0)[:, None, :]) @ np.transpose(V, (0, 2, 1))


def position_gradients(membrane: Membrane, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Deformation gradients and the gradient of Eq. 15 in the 3D positions.

    Parameters
    ----------
    membrane : Membrane
    x : (n, 3) float64
        Deformed positions (m).

    Returns
    -------
    F : (m, 3, 2) float64
    gradient : (n, 3) float64
        ``dE/dx`` (J/m).
    """
    F = deformation_gradients(membrane, x)
    P, _ = _first_piola(F, membrane.mu, membrane.lam)
    gx = membrane.areas[:, None, None] * np.einsum("tia,tka->tki", P, _corner_weights(membrane))  # (m, 3, 3)
    flat = membrane.triangles.ravel()
    n = len(x)
    return F, np.column_stack([np.bincount(flat, gx[:, :, c].ravel(), minlength=n) for c in range(3)])


def parameter_blocks(membrane: Membrane, F: np.ndarray, M: np.ndarray) -> np.ndarray:
    """Exact per-triangle Hessians of Eq. 15 in the corners' parameters, hosts fixed.

    ``J^T H_x J`` with ``H_x`` a triangle's 9x9 Hessian in its corners' positions and the
    block-diagonal ``J (m, 9, 6)`` of the corners' Jacobians.

    Parameters
    ----------
    membrane : Membrane
    F : (m, 3, 2) float64
        Deformation gradients.
    M : (n, 3, 2) float64
        ``dx/du`` of each scalp vertex's host (:meth:`~hairport.solver.hairline.head_chart.HeadChart.jacobians`).

    Returns
    -------
    blocks : (m, 6, 6) float64
        Over the corners' parameters, vertex-major.
    """
    m = len(membrane.triangles)
    H = _position_hessians(F, _corner_weights(membrane), membrane.areas, membrane.mu, membrane.lam).reshape(m, 9, 9)
    J = np.zeros((m, 3, 3, 3, 2))  # [t, k, i, l, a]: corner k's row i, corner l's column a
    Mt = M[membrane.triangles]  # (m, 3, 3, 2)
    for k in range(3):
        J[:, k, :, k, :] = Mt[:, k]
    J = J.reshape(m, 9, 6)
    return np.transpose(J, (0, 2, 1)) @ H @ J


def assemble_blocks(triangles: np.ndarray, blocks: np.ndarray, n: int) -> sp.csr_matrix:
    """A sparse matrix over all parameters from per-triangle blocks (summed where they overlap).

    Parameters
    ----------
    triangles : (m, 3) int64
    blocks : (m, 6, 6) float64
        Over each triangle's corners' parameters, vertex-major.
    n : int
        Vertices.

    Returns
    -------
    matrix : (2n, 2n) scipy.sparse.csr_matrix
    """
    m = len(triangles)
    dof = (2 * triangles[:, :, None] + np.arange(2)[None, None, :]).reshape(m, 6)
    rows = np.repeat(dof, 6, axis=1).ravel()
    cols = np.tile(dof, (1, 6)).ravel()
    return sp.coo_matrix((blocks.ravel(), (rows, cols)), shape=(2 * n, 2 * n)).tocsr()


def _assemble_hessian(membrane: Membrane, F: np.ndarray, M: np.ndarray, project: bool) -> sp.csr_matrix:
    """``(2n, 2n)`` Hessian in u from per-triangle blocks and per-vertex ``M (n, 3, 2)``;
    ``project`` clamps each triangle's 6x6 block in its corners' parameters to PSD."""
    blocks = parameter_blocks(membrane, F, M)
    return assemble_blocks(membrane.triangles, project_psd(blocks) if project else blocks, len(M))


def shifted_solve(H: sp.spmatrix, rhs: np.ndarray) -> np.ndarray:
    """``(H + shift I)^-1 rhs``, the shift :data:`REGULARISATION_SHARE` of ``H``'s largest
    diagonal entry, as a projected Hessian may be singular.

    Parameters
    ----------
    H : (k, k) scipy.sparse matrix
    rhs : (k,) float64

    Returns
    -------
    solution : (k,) float64
    """
    shift = REGULARISATION_SHARE * max(float(np.abs(H.diagonal()).max()), np.finfo(float).tiny)
    return np.atleast_1d(spla.spsolve((H + shift * sp.identity(H.shape[0])).tocsc(), rhs))


def _located(chart: HeadChart, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hosts and 3D positions of ``u``; ``ValueError`` outside the chart."""
    host, _, x = chart.place(u)
    if (host < 0).any():
        raise ValueError(f"{int((host < 0).sum())} scalp vertices lie outside the head chart")
    return host, x


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
    _, gx = position_gradients(membrane, x)
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
