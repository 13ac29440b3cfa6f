"""A requested hairline edit: validation with its error codes, and parsing from the CLI's and the
API's arguments."""

import json

import numpy as np
import pytest

from hairport.solver.hairline.curve import HairlineCurve
from hairport.solver.hairline.edit import (
    MIN_REFINED_TRIANGLES,
    RELOCATION_METHODS,
    HairlineEdit,
    hairline_edit,
    hairline_edit_from_request,
    unknown_method,
)
from hairport.solver.hairline.scalp import DEFAULT_MIN_TRIANGLES
from hairport.solver.model.errors import InputError
from hairport.solver.options import RetargetOptions


def test_bad_edits_are_refused():
    curve = HairlineCurve(np.eye(3), np.zeros(0, np.int64))
    for edit, message in [
        (HairlineEdit(), "exactly one"),
        (HairlineEdit(preset="round", curve=curve), "exactly one"),
        (HairlineEdit(preset="round", method="spline"), "unknown relocation method"),
        (HairlineEdit(preset="round", parameterization="cylinder"), "unknown parameterization"),
        (HairlineEdit(preset="round", min_triangles=3), "min_triangles"),
    ]:
        with pytest.raises(InputError, match=message):
            edit.validate()
    with pytest.raises(InputError, match="baseline"):
        RetargetOptions(method="global-translate", hairline=HairlineEdit(preset="round")).validate()


def refusal_code(call, *args, **kwargs):
    with pytest.raises(InputError) as caught:
        call(*args, **kwargs)
    return caught.value.code


@pytest.mark.parametrize("edit, code", [
    (HairlineEdit(), "bad_option"),
    (HairlineEdit(preset="mohawk"), "unknown_preset"),
    (HairlineEdit(preset="round", amount=1.5), "bad_option"),
    (HairlineEdit(preset="round", amount=float("nan")), "bad_option"),
    (HairlineEdit(preset="round", method="spline"), "bad_option"),
    (HairlineEdit(preset="round", parameterization="cylinder"), "bad_option"),
    (HairlineEdit(preset="round", min_triangles=MIN_REFINED_TRIANGLES - 1), "bad_option"),
])
def test_validate_refusals_carry_their_codes(edit, code):
    assert refusal_code(edit.validate) == code


def test_valid_edits_pass_and_describe_themselves():
    curve = HairlineCurve(np.eye(3), np.zeros(0, np.int64))
    for method in RELOCATION_METHODS:
        HairlineEdit(preset="round", amount=0.0, method=method, min_triangles=MIN_REFINED_TRIANGLES).validate()
    HairlineEdit(curve=curve, parameterization="arap").validate()
    assert HairlineEdit(preset="round", amount=0.5).describe() == "round:0.5"
    assert HairlineEdit(preset="widows-peak").describe() == "widows-peak:1"
    assert HairlineEdit(curve=curve).describe() == "curve"
    assert "spline" in str(unknown_method("spline")) and unknown_method("spline").code == "bad_option"


CURVE = {"units": "cm", "points": [[0, 0, 0], [1, 0, 0], [2, 1, 0]], "turning_points": [0, 2]}


def test_hairline_edit_from_a_preset_a_curve_or_a_file(tmp_path):
    edit = hairline_edit(preset="bell:0.25", method="rbf2d", parameterization="lscm")
    assert (edit.preset, edit.amount, edit.curve, edit.method, edit.parameterization) == (
        "bell", 0.25, None, "rbf2d", "lscm")
    assert edit.min_triangles == DEFAULT_MIN_TRIANGLES
    assert hairline_edit(preset="straight").amount == 1.0
    edit = hairline_edit(curve=CURVE)
    assert edit.preset is None and edit.method == "membrane" and edit.parameterization == "harmonic"
    np.testing.assert_allclose(edit.curve.points, [[0, 0, 0], [0.01, 0, 0], [0.02, 0.01, 0]], rtol=0, atol=1e-15)
    assert edit.curve.turning_points.tolist() == [0, 2]
    path = tmp_path / "curve.json"
    path.write_text(json.dumps(CURVE))
    np.testing.assert_array_equal(hairline_edit(curve_path=path).curve.points, edit.curve.points)


def test_hairline_edit_refusals():
    assert refusal_code(hairline_edit) == "bad_option"  # none given
    assert refusal_code(hairline_edit, preset="round", curve=CURVE) == "bad_option"  # two given
    assert refusal_code(hairline_edit, preset="mohawk") == "unknown_preset"
    assert refusal_code(hairline_edit, preset="round:2") == "bad_option"
    assert refusal_code(hairline_edit, preset="round", method="spline") == "bad_option"
    assert refusal_code(hairline_edit, curve={"points": [[0, 0, 0]]}) == "too_few_points"


def test_hairline_edit_from_the_api_document():
    edit = hairline_edit_from_request({"preset": "round", "amount": 0.5})
    assert (edit.preset, edit.amount, edit.method, edit.parameterization) == ("round", 0.5, "membrane", "harmonic")
    assert hairline_edit_from_request({"preset": "round"}).amount == 1.0
    edit = hairline_edit_from_request({"curve": CURVE, "method": "harmonic", "parameterization": "arap"})
    assert edit.curve is not None and (edit.method, edit.parameterization) == ("harmonic", "arap")
    assert refusal_code(hairline_edit_from_request, {}) == "bad_option"
    assert refusal_code(hairline_edit_from_request, {"preset": "mohawk"}) == "unknown_preset"
    assert refusal_code(hairline_edit_from_request, {"preset": "round", "amount": 2}) == "bad_option"
    assert refusal_code(hairline_edit_from_request, {"preset": "round", "curve": CURVE}) == "bad_option"
