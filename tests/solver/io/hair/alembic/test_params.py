"""Alembic geometry parameters: which dtypes are written as they are, narrowed, or refused."""

import numpy as np
import pytest

pytest.importorskip("alembic3d")

from hairport.solver.io.hair.alembic.params import imath_array, numpy_copy, writable_dtype  # noqa: E402


@pytest.mark.parametrize("values, expected", [
    (np.zeros(2, np.float32), "float32"), (np.zeros(2, np.float64), "float64"), (np.zeros(2, np.int16), "int16"),
    (np.zeros(2, bool), "bool"), (np.zeros(2, np.float16), "float32"), (np.array([1, -5], np.int64), "int32"),
    (np.array([1, 2**40], np.int64), None), (np.array([2**63], np.uint64), None),
])
def test_writable_dtypes(values, expected):
    dtype = writable_dtype(values)
    assert (None if dtype is None else dtype.name) == expected


@pytest.mark.parametrize("type_name, values", [
    ("V3fArray", np.arange(12, dtype=np.float32).reshape(4, 3)), ("IntArray", np.array([3, -1, 7], np.int32)),
    ("ShortArray", np.array([1, -2], np.int16)), ("BoolArray", np.array([True, False, True])),
])
def test_imath_arrays_hold_exactly_what_they_were_filled_with(type_name, values):
    assert np.array_equal(numpy_copy(imath_array(values, type_name)).astype(values.dtype), values)
