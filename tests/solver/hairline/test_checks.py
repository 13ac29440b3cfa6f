"""Input checks shared by the relocation baselines and the density change: what they accept,
what they return, and their refusals (code ``bad_relocation``, the caller named)."""

import numpy as np
import pytest

from hairport.solver.hairline.checks import ERROR_CODE, check_pins, check_points, check_triangles, index_array, refuse
from hairport.solver.model.errors import InputError


def refused(call, *args, match=None):
    with pytest.raises(InputError, match=match) as caught:
        call(*args)
    assert caught.value.code == ERROR_CODE
    assert "caller" in str(caught.value)
    return caught.value


def test_refuse_builds_the_error_with_its_code():
    error = refuse("no scalp", "caller")
    assert isinstance(error, InputError) and error.code == ERROR_CODE == "bad_relocation"
    assert str(error) == "caller: no scalp"


def test_index_array():
    ids = index_array(np.array([3, 1, 2], dtype=np.uint8), 1, "seeds", "caller")
    assert ids.dtype == np.int64 and ids.tolist() == [3, 1, 2]
    assert index_array([], 1, "seeds", "caller").shape == (0,)
    assert index_array([], 2, "triangles", "caller").shape == (0, 3)
    assert index_array(np.zeros((0, 2)), 2, "triangles", "caller").dtype == np.int64
    refused(index_array, [1.0, 2.0], 1, "seeds", "caller", match="seeds must be integer ids, got dtype float64")
    refused(index_array, [[1, 2, 3]], 1, "seeds", "caller",
            match=r"seeds must have 1 dimension\(s\), got shape \(1, 3\)")


def test_check_triangles():
    triangles = check_triangles([[0, 1, 2], [2, 1, 3]], 4, "caller")
    assert triangles.dtype == np.int64 and triangles.shape == (2, 3)
    assert check_triangles(np.zeros((0, 3), np.int64), 0, "caller").shape == (0, 3)
    refused(check_triangles, [[0, 1], [1, 2]], 4, "caller", match=r"must be \(m, 3\), got shape \(2, 2\)")
    refused(check_triangles, [[0, 1, 4]], 4, "caller", match="outside 0 .. 3")
    refused(check_triangles, [[-1, 1, 2]], 4, "caller", match="outside 0 .. 3")
    refused(check_triangles, [[0.0, 1.0, 2.0]], 4, "caller", match="integer ids")


def test_check_points():
    points = check_points([[0, 1], [2, 3]], 2, "u_rest", "caller")
    assert points.dtype == np.float64 and points.tolist() == [[0.0, 1.0], [2.0, 3.0]]
    refused(check_points, np.zeros((4, 3)), 2, "u_rest", "caller", match=r"u_rest must be \(n, 2\), got shape \(4, 3\)")
    refused(check_points, np.zeros(4), 2, "u_rest", "caller", match=r"got shape \(4,\)")
    refused(check_points, [[0.0, np.inf]], 2, "u_rest", "caller", match="u_rest has non-finite values")


def test_check_pins():
    fixed, targets = check_pins([1, 0, 1], [[0.5, 0.5], [1.0, 2.0]], 3, 2, "caller")
    assert fixed.dtype == bool and fixed.tolist() == [True, False, True]
    assert targets.dtype == np.float64 and targets.shape == (2, 2)
    # nothing pinned: any empty targets become (0, dim)
    fixed, targets = check_pins(np.zeros(3, bool), [], 3, 3, "caller")
    assert not fixed.any() and targets.shape == (0, 3)
    refused(check_pins, np.ones(2, bool), np.zeros((2, 2)), 3, 2, "caller",
            match=r"fixed must be \(3,\), got shape \(2,\)")
    refused(check_pins, [True, False, True], np.zeros((1, 2)), 3, 2, "caller",
            match=r"the 2 fixed vertices need targets \(2, 2\), got shape \(1, 2\)")
    refused(check_pins, [True, False, True], [[0.0, np.nan], [0.0, 0.0]], 3, 2, "caller", match="non-finite")
