"""Guide-strand selection (paper Sec. 5) on hand-solvable cases."""

import numpy as np
import pytest

from hairport.solver.adaptation.source.guides import RESAMPLE_POINTS, resample_strands, select_guides
from hairport.solver.model.hair import Hair

BUNDLE_SPACING_M = 1.0
BUNDLE_RADIUS_M = 0.01
STRAND_LENGTH_M = 0.3


def bundles(n_bundles=3, points_per_strand=5):
    """Bundles of 10 parallel straight strands along z: one at the bundle's centre (listed
    first, index 10 b) and nine on a ring of radius 1 cm around it; bundles 1 m apart in x."""
    angles = 2.0 * np.pi * np.arange(9) / 9.0
    ring = BUNDLE_RADIUS_M * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    layout = np.concatenate([[[0.0, 0.0]], ring])  # (10, 2) x, y of the roots
    z = np.linspace(0.0, STRAND_LENGTH_M, points_per_strand)
    strands = []
    for b in range(n_bundles):
        for x, y in layout:
            strands.append(np.stack([np.full_like(z, x + b * BUNDLE_SPACING_M), np.full_like(z, y), z], axis=1))
    return Hair.from_strands(strands)


def test_straight_strand_with_unequal_segments_resamples_evenly_on_the_line():
    direction = np.array([1.0, 2.0, 2.0]) / 3.0
    arc = np.array([0.0, 0.01, 0.05, 0.06, 0.2, 0.3])  # unequal segments, length 0.3
    start = np.array([0.1, -0.2, 0.3])
    hair = Hair.from_strands([start + arc[:, None] * direction])
    resampled = resample_strands(hair, 7)
    assert resampled.shape == (1, 7, 3)
    expected = start + np.linspace(0.0, 0.3, 7)[:, None] * direction
    np.testing.assert_allclose(resampled[0], expected, rtol=0, atol=1e-12)


def test_endpoints_are_copied_exactly_and_shape_is_strands_by_count_by_3():
    rng = np.random.default_rng(3)
    strands = [rng.normal(size=(n, 3)) for n in (RESAMPLE_POINTS, 2, 7, 40)]
    hair = Hair.from_strands(strands)
    resampled = resample_strands(hair)
    assert resampled.shape == (4, RESAMPLE_POINTS, 3)
    assert resampled.dtype == np.float64
    for s, strand in enumerate(strands):
        assert np.array_equal(resampled[s, 0], strand[0])
        assert np.array_equal(resampled[s, -1], strand[-1])
    # a two-point strand resamples onto its segment, evenly
    expected = strands[1][0] + np.linspace(0, 1, RESAMPLE_POINTS)[:, None] * (strands[1][1] - strands[1][0])
    np.testing.assert_allclose(resampled[1], expected, rtol=0, atol=1e-12)


def test_zero_length_strand_and_repeated_points_give_finite_output():
    point = np.array([0.5, 0.5, 0.5])
    hair = Hair.from_strands(
        [
            np.tile(point, (4, 1)),  # zero length
            np.array([[0.0, 0, 0], [0.0, 0, 0], [0.0, 0, 1.0], [0.0, 0, 1.0]]),  # repeated ends
        ]
    )
    resampled = resample_strands(hair, 5)
    assert np.isfinite(resampled).all()
    np.testing.assert_array_equal(resampled[0], np.tile(point, (5, 1)))
    np.testing.assert_allclose(resampled[1][:, 2], [0.0, 0.25, 0.5, 0.75, 1.0], rtol=0, atol=1e-15)


def test_resample_rejects_fewer_than_two_points():
    with pytest.raises(ValueError, match="at least 2"):
        resample_strands(bundles(1), 1)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_three_bundles_get_one_guide_each_at_the_bundle_centre(seed):
    hair = bundles(3)
    guides = select_guides(hair, 3, seed=seed)
    np.testing.assert_array_equal(guides, [0, 10, 20])
    # every strand's nearest guide, in resampled space, is its own bundle's guide
    features = resample_strands(hair).reshape(hair.n_strands, -1)
    distance = np.linalg.norm(features[:, None, :] - features[None, guides, :], axis=2)
    np.testing.assert_array_equal(np.argmin(distance, axis=1), np.repeat(np.arange(3), 10))


def test_guides_do_not_depend_on_particles_per_strand():
    # straight strands resample identically whatever their particle count
    np.testing.assert_array_equal(select_guides(bundles(3, 3), 3), select_guides(bundles(3, 11), 3))


def test_same_seed_same_guides_and_result_is_sorted_unique_int64():
    rng = np.random.default_rng(7)
    strands = [np.cumsum(rng.normal(scale=0.01, size=(int(n), 3)), axis=0) for n in rng.integers(2, 12, 200)]
    hair = Hair.from_strands(strands)
    first = select_guides(hair, 17, seed=5)
    assert np.array_equal(first, select_guides(hair, 17, seed=5))
    assert first.dtype == np.int64
    assert len(first) == 17
    assert np.array_equal(first, np.unique(first))
    assert first.min() >= 0 and first.max() < hair.n_strands


def test_all_strands_when_asking_for_at_least_as_many_guides():
    hair = bundles(1)
    for n_guides in (10, 11, 1000):
        guides = select_guides(hair, n_guides)
        assert guides.dtype == np.int64
        np.testing.assert_array_equal(guides, np.arange(10))


def test_fewer_distinct_strands_than_guides_still_gives_that_many_distinct_guides():
    # 6 strands of only 2 distinct shapes: 4 guides must still be 4 distinct strands
    a = np.array([[0.0, 0, 0], [0.0, 0, 1.0]])
    b = a + [1.0, 0, 0]
    hair = Hair.from_strands([a, a, a, b, b, b])
    guides = select_guides(hair, 4)
    assert len(guides) == 4 and len(np.unique(guides)) == 4
    assert {0, 1, 2} & set(guides) and {3, 4, 5} & set(guides)  # both shapes have a guide


def test_zero_guides_is_an_error():
    with pytest.raises(ValueError, match="n_guides must be at least 1"):
        select_guides(bundles(1), 0)


def test_one_guide_is_the_strand_nearest_the_mean_of_all_strands_also_when_subsampling():
    # 30 strands > 20 * 1 guide: the centre is fitted on a subsample, but then recomputed
    # from all members, whose mean is the middle bundle's centre strand
    for seed in (0, 1):
        np.testing.assert_array_equal(select_guides(bundles(3), 1, seed=seed), [10])


def test_resample_matches_a_per_strand_reference():
    rng = np.random.default_rng(11)
    strands = [rng.normal(size=(int(n), 3)) for n in rng.integers(2, 20, 50)]
    strands[5][:] = strands[5][0]  # zero length
    strands[9][3] = strands[9][2]  # a zero-length segment
    resampled = resample_strands(Hair.from_strands(strands), 9)
    for s, strand in enumerate(strands):
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(strand, axis=0), axis=1))])
        target = np.linspace(0.0, arc[-1], 9)
        expected = np.stack([np.interp(target, arc, strand[:, c]) for c in range(3)], axis=1)
        np.testing.assert_allclose(resampled[s], expected, rtol=0, atol=1e-12)
