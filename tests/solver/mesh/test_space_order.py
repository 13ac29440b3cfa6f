"""Queries in space order: the same answers as in the given order, Z-curve keys of a box's cells."""

import numpy as np

from hairport.solver.mesh import space_order


class _EchoIndex:
    """A face search that answers each point with a number and a point derived from it alone."""

    def closest(self, points):
        return np.floor(points[:, 0] * 1e6).astype(np.int64), 2.0 * points


def test_sorted_queries_come_back_in_the_callers_order(monkeypatch):
    points = np.random.default_rng(4).random((5000, 3))
    monkeypatch.setattr(space_order, "SORT_QUERIES_FROM", 1)
    faces, closest = space_order.search_in_space_order(_EchoIndex(), points)
    np.testing.assert_array_equal(faces, np.floor(points[:, 0] * 1e6).astype(np.int64))
    np.testing.assert_array_equal(closest, 2.0 * points)


def test_morton_keys_interleave_the_axes():
    corners = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], dtype=float)
    keys = space_order.morton_keys(corners)
    top = (1 << 30) - 1  # every bit of the 10-bit cell indices, x at bit 3i, y at 3i + 1, z at 3i + 2
    assert list(keys) == [0, top & 0o1111111111, (top & 0o1111111111) << 1, (top & 0o1111111111) << 2, top]
