"""Section 7.5's relocation alternatives (harmonic, 2D/3D thin-plate RBF), the interior seeds and
Table 3's density change, against hand values and the fields each method must reproduce."""

import numpy as np
import pytest

from hairport.solver.hairline.baselines import (
    RBF_INTERIOR_SEEDS,
    harmonic_displacement,
    interior_seeds,
    rbf_displacement_2d,
    rbf_displacement_3d,
)
from hairport.solver.hairline.density import density_change
from hairport.solver.model.errors import InputError

CELLS = 8  # grid cells per side: (CELLS + 1)^2 vertices on [0, 1]^2
BOWL = 0.3  # curved scalp for the 3D RBF: z = BOWL (x^2 + y^2)


def grid(cells=CELLS):
    """Vertices ``((cells+1)^2, 2)`` of ``[0, 1]^2``, id ``i (cells+1) + j`` at ``(i, j) / cells``,
    and ``2 cells^2`` counter-clockwise triangles (diagonals from ``(i, j)`` to ``(i+1, j+1)``)."""
    xs, ys = np.meshgrid(np.linspace(0.0, 1.0, cells + 1), np.linspace(0.0, 1.0, cells + 1), indexing="ij")
    points = np.column_stack([xs.ravel(), ys.ravel()])
    index = np.arange((cells + 1) ** 2).reshape(cells + 1, cells + 1)
    a, b, c, d = index[:-1, :-1].ravel(), index[1:, :-1].ravel(), index[1:, 1:].ravel(), index[:-1, 1:].ravel()
    return points, np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])


def outer_ring(points):
    return (np.isclose(points, 0.0) | np.isclose(points, 1.0)).any(axis=1)


def flat(points):
    return np.column_stack([points, np.zeros(len(points))])


def bowl(points):
    return np.column_stack([points, BOWL * (points**2).sum(axis=1)])


def expect_refusal(call, *args, **kwargs):
    with pytest.raises(InputError) as raised:
        call(*args, **kwargs)
    assert raised.value.code == "bad_relocation"
    return raised.value


# ----------------------------------------------------------------------------------------
# harmonic displacement
# ----------------------------------------------------------------------------------------


def test_harmonic_translation_moves_every_vertex_by_it():
    uv, triangles = grid()
    fixed = outer_ring(uv)
    shift = np.array([0.13, -0.07])
    u = harmonic_displacement(uv, triangles, fixed, uv[fixed] + shift)
    np.testing.assert_allclose(u - uv, np.broadcast_to(shift, uv.shape), rtol=0, atol=1e-12)


def test_harmonic_reproduces_linear_maps():
    uv, triangles = grid()
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
    uv, triangles = grid(2)
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
    uv, triangles = grid()
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
    uv, triangles = grid()
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
    uv, _ = grid()
    fixed = outer_ring(uv)
    A = np.array([[0.2, -0.1], [0.05, 0.15]])
    b = np.array([0.03, -0.02])
    u = rbf_displacement_2d(uv, fixed, uv[fixed] + uv[fixed] @ A.T + b, np.zeros(0, dtype=np.int64))
    np.testing.assert_allclose(u, uv + uv @ A.T + b, rtol=0, atol=1e-8)


def test_rbf_3d_reproduces_affine_displacements_without_seeds():
    uv, _ = grid()
    rest = bowl(uv)
    fixed = outer_ring(uv)
    A = np.array([[0.1, 0.0, -0.05], [0.02, -0.1, 0.0], [0.0, 0.03, 0.08]])
    b = np.array([0.01, 0.0, -0.02])
    x = rbf_displacement_3d(rest, fixed, rest[fixed] + rest[fixed] @ A.T + b, [])
    np.testing.assert_allclose(x, rest + rest @ A.T + b, rtol=0, atol=1e-8)


def test_rbf_seeds_stay_and_fixed_vertices_reach_their_targets():
    uv, triangles = grid()
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
    uv, _ = grid()
    fixed = outer_ring(uv)
    centre = CELLS // 2 * (CELLS + 1) + CELLS // 2
    u = rbf_displacement_2d(uv, fixed, uv[fixed] + [0.0, 0.1], np.array([centre]))
    d = (u - uv).reshape(CELLS + 1, CELLS + 1, 2)
    np.testing.assert_allclose(d[::-1, :, 1], d[:, :, 1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(d[::-1, :, 0], -d[:, :, 0], rtol=0, atol=1e-12)


def test_every_method_leaves_an_identity_edit_exact():
    uv, triangles = grid()
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
    uv, triangles = grid()
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
    uv, triangles = grid()
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
    uv, triangles = grid(2)  # one interior vertex
    boundary = np.flatnonzero(outer_ring(uv))
    np.testing.assert_array_equal(interior_seeds(triangles, boundary, flat(uv)), [4])
    uv, triangles = grid(1)  # every vertex on the boundary
    assert interior_seeds(triangles, np.arange(4), flat(uv)).shape == (0,)


# ----------------------------------------------------------------------------------------
# density change (Table 3)
# ----------------------------------------------------------------------------------------


def test_density_change_of_a_uniform_scaling():
    uv, triangles = grid()
    rest = bowl(uv)
    roots = np.array([0, 0, 5, -1, 17, 17, 17, 100, -1])
    for s in (0.8, 1.0, 1.25):
        density = density_change(rest, s * rest, triangles, roots)
        np.testing.assert_array_equal(density.triangles, [0, 5, 17, 100])
        np.testing.assert_allclose(density.changes, np.full(4, 1.0 / s**2 - 1.0), rtol=0, atol=1e-12)
        assert density.l1 == pytest.approx(abs(1.0 / s**2 - 1.0), abs=1e-12)
        assert density.linf == pytest.approx(abs(1.0 / s**2 - 1.0), abs=1e-12)
    identity = density_change(rest, rest, triangles, roots)
    assert identity.l1 == identity.linf == 0.0
    np.testing.assert_array_equal(identity.changes, np.zeros(4))


def test_density_change_by_hand():
    rest = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]])
    triangles = np.array([[0, 1, 2], [1, 3, 2]])
    # one triangle: its area doubles (0.5 -> 1), the density halves
    stretched = rest.copy()
    stretched[1, 0] = 2.0
    density = density_change(rest, stretched, triangles[:1], np.array([0, 0, 0]))
    np.testing.assert_allclose(density.changes, [-0.5], rtol=0, atol=1e-15)
    assert (density.l1, density.linf) == pytest.approx((0.5, 0.5), abs=1e-15)
    # lifted out of the plane: area 0.5 sqrt(2), change 1 / sqrt(2) - 1
    lifted = rest.copy()
    lifted[2, 2] = 1.0
    density = density_change(rest, lifted, triangles[:1], np.array([0]))
    np.testing.assert_allclose(density.changes, [1.0 / np.sqrt(2.0) - 1.0], rtol=0, atol=1e-15)
    # two triangles: the first stretched to twice its area (-0.5), the second compressed to
    # half (+1); roots outside the scalp (-1) are ignored
    deformed = rest.copy()
    deformed[0] = [-0.5, -0.5, 0.0]  # first triangle (0, 1, 2): area 0.5 -> 1.0
    deformed[3] = [0.75, 0.75, 0.0]  # second triangle (1, 3, 2): area 0.5 -> 0.25
    density = density_change(rest, deformed, triangles, np.array([1, -1, 0, 1]))
    np.testing.assert_array_equal(density.triangles, [0, 1])
    np.testing.assert_allclose(density.changes, [-0.5, 1.0], rtol=0, atol=1e-15)
    assert density.l1 == pytest.approx(0.75, abs=1e-15)
    assert density.linf == pytest.approx(1.0, abs=1e-15)
    # a collapsed triangle holding roots: infinite change
    collapsed = rest.copy()
    collapsed[2] = [0.5, 0.0, 0.0]
    density = density_change(rest, collapsed, triangles, np.array([0, 1]))
    assert np.isinf(density.changes[0]) and density.linf == np.inf


def test_density_change_without_roots():
    uv, triangles = grid(2)
    for roots in (np.zeros(0, dtype=np.int64), np.array([-1, -1]), []):
        density = density_change(flat(uv), 2.0 * flat(uv), triangles, roots)
        assert density.l1 == density.linf == 0.0
        assert density.changes.shape == density.triangles.shape == (0,)
        assert density.triangles.dtype == np.int64


# ----------------------------------------------------------------------------------------
# refusals
# ----------------------------------------------------------------------------------------


def test_bad_input_is_refused():
    uv, triangles = grid(4)
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

    expect_refusal(density_change, rest, rest[:-1], triangles, [0])
    expect_refusal(density_change, rest, rest, triangles, [-2])
    expect_refusal(density_change, rest, rest, triangles, [len(triangles)])
    expect_refusal(density_change, rest, np.where(np.isclose(rest, 0.0), np.nan, rest), triangles, [0])
    degenerate = rest.copy()
    degenerate[5] = degenerate[0]  # triangle 0 is (0, 5, 6)
    expect_refusal(density_change, degenerate, rest, triangles, [0])
