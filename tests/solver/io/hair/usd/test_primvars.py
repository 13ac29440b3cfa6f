"""Attributes as USD primvars: the type name each dtype, width and role is written with."""

import numpy as np
import pytest

from hairport.solver.io.hair.usd.primvars import usd_type_name
from hairport.solver.model.hair import HairAttribute


@pytest.mark.parametrize("values, role, expected", [
    (np.zeros(3, np.float32), "", ("float[]", 1, "float32")),
    (np.zeros((3, 2), np.float32), "texcoord", ("texCoord2f[]", 1, "float32")),
    (np.zeros((3, 3), np.float64), "color", ("color3d[]", 1, "float64")),
    (np.zeros((3, 3), np.float16), "normal", ("normal3h[]", 1, "float16")),
    (np.zeros((3, 3), np.int32), "color", ("int3[]", 1, "int32")),  # no integer colours in USD
    (np.zeros((3, 2), np.float32), "normal", ("float2[]", 1, "float32")),  # no 2-D normals
    (np.zeros((3, 7), np.float64), "", ("double[]", 7, "float64")),
    (np.zeros(3, np.int16), "", ("int[]", 1, "int32")),
    (np.zeros(3, np.uint16), "", ("uint[]", 1, "uint32")),
    (np.zeros(3, bool), "", ("bool[]", 1, "bool")),
])
def test_usd_type_names(values, role, expected):
    name, size, dtype = usd_type_name(HairAttribute(values, "vertex", role))
    assert (name, size, dtype.name) == expected
