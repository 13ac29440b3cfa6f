"""Conservative distance grid (solver/mesh/distance_grid.py): lower bounds, near masks, signs.

Ground truth is :meth:`MeshQuery.signed_distance` (exact float64) on an icosphere of radius
0.1 m (|p| - r up to the tessellation) and on an axis-aligned cube, where the hand cases are
exact.
"""

import math

import numpy as np
import pytest
import trimesh

from hairport.solver.mesh import distance_grid
from hairport.solver.mesh.collision import collision_query
from hairport.solver.mesh.distance_grid import DEFAULT_GRID_MARGIN, DEFAULT_GRID_SPACING, DistanceGrid, near_mask
from hairport.solver.mesh.query import MeshQuery

RADIUS = 0.1  # m
SPACING = DEFAULT_GRID_SPACING  # 5 mm
TOL = 1e-12  # m, round-off allowance of the bound


@pytest.fixture(scope="module")
def sphere_query():
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=RADIUS)
    return MeshQuery(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64))


@pytest.fixture(scope="module")
def exact_grid(sphere_query):
    """Every node queried exactly."""
    return DistanceGrid.build(sphere_query, spacing=SPACING, exact_band=math.inf)


@pytest.fixture(scope="module")
def banded_grid(sphere_query):
    """The default coarse-to-fine build: exact within 2.5 cm, certified bounds beyond."""
    return DistanceGrid.build(sphere_query, spacing=SPACING)


@pytest.fixture(scope="module")
def samples(sphere_query):
    """20,000 points in and around the grid box (the box grown by 10 cm), and their exact distance."""
    rng = np.random.default_rng(0)
    half = RADIUS + DEFAULT_GRID_MARGIN + 0.1
    points = rng.uniform(-half, half, size=(20_000, 3))
    # more of them near the surface, where the bound matters
    shell = rng.normal(size=(5_000, 3))
    shell *= (RADIUS + rng.normal(scale=0.01, size=5_000) / 1.0)[:, None] / np.linalg.norm(shell, axis=1, keepdims=True)
    points[:5_000] = shell
    return points, sphere_query.signed_distance(points).distance


def in_box(grid, points):
    return np.all((points >= grid.origin) & (points <= grid.upper), axis=1)


def box_distance(grid, points):
    return np.linalg.norm(points - np.clip(points, grid.origin, grid.upper), axis=1)


def test_build_box_and_node_values(sphere_query, exact_grid, banded_grid):
    for grid in (exact_grid, banded_grid):
        assert grid.spacing == SPACING and grid.shape == (49, 49, 49)
        assert grid.values.dtype == np.float64
        # the box is the vertices' bounding box grown by the margin (the last node may overshoot by < 1 cell)
        np.testing.assert_allclose(grid.origin, -RADIUS - DEFAULT_GRID_MARGIN, atol=1e-15)
        assert np.all(grid.upper >= RADIUS + DEFAULT_GRID_MARGIN - 1e-15)
        assert np.all(grid.upper < RADIUS + DEFAULT_GRID_MARGIN + SPACING)
    i, j, k = np.meshgrid(*[np.arange(n) for n in exact_grid.shape], indexing="ij")
    nodes = exact_grid.origin + SPACING * np.stack([i, j, k], axis=-1).reshape(-1, 3)
    exact = sphere_query.signed_distance(nodes).distance
    np.testing.assert_array_equal(exact_grid.values.reshape(-1), exact)
    # the banded grid: exact within the band; beyond, right sign and band <= |v| <= |d|
    banded = banded_grid.values.reshape(-1)
    near = np.abs(exact) < banded_grid.exact_band
    np.testing.assert_array_equal(banded[near], exact[near])
    far = ~near
    assert far.sum() > 50_000 and (banded[far] != exact[far]).sum() > 10_000  # most far nodes were never queried
    np.testing.assert_array_equal(np.sign(banded[far]), np.sign(exact[far]))
    assert np.all(np.abs(banded[far]) >= banded_grid.exact_band)
    assert np.all(np.abs(banded[far]) <= np.abs(exact[far]) + TOL)
    # the node at the centre is inside: 0.1 m deep up to the tessellation
    centre = exact_grid.values[24, 24, 24]
    assert -RADIUS <= centre < -0.99 * RADIUS


@pytest.mark.parametrize("grid_name", ["exact_grid", "banded_grid"])
def test_lower_bound_is_conservative(request, grid_name, samples):
    grid = request.getfixturevalue(grid_name)
    points, exact = samples
    bound = grid.lower_bound(points)
    assert bound.shape == (len(points),) and bound.dtype == np.float64
    assert np.all(bound >= 0.0)
    assert np.all(bound <= np.abs(exact) + TOL), np.max(bound - np.abs(exact))
    outside = ~in_box(grid, points)
    assert outside.sum() > 5_000
    # outside the box: at least the distance to the box, and still below the exact distance
    assert np.all(bound[outside] >= box_distance(grid, points[outside]) - TOL)


def test_lower_bound_is_tight_inside_the_box(exact_grid, banded_grid, samples):
    points, exact = samples
    inside = in_box(exact_grid, points)
    assert inside.sum() > 5_000
    gap = np.abs(exact[inside]) - exact_grid.lower_bound(points[inside])
    # proved: at most twice the distance to the nearest node
    assert gap.max() <= SPACING * math.sqrt(3)
    # away from the medial axis (the centre, where |d| has a peak) within half a cell diagonal
    away = np.linalg.norm(points[inside], axis=1) > 0.3 * RADIUS
    assert gap[away].max() <= SPACING * math.sqrt(3) / 2, gap[away].max() / SPACING
    assert gap[away].mean() < 0.25 * SPACING
    # the banded grid is as tight wherever all the cell's corners are within the band
    banded = banded_grid.lower_bound(points[inside])
    within = np.abs(exact[inside]) < banded_grid.exact_band - SPACING * math.sqrt(3)
    assert within.sum() > 5_000
    np.testing.assert_allclose(np.abs(exact[inside][within]) - banded[within], gap[within], rtol=0, atol=TOL)
    # everywhere: the nearest corner is exact (twice its distance lost) or at least the band
    floor = np.minimum(np.abs(exact[inside]) - SPACING * math.sqrt(3), banded_grid.exact_band - SPACING * math.sqrt(3) / 2)
    assert np.all(banded >= floor - TOL)


@pytest.mark.parametrize("band", [0.002, 0.01, 0.016])
def test_near_mask_contains_every_near_point(exact_grid, banded_grid, samples, band):
    points, exact = samples
    mask = near_mask(banded_grid, points, band)
    assert mask.dtype == bool and mask.shape == (len(points),)
    near = np.abs(exact) < band
    assert near.sum() > 500
    assert np.all(mask[near])
    # for band <= exact_band - spacing * sqrt(3) the banded grid gives the fully exact grid's answer
    np.testing.assert_array_equal(mask, near_mask(exact_grid, points, band))
    # and it is selective: few false positives beyond band + a cell diagonal
    assert not np.any(mask & (np.abs(exact) >= band + SPACING * math.sqrt(3)))


def test_far_points_are_excluded(sphere_query, banded_grid):
    rng = np.random.default_rng(2)
    directions = rng.normal(size=(4_000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    # 5 cm outside (partly beyond the box's 2 cm margin) and 5 cm inside the sphere
    points = np.concatenate([directions[:2_000] * (RADIUS + 0.05), directions[2_000:] * (RADIUS - 0.05)])
    exact = sphere_query.signed_distance(points).distance
    assert np.all(np.abs(np.abs(exact) - 0.05) < 1e-3)
    assert not near_mask(banded_grid, points, 0.01).any()
    # points 1 cm out are all kept at that band, and at 5 mm all dropped
    shell = directions * (RADIUS + 0.009)
    assert near_mask(banded_grid, shell, 0.01).all()
    assert not near_mask(banded_grid, directions * (RADIUS + 0.02), 0.01).any()


def test_max_nodes_grows_the_spacing(sphere_query, samples):
    grid = DistanceGrid.build(sphere_query, spacing=SPACING, max_nodes=5_000)
    assert math.prod(grid.shape) <= 5_000
    # 49^3 nodes at 5 mm do not fit; the box is 0.24 m wide: 16 cells of 15 mm (17^3 = 4913 nodes) do
    assert grid.spacing == pytest.approx(0.015, rel=1e-9) and grid.shape == (17, 17, 17)
    assert np.all(grid.origin <= -RADIUS - DEFAULT_GRID_MARGIN + 1e-15)
    assert np.all(grid.upper >= RADIUS + DEFAULT_GRID_MARGIN)
    # a cap that is not a cube: the smallest spacing whose box fits
    for cap in (4_913, 4_912, 1_000, 8):
        capped = DistanceGrid.build(sphere_query, spacing=SPACING, max_nodes=cap, exact_band=math.inf)
        assert math.prod(capped.shape) <= cap
        finer = capped.spacing * (1 - 1e-9)
        assert math.prod(distance_grid._grid_shape(capped.origin, capped.upper, finer).tolist()) > cap or cap == 8
    points, exact = samples
    bound = grid.lower_bound(points)
    assert np.all(bound <= np.abs(exact) + TOL)
    assert np.all(near_mask(grid, points, 0.01)[np.abs(exact) < 0.01])
    inside = in_box(grid, points)
    floor = np.minimum(np.abs(exact) - grid.spacing * math.sqrt(3), grid.exact_band - grid.spacing * math.sqrt(3) / 2)
    assert np.all(bound[inside] >= floor[inside] - TOL)


def test_points_outside_the_box(sphere_query, banded_grid):
    rng = np.random.default_rng(3)
    directions = rng.normal(size=(3_000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    points = directions * rng.uniform(0.2, 2.0, size=(3_000, 1))  # all beyond the box's corner radius 0.21
    points = points[~in_box(banded_grid, points)]
    exact = sphere_query.signed_distance(points).distance
    bound = banded_grid.lower_bound(points)
    assert np.all(bound <= exact + TOL)
    assert np.all(bound >= box_distance(banded_grid, points) - TOL)
    assert np.all(banded_grid.sign_where_certain(points) == 1)
    # hand case: on the +x axis, 1 m out; the box face is at 0.12, its node there 0.02 from the sphere
    p = np.array([[1.0, 0.0, 0.0]])
    expected = math.sqrt((1.0 - 0.12) ** 2 + banded_grid.values[-1, 24, 24] ** 2)
    assert banded_grid.values[-1, 24, 24] == pytest.approx(0.02, abs=1e-12)
    assert banded_grid.lower_bound(p)[0] == pytest.approx(expected, abs=1e-12)
    assert expected <= sphere_query.signed_distance(p).distance[0] == pytest.approx(0.9, abs=1e-12)


def test_sign_where_certain(exact_grid, banded_grid, samples):
    points, exact = samples
    for grid in (exact_grid, banded_grid):
        sign = grid.sign_where_certain(points)
        assert sign.dtype == np.int8
        known = sign != 0
        np.testing.assert_array_equal(sign[known], np.sign(exact[known]))
        # certain wherever the bound is positive, in particular beyond a cell diagonal
        np.testing.assert_array_equal(known, grid.lower_bound(points) > 0)
        assert known[np.abs(exact) > SPACING * math.sqrt(3)].all()


def test_bound_and_sign_in_one_pass(banded_grid, samples):
    points, _ = samples
    bound, sign = banded_grid.bound_and_sign(points)
    np.testing.assert_array_equal(bound, banded_grid.lower_bound(points))
    np.testing.assert_array_equal(sign, banded_grid.sign_where_certain(points))


def test_an_open_body_has_bounds_but_no_certain_sign():
    """A sphere open below z = -0.05: inside changes across the film over the hole too, where
    no surface bounds it: the grid claims no sign, not even outside its box."""
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=RADIUS)
    vertices, faces = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)
    query = collision_query(vertices, faces[~(vertices[faces, 2] < -0.05).any(axis=1)])
    grid = DistanceGrid.build(query, spacing=SPACING)
    assert not grid.closed and not query.closed
    points = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -0.08], [0.0, 0.0, 0.5]])
    bound, sign = grid.bound_and_sign(points)
    np.testing.assert_array_equal(sign, [0, 0, 0])
    assert (bound <= np.abs(query.signed_distance(points).distance) + TOL).all() and bound[2] > 0.3
    assert DistanceGrid.build(collision_query(vertices, faces), spacing=0.02).closed


def cube_grid():
    """Cube [-0.1, 0.1]^3, grid spacing 5 cm with a 5 cm margin: nodes at -0.15, -0.1, ..., 0.15."""
    mesh = trimesh.creation.box(extents=(0.2, 0.2, 0.2))
    query = MeshQuery(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64))
    return query, DistanceGrid.build(query, spacing=0.05, margin=0.05, exact_band=math.inf)


def test_hand_cases_on_a_cube():
    query, grid = cube_grid()
    assert grid.shape == (7, 7, 7)
    np.testing.assert_allclose(grid.origin, -0.15, atol=1e-15)
    points = np.array(
        [
            [0.125, 0.0, 0.0],  # between the face x = 0.1 and node (0.15, 0, 0): that node gives 0.05 - 0.025
            [0.125, 0.025, 0.025],  # cell centre: best corners at 0.05 and a half diagonal 0.025 sqrt(3)
            [0.25, 0.0, 0.0],  # outside the box: sqrt(0.1^2 + 0.05^2) (box distance 0.1, node 0.05)
            [0.0, 0.0, 0.0],  # the centre node, 0.1 deep
            [0.1, 0.0, 0.0],  # on the surface
            [0.0, 0.025, 0.0],  # inside, between the centre node and (0, 0.05, 0) at depth 0.05
        ]
    )
    expected = [0.025, 0.05 - 0.025 * math.sqrt(3), math.sqrt(0.1**2 + 0.05**2), 0.1, 0.0, 0.1 - 0.025]
    np.testing.assert_allclose(grid.lower_bound(points), expected, rtol=0, atol=1e-15)
    exact = query.signed_distance(points).distance
    np.testing.assert_allclose(exact, [0.025, 0.025, 0.15, -0.1, 0.0, -0.075], atol=1e-15)
    np.testing.assert_array_equal(grid.sign_where_certain(points), [1, 1, 1, -1, 0, -1])
    np.testing.assert_array_equal(near_mask(grid, points, 0.026), [True, True, False, False, True, False])


def test_edge_inputs(banded_grid):
    assert banded_grid.lower_bound(np.zeros((0, 3))).shape == (0,)
    assert near_mask(banded_grid, np.zeros((0, 3)), 0.01).shape == (0,)
    # non-finite points get no bound: they stay in the mask (the exact query decides)
    points = np.array([[np.nan, 0.0, 0.0], [np.inf, 0.0, 0.0], [0.0, 0.0, 0.0]])
    np.testing.assert_array_equal(banded_grid.lower_bound(points)[:2], 0.0)
    np.testing.assert_array_equal(near_mask(banded_grid, points, 0.01), [True, True, False])
    np.testing.assert_array_equal(banded_grid.sign_where_certain(points), [0, 0, -1])
    with pytest.raises(ValueError):
        DistanceGrid(np.zeros(3), 0.0, np.zeros((2, 2, 2)))
    with pytest.raises(ValueError):
        DistanceGrid(np.zeros(3), 0.01, np.zeros((1, 2, 2)))


def test_reference_in_blocks_matches_one_block(banded_grid, samples, monkeypatch):
    points, _ = samples
    whole = banded_grid._evaluate_reference(points, want_sign=True)
    monkeypatch.setattr(distance_grid, "EVAL_CHUNK", 777)
    for blocks, one in zip(banded_grid._evaluate_reference(points, want_sign=True), whole):
        np.testing.assert_array_equal(blocks, one)


@pytest.mark.parametrize("covers_mesh, closed", [(True, True), (False, True), (True, False)])
def test_the_compiled_evaluation_is_the_numpy_reference_to_the_bit(banded_grid, samples, covers_mesh, closed):
    """Inside and outside the box (bounds from its projection, or 0 when the box does not
    cover the mesh), certain and unknown signs, non-finite points."""
    grid = DistanceGrid(banded_grid.origin, banded_grid.spacing, banded_grid.values, banded_grid.exact_band,
                        covers_mesh, closed)
    points, _ = samples
    rng = np.random.default_rng(7)
    around = rng.uniform(grid.origin - 0.05, grid.upper + 0.05, size=(20000, 3))
    points = np.concatenate([points, around, [[np.nan, 0.0, 0.0], [np.inf, 0.0, 0.0], [0.0, -np.inf, 0.0]]])
    bound, sign = grid.bound_and_sign(points)
    reference_bound, reference_sign = grid._evaluate_reference(points, want_sign=True)
    np.testing.assert_array_equal(bound, reference_bound)
    np.testing.assert_array_equal(sign, reference_sign)
    outside = np.any((around < grid.origin) | (around > grid.upper), axis=1)
    assert outside.sum() > 1000 and (sign == 0).sum() > 3
    assert (sign != 0).sum() > 1000 if closed else (sign == 0).all()
    assert (bound[:-3] == 0).sum() > 1000 if not covers_mesh else (bound[:-3] > 0).sum() > 20000


def test_region_grid_bounds_inside_and_defers_outside():
    """A grid over part of the mesh: valid bounds inside its box, 0 (exact query) outside."""
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=0.1)
    query = MeshQuery(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    region = (np.array([0.0, -0.2, -0.2]), np.array([0.2, 0.2, 0.2]))
    grid = DistanceGrid.build(query, spacing=5e-3, region=region)
    assert not grid.covers_mesh
    assert grid.origin[0] >= 0.0 and grid.upper[0] <= 0.1 + DEFAULT_GRID_MARGIN + 5e-3
    rng = np.random.default_rng(4)
    points = rng.uniform(-0.15, 0.15, size=(5000, 3))
    exact = np.abs(query.signed_distance(points).distance)
    bound = grid.lower_bound(points)
    assert np.all(bound <= exact + 1e-12)
    left = points[:, 0] < grid.origin[0]
    assert left.sum() > 1000 and np.all(bound[left] == 0.0)
    inside_box = (points[:, 0] > grid.origin[0] + 0.01) & (exact < 0.02)  # node values are exact near the body
    assert np.all(exact[inside_box] - bound[inside_box] <= 5e-3 * np.sqrt(3) + 1e-12)
    whole = DistanceGrid.build(query, spacing=5e-3, region=(np.full(3, -1.0), np.full(3, 1.0)))
    assert whole.covers_mesh


def test_a_grid_near_some_points_is_exact_there_and_certified_everywhere(sphere_query, banded_grid, samples):
    """``near`` and ``reach``: the nodes within reach of the points are the banded grid's exact ones; the others
    keep certified bounds, so every bound and sign still holds, and points near the given ones are told apart as on
    the full grid."""
    rng = np.random.default_rng(5)
    cap = rng.normal(size=(3000, 3))
    cap = cap[cap[:, 2] > 0.5 * np.linalg.norm(cap, axis=1)]  # a cap of the sphere, hair on a scalp
    near = cap / np.linalg.norm(cap, axis=1, keepdims=True) * (RADIUS + rng.uniform(0.0, 0.01, size=(len(cap), 1)))
    grid = DistanceGrid.build(sphere_query, spacing=SPACING, near=near, reach=0.01)
    i, j, k = np.meshgrid(*[np.arange(n) for n in grid.shape], indexing="ij")
    nodes = grid.origin + SPACING * np.stack([i, j, k], axis=-1).reshape(-1, 3)
    exact = sphere_query.signed_distance(nodes).distance
    values, full = grid.values.reshape(-1), banded_grid.values.reshape(-1)
    from scipy.spatial import cKDTree

    to_near = cKDTree(near).query(nodes)[0]
    within = (np.abs(exact) < grid.exact_band) & (to_near <= 0.01)
    assert within.sum() > 2000
    np.testing.assert_array_equal(values[within], exact[within])
    skipped = (np.abs(exact) < grid.exact_band) & (values != exact)
    assert skipped.sum() > 5000 and to_near[skipped].min() > 0.01  # the far side was not queried
    assert np.all(np.abs(values) <= np.abs(exact) + TOL)
    certain = values != 0
    np.testing.assert_array_equal(np.sign(values[certain]), np.sign(exact[certain]))
    # points within the reach: the same bounds as on the banded grid; every point: a bound and a sign that hold
    points, truth = samples
    close = cKDTree(near).query(points)[0] < 0.005
    assert close.sum() > 100
    np.testing.assert_array_equal(grid.lower_bound(points[close]), banded_grid.lower_bound(points[close]))
    bound, sign = grid.bound_and_sign(points)
    assert np.all(bound <= np.abs(truth) + TOL)
    assert np.all((sign == 0) | (sign == np.sign(truth)))
    assert not np.array_equal(full, values)
    with pytest.raises(ValueError, match="reach"):
        DistanceGrid.build(sphere_query, near=near, reach=-1.0)
