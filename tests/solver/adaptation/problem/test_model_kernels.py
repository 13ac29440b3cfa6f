"""The compiled Newton model per strand (solver/adaptation/problem/model_kernels.py) against
:func:`.energies.clamped_direction_hessians` and :func:`.strand_problem.newton_system`."""

import numpy as np

from hairport.solver.adaptation.problem import model_kernels
from hairport.solver.adaptation.problem.energies import PARALLEL_SINE, clamped_direction_hessians
from hairport.solver.adaptation.problem.strand_problem import newton_system
from tests.solver.adaptation.fine.test_strand_kernels import WEIGHTS, random_problem, strand_blocks, unit


def test_clamped_direction_hessian_matches_numpy_including_parallel_directions():
    rng = np.random.default_rng(0)
    u = unit(rng.normal(size=(40, 3)))
    d = unit(rng.normal(size=(40, 3)))
    d[0], d[1] = u[0], -u[1]  # parallel and antiparallel: the fallback normal
    d[2] = unit(u[2] + 1e-13 * rng.normal(size=3))  # below PARALLEL_SINE
    floor = rng.uniform(0.0, 2.0, 40)
    floor[3] = 0.0
    expected = clamped_direction_hessians(u, d, floor)
    block = np.empty((3, 3))
    for m in range(40):
        model_kernels.clamped_direction_hessian(u[m], d[m], floor[m], PARALLEL_SINE, block)
        np.testing.assert_allclose(block, expected[m], rtol=0, atol=1e-14)


def test_assembled_strands_are_the_newton_system():
    rng = np.random.default_rng(1)
    problem, points = random_problem(rng)
    damping = rng.uniform(1e-4, 1.0, problem.n_strands)
    system = newton_system(problem, points, WEIGHTS, damping[problem.strand_of])
    assert system.coupling is None
    diagonal, upper, gradient = strand_blocks(problem, points, damping)
    scale = np.abs(system.diagonal).max()
    np.testing.assert_allclose(diagonal, system.diagonal, rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(upper, system.upper, rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(gradient, system.gradient, rtol=0, atol=1e-13 * np.abs(system.gradient).max())
    assert np.abs(upper[problem.offsets[1:] - 1]).max() == 0.0  # strands do not touch
