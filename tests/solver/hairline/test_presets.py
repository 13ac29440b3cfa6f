"""Preset hairline edits: parsing and the shapes of the preset curves on the MakeHuman head."""

import numpy as np
import pytest

from hairport.solver.hairline.curve import first_self_crossing, smoothed_arc_length
from hairport.solver.hairline.edit import HairlineEdit
from hairport.solver.hairline.presets import BAND, PRESETS, lateral_position, parse_preset, spherical
from hairport.solver.hairline.relocation import edit_curve
from hairport.solver.model.errors import InputError


def test_parse_preset():
    with pytest.raises(InputError, match="unknown hairline preset"):
        parse_preset("mohawk")
    with pytest.raises(InputError, match=r"in \[0, 1\]"):
        parse_preset("round:1.5")
    with pytest.raises(InputError, match="not a number"):
        parse_preset("round:lots")
    assert parse_preset("widows-peak") == ("widows-peak", 1.0) and parse_preset("bell:0.25") == ("bell", 0.25)


def test_preset_curves_are_valid_hairlines_of_the_expected_shape(scalp_setup):
    front = scalp_setup.rest[scalp_setup.front]
    theta, phi, _ = spherical(front, scalp_setup.frame)
    x = lateral_position(smoothed_arc_length(front), theta)
    centre, temples, band = np.abs(x) < 0.1, (np.abs(x) > 0.4) & (np.abs(x) < BAND), np.abs(x) < BAND
    sides = (np.abs(x) > 0.75) & (np.abs(x) < 0.95)
    for name in PRESETS:
        curve = edit_curve(scalp_setup, HairlineEdit(preset=name))
        assert len(curve.points) == len(front) and np.array_equal(curve.turning_points, scalp_setup.turning)
        np.testing.assert_array_equal(curve.points[[0, -1]], front[[0, -1]])
        uv, distance = scalp_setup.parameters(curve.points)
        assert distance.max() < 1e-9, name  # on the head
        assert first_self_crossing(uv) is None, name
        _, new, _ = spherical(curve.points, scalp_setup.frame)
        change = np.degrees(new - phi)
        lift = lambda where: float(np.mean(np.degrees(new)[where]))  # noqa: E731
        if name == "straight":
            assert np.std(np.degrees(new)[band]) < 0.5 * np.std(np.degrees(phi)[band])
        elif name == "widows-peak":
            assert lift(centre) < lift(temples) - 5.0  # the peak points down the forehead
        elif name == "triangular":
            assert lift(centre) > lift(temples) + 2.0
        elif name in ("round", "bell"):
            assert lift(temples) < lift(centre) - 1.0
        elif name == "m-shape":
            assert lift(temples) > lift(centre) + 3.0
        elif name == "receding":
            assert change[band].min() > 5.0  # every band point moves back by > 5 degrees
        elif name == "sideburns":
            # tongues in front of the ears; on the forehead only the staircase is smoothed
            assert change[sides].min() < -5.0 and np.abs(change[np.abs(x) < 0.5]).max() < 1.0

