"""The compiled merits of both levels' line searches (solver/adaptation/problem/merit_kernels.py) against
:func:`.strand_problem.group_energies`."""

import numpy as np

from hairport.solver.adaptation.problem import merit_kernels
from hairport.solver.adaptation.problem.energies import WELD_LENGTH_M
from hairport.solver.adaptation.problem.strand_problem import group_energies
from hairport.solver.mesh.polyline import MIN_SEGMENT_LENGTH
from tests.solver.adaptation.fine.test_strand_kernels import WEIGHTS, packed_trials


def test_strand_merits_at_packed_trial_points_and_at_the_iterate_are_the_reference():
    rng, problem, points, step, strands, fraction, packed, index = packed_trials(7)
    n = problem.n_particles
    moved = points[index] + np.repeat(fraction, np.diff(packed))[:, None] * step[index]
    moved_distance = rng.normal(scale=1e-3, size=len(index))
    moved_distance[::4] = np.inf
    arrays = (problem.source_directions, problem.initial, problem.coupling.diagonal(), problem.features, problem.gamma,
              problem.rest_lengths)
    penalty = rng.uniform(0.0, 10.0, problem.n_strands)
    merit = np.zeros(3)
    merit_kernels.strand_merits(strands, problem.offsets, packed[:-1], moved, moved_distance, *arrays,
                                      problem.fixed, WEIGHTS.alpha, WEIGHTS.beta, WEIGHTS.spacing, *WEIGHTS.spacing_band, penalty, 5e-4,
                                      MIN_SEGMENT_LENGTH, WELD_LENGTH_M, merit)
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
    merit_kernels.strand_merits(strands, problem.offsets, problem.offsets[strands], points, distance, *arrays,
                                      problem.fixed, WEIGHTS.alpha, WEIGHTS.beta, WEIGHTS.spacing, *WEIGHTS.spacing_band, penalty, 5e-4,
                                      MIN_SEGMENT_LENGTH, WELD_LENGTH_M,
                                      at_iterate)
    expected = group_energies(problem, points, WEIGHTS, problem.strand_of, problem.n_strands,
                              penalty[problem.strand_of], distance, 5e-4)
    np.testing.assert_allclose(at_iterate, expected[strands], rtol=1e-13)

