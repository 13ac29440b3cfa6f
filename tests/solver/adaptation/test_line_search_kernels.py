"""The line-search kernels of the compiled fine level (solver/adaptation/line_search_kernels.py) against numpy."""

import numpy as np
import pytest

from hairport.solver.adaptation import line_search_kernels
from hairport.solver.adaptation.strand_problem import group_energies
from hairport.solver.mesh.polyline import MIN_SEGMENT_LENGTH
from tests.solver.adaptation.test_strand_kernels import WEIGHTS, random_problem, unit


def test_line_search_kernels_gather_price_and_commit_trial_points():
    rng = np.random.default_rng(7)
    problem, points = random_problem(rng)
    n = problem.n_particles
    step = rng.normal(scale=1e-3, size=(n, 3))
    strands = np.array([0, 3, 4], dtype=np.int64)
    fraction = np.array([1.0, 0.5, 0.25])
    packed = np.concatenate([[0], np.cumsum(np.diff(problem.offsets)[strands])]).astype(np.int64)
    index = np.concatenate([np.arange(problem.offsets[s], problem.offsets[s + 1]) for s in strands])
    moved, free = np.empty((packed[-1], 3)), np.empty(packed[-1], dtype=bool)
    line_search_kernels.gather_trial_points(strands, problem.offsets, packed, points, step, fraction, problem.fixed,
                                            moved, free)
    per_particle = np.repeat(fraction, np.diff(packed))
    np.testing.assert_array_equal(moved, points[index] + per_particle[:, None] * step[index])
    np.testing.assert_array_equal(free, ~problem.fixed[index])

    moved_distance = rng.normal(scale=1e-3, size=len(index))
    moved_distance[::4] = np.inf
    arrays = (problem.source_directions, problem.initial, problem.coupling.diagonal(), problem.features, problem.gamma)
    penalty = rng.uniform(0.0, 10.0, problem.n_strands)
    merit = np.zeros(3)
    line_search_kernels.strand_merits(strands, problem.offsets, packed[:-1], moved, moved_distance, *arrays,
                                      problem.fixed, WEIGHTS.alpha, WEIGHTS.beta, penalty, 5e-4, MIN_SEGMENT_LENGTH, merit)
    trial = points.copy()
    trial[index] = moved
    trial_distance = np.full(n, np.inf)
    trial_distance[index] = moved_distance
    expected = group_energies(problem, trial, WEIGHTS, problem.strand_of, problem.n_strands,
                              penalty[problem.strand_of], trial_distance, 5e-4)
    np.testing.assert_allclose(merit, expected[strands], rtol=1e-13)
    # at the iterate: the chunk's own rows
    at_iterate = np.zeros(3)
    distance = np.where(np.arange(n) % 3 == 0, np.inf, rng.normal(scale=1e-3, size=n))
    line_search_kernels.strand_merits(strands, problem.offsets, problem.offsets[strands], points, distance, *arrays,
                                      problem.fixed, WEIGHTS.alpha, WEIGHTS.beta, penalty, 5e-4, MIN_SEGMENT_LENGTH,
                                      at_iterate)
    expected = group_energies(problem, points, WEIGHTS, problem.strand_of, problem.n_strands,
                              penalty[problem.strand_of], distance, 5e-4)
    np.testing.assert_allclose(at_iterate, expected[strands], rtol=1e-13)

    take = np.array([True, False, True])
    committed, distance, normal, near = points.copy(), np.zeros(n), np.zeros((n, 3)), np.zeros(n, dtype=bool)
    moved_normal, moved_near = unit(rng.normal(size=(len(index), 3))), np.isfinite(moved_distance)
    max_step, shortfall, clearance = np.zeros(3), np.zeros(3), np.zeros(3)
    line_search_kernels.commit_trial_points(strands, problem.offsets, packed, take, moved, moved_distance,
                                            moved_normal, moved_near, problem.fixed, 5e-4, committed, distance, normal,
                                            near, max_step, shortfall, clearance)
    for t, s in enumerate(strands):
        rows = slice(problem.offsets[s], problem.offsets[s + 1])
        mine = slice(packed[t], packed[t + 1])
        if not take[t]:
            np.testing.assert_array_equal(committed[rows], points[rows])
            continue
        np.testing.assert_array_equal(committed[rows], moved[mine])
        np.testing.assert_array_equal(distance[rows], moved_distance[mine])
        np.testing.assert_array_equal(normal[rows], moved_normal[mine])
        np.testing.assert_array_equal(near[rows], moved_near[mine])
        assert max_step[t] == pytest.approx(np.linalg.norm(moved[mine] - points[rows], axis=1).max(), rel=1e-15)
        free_distance = moved_distance[mine][~problem.fixed[rows]]
        assert shortfall[t] == 5e-4 - free_distance.min()
        assert clearance[t] == free_distance.min()
    # the clearance of the strands that stay: read from the chunk's (now committed) distances
    stay_short, stay_clearance = np.zeros(3), np.zeros(3)
    line_search_kernels.strand_clearances(strands, problem.offsets, distance, problem.fixed, 5e-4, stay_short,
                                          stay_clearance)
    for t, s in enumerate(strands):
        free_distance = distance[problem.offsets[s]:problem.offsets[s + 1]][~problem.fixed[problem.offsets[s]:problem.offsets[s + 1]]]
        assert stay_clearance[t] == free_distance.min() and stay_short[t] == 5e-4 - free_distance.min()
