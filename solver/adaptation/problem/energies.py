"""The energies of Eq. 1 (Eq. 7, 10, 11, weighted by Eq. 21's gamma): values, gradient and Hessian.

The kNN sets and weights behind Eq. 10 (Eq. 8-9, and Eq. 14's guide-only sets) are
:mod:`.neighbours`'.

Convention: particles ``(N, 3) float64`` in meters, CSR strands as in
:mod:`hairport.solver.model.hair`. Eq. 10 and Eq. 11 are separable in x, y, z (one ``(N, N)``
operator acts on all three coordinate columns alike); Eq. 7's Gauss-Newton blocks couple
the coordinates of a segment's two particles only.

* Strand shape (Eq. 7): ``sum_s || u_s(p) - d-bar_s ||^2`` with ``u_s`` the unit direction
  of segment ``s`` and ``d-bar`` the unit source directions. Its exact gradient and its
  exact per-segment Hessian projected to PSD are used (see :func:`shape_blocks`): Newton's
  method reaches the minimiser of Eq. 1 in a few outer iterations. Freezing the lengths in
  both gradient and Hessian, as the paper's text suggests, converges linearly at a rate of
  about ``1 - beta l^2`` (30-60+ iterations measured on 4-6 mm segments) to a slightly
  different fixed point.
* Inter-strand (Eq. 10): ``sum_i gamma_i || (K p)_i - L-bar_i ||^2`` with
  ``K = diag(sum_j w_ij) - W`` from inverse-distance kNN weights (Eq. 9) over particles of
  other strands (or of guide strands only, Eq. 14) and ``L-bar = K p-bar``.
* Hair-body (Eq. 11): ``sum_i gamma_i || p_i - p-hat_i ||^2``.
* Spacing, beyond the paper (:mod:`.spacing`): ``sum_s excess(l_s / t_s)^2``, how far each segment's
  length over its rest length ``t`` (from the source and the initial transfer) lies outside a free
  band; weight ``lambda_s`` (0: Eq. 1 exactly).
* Welded segments, beyond the paper: a source segment no longer than
  :data:`~hairport.solver.model.hair.DEGENERATE_SEGMENT_M` has no direction (``d-bar = 0`` marks
  it) and Eq. 7's term, whose Hessian is ``2 / l^2``, is singular there. Such a segment gets
  ``|| e ||^2 / w^2`` instead (``w`` = :data:`WELD_LENGTH_M`): its two particles move as one, and
  its Hessian ``2 / w^2`` stays within float64's reach of the rest (no spacing term either).
  :mod:`hairport.solver.model.degenerate` lists the degenerate kinds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from hairport.solver.adaptation.problem.spacing import (
    segment_rest_lengths,
    spacing_blocks,
    spacing_gradients,
    spacing_residuals,
)
from hairport.solver.mesh.polyline import MIN_SEGMENT_LENGTH
from hairport.solver.model.hair import DEGENERATE_SEGMENT_M

#: Eq. 7's negative curvature is kept down to this share of beta (per segment); a particle
#: belongs to at most two segments, each adding up to twice its block, so a share below 1/4
#: leaves the Hessian positive definite through Eq. 11's term alone
NEGATIVE_CURVATURE_SHARE = 0.2
#: the length scale (m) of a welded segment's spring ``|| e ||^2 / w^2``: the degenerate length
#: itself, so a weld costs Eq. 7's order (1) once it opens that far; its Hessian ``2 / w^2 = 2e12``
#: per m^2 is 10^9 times Eq. 11's ``2 beta``, where banded Cholesky keeps 7 digits (Eq. 7's
#: ``2 / l^2`` at the 1e-9 m floor the lengths had, 2e18, left none)
WELD_LENGTH_M = DEGENERATE_SEGMENT_M


def segment_operator(segments: np.ndarray, n: int) -> sp.csr_matrix:
    """``D`` with ``(D p)_s = p_b - p_a`` for segment ``s = (a, b)``.

    Parameters
    ----------
    segments : (M, 2) int64
    n : int

    Returns
    -------
    D : (M, n) csr_matrix
    """
    m = len(segments)
    rows = np.repeat(np.arange(m), 2)
    values = np.tile([-1.0, 1.0], m)
    return sp.csr_matrix((values, (rows, segments.ravel())), shape=(m, n))


def unit_rows(vectors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Row norms (clamped at :data:`MIN_SEGMENT_LENGTH`) and unit rows of ``(M, 3)`` vectors.

    The floor is far below :data:`~hairport.solver.model.hair.DEGENERATE_SEGMENT_M` on purpose: Eq. 1
    folds a strand's excess length into segments it collapses during a solve (:mod:`.spacing`), whose
    directions still count; only a segment degenerate in the source is welded."""
    length = np.maximum(np.linalg.norm(vectors, axis=1), MIN_SEGMENT_LENGTH)
    return length, vectors / length[:, None]


def source_directions(differences: np.ndarray) -> np.ndarray:
    """Eq. 7's ``d-bar``: unit rows of the source segments ``(M, 3)``, and 0 for a degenerate one
    (no longer than :data:`~hairport.solver.model.hair.DEGENERATE_SEGMENT_M`: welded).

    Returns
    -------
    directions : (M, 3) float64
    """
    length = np.linalg.norm(differences, axis=1)
    long = length > DEGENERATE_SEGMENT_M
    return np.divide(differences, length[:, None], out=np.zeros(differences.shape), where=long[:, None])


def welded(directions: np.ndarray) -> np.ndarray:
    """(M,) bool: the segments of ``directions (M, 3)`` (:func:`source_directions`) that are welded."""
    return ~directions.any(axis=1)


def shape_values(vectors: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Eq. 7's term of each segment ``(M, 3)``, the weld's where ``directions`` is 0: ``(M,)``."""
    _, unit = unit_rows(vectors)
    value = np.sum((unit - directions) ** 2, axis=1)
    weld = welded(directions)
    if weld.any():
        value[weld] = np.einsum("ij,ij->i", vectors[weld], vectors[weld]) / WELD_LENGTH_M**2
    return value


def shape_residuals(vectors: np.ndarray, directions: np.ndarray, length: np.ndarray, unit: np.ndarray) -> np.ndarray:
    """Half the gradient of :func:`shape_values` in each segment vector: ``(u (u . d) - d) / l``, and
    ``e / w^2`` for a welded segment. ``length, unit`` are :func:`unit_rows` of ``vectors (M, 3)``.

    Returns
    -------
    residual : (M, 3) float64
    """
    cosine = np.einsum("ij,ij->i", unit, directions)
    residual = (unit * cosine[:, None] - directions) / length[:, None]
    weld = welded(directions)
    if weld.any():
        residual[weld] = vectors[weld] / WELD_LENGTH_M**2
    return residual


def weld_blocks(blocks: np.ndarray, directions: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """``blocks (M, 3, 3)`` with the rows of welded segments replaced by ``scale I / w^2`` (in place):
    half the weld's Hessian at ``scale`` 1, in the units of :func:`shape_blocks`."""
    weld = welded(directions)
    if weld.any():
        blocks[weld] = (scale / WELD_LENGTH_M**2) * np.eye(3)
    return blocks


@dataclass(frozen=True, eq=False)
class ShapeModel:
    """Everything about Eq. 1's energies that depends on the source hairstyle only.

    Attributes
    ----------
    segments : (M, 2) int64
    D : (M, N) csr_matrix
        Segment differences.
    source_directions : (M, 3) float64
        Unit source segment directions ``d-bar``.
    K : (N, N) csr_matrix
        Inter-strand Laplacian.
    source_features : (N, 3) float64
        ``L-bar = K p-bar``.
    source_lengths : (M,) float64
        Source segment lengths (the spacing term's, :mod:`.spacing`).
    """

    segments: np.ndarray
    D: sp.csr_matrix
    source_directions: np.ndarray
    K: sp.csr_matrix
    source_features: np.ndarray
    source_lengths: np.ndarray

    @classmethod
    def build(cls, source_points: np.ndarray, segments: np.ndarray, K: sp.csr_matrix) -> "ShapeModel":
        """Assemble from source particles ``(N, 3)``, segments ``(M, 2)`` and ``K (N, N)``."""
        D = segment_operator(segments, len(source_points))
        differences = D @ source_points
        return cls(segments, D, source_directions(differences), K.tocsr(), K @ source_points,
                   np.linalg.norm(differences, axis=1))

    def rest_lengths(self, initial: np.ndarray) -> np.ndarray:
        """The spacing term's rest length per segment ``(M,)`` for the initial transfer ``(N, 3)`` (0, no
        term, for a welded segment)."""
        rest = segment_rest_lengths(self.segments, self.source_lengths, initial)
        rest[welded(self.source_directions)] = 0.0
        return rest


@dataclass(frozen=True)
class EnergyWeights:
    """Eq. 1's weights (Table 1, meters) and the spacing term's (:mod:`.spacing`; 0 here: the paper's Eq. 1)."""

    alpha: float = 3e3
    beta: float = 1e3
    spacing: float = 0.0
    spacing_band: tuple[float, float] = (1.0, 1.0)


def shape_blocks(
    model: ShapeModel,
    points: np.ndarray,
    radial_damping: float = 0.0,
    curvature_floor: np.ndarray | float = 0.0,
) -> np.ndarray:
    """Half the Hessian of Eq. 7 per segment, projected to positive semi-definite.

    For ``f(e) = || e/|e| - d ||^2`` with ``u = e/|e|``, ``l = |e|`` and ``c = u . d`` the
    exact Hessian is ``2/l^2 (d u^T + u d^T + c I - 3 c u u^T)``. Where the direction matches
    (``u = d``) it is the Gauss-Newton block ``2/l^2 (I - u u^T)``; away from it Gauss-Newton
    drops a term that is not small (it converged linearly, ~5 % per outer iteration on the
    MakeHuman pair), so the exact block is used. Its radial eigenvalue is negative
    (about ``-angle^2 / l^2``): Eq. 7 alone is not convex. Clamping it to 0 (projected
    Newton) overestimated the curvature along Newton steps 7-fold on the MakeHuman pair
    and made convergence linear, so eigenvalues are clamped at ``-curvature_floor`` (per
    segment, in 1/m^2 units) instead, a share of the hair-body stiffness that keeps the
    whole Hessian positive definite.

    Eq. 7 has (almost) no stiffness along ``u``: a Newton step may shrink or invert a
    segment, where the energy is singular. ``radial_damping`` adds ``mu u u^T / l^2`` (the
    frozen-length model's stiffness along ``u`` at ``mu = 1``), a Levenberg-Marquardt term
    that the solver raises when steps fail and lowers when they succeed.

    A welded segment (no source direction) gets its spring's ``I / w^2`` (:func:`weld_blocks`).

    Returns
    -------
    blocks : (M, 3, 3) float64
    """
    length, unit = unit_rows(model.D @ points)
    floor = np.broadcast_to(np.asarray(curvature_floor, dtype=np.float64), length.shape) * length**2
    projected = clamped_direction_hessians(unit, model.source_directions, floor)
    damped = projected + np.asarray(radial_damping)[..., None, None] * unit[:, :, None] * unit[:, None, :]
    return weld_blocks(damped / length[:, None, None] ** 2, model.source_directions)


#: below this sine of the angle between a segment and its source direction the two are
#: treated as parallel in :func:`clamped_direction_hessians`
PARALLEL_SINE = 1e-12


def clamped_direction_hessians(unit: np.ndarray, direction: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """Half the Hessian of ``||u - d||^2`` in ``u``'s unscaled frame, eigenvalues clamped at ``-floor``.

    The exact matrix ``A = d u^T + u d^T + c (I - 3 u u^T)`` (``c = u . d``) has, in closed
    form, the eigenvalue ``c`` along ``w``, normal to ``u`` and ``d``, and on the plane of
    ``u`` and ``e = (d - c u) / s`` (``s = |d - c u|``, the sine) the matrix
    ``[[0, s], [s, c]]`` with eigenvalues ``(c -+ sqrt(c^2 + 4 s^2)) / 2``: one is never
    negative, the other never positive. Only the non-positive ones need the clamp, so no
    general 3x3 eigensolver is needed (7x faster than ``numpy.linalg.eigh`` on 10^5 blocks).

    Parameters
    ----------
    unit : (M, 3) float64
        Unit segment directions ``u``.
    direction : (M, 3) float64
        Unit source directions ``d``.
    floor : (M,) float64
        Eigenvalues below ``-floor`` are raised to it (>= 0).

    Returns
    -------
    blocks : (M, 3, 3) float64
    """
    c = np.einsum("ij,ij->i", unit, direction)
    v = direction - c[:, None] * unit
    s = np.linalg.norm(v, axis=1)
    parallel = s < PARALLEL_SINE
    # any unit vector normal to u where d is (anti)parallel to u
    axis = np.zeros_like(unit)
    axis[np.arange(len(unit)), np.argmin(np.abs(unit), axis=1)] = 1.0
    fallback = np.cross(unit, axis)
    e = np.where(parallel[:, None], fallback, v)
    # e is 0 only where u and d are both 0 (a welded segment at zero length, whose block is replaced)
    e_norm = np.linalg.norm(e, axis=1, keepdims=True)
    np.divide(e, e_norm, out=e, where=e_norm > 0)
    w = np.cross(unit, e)
    low = 0.5 * (c - np.sqrt(c * c + 4.0 * s * s))
    # eigenvector (s, low) in the (u, e) basis; where s = 0 it is e (c < 0) or u (c >= 0, low = 0)
    q = s[:, None] * unit + low[:, None] * e
    q_norm = np.linalg.norm(q, axis=1)
    q = np.where((q_norm > 0)[:, None], q / np.where(q_norm > 0, q_norm, 1.0)[:, None], e)
    outer_ud = unit[:, :, None] * direction[:, None, :]
    exact = outer_ud + np.transpose(outer_ud, (0, 2, 1)) + c[:, None, None] * (
        np.eye(3)[None] - 3.0 * unit[:, :, None] * unit[:, None, :]
    )
    raise_low = np.maximum(low, -floor) - low
    raise_w = np.maximum(c, -floor) - c
    return exact + raise_low[:, None, None] * q[:, :, None] * q[:, None, :] + raise_w[:, None, None] * w[:, :, None] * w[:, None, :]


def hessian(
    model: ShapeModel,
    points: np.ndarray,
    weights: EnergyWeights,
    gamma: np.ndarray | None = None,
    radial_damping: float = 0.0,
    rest: np.ndarray | None = None,
) -> sp.csr_matrix:
    """Projected-Newton Hessian of Eq. 1 at ``points``, ``(3N, 3N)``, particle-major (x0 y0 z0 x1 ...).

    ``2 (D^T B D + (alpha K^T diag(gamma) K + beta diag(gamma)) (x) I_3)`` with ``B`` the
    :func:`shape_blocks`, plus the spacing term's blocks for rest lengths ``rest (M,)``
    (:meth:`ShapeModel.rest_lengths`) when ``weights.spacing`` is not 0.
    """
    n = len(points)
    m = len(model.segments)
    g = np.ones(n) if gamma is None else gamma
    floor = NEGATIVE_CURVATURE_SHARE * weights.beta * np.minimum(g[model.segments[:, 0]], g[model.segments[:, 1]])
    segment_blocks = shape_blocks(model, points, radial_damping, floor)
    if weights.spacing:
        length, unit = unit_rows(model.D @ points)
        segment_blocks += 0.5 * spacing_blocks(unit, length, _rest(model, rest), weights.spacing, weights.spacing_band)
        weld_blocks(segment_blocks, model.source_directions)  # the spacing term skips welds (rest 0) anyway
    blocks = sp.bsr_matrix((segment_blocks, np.arange(m), np.arange(m + 1)), shape=(3 * m, 3 * m))
    D3 = sp.kron(model.D, sp.identity(3), format="csr")
    shape = D3.T @ blocks.tocsr() @ D3
    coupled = weights.alpha * (model.K.T @ sp.diags(g) @ model.K) + weights.beta * sp.diags(g)
    return (2.0 * (shape + sp.kron(coupled, sp.identity(3)))).tocsr()


def _rest(model: ShapeModel, rest: np.ndarray | None) -> np.ndarray:
    if rest is None:
        raise ValueError("the spacing term needs the rest lengths (ShapeModel.rest_lengths)")
    return rest


def gradient(
    model: ShapeModel,
    points: np.ndarray,
    initial: np.ndarray,
    weights: EnergyWeights,
    gamma: np.ndarray | None = None,
    rest: np.ndarray | None = None,
) -> np.ndarray:
    """Exact gradient ``(N, 3)`` of Eq. 1 (with Eq. 21's weights) at ``points``, plus the spacing
    term's for rest lengths ``rest (M,)`` when ``weights.spacing`` is not 0.

    Eq. 7's part is ``2 D^T [(u (u . d-bar) - d-bar) / l]`` per segment (``e / w^2`` welded).
    """
    vectors = model.D @ points
    length, unit = unit_rows(vectors)
    g = np.ones(len(points)) if gamma is None else gamma
    shape_residual = shape_residuals(vectors, model.source_directions, length, unit)
    if weights.spacing:
        shape_residual += 0.5 * spacing_gradients(unit, length, _rest(model, rest), weights.spacing, weights.spacing_band)
    inter_residual = model.K @ points - model.source_features
    return 2.0 * (
        model.D.T @ shape_residual
        + weights.alpha * (model.K.T @ (g[:, None] * inter_residual))
        + weights.beta * g[:, None] * (points - initial)
    )


@dataclass(frozen=True)
class EnergyTerms:
    """Values of Eq. 1's terms (unweighted) at a hairstyle."""

    strand_shape: float
    inter_strand: float
    hair_body: float
    spacing: float = 0.0

    def total(self, weights: EnergyWeights) -> float:
        return (self.strand_shape + weights.alpha * self.inter_strand + weights.beta * self.hair_body
                + weights.spacing * self.spacing)


def energy_terms(model: ShapeModel, points: np.ndarray, initial: np.ndarray, gamma: np.ndarray | None = None,
                 rest: np.ndarray | None = None, band: tuple[float, float] = (1.0, 1.0)) -> EnergyTerms:
    """Exact (nonlinear) Eq. 7, Eq. 10 and Eq. 11 at ``points``, and the spacing term for rest lengths ``rest``.

    Parameters
    ----------
    points : (N, 3) float64
    initial : (N, 3) float64
        ``p-hat`` of Eq. 11.
    gamma : (N,) float64, optional
        Eq. 21's weights.
    rest : (M,) float64, optional
        :meth:`ShapeModel.rest_lengths` (the spacing term is 0 without them).
    band : (low, high)
        The spacing term's free band (``EnergyWeights.spacing_band``).
    """
    g = np.ones(len(points)) if gamma is None else gamma
    vectors = model.D @ points
    length, _ = unit_rows(vectors)
    shape = float(np.sum(shape_values(vectors, model.source_directions)))
    inter = float(np.sum(g * np.sum((model.K @ points - model.source_features) ** 2, axis=1)))
    body = float(np.sum(g * np.sum((points - initial) ** 2, axis=1)))
    spacing = 0.0 if rest is None else float(np.sum(spacing_residuals(length, rest, band) ** 2))
    return EnergyTerms(shape, inter, body, spacing)
