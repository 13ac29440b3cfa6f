"""Section 7.5's relocation alternatives (harmonic, 2D/3D thin-plate RBF) and the interior seeds,
against hand values and the fields each method must reproduce."""

import numpy as np

from hairport.solver.hairline.baselines import (
    RBF_INTERIOR_SEEDS,
    harmonic_displacement,
    interior_seeds,
    rbf_displacement_2d,
    rbf_displacement_3d,
)
from tests.solver.hairline.unit_square import CELLS, bowl, expect_refusal, flat, outer_ring, square_grid

# ----------------------------------------------------------------------------------------
# harmonic displacement
# ----------------------------------------------------------------------------------------


def test_harmonic_translation_moves_every_vertex_by_it():
    uv, triangles = square_grid()
    fixed = outer_ring(uv)
    shift = np.array([0.13, -0.07])
    u = harmonic_displacement(uv, triangles, fixed, uv[fixed] + shift)
    np.testing.assert_allclose(u - uv, np.broadcast_to(shift, uv.shape), rtol=0, atol=1e-12)


def test_harmonic_reproduces_linear_maps():
    uv, triangles = square_grid()
    fixed = outer_ring(uv)
    centre = np.array([0.5, 0.5])
    u = harmonic_displacement(uv, triangles, fixed, centre + 1.2 * (uv[fixed] - centre))
    np.testing.assert_allclose(u, centre + 1.2 * (uv - centre), rtol=0, atol=1e-10)
    shear = np.array([[1.1, 0.3], [-0.2, 0.9]])
    u = harmonic_displacement(uv, triangles, fixed, uv[fixed] @ shear.T + 0.05)
    np.testing.assert_allclose(u, uv @ shear.T + 0.05, rtol=0, atol=1e-10)


def test_harmonic_uses_cotangent_weights_of_the_uv_triangles():
    # 3x3 vertices, one interior vertex (id 4). Its diagonal edges face right angles (cot 90 = 0),
    # its axis edges two 45-degree angles (weight 1 each): it moves by the mean of its 4 axis
    # neighbours' motions; moving only the right-middle vertex (id 7) by 0.4 moves it by 0.1
    # (a uniform graph Laplacian, 6 neighbours, would give 0.4 / 6).
    uv, triangles = square_grid(2)
    fixed = outer_ring(uv)
    target = uv.copy()
    target[7, 0] += 0.4
    u = harmonic_displacement(uv, triangles, fixed, target[fixed])
    np.testing.assert_allclose(u[4], uv[4] + [0.1, 0.0], rtol=0, atol=1e-14)
    # The same mesh with another parameterization (stretched along x by 2): the horizontal
    # edges face angles atan 2 (cot 1/2, weight 1/2), the vertical ones atan 1/2 (weight 2):
    # a horizontal neighbour carries (1/2) / (1/2 + 1/2 + 2 + 2) = 0.1 of its motion, 0.04.
    stretched = uv * [2.0, 1.0]
    target = stretched.copy()
    target[7, 0] += 0.4
    u = harmonic_displacement(stretched, triangles, fixed, target[fixed])
    np.testing.assert_allclose(u[4], stretched[4] + [0.04, 0.0], rtol=0, atol=1e-14)


def test_harmonic_identity_is_exact_and_unanchored_pieces_stay():
    uv, triangles = square_grid()
    fixed = outer_ring(uv)
    n = len(uv)
    # an extra triangle with no fixed vertex, and a vertex in no triangle
    uv = np.vstack([uv, [[2.0, 2.0], [2.5, 2.0], [2.0, 2.5], [3.0, 3.0]]])
    triangles = np.vstack([triangles, [[n, n + 1, n + 2]]])
    fixed = np.concatenate([fixed, np.zeros(4, dtype=bool)])
    u = harmonic_displacement(uv, triangles, fixed, uv[fixed])
    assert np.abs(u - uv).max() <= 1e-14
    u = harmonic_displacement(uv, triangles, fixed, uv[fixed] + 0.25)
    np.testing.assert_array_equal(u[n:], uv[n:])
    np.testing.assert_allclose(u[:n], uv[:n] + 0.25, rtol=0, atol=1e-12)


def test_harmonic_fixed_vertices_get_their_targets_exactly():
    uv, triangles = square_grid()
    fixed = outer_ring(uv)
    rng = np.random.default_rng(3)
    target = uv[fixed] + 0.02 * rng.standard_normal((int(fixed.sum()), 2))
    u = harmonic_displacement(uv, triangles, fixed, target)
    np.testing.assert_array_equal(u[fixed], target)
    # the maximum principle: interior displacements stay within the boundary's range
    d = u - uv
    assert (d[~fixed].min(axis=0) >= d[fixed].min(axis=0) - 1e-12).all()
    assert (d[~fixed].max(axis=0) <= d[fixed].max(axis=0) + 1e-12).all()


# ----------------------------------------------------------------------------------------
# thin-plate-spline displacements
# ----------------------------------------------------------------------------------------


def test_rbf_2d_reproduces_affine_displacements_without_seeds():
    uv, _ = square_grid()
    fixed = outer_ring(uv)
    A = np.array([[0.2, -0.1], [0.05, 0.15]])
    b = np.array([0.03, -0.02])
    u = rbf_displacement_2d(uv, fixed, uv[fixed] + uv[fixed] @ A.T + b, np.zeros(0, dtype=np.int64))
    np.testing.assert_allclose(u, uv + uv @ A.T + b, rtol=0, atol=1e-8)


def test_rbf_3d_reproduces_affine_displacements_without_seeds():
    uv, _ = square_grid()
    rest = bowl(uv)
    fixed = outer_ring(uv)
    A = np.array([[0.1, 0.0, -0.05], [0.02, -0.1, 0.0], [0.0, 0.03, 0.08]])
    b = np.array([0.01, 0.0, -0.02])
    x = rbf_displacement_3d(rest, fixed, rest[fixed] + rest[fixed] @ A.T + b, [])
    np.testing.assert_allclose(x, rest + rest @ A.T + b, rtol=0, atol=1e-8)


def test_rbf_seeds_stay_and_fixed_vertices_reach_their_targets():
    uv, triangles = square_grid()
    fixed = outer_ring(uv)
    seeds = interior_seeds(triangles, np.flatnonzero(fixed), flat(uv), count=5)
    shift = np.array([0.0, 0.1])
    u = rbf_displacement_2d(uv, fixed, uv[fixed] + shift, seeds)
    np.testing.assert_array_equal(u[fixed], uv[fixed] + shift)
    np.testing.assert_array_equal(u[seeds], uv[seeds])
    free = ~fixed
    free[seeds] = False
    # every datum has zero x displacement, so the x field is zero; the pinned core holds the
    # interior back: no free vertex moves as far as the hairline (between the seeds the
    # spline overshoots a little backwards, which a harmonic field could not)
    np.testing.assert_array_equal(u[:, 0], uv[:, 0])
    assert np.abs(u[free, 1] - uv[free, 1]).max() < 0.1
    rest = bowl(uv)
    x = rbf_displacement_3d(rest, fixed, rest[fixed] + [0.0, 0.1, 0.02], seeds)
    np.testing.assert_array_equal(x[fixed], rest[fixed] + [0.0, 0.1, 0.02])
    np.testing.assert_array_equal(x[seeds], rest[seeds])


def test_rbf_2d_is_symmetric_with_a_symmetric_setup():
    # translation along y, a single seed at the centre: mirroring x -> 1 - x maps the data
    # onto itself, so the field is mirror-symmetric
    uv, _ = square_grid()
    fixed = outer_ring(uv)
    centre = CELLS // 2 * (CELLS + 1) + CELLS // 2
    u = rbf_displacement_2d(uv, fixed, uv[fixed] + [0.0, 0.1], np.array([centre]))
    d = (u - uv).reshape(CELLS + 1, CELLS + 1, 2)
    np.testing.assert_allclose(d[::-1, :, 1], d[:, :, 1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(d[::-1, :, 0], -d[:, :, 0], rtol=0, atol=1e-12)


def test_every_method_leaves_an_identity_edit_exact():
    uv, triangles = square_grid()
    rest = bowl(uv)
    fixed = outer_ring(uv)
    seeds = interior_seeds(triangles, np.flatnonzero(fixed), rest)
    assert np.abs(harmonic_displacement(uv, triangles, fixed, uv[fixed]) - uv).max() <= 1e-14
    assert np.abs(rbf_displacement_2d(uv, fixed, uv[fixed], seeds) - uv).max() <= 1e-14
    assert np.abs(rbf_displacement_3d(rest, fixed, rest[fixed], seeds) - rest).max() <= 1e-14


# ----------------------------------------------------------------------------------------
# interior seeds
# ----------------------------------------------------------------------------------------


def hops_from_ring(cells=CELLS):
    """Hop distance of vertex ``(i, j)`` from the outer ring: ``min(i, j, cells - i, cells - j)``
    (the diagonals go along (+1, +1) and do not shorten it)."""
    i, j = np.meshgrid(np.arange(cells + 1), np.arange(cells + 1), indexing="ij")
    return np.minimum.reduce([i, j, cells - i, cells - j]).ravel()


def test_interior_seeds_lie_in_the_core_and_are_distinct():
    uv, triangles = square_grid()
    boundary = np.flatnonzero(outer_ring(uv))
    seeds = interior_seeds(triangles, boundary, flat(uv))
    hops = hops_from_ring()
    assert seeds.dtype == np.int64
    assert len(seeds) == RBF_INTERIOR_SEEDS == len(np.unique(seeds))
    assert not np.isin(seeds, boundary).any()
    assert (hops[seeds] >= hops.max() / 2).all()
    np.testing.assert_array_equal(seeds, np.sort(seeds))
    np.testing.assert_array_equal(interior_seeds(triangles, boundary[::-1], flat(uv)), seeds)


def test_interior_seeds_farthest_point_order_by_hand():
    # The core is the 5x5 block i, j in 2..6 (hops >= 2). The start is the centre (4, 4), id 40;
    # the farthest core vertices from it are the block's corners, the lowest id (2, 2) = 20;
    # then (2, 6), (6, 2) and (6, 6) are all 2 sqrt(2) cells from the picked set: (2, 6) = 24.
    uv, triangles = square_grid()
    boundary = np.flatnonzero(outer_ring(uv))
    rest = flat(uv)
    np.testing.assert_array_equal(interior_seeds(triangles, boundary, rest, count=1), [40])
    np.testing.assert_array_equal(interior_seeds(triangles, boundary, rest, count=2), [20, 40])
    np.testing.assert_array_equal(interior_seeds(triangles, boundary, rest, count=3), [20, 24, 40])
    core = np.flatnonzero(hops_from_ring() >= 2)
    assert len(core) == 25
    np.testing.assert_array_equal(interior_seeds(triangles, boundary, rest, count=30), core)
    assert interior_seeds(triangles, boundary, rest, count=0).shape == (0,)


def test_interior_seeds_small_scalp():
    uv, triangles = square_grid(2)  # one interior vertex
    boundary = np.flatnonzero(outer_ring(uv))
    np.testing.assert_array_equal(interior_seeds(triangles, boundary, flat(uv)), [4])
    uv, triangles = square_grid(1)  # every vertex on the boundary
    assert interior_seeds(triangles, np.arange(4), flat(uv)).shape == (0,)



# ----------------------------------------------------------------------------------------
# refusals
# ----------------------------------------------------------------------------------------


def test_bad_input_is_refused():
    uv, triangles = square_grid(4)
    fixed = outer_ring(uv)
    rest = bowl(uv)
    seeds = np.array([12])
    expect_refusal(harmonic_displacement, uv, triangles, fixed, uv[fixed][:-1])
    expect_refusal(harmonic_displacement, uv, triangles, fixed[:-1], uv[fixed])
    bad = uv.copy()
    bad[12, 0] = np.nan
    expect_refusal(harmonic_displacement, bad, triangles, fixed, uv[fixed])
    target = uv[fixed].copy()
    target[0, 1] = np.inf
    expect_refusal(harmonic_displacement, uv, triangles, fixed, target)
    expect_refusal(harmonic_displacement, uv, triangles + len(uv), fixed, uv[fixed])
    expect_refusal(harmonic_displacement, uv, triangles.astype(float), fixed, uv[fixed])
    squashed = uv.copy()
    squashed[12] = squashed[6]  # triangles around vertex 12 collapse in uv
    expect_refusal(harmonic_displacement, squashed, triangles, fixed, squashed[fixed])

    expect_refusal(rbf_displacement_2d, uv, fixed, uv[fixed][:-1], seeds)
    expect_refusal(rbf_displacement_2d, bad, fixed, uv[fixed], seeds)
    error = expect_refusal(rbf_displacement_2d, uv, fixed, uv[fixed], np.array([0, 12]))
    assert "fixed" in str(error)
    expect_refusal(rbf_displacement_2d, uv, fixed, uv[fixed], np.array([len(uv)]))
    expect_refusal(rbf_displacement_2d, uv, fixed, uv[fixed], np.array([12.0]))
    expect_refusal(rbf_displacement_3d, rest, fixed, rest[fixed][:, :2], seeds)
    expect_refusal(rbf_displacement_3d, flat(uv), fixed, flat(uv)[fixed] + 0.1, seeds)  # coplanar data
    few = np.zeros(len(uv), dtype=bool)
    few[:2] = True
    expect_refusal(rbf_displacement_2d, uv, few, uv[few], [])

    boundary = np.flatnonzero(fixed)
    expect_refusal(interior_seeds, triangles, [], rest)
    expect_refusal(interior_seeds, triangles, boundary + 100, rest)
    expect_refusal(interior_seeds, triangles, boundary, rest, count=-1)
    expect_refusal(interior_seeds, triangles, boundary, rest[:, :2])
