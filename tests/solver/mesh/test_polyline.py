"""Polylines and segments (solver/mesh/polyline.py): arc length, closest points on segments."""

import numpy as np

from hairport.solver.mesh.polyline import closest_points_on_segments, polyline_arc_length


def test_arc_length_of_a_known_polyline():
    points = np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 4.0], [6.0, 8.0], [6.0, 0.0]])  # a repeated point adds 0
    np.testing.assert_array_equal(polyline_arc_length(points), [0.0, 5.0, 5.0, 10.0, 18.0])
    np.testing.assert_array_equal(polyline_arc_length(np.array([[1.0, 2.0, 3.0]])), [0.0])
    helix = np.stack([np.cos(np.linspace(0, 2 * np.pi, 10001)), np.sin(np.linspace(0, 2 * np.pi, 10001)),
                      np.linspace(0, 1, 10001)], axis=1)
    assert abs(polyline_arc_length(helix)[-1] - np.hypot(2 * np.pi, 1.0)) < 1e-6


def test_closest_points_on_a_segment_by_hand():
    heads, tails = np.array([[-1.0, 0.0, 0.0]]), np.array([[1.0, 0.0, 0.0]])
    points = np.array([[0.5, 2.0, 0.0], [-3.0, 1.0, 0.0], [4.0, 0.0, -1.0]])  # beside, before, beyond
    t, closest = closest_points_on_segments(points, heads, tails)
    np.testing.assert_array_equal(t[:, 0], [0.75, 0.0, 1.0])
    np.testing.assert_array_equal(closest[:, 0], [[0.5, 0.0, 0.0], [-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])


def test_closest_points_on_segments_against_dense_sampling():
    rng = np.random.default_rng(8)
    points = rng.normal(size=(30, 3))
    heads, tails = rng.normal(size=(7, 3)), rng.normal(size=(7, 3))
    tails[0] = heads[0]  # a degenerate segment
    t, closest = closest_points_on_segments(points, heads, tails)
    assert t.shape == (30, 7) and closest.shape == (30, 7, 3)
    assert t.min() >= 0 and t.max() <= 1
    grid = np.linspace(0.0, 1.0, 20001)
    samples = heads[None, :, None] + grid[None, None, :, None] * (tails - heads)[None, :, None]  # (1, B, G, 3)
    best = np.linalg.norm(points[:, None, None] - samples, axis=-1).min(axis=-1)
    got = np.linalg.norm(points[:, None] - closest, axis=-1)
    assert (got <= best + 1e-12).all() and (best - got).max() < 1e-6
    np.testing.assert_allclose(closest[:, 0], np.broadcast_to(heads[0], (30, 3)))
