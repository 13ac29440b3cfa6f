"""The line-search kernels of the compiled fine level (solver/adaptation/fine/line_search_kernels.py) against numpy."""

import numpy as np
import pytest

from hairport.solver.adaptation.fine import line_search_kernels
from tests.solver.adaptation.fine.test_strand_kernels import packed_trials, unit


def test_line_search_kernels_gather_and_commit_trial_points():
    rng, problem, points, step, strands, fraction, packed, index = packed_trials(7)
    n = problem.n_particles
    moved, free = np.empty((packed[-1], 3)), np.empty(packed[-1], dtype=bool)
    line_search_kernels.gather_trial_points(strands, problem.offsets, packed, points, step, fraction, problem.fixed,
                                            moved, free)
    per_particle = np.repeat(fraction, np.diff(packed))
    np.testing.assert_array_equal(moved, points[index] + per_particle[:, None] * step[index])
    np.testing.assert_array_equal(free, ~problem.fixed[index])

    moved_distance = rng.normal(scale=1e-3, size=len(index))
    moved_distance[::4] = np.inf

    take = np.array([True, False, True])
    committed, distance, normal, near = points.copy(), np.zeros(n), np.zeros((n, 3)), np.zeros(n, dtype=bool)
    moved_normal, moved_near = unit(rng.normal(size=(len(index), 3))), np.isfinite(moved_distance)
    max_step, shortfall, clearance = np.zeros(3), np.zeros(3), np.zeros(3)
    line_search_kernels.commit_trial_points(strands, problem.offsets, packed, take, moved, moved_distance,
                                            moved_normal, moved_near, problem.fixed, 5e-4, committed, distance, normal,
                                            near, max_step, shortfall, clearance)
    for t, s in enumerate(strands):
        rows = slice(problem.offsets[s], problem.offsets[s + 1])
        mine = slice(packed[t], packed[t + 1])
        if not take[t]:
            np.testing.assert_array_equal(committed[rows], points[rows])
            continue
        np.testing.assert_array_equal(committed[rows], moved[mine])
        np.testing.assert_array_equal(distance[rows], moved_distance[mine])
        np.testing.assert_array_equal(normal[rows], moved_normal[mine])
        np.testing.assert_array_equal(near[rows], moved_near[mine])
        assert max_step[t] == pytest.approx(np.linalg.norm(moved[mine] - points[rows], axis=1).max(), rel=1e-15)
        free_distance = moved_distance[mine][~problem.fixed[rows]]
        assert shortfall[t] == 5e-4 - free_distance.min()
        assert clearance[t] == free_distance.min()
    # the clearance of the strands that stay: read from the chunk's (now committed) distances
    stay_short, stay_clearance = np.zeros(3), np.zeros(3)
    line_search_kernels.strand_clearances(strands, problem.offsets, distance, problem.fixed, 5e-4, stay_short,
                                          stay_clearance)
    for t, s in enumerate(strands):
        free_distance = distance[problem.offsets[s]:problem.offsets[s + 1]][~problem.fixed[problem.offsets[s]:problem.offsets[s + 1]]]
        assert stay_clearance[t] == free_distance.min() and stay_short[t] == 5e-4 - free_distance.min()


@pytest.fixture(scope="module")
def sphere_query():
    from hairport.solver.mesh.query import MeshQuery
    from tests.solver.hair_shapes import sphere_character

    head = sphere_character()
    return MeshQuery(head.vertices, head.faces)


def test_trial_distance_bounds_and_anchor_commits_equal_the_numpy_anchors(sphere_query):
    """bound_trial_distances / commit_anchors against :class:`.constraints.QueryAnchors` on a real body:
    the same points asked, the same bounds, each bound at most the exact distance, the same anchors after."""
    from hairport.solver.adaptation.problem.constraints import BodyDistance, QueryAnchors, reaching

    rng = np.random.default_rng(11)
    query = sphere_query
    offsets = np.array([0, 40, 100, 160], dtype=np.int64)
    n = offsets[-1]
    direction = rng.normal(size=(n, 3))
    radius = np.linalg.norm(query.vertices, axis=1).max()
    points = direction / np.linalg.norm(direction, axis=1, keepdims=True) * radius * rng.uniform(0.99, 1.05, (n, 1))
    body = BodyDistance(query)
    distance, normal, near = body(points)
    near[::17] = False  # the broad phase's far particles: always asked again
    distance[::17] = np.inf
    reference = QueryAnchors(points, distance, normal, near)
    anchors = [points.copy(), distance.copy(), normal.copy(), near.copy()]
    strands = np.array([0, 2], dtype=np.int64)
    packed = np.array([0, 40, 100], dtype=np.int64)
    index = np.concatenate([np.arange(0, 40), np.arange(100, 160)])
    moved = points[index] + rng.normal(scale=2e-3, size=(len(index), 3))
    eps_c, margin = 5e-4, 1e-3

    d, nrm, nr, queried = reference.trial_distance(body, moved, index, eps_c, margin)
    kd, knrm = np.full(len(index), np.nan), np.full((len(index), 3), np.nan)
    knr, kqueried = np.zeros(len(index), dtype=bool), np.zeros(len(index), dtype=bool)
    line_search_kernels.bound_trial_distances(strands, offsets, packed, moved, *anchors, eps_c + margin, kd, knrm, knr,
                                              kqueried)
    np.testing.assert_array_equal(kqueried, queried)
    assert 0 < queried.sum() < len(index) and queried[np.isin(index, np.arange(0, n, 17))].all()
    np.testing.assert_allclose(kd[~kqueried], d[~queried], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(knrm[~kqueried], nrm[~queried])
    assert knr[~kqueried].all()
    exact = query.signed_distance(moved).distance
    assert np.all(d[~queried] <= exact[~queried] + 1e-15) and np.all(d[~queried] >= eps_c + margin)
    np.testing.assert_allclose(d[queried], exact[queried], rtol=0, atol=1e-12)

    kd[kqueried], knrm[kqueried], knr[kqueried] = d[queried], nrm[queried], nr[queried]
    take = np.array([True, False])
    bounded = np.zeros(n, dtype=bool)
    line_search_kernels.commit_anchors(strands, offsets, packed, take, kqueried, moved, kd, knrm, knr, *anchors,
                                       bounded)
    taken = np.arange(len(index)) < 40
    reference.commit(index[taken], moved[taken], d[taken], nrm[taken], nr[taken], queried[taken])
    for kernel_array, numpy_array in zip(anchors + [bounded], (reference.points, reference.distance, reference.normal,
                                                               reference.near, reference.bounded)):
        np.testing.assert_array_equal(kernel_array, numpy_array)
    assert not np.array_equal(anchors[0], points) and 0 < bounded.sum() < 40  # some anchors moved, some bounded

    step = np.zeros((n, 3))
    step[index[taken & ~queried][0]] = [0.0, 0.0, 1.0]  # a bounded particle's step past its slack
    hit = np.zeros(2, dtype=bool)
    line_search_kernels.reaching_strands(strands, offsets, step, reference.distance, bounded, eps_c, hit)
    np.testing.assert_array_equal(hit, [True, False])
    np.testing.assert_array_equal(reaching(step, reference.distance, bounded, eps_c), np.isin(np.arange(n),
                                  index[taken & ~queried][:1]))
