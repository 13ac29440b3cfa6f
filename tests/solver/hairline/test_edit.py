"""A requested hairline edit: validation and parsing."""

import numpy as np
import pytest

from hairport.solver.hairline.curve import HairlineCurve
from hairport.solver.hairline.edit import HairlineEdit
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
