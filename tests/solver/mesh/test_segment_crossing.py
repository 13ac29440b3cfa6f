"""Segments passing through the body between two particles outside it (solver/mesh/segment_crossing.py)."""

import numpy as np
import pytest

from hairport.solver.mesh.collision import collision_query
from hairport.solver.mesh.segment_crossing import crossing_segments, segment_entries
from tests.solver.mesh.meshes import icosphere

#: a shoulder-like curvature: 5 cm
RADIUS = 0.05
EPS_C = 5e-4


@pytest.fixture(scope="module")
def sphere():
    return collision_query(*icosphere(radius=RADIUS, subdivisions=5))


def chord(query, length: float, clearance: float, direction=(1.0, 0.0, 0.0)):
    """Two particles ``clearance`` off the body about its +z pole, ``length`` apart along ``direction``."""
    direction = np.asarray(direction) / np.linalg.norm(direction)
    pole = query.signed_distance(np.array([[0.0, 0.0, 2 * RADIUS]])).closest[0]
    ends = []
    for side in (-0.5, 0.5):
        guess = pole + side * length * direction
        sd = query.signed_distance(guess[None])
        ends.append(sd.closest[0] + clearance * sd.normal[0])
    return np.array(ends)


def test_a_16_mm_chord_half_a_millimetre_off_a_5_cm_shoulder_crosses_it_and_an_8_mm_one_does_not(sphere):
    long_chord, short_chord = chord(sphere, 0.016, EPS_C), chord(sphere, 0.008, EPS_C)
    points = np.vstack([long_chord, short_chord])
    assert (sphere.signed_distance(points).distance > EPS_C - 1e-9).all()  # every particle clear of the body
    crossings = crossing_segments(points, np.array([[0, 1], [2, 3]]), np.zeros(4, dtype=bool), sphere)
    assert crossings.rows.tolist() == [0]
    sagitta = 0.016**2 / (8 * RADIUS)  # 0.64 mm, over the 0.5 mm clearance
    assert crossings.depth[0] == pytest.approx(sagitta - EPS_C, abs=3e-5)
    assert crossings.deepest_at[0] == pytest.approx(0.5, abs=0.04)
    assert crossings.normal[0] @ [0.0, 0.0, 1.0] > 0.99
    report = crossings.report(np.array([[0, 1], [2, 3]]), np.array([0, 2, 4]))
    assert report == {"count": 1, "deepest_m": pytest.approx(crossings.depth[0]), "deepest_strand": 0,
                      "deepest_segment": 0}


def random_segments(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` segments of 4-40 mm centred 0-4 mm off the sphere, in random directions: ``points (2n, 3)``
    (first ends, then second ends) and ``segments (n, 2)``."""
    rng = np.random.default_rng(seed)
    centres = rng.normal(size=(n, 3))
    centres = (RADIUS + rng.uniform(0.0, 0.004, n))[:, None] * centres / np.linalg.norm(centres, axis=1, keepdims=True)
    offsets = rng.normal(size=(n, 3)) * rng.uniform(0.002, 0.02, n)[:, None]
    return np.vstack([centres - offsets, centres + offsets]), np.stack([np.arange(n), np.arange(n) + n], axis=1)


def test_the_count_equals_a_dense_sampling_of_random_segments_near_the_body(sphere):
    n = 4000
    points, segments = random_segments(n, seed=4)
    is_root = np.zeros(2 * n, dtype=bool)
    crossings = crossing_segments(points, segments, is_root, sphere)
    # the reference: 2,000 points along each segment, ends outside and some point inside
    at = np.linspace(0.0, 1.0, 2001)[1:-1]
    samples = points[:n, None, :] + at[None, :, None] * (points[n:] - points[:n])[:, None, :]
    inside = sphere.signed_distance(samples.reshape(-1, 3)).distance.reshape(n, -1) < 0
    ends_out = (sphere.signed_distance(points).distance >= 0).reshape(2, n).all(axis=0)
    expected = np.flatnonzero(ends_out & inside.any(axis=1))
    assert 100 < len(expected) < n - 100  # both kinds are common
    np.testing.assert_array_equal(crossings.rows, expected)


def test_a_segment_from_a_root_on_the_scalp_counts_only_when_it_dips_back_in(sphere):
    pole = sphere.signed_distance(np.array([[0.0, 0.0, 2 * RADIUS]])).closest[0]
    away = pole + [0.0, 0.0, 0.01]  # straight out: no crossing
    grazing = chord(sphere, 0.03, EPS_C)[1]  # along the surface 3 cm off, clear at its end: dips in between
    points = np.vstack([pole, away, pole, grazing])
    is_root = np.array([True, False, True, False])
    crossings = crossing_segments(points, np.array([[0, 1], [2, 3]]), is_root, sphere)
    assert crossings.rows.tolist() == [1] and crossings.depth[0] > 2e-4


def test_a_segment_with_an_end_inside_is_the_particle_checks_not_this_one(sphere):
    ends = chord(sphere, 0.016, EPS_C)
    points = np.vstack([ends, [0.0, 0.0, RADIUS - 0.005]])
    segments = np.array([[0, 1], [1, 2]])
    assert segment_entries(points, segments, np.zeros(3, dtype=bool), sphere).tolist() == [True, True]
    assert crossing_segments(points, segments, np.zeros(3, dtype=bool), sphere).rows.tolist() == [0]


def test_a_check_among_some_segments_joined_with_the_rest_is_the_whole_check(sphere):
    """``among`` casts only those rows; the crossings of two disjoint parts, joined, are those of the whole."""
    rng = np.random.default_rng(7)
    n = 600
    points, segments = random_segments(n, seed=7)
    is_root = np.zeros(2 * n, dtype=bool)
    whole = crossing_segments(points, segments, is_root, sphere)
    some = np.flatnonzero(rng.random(n) < 0.4)
    rest = np.setdiff1d(np.arange(n), some)
    first = crossing_segments(points, segments, is_root, sphere, among=some)
    second = crossing_segments(points, segments, is_root, sphere, among=rest)
    assert 0 < first.count < whole.count and set(first.rows) <= set(some)
    joined = second.joined(first)
    for name in ("rows", "depth", "deepest_point", "deepest_at", "normal"):
        np.testing.assert_array_equal(getattr(joined, name), getattr(whole, name))
