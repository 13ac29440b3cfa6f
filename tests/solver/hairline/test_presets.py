"""Preset hairline edits: parsing and the shapes of the preset curves on the MakeHuman head."""

import numpy as np
import pytest

from hairport.solver.hairline.curve import first_self_crossing, smoothed_arc_length
from hairport.solver.hairline.edit import HairlineEdit
from hairport.solver.hairline.presets import (
    BAND,
    PRESETS,
    RECEDING_M,
    TAPER_END,
    check_preset,
    lateral_position,
    parse_preset,
    preset_curve,
    preset_elevation,
    spherical,
    taper,
    unknown_preset,
)
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



def test_check_preset():
    for name in PRESETS:
        check_preset(name)
    with pytest.raises(InputError, match="unknown hairline preset 'mohawk'; expected one of straight, round") as caught:
        check_preset("mohawk")
    assert caught.value.code == "unknown_preset"
    assert unknown_preset("x").code == "unknown_preset"
    with pytest.raises(InputError) as caught:
        preset_elevation("mohawk", np.zeros(3), np.zeros(3), 0.1, 1.0)
    assert caught.value.code == "unknown_preset"


def test_lateral_position_by_hand():
    # the midline (azimuth 0) is crossed a quarter of the way along: 1 m of 4
    arc = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    theta = np.array([-1.0, 0.0, 0.5, 1.0, 1.5])
    np.testing.assert_allclose(lateral_position(arc, theta), [-1.0, 0.0, 1 / 3, 2 / 3, 1.0], rtol=0, atol=1e-15)
    with pytest.raises(InputError) as caught:
        lateral_position(arc, -theta)  # from the left ear: refused
    assert caught.value.code == "bad_scalp"


def test_taper_is_one_on_the_band_and_zero_toward_the_ears():
    x = np.array([0.0, -BAND, BAND, 0.5 * (BAND + TAPER_END), -TAPER_END, 1.0])
    np.testing.assert_allclose(taper(x), [1.0, 1.0, 1.0, 0.5, 0.0, 0.0], rtol=0, atol=1e-15)


def test_preset_elevations_by_hand():
    x = np.array([-1.0, -0.5, 0.0, 0.1, 0.5, 1.0])
    phi0 = np.array([0.1, 0.3, 0.5, 0.7, 0.2, 0.1])
    # the base level is the median elevation over |x| <= CENTRE: of 0.5 and 0.7
    straight = preset_elevation("straight", x, phi0, 0.1, 1.0)
    np.testing.assert_allclose(straight[[1, 2, 3, 4]], 0.6, rtol=0, atol=1e-15)  # inside the band
    np.testing.assert_array_equal(straight[[0, 5]], phi0[[0, 5]])  # the ends never move
    # receding raises every band point by A/R (0.7 + 0.3 (x/BAND)^2)
    receding = preset_elevation("receding", x, phi0, 0.1, 1.0)
    np.testing.assert_allclose(receding[2], 0.5 + RECEDING_M / 0.1 * 0.7, rtol=1e-15)


def test_amount_zero_gives_the_current_hairline_back(scalp_setup):
    front = scalp_setup.rest[scalp_setup.front]
    curve = preset_curve("round", 0.0, front, scalp_setup.turning, scalp_setup.frame, scalp_setup.head)
    np.testing.assert_array_equal(curve.points, front)
    np.testing.assert_array_equal(curve.turning_points, scalp_setup.turning)
