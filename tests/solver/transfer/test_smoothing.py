"""Initial transfer, smoothing (solver/transfer/smoothing.py, Eq. 4-6): the strand Laplacian and adaptive smoothing."""

import numpy as np

from hairport.solver.model.hair import DEGENERATE_SEGMENT_M
from hairport.solver.transfer.smoothing import smooth_strands, strand_laplacian
from tests.solver.hair_shapes import outward_strands, sphere_character


def test_strand_laplacian_of_a_straight_line_is_zero_and_of_a_corner_is_the_turn():
    points = np.stack([np.zeros(5), -0.01 * np.arange(5), np.zeros(5)], axis=1)
    L = strand_laplacian(points, np.array([0, 5]))
    np.testing.assert_allclose(L @ points, 0.0, atol=1e-15)
    assert np.diff(L.indptr)[[0, 4]].tolist() == [0, 0]  # no rows for root and tip
    corner = np.array([[0.0, 0, 0], [0.0, -0.01, 0], [0.02, -0.01, 0]])
    # unit directions (0,-1,0) then (1,0,0): the Laplacian is their difference
    np.testing.assert_allclose((strand_laplacian(corner, np.array([0, 3])) @ corner)[1], [1.0, 1.0, 0.0])


def test_smoothing_leaves_a_smooth_transfer_untouched():
    source = sphere_character()
    hair = outward_strands(source)
    smoothed, unsmooth = smooth_strands(hair.points + 0.01, hair.points, hair.offsets)
    assert not unsmooth.any()
    np.testing.assert_array_equal(smoothed, hair.points + 0.01)


def test_smoothing_removes_a_staircase_step():
    n = 12
    source = np.stack([np.zeros(n), -0.005 * np.arange(n), np.zeros(n)], axis=1)
    stair = source.copy()
    stair[6:, 0] += 0.004  # a 4 mm jog between particle 5 and 6
    offsets = np.array([0, n])
    L = strand_laplacian(source, offsets)
    smoothed, unsmooth = smooth_strands(stair, source, offsets)
    assert unsmooth[5] and unsmooth[6]
    before = np.linalg.norm(L @ stair - L @ source, axis=1).max()
    after = np.linalg.norm(L @ smoothed - L @ source, axis=1).max()
    assert before > 0.3 and after <= 0.3
    assert smoothed[0].tolist() == stair[0].tolist()  # the root is Dirichlet


def test_strand_laplacian_weights_are_inverse_source_lengths_floored():
    # a repeated particle: its zero-length segment counts as DEGENERATE_SEGMENT_M long (the solve's weld)
    points = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, -0.01, 0.0], [0.0, -0.03, 0.0]])
    L = strand_laplacian(points, np.array([0, 4])).toarray()
    np.testing.assert_array_equal(L[1], [1 / DEGENERATE_SEGMENT_M, -(1 / DEGENERATE_SEGMENT_M + 100.0), 100.0, 0.0])
    np.testing.assert_allclose(L[2], [0.0, 100.0, -150.0, 50.0], rtol=1e-12)
    assert not L[[0, 3]].any()


def test_the_run_by_run_solve_equals_the_sparse_lu_solve():
    from hairport.solver.transfer.smoothing import restore_laplacian, restore_laplacian_reference

    rng = np.random.default_rng(5)
    source = sphere_character()
    hair = outward_strands(source, n_strands=30, n_points=12)
    L = strand_laplacian(hair.points, hair.offsets)
    anchored = hair.points + rng.normal(scale=2e-3, size=hair.points.shape)
    features = L @ hair.points
    interior = np.flatnonzero(np.diff(L.indptr) > 0)
    # runs of every length: single particles, pairs, whole strand interiors, a repeated particle's huge weight
    unsmooth = np.sort(rng.choice(interior, size=len(interior) // 2, replace=False))
    unsmooth = np.union1d(unsmooth, interior[(interior > hair.offsets[3]) & (interior < hair.offsets[4])])
    solved = restore_laplacian(L, anchored, features, unsmooth)
    reference = restore_laplacian_reference(L, anchored, features, unsmooth)
    assert np.abs(solved - reference).max() < 1e-12
    np.testing.assert_array_equal(np.delete(solved, unsmooth, axis=0), np.delete(anchored, unsmooth, axis=0))
    np.testing.assert_allclose((L @ solved)[unsmooth], features[unsmooth], atol=1e-9)  # Eq. 4 holds on the set
    assert np.abs(solved - anchored)[unsmooth].max() > 1e-3  # and it moved them
