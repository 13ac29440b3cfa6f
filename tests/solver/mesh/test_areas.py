"""Signed planar and unsigned 3D triangle areas against hand values and libigl."""

import igl
import numpy as np
import pytest

from hairport.solver.mesh.areas import signed_areas, triangle_areas
from tests.solver.triangle_grids import grid


def test_signed_areas_by_hand():
    points = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 3.0], [2.0, 3.0]])
    triangles = np.array([[0, 1, 2], [0, 2, 1], [1, 3, 2], [0, 1, 1]])
    np.testing.assert_array_equal(signed_areas(points, triangles), [3.0, -3.0, 3.0, 0.0])
    # integer coordinates are taken as float64
    np.testing.assert_array_equal(signed_areas(points.astype(np.int64), triangles[:1]), [3.0])
    assert signed_areas(points, np.zeros((0, 3), np.int64)).shape == (0,)


def test_signed_areas_of_a_grid_sum_to_its_area():
    points, triangles = grid(5, 3, -1.0, 1.5, 0.0, 0.75)
    areas = signed_areas(points, triangles)
    np.testing.assert_allclose(areas, np.full(30, 2.5 * 0.75 / 30), rtol=1e-14)
    # mirrored in y: every triangle turns clockwise
    np.testing.assert_allclose(signed_areas(points * [1.0, -1.0], triangles), -areas, rtol=0, atol=0)


def test_triangle_areas_by_hand():
    points = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
    triangles = np.array([[0, 1, 2], [3, 0, 1], [3, 1, 0], [3, 0, 0]])
    np.testing.assert_allclose(triangle_areas(points, triangles), [np.sqrt(3.0) / 2.0, 0.5, 0.5, 0.0], rtol=1e-15)
    # scaling by s scales the area by s^2
    np.testing.assert_allclose(triangle_areas(3.0 * points, triangles), 9.0 * triangle_areas(points, triangles),
                               rtol=1e-15)


def test_triangle_areas_are_the_absolute_signed_areas_in_a_plane():
    points, triangles = grid(4, 4, 0.0, 1.0, 0.0, 1.0)
    triangles[::3] = triangles[::3, ::-1]  # some clockwise
    flat = np.column_stack([points, np.zeros(len(points))])
    np.testing.assert_allclose(triangle_areas(flat, triangles), np.abs(signed_areas(points, triangles)), rtol=1e-15)


def test_triangle_areas_match_libigl():
    rng = np.random.default_rng(4)
    points = rng.normal(size=(60, 3))
    triangles = np.array([rng.choice(60, 3, replace=False) for _ in range(100)])
    expected = 0.5 * igl.doublearea(points, triangles)
    np.testing.assert_allclose(triangle_areas(points, triangles), expected, rtol=1e-12)
    assert triangle_areas(points, triangles).sum() == pytest.approx(expected.sum(), rel=1e-13)
