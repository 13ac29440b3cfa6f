"""The active set over the kinks of the embedded head: vertices on a head edge or vertex are held
where every side goes uphill, snapped onto it, or differentiated in their downhill triangle."""

import numpy as np
import pytest

from hairport.solver.hairline.head_chart import HeadChart
from hairport.solver.hairline.kinks import AT_VERTEX, FREE, ON_EDGE, SNAP_BARYCENTRIC, kink_activity

#: height (m) of the roof's ridge corner and depth of the pit
RISE = 0.5
UP = np.array([[0.0, 0.0, 1.0]])


def roof():
    """Two uv triangles over the unit square sharing the diagonal from (1, 0) to (0, 1): the first
    flat, the second rising to ``RISE`` at (1, 1), so the head bends along the diagonal."""
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    vertices = np.column_stack([uv, [0.0, 0.0, 0.0, RISE]])
    return HeadChart.build(vertices, np.array([[0, 1, 2], [1, 3, 2]]), uv)


def fan(depth):
    """Six triangles around vertex 0 at uv (0, 0) and ``z = -depth``; ring vertex ``i`` at angle
    ``60 (i - 1)`` degrees on the unit circle, ``z = 0``; triangle ``i - 1`` is ``(0, i, i + 1)``."""
    angle = np.radians(60.0 * np.arange(6))
    uv = np.vstack([[0.0, 0.0], np.column_stack([np.cos(angle), np.sin(angle)])])
    vertices = np.column_stack([uv, np.r_[-depth, np.zeros(6)]])
    faces = np.array([[0, i, i % 6 + 1] for i in range(1, 7)])
    return HeadChart.build(vertices, faces, uv)


def activity(chart, host, barycentric, gradient, reach=None, free=True):
    args = (chart, np.array([host]), np.array([barycentric], dtype=float), np.asarray(gradient, dtype=float),
            np.array([free]))
    return kink_activity(*args) if reach is None else kink_activity(*args, reach=reach)


def test_a_vertex_inside_a_triangle_is_free():
    host, mode, tangent, snapped = activity(roof(), 0, [0.2, 0.3, 0.5], UP)
    assert host.tolist() == [0] and mode.tolist() == [FREE]
    np.testing.assert_array_equal(tangent, [[0.0, 0.0]])
    np.testing.assert_allclose(snapped, [[0.3, 0.5]], rtol=0, atol=1e-15)


def test_a_vertex_on_the_ridge_pushed_uphill_both_ways_is_held_on_it():
    # dE/dx = +z: into the flat side costs nothing (slope 0), into the rising side RISE sqrt(2)
    host, mode, tangent, snapped = activity(roof(), 0, [0.0, 0.5, 0.5], UP)
    assert host.tolist() == [0] and mode.tolist() == [ON_EDGE]
    np.testing.assert_allclose(tangent, [[-np.sqrt(0.5), np.sqrt(0.5)]], rtol=0, atol=1e-15)  # along 1 -> 2
    np.testing.assert_allclose(snapped, [[0.5, 0.5]], rtol=0, atol=1e-15)


def test_a_vertex_on_the_ridge_with_a_downhill_side_moves_into_it():
    # dE/dx = -z: the rising triangle goes downhill
    host, mode, tangent, _ = activity(roof(), 0, [0.0, 0.5, 0.5], -UP)
    assert host.tolist() == [1] and mode.tolist() == [FREE]
    np.testing.assert_array_equal(tangent, [[0.0, 0.0]])


def test_a_vertex_near_the_ridge_is_snapped_onto_it_within_reach():
    near = [1e-8, 0.5, 0.5 - 1e-8]
    host, mode, _, snapped = activity(roof(), 0, near, UP, reach=SNAP_BARYCENTRIC)
    assert mode.tolist() == [ON_EDGE] and host.tolist() == [0]
    assert snapped[0].sum() == pytest.approx(1.0, abs=1e-15)  # on the diagonal u + v = 1
    # within the default reach it is not on the edge: free, not snapped
    host, mode, _, snapped = activity(roof(), 0, near, UP)
    assert mode.tolist() == [FREE] and host.tolist() == [0]
    np.testing.assert_allclose(snapped, [[0.5, 0.5 - 1e-8]], rtol=0, atol=1e-15)


def test_a_vertex_at_the_bottom_of_a_pit_is_held_there():
    chart = fan(RISE)
    host, mode, tangent, snapped = activity(chart, 3, [1.0, 0.0, 0.0], UP)
    assert mode.tolist() == [AT_VERTEX] and host.tolist() == [3]
    np.testing.assert_array_equal(tangent, [[0.0, 0.0]])
    np.testing.assert_array_equal(snapped, [[0.0, 0.0]])


def test_a_vertex_at_a_head_vertex_moves_into_its_steepest_triangle():
    # flat fan, steepest descent at 30 degrees: inside triangle 0 (between 0 and 60 degrees)
    gradient = [[-np.cos(np.pi / 6), -np.sin(np.pi / 6), 0.0]]
    host, mode, _, _ = activity(fan(0.0), 3, [1.0, 0.0, 0.0], gradient)
    assert host.tolist() == [0] and mode.tolist() == [FREE]


def test_fixed_vertices_are_left_alone():
    host, mode, _, snapped = activity(roof(), 0, [0.0, 0.5, 0.5], UP, free=False)
    assert host.tolist() == [0] and mode.tolist() == [FREE]
    np.testing.assert_allclose(snapped, [[0.5, 0.5]], rtol=0, atol=1e-15)
