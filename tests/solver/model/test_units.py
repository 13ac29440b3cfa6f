"""Length units: meters per unit, and unknown units refused."""

import pytest

from hairport.solver.model.errors import InputError
from hairport.solver.model.units import METERS_PER_UNIT, UNITS, unit_scale


def test_scales():
    assert UNITS == tuple(METERS_PER_UNIT) == ("m", "dm", "cm", "mm")
    assert [unit_scale(u) for u in UNITS] == [1.0, 0.1, 0.01, 0.001]
    with pytest.raises(InputError) as refused:
        unit_scale("ft")
    assert "expected one of m, dm, cm, mm" in str(refused.value)
