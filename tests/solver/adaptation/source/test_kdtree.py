"""The compiled k-d tree (solver/adaptation/source/kdtree.py): exact kNN of other groups, against brute force."""

import numpy as np
import pytest

from hairport.solver.adaptation.source.kdtree import LEAF_SIZE, build_tree, query_tree


def _brute_force(points, groups, queries, query_groups, k):
    d = np.linalg.norm(queries[:, None] - points[None], axis=2)
    d[query_groups[:, None] == groups[None]] = np.inf
    d = np.pad(d, ((0, 0), (0, max(0, k - d.shape[1]))), constant_values=np.inf)
    order = np.argsort(d, axis=1, kind="stable")[:, :k]
    return order, np.take_along_axis(d, order, axis=1)


@pytest.mark.parametrize("count, k", [(1, 3), (5, 3), (LEAF_SIZE + 1, 4), (300, 5), (2000, 1)])
def test_the_tree_finds_the_exact_nearest_points_of_other_groups(count, k):
    rng = np.random.default_rng(count)
    points = rng.normal(size=(count, 3)) * [1.0, 0.2, 3.0]  # stretched: the widest axis changes per node
    groups = rng.integers(0, 7, count)
    queries = np.concatenate([points[: min(count, 50)], rng.normal(size=(50, 3))])
    query_groups = np.concatenate([groups[: min(count, 50)], rng.integers(0, 7, 50)])
    index = np.full((len(queries), k), -1, dtype=np.int32)
    distance = np.empty((len(queries), k))
    tree = build_tree(points, np.arange(count) + 1000, groups)
    assert query_tree(tree, queries, query_groups, index, distance, max_skipped=10**9).all()
    expected_index, expected_distance = _brute_force(points, groups, queries, query_groups, k)
    found = np.isfinite(expected_distance)
    np.testing.assert_array_equal(np.isfinite(distance), found)
    np.testing.assert_allclose(distance[found], expected_distance[found], rtol=1e-15, atol=0)
    np.testing.assert_array_equal(index[found], expected_index[found] + 1000)  # the ids given to the tree
    assert (index[~found] == -1).all()  # columns beyond the points found are left alone


def test_a_query_that_meets_too_many_points_of_its_own_group_gives_up():
    line = np.stack([np.zeros(500), np.zeros(500), 0.001 * np.arange(500)], axis=1)  # one long strand alone
    tree = build_tree(line, np.arange(500), np.zeros(500, dtype=np.int64))
    index, distance = np.zeros((2, 2), dtype=np.int64), np.empty((2, 2))
    # its own particles: after 100 of them and no other, the query gives up; a query of another strand does not
    complete = query_tree(tree, line[[250, 10]], np.array([0, 1]), index, distance, max_skipped=100)
    assert complete.tolist() == [False, True]
    assert index[1, 0] == 10 and index[1, 1] in (9, 11)
    # allowed to meet them all, it completes and finds nobody
    assert query_tree(tree, line[[250]], np.array([0]), index[:1], distance[:1], max_skipped=10**6).all()
    assert np.isinf(distance[0]).all()
    # with a second strand far away, the exact answer is that strand's two particles
    far = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.1]])
    tree = build_tree(np.concatenate([line, far]), np.arange(502), np.array([0] * 500 + [1, 1]))
    assert query_tree(tree, line[[250]], np.array([0]), index[:1], distance[:1], max_skipped=10**6).all()
    assert sorted(index[0].tolist()) == [500, 501]


def test_coincident_points_and_ties_keep_every_point_once():
    points = np.repeat(np.eye(3), 6, axis=0)  # 18 points, six on each of three places
    groups = np.arange(18)
    tree = build_tree(points, np.arange(18), groups)
    index, distance = np.zeros((1, 12), dtype=np.int64), np.empty((1, 12))
    query_tree(tree, np.array([[1.0, 0.0, 0.0]]), np.array([-1]), index, distance, max_skipped=0)
    assert sorted(index[0, :6].tolist()) == list(range(6)) and (distance[0, :6] == 0.0).all()
    assert len(set(index[0].tolist())) == 12
    np.testing.assert_allclose(distance[0, 6:], np.sqrt(2.0))
