"""Eq. 1 over a set of strands and its projected-Newton model (gradient, strand-banded Hessian)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from hairport.solver.adaptation.problem import banded, merit_kernels, model_kernels
from hairport.solver.adaptation.problem.constraints import clearance_violation
from hairport.solver.adaptation.problem.energies import (
    NEGATIVE_CURVATURE_SHARE,
    PARALLEL_SINE,
    WELD_LENGTH_M,
    EnergyWeights,
    ShapeModel,
    clamped_direction_hessians,
    shape_residuals,
    shape_values,
    unit_rows,
    weld_blocks,
    welded,
)
from hairport.solver.adaptation.problem.spacing import spacing_blocks, spacing_gradients, spacing_residuals
from hairport.solver.mesh.polyline import MIN_SEGMENT_LENGTH


@dataclass(frozen=True, eq=False)
class StrandProblem:
    """Eq. 1 over a set of strands: ``sum_seg ||u - d||^2 + alpha sum_i gamma_i ||(K p)_i - f_i||^2 + beta sum_i gamma_i ||p_i - p-hat_i||^2``,
    plus the spacing term ``lambda_s sum_seg excess(l / t)^2`` (:mod:`.spacing`) where ``weights.spacing`` is not 0.

    Attributes
    ----------
    offsets : (S+1,) int64
        CSR strand layout.
    source_directions : (N, 3) float64
        Unit source direction of the segment starting at each particle, 0 for a welded one
        (:func:`.energies.source_directions`; tip rows unused).
    initial : (N, 3) float64
        ``p-hat`` (Eq. 11).
    coupling : (N, N) csr_matrix
        ``K`` of Eq. 10 over these particles; diagonal for Eq. 14's fine level.
    features : (N, 3) float64
        ``f``: the source features ``L-bar`` (plus the fixed neighbours' share for Eq. 14).
    gamma : (N,) float64
        Eq. 21's weights.
    fixed : (N,) bool
        Particles that do not move (roots).
    rest_lengths : (N,) float64 or None
        The spacing term's rest length of the segment starting at each particle (0: no term;
        :func:`~hairport.solver.mesh.polyline.rest_lengths`); None only for a problem solved without it
        (``weights.spacing`` 0).
    """

    offsets: np.ndarray
    source_directions: np.ndarray
    initial: np.ndarray
    coupling: sp.csr_matrix
    features: np.ndarray
    gamma: np.ndarray
    fixed: np.ndarray
    rest_lengths: np.ndarray | None = None

    def spacing_rest(self, weights: EnergyWeights) -> np.ndarray | None:
        """The rest lengths ``(N,)`` when ``weights`` turn the spacing term on, else None.

        Raises
        ------
        ValueError
            If the term is on and the problem has no rest lengths.
        """
        if not weights.spacing:
            return None
        if self.rest_lengths is None:
            raise ValueError("the spacing term is on (weights.spacing) but the problem has no rest lengths")
        return self.rest_lengths

    @property
    def n_particles(self) -> int:
        return len(self.initial)

    @property
    def n_strands(self) -> int:
        return len(self.offsets) - 1

    @cached_property
    def strand_of(self) -> np.ndarray:
        """(N,) int64."""
        return np.repeat(np.arange(self.n_strands), np.diff(self.offsets))

    @cached_property
    def segment_starts(self) -> np.ndarray:
        """(M,) int64 particles that start a segment (all but strand tips)."""
        starts = np.ones(self.n_particles, dtype=bool)
        starts[self.offsets[1:] - 1] = False
        return np.flatnonzero(starts)

    @cached_property
    def gram(self) -> sp.csr_matrix:
        """``K^T diag(gamma) K`` (constant over a solve)."""
        K = self.coupling
        return (K.T @ sp.diags(self.gamma) @ K).tocsr()

    @cached_property
    def gram_off_diagonal(self) -> sp.csr_matrix:
        """``K^T diag(gamma) K`` without its diagonal, stored zeros dropped: what couples particles."""
        off_diagonal = (self.gram - sp.diags(self.gram.diagonal())).tocsr()
        off_diagonal.eliminate_zeros()
        return off_diagonal

    @cached_property
    def coupled(self) -> bool:
        """Whether ``K`` links particles of different strands."""
        K = self.coupling.tocoo()
        return bool(np.any(self.strand_of[K.row] != self.strand_of[K.col]))

    def subset(self, strands: np.ndarray) -> tuple["StrandProblem", np.ndarray]:
        """The problem over some strands ``(s,) int64`` (ascending) and their particle indices.

        Only meaningful for an uncoupled problem (couplings to other strands are dropped).
        """
        counts = np.diff(self.offsets)[strands]
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        index = np.repeat(self.offsets[strands] - offsets[:-1], counts) + np.arange(offsets[-1])
        return (
            StrandProblem(
                offsets,
                self.source_directions[index],
                self.initial[index],
                self.coupling[index][:, index].tocsr(),
                self.features[index],
                self.gamma[index],
                self.fixed[index],
                None if self.rest_lengths is None else self.rest_lengths[index],
            ),
            index,
        )


    def strand_run(self, first: int, stop: int) -> tuple["StrandProblem", slice]:
        """The problem over the consecutive strands ``first .. stop - 1`` and their particles' slice.

        Its arrays are views of this problem's (no copy); only meaningful for an uncoupled problem
        (couplings to other strands are dropped).
        """
        rows = slice(int(self.offsets[first]), int(self.offsets[stop]))
        return (
            StrandProblem(
                self.offsets[first:stop + 1] - self.offsets[first],
                self.source_directions[rows],
                self.initial[rows],
                self.coupling[rows, rows].tocsr(),
                self.features[rows],
                self.gamma[rows],
                self.fixed[rows],
                None if self.rest_lengths is None else self.rest_lengths[rows],
            ),
            rows,
        )


def problem_from_shape_model(
    model: ShapeModel, offsets: np.ndarray, initial: np.ndarray, fixed: np.ndarray, gamma: np.ndarray | None = None
) -> StrandProblem:
    """The :class:`StrandProblem` of a whole hairstyle's :class:`.energies.ShapeModel` (with its spacing
    term's rest lengths for this initial transfer)."""
    n = len(initial)
    initial = np.asarray(initial, dtype=np.float64)
    directions = np.zeros((n, 3))
    directions[model.segments[:, 0]] = model.source_directions
    rest = np.zeros(n)
    rest[model.segments[:, 0]] = model.rest_lengths(initial)
    return StrandProblem(
        np.asarray(offsets, dtype=np.int64), directions, initial, model.K,
        model.source_features, np.ones(n) if gamma is None else np.asarray(gamma, dtype=np.float64),
        np.asarray(fixed, dtype=bool), rest,
    )


def group_energies(
    problem: StrandProblem, points: np.ndarray, weights: EnergyWeights, group: np.ndarray, n_groups: int,
    penalty: float | np.ndarray = 0.0, distance: np.ndarray | None = None, eps_c: float = 0.0,
) -> np.ndarray:
    """Eq. 1 summed per group ``(n_groups,)`` of particles (``group (N,)``), plus ``penalty``
    (a number, or one per particle ``(N,)``) times the clearance short of ``eps_c``
    (:func:`.constraints.clearance_violation`) when ``distance (N,)`` is given: the
    active-set line search's merit."""
    seg = problem.segment_starts
    vectors = points[seg + 1] - points[seg]
    directions = problem.source_directions[seg]
    per_particle = np.zeros(problem.n_particles)
    per_particle[seg] = shape_values(vectors, directions)
    rest = problem.spacing_rest(weights)
    if rest is not None:
        length, _ = unit_rows(vectors)
        rest = np.where(welded(directions), 0.0, rest[seg])  # a weld has no spacing term
        per_particle[seg] += weights.spacing * spacing_residuals(length, rest, weights.spacing_band) ** 2
    residual = problem.coupling @ points - problem.features
    per_particle += weights.alpha * problem.gamma * np.sum(residual**2, axis=1)
    per_particle += weights.beta * problem.gamma * np.sum((points - problem.initial) ** 2, axis=1)
    if distance is not None and np.any(np.asarray(penalty) > 0):
        per_particle += penalty * clearance_violation(distance, eps_c, problem.fixed)
    return np.bincount(group, per_particle, minlength=n_groups)


def strand_energies(
    problem: StrandProblem, points: np.ndarray, weights: EnergyWeights, penalty: float = 0.0,
    distance: np.ndarray | None = None, eps_c: float = 0.0,
) -> np.ndarray:
    """:func:`group_energies` per strand ``(S,)`` with one ``penalty`` for every particle, by the compiled merit
    (:func:`.merit_kernels.strand_merits`): any ``K``, its residual ``K p - L-bar`` taken once by a sparse product.
    Equal to the reference up to the order of the sums (tested)."""
    n = problem.n_particles
    residual = np.ascontiguousarray(problem.coupling @ points - problem.features)
    rest = problem.spacing_rest(weights) if weights.spacing else None
    strands = np.arange(problem.n_strands, dtype=np.int64)
    merit = np.zeros(problem.n_strands)
    merit_kernels.strand_merits(
        strands, problem.offsets, problem.offsets[:-1], np.ascontiguousarray(points, dtype=np.float64),
        np.zeros(n) if distance is None else np.ascontiguousarray(distance, dtype=np.float64),
        np.ascontiguousarray(problem.source_directions, dtype=np.float64),
        np.ascontiguousarray(problem.initial, dtype=np.float64), np.zeros(n), residual,
        np.ascontiguousarray(problem.gamma, dtype=np.float64),
        np.zeros(1) if rest is None else np.ascontiguousarray(rest, dtype=np.float64),
        np.ascontiguousarray(problem.fixed, dtype=np.bool_), float(weights.alpha), float(weights.beta),
        float(weights.spacing), float(weights.spacing_band[0]), float(weights.spacing_band[1]),
        np.full(problem.n_strands, float(penalty) if distance is not None else 0.0), float(eps_c),
        MIN_SEGMENT_LENGTH, WELD_LENGTH_M, merit)
    return merit


@dataclass(frozen=True, eq=False)
class NewtonSystem:
    """Gradient and Hessian of Eq. 1 at an iterate.

    Attributes
    ----------
    gradient : (N, 3) float64
    diagonal, upper : (N, 3, 3) float64
        The strand-banded part (exact Hessian when ``K`` is diagonal), :mod:`.banded` layout.
    coupling : (N, N) csr_matrix or None
        ``2 alpha K^T G K`` minus its diagonal, when strands are coupled through it.
    """

    gradient: np.ndarray
    diagonal: np.ndarray
    upper: np.ndarray
    coupling: sp.csr_matrix | None

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """``H x`` for ``x (N, 3)``."""
        y = banded.matvec(self.diagonal, self.upper, x)
        if self.coupling is not None:
            y += self.coupling @ x
        return y


def newton_system(
    problem: StrandProblem, points: np.ndarray, weights: EnergyWeights, radial_damping: np.ndarray
) -> NewtonSystem:
    """Projected-Newton model of Eq. 1 at ``points`` (see :func:`.energies.shape_blocks`).

    Parameters
    ----------
    radial_damping : (N,) float64
        Levenberg-Marquardt damping along the segment starting at each particle.
    """
    n = problem.n_particles
    seg = problem.segment_starts
    vectors = points[seg + 1] - points[seg]
    length, unit = unit_rows(vectors)
    d = problem.source_directions[seg]
    g = problem.gamma
    floor = NEGATIVE_CURVATURE_SHARE * weights.beta * np.minimum(g[seg], g[seg + 1]) * length**2
    projected = clamped_direction_hessians(unit, d, floor)
    mu = radial_damping[seg]
    blocks = 2.0 * (projected + mu[:, None, None] * unit[:, :, None] * unit[:, None, :]) / length[:, None, None] ** 2
    rest = problem.spacing_rest(weights)
    if rest is not None:
        rest = np.where(welded(d), 0.0, rest[seg])  # a weld has no spacing term
        blocks += spacing_blocks(unit, length, rest, weights.spacing, weights.spacing_band)
    weld_blocks(blocks, d, 2.0)

    K = problem.coupling
    kdiag = problem.gram.diagonal()
    diagonal = np.zeros((n, 3, 3))
    diagonal[seg] += blocks
    diagonal[seg + 1] += blocks
    diagonal += (2.0 * weights.alpha * kdiag + 2.0 * weights.beta * g)[:, None, None] * np.eye(3)[None]
    upper = np.zeros((n, 3, 3))
    upper[seg] = -blocks
    off_diagonal = problem.gram_off_diagonal
    coupling = 2.0 * weights.alpha * off_diagonal if off_diagonal.nnz else None

    shape_residual = shape_residuals(vectors, d, length, unit)
    if rest is not None:
        shape_residual += 0.5 * spacing_gradients(unit, length, rest, weights.spacing, weights.spacing_band)
    gradient = np.zeros((n, 3))
    gradient[seg] -= 2.0 * shape_residual
    gradient[seg + 1] += 2.0 * shape_residual
    gradient += 2.0 * weights.alpha * (K.T @ (g[:, None] * (K @ points - problem.features)))
    gradient += 2.0 * weights.beta * g[:, None] * (points - problem.initial)
    return NewtonSystem(gradient, diagonal, upper, coupling)


def compiled_newton_system(
    problem: StrandProblem, points: np.ndarray, weights: EnergyWeights, strand_damping: np.ndarray
) -> NewtonSystem:
    """:func:`newton_system` with its strand-banded part compiled (:func:`.model_kernels.assemble_strands`, the
    strands in parallel) and ``K``'s terms by sparse products: equal to it up to the order of the sums (tested).

    Parameters
    ----------
    strand_damping : (S,) float64
        Each strand's radial damping.
    """
    n = problem.n_particles
    rest = problem.spacing_rest(weights) if weights.spacing else None
    g = np.ascontiguousarray(problem.gamma, dtype=np.float64)
    points = np.ascontiguousarray(points, dtype=np.float64)
    diagonal, upper, gradient = np.empty((n, 3, 3)), np.empty((n, 3, 3)), np.empty((n, 3))
    model_kernels.assemble_strands(
        problem.offsets, points, np.ascontiguousarray(problem.source_directions, dtype=np.float64),
        np.ascontiguousarray(problem.initial, dtype=np.float64), g,
        np.zeros(1) if rest is None else np.ascontiguousarray(rest, dtype=np.float64), float(weights.beta),
        float(weights.spacing), float(weights.spacing_band[0]), float(weights.spacing_band[1]),
        np.ascontiguousarray(strand_damping, dtype=np.float64), MIN_SEGMENT_LENGTH, WELD_LENGTH_M,
        NEGATIVE_CURVATURE_SHARE, PARALLEL_SINE, diagonal, upper, gradient)
    K = problem.coupling
    stiffness = 2.0 * weights.alpha * problem.gram.diagonal()
    for a in range(3):
        diagonal[:, a, a] += stiffness
    gradient += 2.0 * weights.alpha * (K.T @ (g[:, None] * (K @ points - problem.features)))
    off_diagonal = problem.gram_off_diagonal
    return NewtonSystem(gradient, diagonal, upper, 2.0 * weights.alpha * off_diagonal if off_diagonal.nnz else None)
