"""The compiled per-strand kernels (solver/adaptation/fine/strand_kernels.py) against their numpy references on random data."""

import numpy as np
import pytest
import scipy.sparse as sp

from hairport.solver.adaptation.coupled.contact_qp import Frames, solve_qp
from hairport.solver.adaptation.fine import strand_kernels
from hairport.solver.adaptation.problem import model_kernels
from hairport.solver.adaptation.problem.energies import (
    NEGATIVE_CURVATURE_SHARE,
    PARALLEL_SINE,
    WELD_LENGTH_M,
    EnergyWeights,
)
from hairport.solver.adaptation.problem.strand_problem import StrandProblem, newton_system
from hairport.solver.mesh.polyline import MIN_SEGMENT_LENGTH
from tests.solver.adaptation.problem.test_banded import random_block_tridiagonal

#: with the spacing term on, and a free band (segments inside and outside it): the kernels and their
#: references carry it (issue 16)
WEIGHTS = EnergyWeights(alpha=3e3, beta=1e3, spacing=1.0, spacing_band=(0.9, 1.1))


def unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def random_problem(rng, counts=(7, 2, 1, 12, 5)):
    """Strands of ``counts`` particles (4 mm segments, directions off their sources), a diagonal ``K``,
    rest lengths of 2-6 mm (segments stretched and compressed; a few without the spacing term)."""
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    n = offsets[-1]
    points = np.cumsum(rng.normal(scale=0.004, size=(n, 3)), axis=0)
    fixed = np.zeros(n, dtype=bool)
    fixed[offsets[:-1]] = True
    problem = StrandProblem(offsets, unit(rng.normal(size=(n, 3))), points + rng.normal(scale=2e-3, size=(n, 3)),
                            sp.diags(rng.uniform(0.5, 2.0, n), format="csr"), rng.normal(scale=0.01, size=(n, 3)),
                            rng.uniform(0.2, 1.0, n), fixed,
                            np.where(np.arange(n) % 5 == 2, 0.0, rng.uniform(0.002, 0.006, n)))
    return problem, points


def packed_trials(seed: int):
    """:func:`random_problem`, a random step, and 3 of its strands packed back to back as the line search packs its
    trial points: ``(problem, points, step, strands (3,), fraction (3,), packed (4,), index (P,))``."""
    rng = np.random.default_rng(seed)
    problem, points = random_problem(rng)
    step = rng.normal(scale=1e-3, size=(problem.n_particles, 3))
    strands = np.array([0, 3, 4], dtype=np.int64)
    fraction = np.array([1.0, 0.5, 0.25])
    packed = np.concatenate([[0], np.cumsum(np.diff(problem.offsets)[strands])]).astype(np.int64)
    index = np.concatenate([np.arange(problem.offsets[s], problem.offsets[s + 1]) for s in strands])
    return rng, problem, points, step, strands, fraction, packed, index


def strand_blocks(problem, points, damping):
    """:func:`model_kernels.assemble_strand` of every strand, concatenated like :func:`newton_system`."""
    n = problem.n_particles
    diagonal, upper, gradient = np.zeros((n, 3, 3)), np.zeros((n, 3, 3)), np.zeros((n, 3))
    w = problem.coupling.diagonal()
    for s in range(problem.n_strands):
        a, b = problem.offsets[s], problem.offsets[s + 1]
        model_kernels.assemble_strand(
            a, b - a, points, problem.source_directions, problem.initial, w, problem.features, problem.gamma,
            problem.rest_lengths, WEIGHTS.alpha, WEIGHTS.beta, WEIGHTS.spacing, *WEIGHTS.spacing_band, damping[s], MIN_SEGMENT_LENGTH,
            WELD_LENGTH_M, NEGATIVE_CURVATURE_SHARE, PARALLEL_SINE,
            diagonal[a:b], upper[a:b], gradient[a:b],
        )
    return diagonal, upper, gradient


def test_contact_frames_and_rotation_match_the_frames_class():
    rng = np.random.default_rng(2)
    n = 9
    diagonal, upper, _ = random_block_tridiagonal(n, rng)
    gradient = rng.normal(size=(n, 3))
    rotated = rng.random(n) < 0.5
    rotated[[0, 4, 5]] = [True, True, False]
    normals = unit(rng.normal(size=(n, 3)))
    normals[4] = [0.0, 0.0, -1.0]  # axis-aligned: argmin ties
    frames = np.zeros((n, 3, 3))
    for i in np.flatnonzero(rotated):
        strand_kernels.contact_frame(normals[i], frames[i])
    reference = Frames(n, np.flatnonzero(rotated), normals[rotated])
    np.testing.assert_allclose(frames[rotated], reference.R if not reference.dense else reference.R[rotated],
                               rtol=0, atol=1e-15)
    expected_diagonal, expected_upper = reference.rotate_blocks(diagonal, upper)
    expected_gradient = reference.to_local(gradient)
    strand_kernels.rotate_strand(rotated, frames, diagonal, upper, gradient)
    np.testing.assert_allclose(diagonal, expected_diagonal, rtol=0, atol=1e-13)
    np.testing.assert_allclose(upper, expected_upper, rtol=0, atol=1e-13)
    np.testing.assert_allclose(gradient, expected_gradient, rtol=0, atol=1e-14)


def test_active_set_qp_of_a_strand_matches_solve_qp():
    """One strand's rotated QP by the kernel against :func:`contact_qp.solve_qp` (several constraints active)."""
    rng = np.random.default_rng(5)
    problem, points = random_problem(rng, counts=(14,))
    n = problem.n_particles
    damping = np.array([0.3])
    system = newton_system(problem, points, WEIGHTS, np.full(n, 0.3))
    normals = unit(rng.normal(size=(n, 3)))
    lower = rng.normal(scale=2e-3, size=n) + 1e-3
    constrained = ~problem.fixed & (rng.random(n) < 0.8)
    start_active = constrained & (rng.random(n) < 0.3)
    step, multipliers, active, rounds, _ = solve_qp(system, problem.fixed, constrained, normals, lower, start_active)
    assert active.sum() >= 3 and rounds >= 2

    diagonal, upper, gradient = strand_blocks(problem, points, damping)
    frames = np.zeros((n, 3, 3))
    for i in np.flatnonzero(constrained):
        strand_kernels.contact_frame(normals[i], frames[i])
    strand_kernels.rotate_strand(constrained, frames, diagonal, upper, gradient)
    kernel_active = start_active.copy()
    y, kernel_multipliers = np.empty((n, 3)), np.empty(n)
    kernel_rounds = strand_kernels.active_set_qp(diagonal, upper, gradient, problem.fixed, constrained, lower,
                                                 kernel_active, 50, y, kernel_multipliers)
    kernel_step = np.where(constrained[:, None], np.einsum("nij,nj->ni", frames, y), y)
    assert kernel_rounds == rounds
    np.testing.assert_array_equal(kernel_active, active)
    np.testing.assert_allclose(kernel_step, step, rtol=0, atol=1e-12)
    np.testing.assert_allclose(kernel_multipliers, multipliers, rtol=0, atol=1e-9 * np.abs(multipliers).max())


def test_newton_qp_steps_give_the_steps_and_predictions_of_the_numpy_model():
    """The fused kernel over a list of strands: steps, active sets, raised penalties, predicted change per strand."""
    rng = np.random.default_rng(6)
    problem, points = random_problem(rng)
    n, s = problem.n_particles, problem.n_strands
    distance = rng.normal(scale=1e-3, size=n)
    distance[rng.random(n) < 0.3] = np.inf  # far from the body: no constraint
    normal = unit(rng.normal(size=(n, 3)))
    near = np.isfinite(distance)
    eps_c = 5e-4
    damping = rng.uniform(1e-3, 1.0, s)
    strands = np.array([0, 1, 3, 4], dtype=np.int64)  # strand 2 (one particle) stays closed
    penalty = np.array([0.0, 5.0, 7.0, 1e6, 0.0])
    active = np.zeros(n, dtype=bool)
    step = np.zeros((n, 3))
    rounds = np.zeros(4, dtype=np.int64)
    predicted = np.zeros(4)
    strand_kernels.newton_qp_steps(
        strands, problem.offsets, points, distance, normal, near, problem.source_directions, problem.initial,
        problem.coupling.diagonal(), problem.features, problem.gamma, problem.rest_lengths, problem.fixed,
        WEIGHTS.alpha, WEIGHTS.beta, WEIGHTS.spacing, *WEIGHTS.spacing_band, eps_c, damping, penalty, active, step, rounds, predicted, MIN_SEGMENT_LENGTH,
        WELD_LENGTH_M, NEGATIVE_CURVATURE_SHARE, PARALLEL_SINE, 2.0, 50)
    for t, strand in enumerate(strands):
        sub, rows = problem.strand_run(int(strand), int(strand) + 1)
        m = sub.n_particles
        system = newton_system(sub, points[rows], WEIGHTS, np.full(m, damping[strand]))
        constrained = near[rows] & ~sub.fixed
        expected, multipliers, expected_active, expected_rounds, _ = solve_qp(
            system, sub.fixed, constrained, normal[rows], eps_c - distance[rows], np.zeros(m, dtype=bool))
        np.testing.assert_allclose(step[rows], expected, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(active[rows], expected_active)
        assert rounds[t] == expected_rounds
        expected_change = np.sum(expected * (system.gradient + 0.5 * system.matvec(expected)))
        assert predicted[t] == pytest.approx(expected_change, rel=1e-9, abs=1e-15)
        raised = max([0.0, 5.0, 7.0, 1e6, 0.0][strand], 2.0 * np.abs(multipliers).max(initial=0.0))
        assert penalty[strand] == pytest.approx(raised, rel=1e-9)
    assert np.all(step[problem.offsets[2]:problem.offsets[3]] == 0.0) and penalty[2] == 7.0
    assert penalty[3] == 1e6  # a running maximum
    assert (rounds >= 1).all() and active.any()
