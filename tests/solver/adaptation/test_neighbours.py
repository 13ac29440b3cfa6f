"""Eq. 8-9 (solver/adaptation/neighbours.py): kNN of other strands, inverse-distance weights, the Laplacian K."""

import numpy as np

from hairport.solver.adaptation.neighbours import knn_other_strands, laplacian_operator
from tests.solver.hair_shapes import model_of, parallel_strands


def test_knn_excludes_own_strand_and_weights_sum_to_one():
    hair = parallel_strands()
    nb = knn_other_strands(hair.points, hair.strand_of, 3)
    assert (hair.strand_of[nb.index] != hair.strand_of[:, None]).all()
    np.testing.assert_allclose(nb.weight.sum(axis=1), 1.0, atol=1e-15)


def test_knn_nearest_is_the_adjacent_strand_at_equal_height():
    hair = parallel_strands(spacing=0.01, step=0.005)
    nb = knn_other_strands(hair.points, hair.strand_of, 1)
    middle = np.flatnonzero(hair.strand_of == 0)
    # strand 0's nearest other particle is strand 1's particle at the same height, 1 cm away
    np.testing.assert_allclose(np.linalg.norm(hair.points[nb.index[middle, 0]] - hair.points[middle], axis=1), 0.01)


def test_knn_inverse_distance_weights_match_eq9():
    hair = parallel_strands(n_strands=3, spacing=0.01)
    nb = knn_other_strands(hair.points, hair.strand_of, 2)
    i = 0  # strand 0 root: neighbours at 1 cm (strand 1 root) and at sqrt(1^2+0.5^2) cm (strand 1 next)
    d = np.linalg.norm(hair.points[nb.index[i]] - hair.points[i], axis=1)
    expected = (1 / d) / np.sum(1 / d)
    np.testing.assert_allclose(nb.weight[i], expected, rtol=1e-14)


def test_knn_candidates_restrict_neighbours_to_guides():
    hair = parallel_strands(n_strands=4)
    guides = np.isin(hair.strand_of, [0, 3])
    nb = knn_other_strands(hair.points, hair.strand_of, 2, candidates=guides)
    assert guides[nb.index].all()


def test_knn_single_strand_has_no_neighbours():
    hair = parallel_strands(n_strands=1)
    nb = knn_other_strands(hair.points, hair.strand_of, 5)
    assert np.all(nb.weight == 0.0)
    K = laplacian_operator(nb, np.arange(hair.n_particles), hair.n_particles)
    assert abs(K).sum() == 0.0


def test_laplacian_is_translation_invariant():
    hair = parallel_strands()
    model = model_of(hair, k=2)
    shifted = hair.points + np.array([0.3, -1.0, 2.0])
    np.testing.assert_allclose(model.K @ shifted, model.source_features, atol=1e-14)
