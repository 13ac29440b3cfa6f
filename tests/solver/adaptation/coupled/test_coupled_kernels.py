"""Compiled kernels of the coupled active-set rounds (solver/adaptation/coupled/coupled_kernels.py) against
their numpy references: scipy's banded Cholesky, the block products of contact_qp.Frames and of
the Newton system, and the module's numpy conjugate gradients."""

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sp

from hairport.solver import kernels
from hairport.solver.adaptation.coupled import coupled_kernels
from hairport.solver.adaptation.coupled.contact_qp import CG_MAX_STEPS, CG_RELATIVE_TOLERANCE, Frames
from hairport.solver.adaptation.coupled.coupled_kernels import (
    BANDWIDTH,
    RotatedHessian,
    band_runs,
    factor_bands,
    reference_pinned_solve,
    reference_product,
    rotate_blocks,
    solve_bands,
    sparse_product,
)
from hairport.solver.adaptation.loop.options import SolveOptions
from hairport.solver.adaptation.problem import banded
from hairport.solver.adaptation.problem.constraints import fixed_coordinates, linearised_clearance
from hairport.solver.adaptation.problem.energies import EnergyWeights
from hairport.solver.adaptation.problem.strand_problem import newton_system, problem_from_shape_model
from hairport.solver.mesh.query import MeshQuery
from tests.solver.hair_shapes import model_of, outward_strands, sphere_character, tilt_into_surface

#: m: the kernels equal their numpy reference to this on these small problems (issue 13)
SAME = 1e-9


def block_tridiagonal(n, breaks=(), seed=0):
    """A random symmetric positive definite block-tridiagonal matrix: its blocks and the dense matrix.
    The off-diagonal blocks after the particles in ``breaks`` are zero (strand ends)."""
    rng = np.random.default_rng(seed)
    lower = rng.normal(size=(3 * n, 3 * n))
    dense = lower @ lower.T + 3 * n * np.eye(3 * n)
    block = np.arange(3 * n) // 3
    dense[np.abs(block[:, None] - block[None, :]) > 1] = 0.0
    for i in breaks:
        dense[3 * i:3 * i + 3, 3 * i + 3:3 * i + 6] = dense[3 * i + 3:3 * i + 6, 3 * i:3 * i + 3] = 0.0
    diagonal = np.stack([dense[3 * i:3 * i + 3, 3 * i:3 * i + 3] for i in range(n)])
    upper = np.zeros((n, 3, 3))
    for i in range(n - 1):
        upper[i] = dense[3 * i:3 * i + 3, 3 * i + 3:3 * i + 6]
    return diagonal, upper, dense


def test_band_factor_and_solve_are_lapacks_with_pinned_identity_rows():
    n = 9
    diagonal, upper, _ = block_tridiagonal(n, breaks=(3,))
    pinned = np.zeros((n, 3), dtype=bool)
    pinned[0] = pinned[4] = True  # roots of two strands
    pinned[6, 0] = True  # an active constraint
    reference = scipy.linalg.cholesky_banded(banded.with_fixed_unknowns(banded.to_bands(diagonal, upper), pinned.ravel()),
                                             lower=False)
    runs = band_runs(upper)
    np.testing.assert_array_equal(runs, [0, 4, n])
    factor = np.empty((3 * n, BANDWIDTH + 1))
    assert factor_bands(diagonal, upper, pinned, runs, np.arange(2), factor)
    rows = np.arange(3 * n)
    np.testing.assert_allclose(1.0 / factor[:, 0], reference[BANDWIDTH], rtol=1e-14)
    for m in range(1, BANDWIDTH + 1):  # U[r, r + m] in LAPACK's band row BANDWIDTH - m, column r + m
        np.testing.assert_allclose(factor[rows[:-m], m], reference[BANDWIDTH - m, rows[m:]], rtol=0, atol=1e-14)
    rhs = np.random.default_rng(1).normal(size=(n, 3))
    out = np.empty((n, 3))
    solve_bands(factor, pinned, runs, rhs, out)
    expected = scipy.linalg.cho_solve_banded((reference, False), rhs.ravel()).reshape(n, 3)
    expected[pinned] = 0.0
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-14 * np.abs(expected).max())
    assert np.all(out[pinned] == 0.0)


def test_band_factor_reports_an_indefinite_matrix():
    diagonal, upper, _ = block_tridiagonal(4)
    diagonal[2] = -np.eye(3)
    factor = np.empty((12, BANDWIDTH + 1))
    assert not factor_bands(diagonal, upper, np.zeros((4, 3), dtype=bool), band_runs(upper), np.arange(1), factor)
    hessian = RotatedHessian.build(np.broadcast_to(np.eye(3), (4, 3, 3)), diagonal, upper, sp.csr_matrix((4, 4)))
    with pytest.raises(np.linalg.LinAlgError):
        hessian.pinned_solve(np.ones((4, 3)), np.zeros((4, 3), dtype=bool), np.zeros((4, 3)), None, 1e-6, 10)


@pytest.fixture(scope="module")
def coupled_round():
    """The first QP of 30 kNN-coupled strands tilted into a sphere: its Newton system, frames and pins."""
    source = sphere_character()
    query = MeshQuery(source.vertices, source.faces)
    hair = outward_strands(source, n_strands=30, n_points=10, seed=3)
    start = tilt_into_surface(hair, query, np.radians(95.0))
    problem = problem_from_shape_model(model_of(hair), hair.offsets, start, hair.is_root)
    assert problem.coupled
    system = newton_system(problem, start, EnergyWeights(), np.ones(problem.n_particles))
    sd = query.signed_distance(start)
    constrained, lower = linearised_clearance(sd.distance, SolveOptions().eps_c, problem.fixed)
    frames = Frames(problem.n_particles, np.flatnonzero(constrained), sd.normal[constrained])
    pinned = fixed_coordinates(problem.fixed)
    active = constrained & (lower > 0)  # the particles inside
    assert 20 < active.sum() < constrained.sum()
    pinned[:, 0] |= active
    values = np.zeros((problem.n_particles, 3))
    values[:, 0] = np.where(active, lower, 0.0)
    return system, frames, pinned, values


def test_rotated_blocks_and_product_are_the_numpy_ones(coupled_round):
    system, frames, _, _ = coupled_round
    hessian = RotatedHessian.build(frames.all_rotations(), system.diagonal, system.upper, system.coupling)
    rotated_diagonal, rotated_upper = frames.rotate_blocks(system.diagonal, system.upper)
    np.testing.assert_allclose(hessian.rotated_diagonal, rotated_diagonal, rtol=0, atol=1e-12 * np.abs(rotated_diagonal).max())
    np.testing.assert_allclose(hessian.rotated_upper, rotated_upper, rtol=0, atol=1e-12 * np.abs(rotated_upper).max())
    out_diagonal, out_upper = np.empty_like(rotated_diagonal), np.empty_like(rotated_upper)
    rotate_blocks(frames.all_rotations(), system.diagonal, system.upper, out_diagonal, out_upper)
    np.testing.assert_array_equal(out_diagonal, hessian.rotated_diagonal)
    y = np.random.default_rng(2).normal(scale=1e-3, size=system.gradient.shape)
    expected = frames.to_local(system.matvec(frames.to_world(y)))
    np.testing.assert_allclose(hessian.product(y), expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    np.testing.assert_allclose(reference_product(hessian, y), expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    # a vector that is zero but at a few particles
    rows = np.array([0, 7, 8, 150, len(y) - 1])
    sparse = np.zeros_like(y)
    sparse[rows] = y[rows]
    out = np.empty_like(y)
    sparse_product(hessian.R, hessian.rotated_diagonal, hessian.rotated_upper, hessian.coupling.indptr,
                   hessian.coupling.indices, hessian.coupling.data, rows, sparse, out)
    expected = hessian.product(sparse)
    assert np.count_nonzero(np.any(expected != 0, axis=1)) > 30
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-12 * np.abs(expected).max())


@pytest.mark.parametrize("warm", [False, True], ids=["from zero", "from a guess"])
def test_pinned_solve_is_the_numpy_reference(coupled_round, warm):
    system, frames, pinned, values = coupled_round
    hessian = RotatedHessian.build(frames.all_rotations(), system.diagonal, system.upper, system.coupling)
    rhs = -frames.to_local(system.gradient)
    guess = np.random.default_rng(3).normal(scale=1e-3, size=rhs.shape) if warm else None
    rotated_diagonal, rotated_upper = frames.rotate_blocks(system.diagonal, system.upper)
    numpy_hessian = RotatedHessian(frames.all_rotations(), rotated_diagonal, rotated_upper, system.coupling)
    expected, expected_steps, expected_residual = reference_pinned_solve(
        numpy_hessian, rhs, pinned, values, guess, CG_RELATIVE_TOLERANCE, CG_MAX_STEPS)
    y, steps, residual = hessian.pinned_solve(rhs, pinned, values, guess, CG_RELATIVE_TOLERANCE, CG_MAX_STEPS)
    assert 5 < steps == expected_steps < CG_MAX_STEPS
    assert np.abs(expected).max() > 1e-3  # a step of millimetres
    np.testing.assert_allclose(y, expected, rtol=0, atol=SAME)
    np.testing.assert_array_equal(y[pinned], values[pinned])
    # it solves the system: the free residual is at the tolerance, relative to the zero guess's
    start = np.where(pinned, values, 0.0)
    cold = np.linalg.norm(np.where(pinned, 0.0, rhs - hessian.product(start)))
    exact_residual = rhs - hessian.product(y)
    assert np.linalg.norm(np.where(pinned, 0.0, exact_residual)) <= 1.01 * CG_RELATIVE_TOLERANCE * cold
    # the recursion's residual is the true one, at the pinned unknowns too (they give the multipliers)
    scale = np.abs(exact_residual).max()
    np.testing.assert_allclose(residual, exact_residual, rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(expected_residual, exact_residual, rtol=0, atol=1e-9 * scale)


def test_a_new_round_refactorises_only_the_strands_whose_pins_changed(coupled_round):
    system, frames, pinned, _ = coupled_round
    hessian = RotatedHessian.build(frames.all_rotations(), system.diagonal, system.upper, system.coupling)
    first = hessian.factor(pinned).copy()
    changed = pinned.copy()
    particle = np.flatnonzero(~pinned[:, 0])[40]
    changed[particle, 0] = True
    second = hessian.factor(changed)
    fresh = RotatedHessian.build(frames.all_rotations(), system.diagonal, system.upper, system.coupling).factor(changed)
    np.testing.assert_array_equal(second, fresh)
    run = np.searchsorted(hessian.runs, particle, side="right") - 1
    strand = slice(3 * hessian.runs[run], 3 * hessian.runs[run + 1])
    assert np.any(second[strand] != first[strand])
    second[strand] = first[strand]
    np.testing.assert_array_equal(second, first)  # the other strands' rows as they were


def test_kernels_are_warmed_up():
    assert coupled_kernels in kernels.MODULES
    assert coupled_kernels.__name__ in kernels.warm_up().seconds
