"""Tests for solver/body/scale.py: units from sizes, and whether a groom sits on a body in some units."""

import numpy as np
import pytest

from hairport.solver.body.scale import (
    best_fit,
    largest_extent,
    log_outside,
    relative_fits,
    root_fit_share,
    units_from_ratio,
    units_from_sizes,
)
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.units import METERS_PER_UNIT
from hairport.solver.synthetic.groom import generate_groom


@pytest.fixture(scope="module")
def roots(toy_a, query_a):
    hair = generate_groom(toy_a, "short", 150, 6, seed=5, query=query_a)
    return hair.points[hair.roots]


def test_sizes_pick_the_unit_of_a_body_and_its_scalp_in_every_unit(toy_a, roots):
    assert 0.15 < largest_extent(roots) < 0.25 and largest_extent(toy_a.vertices) == pytest.approx(0.61)
    for units, scale in METERS_PER_UNIT.items():
        guess = units_from_sizes(toy_a.vertices / scale, roots / scale)
        assert (guess.units, guess.plausible) == (units, True), units
        assert f"in {units} the body is 0.61 m and the scalp" in guess.describe()
    # a groom of two strands says nothing about its scalp: the body's size decides
    assert units_from_sizes(toy_a.vertices * 1000, roots[:2] * 1000).units == "mm"
    # nothing plausible: the least implausible reading, flagged
    tiny = units_from_sizes(toy_a.vertices * 1e-5, roots * 1e-5)
    assert (tiny.units, tiny.plausible) == ("m", False)


def test_log_outside_and_units_from_ratio():
    assert log_outside(0.5, (0.1, 1.0)) == 0.0
    assert log_outside(2.0, (0.1, 1.0)) == pytest.approx(np.log(2.0))
    assert log_outside(0.01, (0.1, 1.0)) == pytest.approx(np.log(10.0)) and log_outside(0.0, (0.1, 1.0)) == np.inf
    assert [units_from_ratio(r) for r in (0.9, 0.13, 0.008, 0.0013, 3.0)] == ["m", "dm", "cm", "mm", "m"]


def test_the_fit_share_is_zero_on_the_body_and_large_in_other_units(toy_a, query_a, roots):
    assert root_fit_share(query_a, roots) < 1e-6
    shares = relative_fits(query_a, roots * 100.0, "m")  # the hair file in cm, the body in meters
    assert best_fit(shares) == "cm" and shares["cm"] < 1e-6
    assert min(shares[u] for u in ("m", "dm", "mm")) > 1.0, shares
    # sunk 2 cm along -y (into the head): still this body's groom, by a wide margin
    assert 0.05 < root_fit_share(query_a, roots - [0.0, 0.02, 0.0]) < 0.2
    far = relative_fits(query_a, roots + [5.0, 0.0, 0.0], "m")
    assert best_fit(far) is None and min(far.values()) > 0.5, far
    # a single root: the body's size stands in for the scalp's
    body_in_mm = MeshQuery(toy_a.vertices * 1000, toy_a.faces)
    assert root_fit_share(body_in_mm, roots[:1] * 1000) < 1e-6


def _unique_rows(points: np.ndarray, limit: int) -> int:
    """The count the fit used before: a sort of the rows (np.unique)."""
    return min(len(np.unique(points.reshape(-1, 3), axis=0)), limit)


def test_distinct_rows_counts_as_a_sort_of_the_rows_did():
    from hairport.solver.body.scale import DISTINCT_PREFIX_ROWS, MIN_SCALP_ROOTS, distinct_rows

    rng = np.random.default_rng(7)
    many = DISTINCT_PREFIX_ROWS * 3
    same = np.tile([[0.1, 1.6, 0.02]], (many, 1))
    cases = {
        "none": np.zeros((0, 3)),
        "one": same[:1],
        "all at one point": same,
        "two points, the second at the end": np.vstack([same, [[0.1, 1.6, 0.03]]]),
        "three points past the prefix": np.vstack([same, [[0.1, 1.6, 0.03]], same, [[0.2, 1.6, 0.02]]]),
        "signed zeros are equal": np.array([[0.0, 0.0, 0.0], [-0.0, 0.0, -0.0], [0.0, -0.0, 0.0]]),
        "a NaN row equals none, itself included": np.array([[np.nan, 0, 0], [np.nan, 0, 0], [1.0, 2, 3]]),
        "one NaN row": np.vstack([same, [[np.nan, 0, 0]]]),
        "a grid of repeats": rng.integers(0, 2, size=(5000, 3)).astype(np.float64),
        "random": rng.normal(size=(5000, 3)),
        "float32": rng.normal(size=(100, 3)).astype(np.float32),
    }
    counted = {name: [distinct_rows(points, limit) for limit in (1, 2, MIN_SCALP_ROOTS, 10)]
               for name, points in cases.items()}
    expected = {name: [_unique_rows(points, limit) for limit in (1, 2, MIN_SCALP_ROOTS, 10)]
                for name, points in cases.items()}
    assert counted == expected
    assert counted["all at one point"] == [1, 1, 1, 1] and counted["three points past the prefix"] == [1, 2, 3, 3]
    assert counted["a NaN row equals none, itself included"] == [1, 2, 3, 3]


def test_largest_extent_is_the_bounding_box_of_every_point():
    rng = np.random.default_rng(3)
    for points in (rng.normal(size=(10_000, 3)) * [1.0, 30.0, 0.01], rng.normal(size=(7, 3)).astype(np.float32),
                   np.array([[1.0, 2.0, 3.0]]), np.array([[0.0, 0.0, 0.0], [np.nan, 1.0, 1.0]])):
        old = np.asarray(points, dtype=np.float64)
        np.testing.assert_equal(largest_extent(points), float((old.max(axis=0) - old.min(axis=0)).max()))
    assert largest_extent(np.zeros((0, 3))) == 0.0
    assert largest_extent(np.array([[0.0, 0.0, 0.0], [0.5, -2.0, 1.0]])) == 2.0
