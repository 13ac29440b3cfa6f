"""Eq. 8-9 (solver/adaptation/source/neighbours.py): kNN of other strands, inverse-distance weights, the Laplacian K."""

import tracemalloc

import numpy as np
import pytest

from hairport.solver.adaptation.source import neighbours
from hairport.solver.adaptation.source.neighbours import KNN_MAX_ROUND_CANDIDATES, knn_other_strands, laplacian_operator
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


def _brute_force_distances(points, strand_of, k, pool):
    """(N, k) sorted distances to the k nearest pool particles of other strands (inf padding)."""
    d = np.linalg.norm(points[:, None] - points[pool][None], axis=2)
    d[strand_of[:, None] == strand_of[pool][None]] = np.inf
    d = np.sort(d, axis=1)[:, :k]
    return np.pad(d, ((0, 0), (0, k - d.shape[1])), constant_values=np.inf)


def _found_distances(points, nb):
    return np.where(nb.weight > 0, np.linalg.norm(points[nb.index] - points[:, None], axis=2), np.inf)


def _random_walk_groom(counts, seed):
    rng = np.random.default_rng(seed)
    counts = np.asarray(counts)
    points = np.cumsum(rng.normal(scale=0.01, size=(counts.sum(), 3)), axis=0)
    return points, np.repeat(np.arange(len(counts)), counts)


@pytest.mark.parametrize("seed", range(6))
def test_knn_is_exact_for_long_and_short_strands_alike(seed):
    # strands longer than the rounds' candidate cap take the exact other-strand search
    rng = np.random.default_rng(seed)
    counts = rng.integers(2, 900, rng.integers(2, 6))
    points, strand_of = _random_walk_groom(counts, seed)
    candidates = rng.random(len(points)) < 0.6 if seed % 2 else None
    pool = np.arange(len(points)) if candidates is None else np.flatnonzero(candidates)
    k = int(rng.integers(1, 8))
    nb = knn_other_strands(points, strand_of, k, candidates=candidates)
    assert (counts + k > KNN_MAX_ROUND_CANDIDATES).any()
    np.testing.assert_allclose(_found_distances(points, nb), _brute_force_distances(points, strand_of, k, pool),
                               rtol=1e-12)
    found = nb.weight > 0
    assert (strand_of[nb.index][found] != np.broadcast_to(strand_of[:, None], nb.index.shape)[found]).all()


def test_the_exact_search_gives_the_rounds_neighbours(monkeypatch):
    points, strand_of = _random_walk_groom([40] * 60, seed=3)
    rounds = knn_other_strands(points, strand_of, 5)
    monkeypatch.setattr(neighbours, "KNN_MAX_ROUND_CANDIDATES", 0)  # every missed particle goes exact
    exact = knn_other_strands(points, strand_of, 5)
    assert neighbours.KNN_EXTRA_CANDIDATES + 5 < 40  # so the first round misses on some particles
    np.testing.assert_array_equal(exact.index, rounds.index)
    np.testing.assert_array_equal(exact.weight, rounds.weight)


def test_a_long_lonely_strand_takes_memory_linear_in_its_particles():
    # before: the rounds doubled up to the whole strand, (N, N) candidate arrays (~1 GB here)
    n = 5_000
    hair = parallel_strands(n_strands=1, n_points=n, step=1e-4)
    tracemalloc.start()
    try:
        nb = knn_other_strands(hair.points, hair.strand_of, 5)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak / n < 2_000, f"{peak / n:.0f} bytes per particle"
    assert np.all(nb.weight == 0.0) and np.array_equal(nb.index, np.repeat(np.arange(n)[:, None], 5, axis=1))


def test_a_long_strand_beside_a_short_one_finds_the_short_one_exactly():
    long = np.stack([np.linspace(0, 1, 4_000), np.zeros(4_000), np.zeros(4_000)], axis=1)
    short = np.array([[0.0, 0.05, 0.0], [0.5, 0.05, 0.0], [1.0, 0.05, 0.0]])
    points, strand_of = np.concatenate([long, short]), np.repeat([0, 1], [4_000, 3])
    nb = knn_other_strands(points, strand_of, 5)
    # the long strand's particles have 3 neighbours, the short strand's 5
    assert (np.count_nonzero(nb.weight[:4_000], axis=1) == 3).all()
    assert (np.count_nonzero(nb.weight[4_000:], axis=1) == 5).all()
    np.testing.assert_allclose(_found_distances(points, nb), _brute_force_distances(points, strand_of, 5,
                                                                                    np.arange(len(points))))


def test_fewer_than_k_neighbours_renormalise_eq9_and_pad_with_the_particle():
    hair = parallel_strands(n_strands=3, n_points=4, spacing=0.01)
    guides = hair.strand_of == 0  # 4 candidates, k = 6
    queries = np.flatnonzero(hair.strand_of == 2)
    nb = knn_other_strands(hair.points, hair.strand_of, 6, candidates=guides, queries=queries)
    found = nb.weight > 0
    assert (found.sum(axis=1) == 4).all()
    np.testing.assert_allclose(nb.weight.sum(axis=1), 1.0, atol=1e-15)
    d = np.linalg.norm(hair.points[nb.index[:, :4]] - hair.points[queries, None], axis=2)
    np.testing.assert_allclose(nb.weight[:, :4], (1 / d) / (1 / d).sum(axis=1, keepdims=True), rtol=1e-14)
    assert (nb.index[:, 4:] == queries[:, None]).all()
    # K's row of such a particle still sums to zero: translation invariance holds
    K = laplacian_operator(nb, queries, hair.n_particles)
    np.testing.assert_allclose(K @ np.ones(hair.n_particles), 0.0, atol=1e-15)


@pytest.mark.parametrize("dtype", [np.int32, np.int64])
def test_the_compiled_neighbour_average_equals_the_numpy_gather(dtype):
    points, strand_of = _random_walk_groom([30, 7, 50, 12], seed=4)
    nb = knn_other_strands(points, strand_of, 5)
    nb = neighbours.Neighbours(nb.index.astype(dtype), nb.weight)
    average = neighbours.neighbour_average(nb, points)
    np.testing.assert_array_equal(average, neighbours.neighbour_average_reference(nb, points))
    # the weights sum to 1 per row: the average lies within the neighbours' bounding box
    assert (average >= points[nb.index].min(axis=1) - 1e-15).all()
    assert (average <= points[nb.index].max(axis=1) + 1e-15).all()


@pytest.mark.parametrize("seed", range(4))
def test_the_compiled_tree_finds_the_reference_s_sets_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    points, strand_of = _random_walk_groom(rng.integers(2, 80, 120), seed)
    guides = np.isin(strand_of, rng.choice(120, 15, replace=False))
    for candidates, queries in ((None, None), (guides, None), (guides, np.flatnonzero(~guides))):
        nb = knn_other_strands(points, strand_of, 5, candidates=candidates, queries=queries)
        reference = neighbours.knn_other_strands_reference(points, strand_of, 5, candidates=candidates,
                                                           queries=queries)
        np.testing.assert_array_equal(nb.index, reference.index)
        np.testing.assert_array_equal(nb.weight, reference.weight)
        assert nb.index.dtype == np.int32 and (nb.weight > 0).all()


def test_a_twin_at_distance_zero_takes_the_whole_bounded_weight():
    """A duplicate strand (model/degenerate.py): Eq. 9's clamp and normalisation keep the row bounded."""
    hair = parallel_strands(n_strands=3, spacing=0.01)
    twins = type(hair).from_strands([hair.strand(0), hair.strand(0).copy(), hair.strand(1), hair.strand(2)])
    nb = knn_other_strands(twins.points, twins.strand_of, 3)
    first = np.flatnonzero(twins.strand_of == 0)
    assert (twins.strand_of[nb.index[first, 0]] == 1).all()  # the twin, nearest
    assert (nb.weight[first, 0] > 1.0 - 1e-6).all() and (nb.weight >= 0).all() and (nb.weight <= 1).all()
    np.testing.assert_allclose(nb.weight.sum(axis=1), 1.0, atol=1e-12)


def test_rows_farther_than_the_reach_have_no_neighbours_and_no_one_names_them():
    hair = parallel_strands(n_strands=4, spacing=0.01)
    away = type(hair).from_strands([hair.strand(s) for s in range(3)] + [hair.strand(3) + np.array([2.0, 0, 0])])
    free = knn_other_strands(away.points, away.strand_of, 3)
    cut = knn_other_strands(away.points, away.strand_of, 3, reach=0.5)
    far = away.strand_of == 3
    assert (free.weight[far].sum(axis=1) > 0.99).all()  # unbounded, it names the others 2 m away
    assert (cut.weight[far] == 0).all() and (cut.index[far] == np.flatnonzero(far)[:, None]).all()
    np.testing.assert_array_equal(cut.weight[~far], free.weight[~far])  # nobody named it: the rest is equal
    reference = neighbours.knn_other_strands_reference(away.points, away.strand_of, 3, reach=0.5)
    np.testing.assert_array_equal(reference.weight, cut.weight)


def test_collapsed_strands_are_nobodys_neighbours_and_have_none():
    hair = parallel_strands(n_strands=4, spacing=0.01)
    strands = [hair.strand(s) for s in range(4)]
    with_collapsed = type(hair).from_strands(strands[:2] + [np.repeat(strands[1][:1], 6, axis=0)] + strands[2:])
    nb = neighbours.knn_shaped_strands(with_collapsed, 3)
    still = with_collapsed.strand_of == 2
    assert (nb.weight[still] == 0).all() and not still[nb.index[~still]].any()
    alone = neighbours.knn_shaped_strands(hair, 3)  # the groom without it: the same rows
    np.testing.assert_array_equal(nb.weight[~still], alone.weight)
