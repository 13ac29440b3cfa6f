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
