"""Drawn hairline curves: parsing, reading, checks on the head and the smoothed arc length."""

import json

import numpy as np
import pytest

from hairport.solver.hairline.curve import (
    check_curve_on_head,
    first_self_crossing,
    parse_hairline_curve,
    read_hairline_curve,
    smooth_polyline,
    smoothed_arc_length,
)
from hairport.solver.model.errors import InputError


def test_curve_parsing_converts_units_and_keeps_turning_points():
    curve = parse_hairline_curve({"units": "cm", "points": [[0, 0, 0], [1, 0, 0], [2, 1, 0], [3, 1, 0]],
                                  "turning_points": [0, 2, 3]})
    np.testing.assert_allclose(curve.points[2], [0.02, 0.01, 0.0])
    assert curve.turning_points.tolist() == [0, 2, 3]


@pytest.mark.parametrize("document, code", [
    ([1, 2, 3], "bad_curve"),
    ({"points": [[0, 0, 0], [1, 0, 0]]}, "too_few_points"),
    ({"points": [[0, 0], [1, 0], [2, 0]]}, "bad_curve"),
    ({"points": [[0, 0, 0], [1, 0, float("nan")], [2, 0, 0]]}, "non_finite"),
    ({"points": [[0, 0, 0], [0, 0, 0], [2, 0, 0]]}, "bad_curve"),
    ({"points": [[0, 0, 0], [1, 0, 0], [2, 0, 0]], "turning_points": [0, 3]}, "bad_curve"),
    ({"points": [[0, 0, 0], [1, 0, 0], [2, 0, 0]], "turning_points": [2, 1]}, "bad_curve"),
    ({"points": [[0, 0, 0], [1, 0, 0], [2, 0, 0]], "units": "ft"}, "unknown_units"),
])
def test_malformed_curves_are_refused(document, code):
    with pytest.raises(InputError) as caught:
        parse_hairline_curve(document, "new-hairline.json")
    assert caught.value.code == code and "new-hairline.json" in str(caught.value)


def test_curve_file_errors_name_the_file(tmp_path):
    bad = tmp_path / "curve.json"
    bad.write_text("{not json")
    with pytest.raises(InputError, match="curve.json: not valid JSON"):
        read_hairline_curve(bad)
    good = tmp_path / "good.json"
    good.write_text(json.dumps({"points": [[0, 0, 0], [0.01, 0, 0], [0.02, 0.005, 0]]}))
    assert read_hairline_curve(good).points.shape == (3, 3)


def test_self_crossing_and_off_head_curves_are_refused():
    zigzag = np.array([[0, 0], [2, 0], [2, 1], [1, -1]], dtype=float)  # last segment crosses the first
    assert first_self_crossing(zigzag) == (0, 2)
    arch = np.array([[0, 0], [1, 1], [2, 1.2], [3, 1], [4, 0]], dtype=float)
    assert first_self_crossing(arch) is None
    curve = parse_hairline_curve({"points": np.column_stack([zigzag, np.zeros(4)]).tolist()})
    with pytest.raises(InputError) as caught:
        check_curve_on_head(curve, np.zeros(4), zigzag)
    assert caught.value.code == "self_intersecting"
    with pytest.raises(InputError) as caught:
        check_curve_on_head(curve, np.array([0.0, 0.001, 0.05, 0.0]), arch[:4])
    assert caught.value.code == "off_head" and "point 2" in str(caught.value) and "5.0 cm" in str(caught.value)


def test_smoothing_keeps_the_ends_and_removes_a_staircase():
    # a 10 cm staircase of 5 mm steps along x, sampled twice as densely in a second copy
    corners = np.array([[0.005 * (i // 2 + i % 2), 0.005 * (i // 2), 0.0] for i in range(41)])
    dense = np.repeat(corners, 2, axis=0)[1:]
    dense[1::2] = 0.5 * (dense[:-1:2] + dense[2::2])
    for points in (corners, dense):
        smooth = smooth_polyline(points)
        np.testing.assert_array_equal(smooth[[0, -1]], points[[0, -1]])
        arc = smoothed_arc_length(points)
        assert arc[0] == 0.0 and np.all(np.diff(arc) >= 0)
        # the staircase has length 0.2 m; the diagonal it follows 0.1 * sqrt(2)
        assert arc[-1] == pytest.approx(0.1 * np.sqrt(2), rel=0.02)
    # the same arc length whatever the sampling
    assert smoothed_arc_length(corners)[-1] == pytest.approx(smoothed_arc_length(dense)[-1], rel=1e-3)
