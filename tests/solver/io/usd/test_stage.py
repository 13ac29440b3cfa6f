"""USD stages: the unit a metersPerUnit names, and clear errors for stages that cannot be read."""

import pytest
from pxr import Usd, UsdGeom

from hairport.solver.io.hair.common import ReadContext, ReadLimits
from hairport.solver.io.usd.stage import open_stage, stage_units, unit_of
from hairport.solver.model.errors import InputError

CTX = ReadContext("s.usda", ReadLimits(), "m")


def test_units_named_by_metres_per_unit():
    assert [unit_of(value) for value in (1.0, 0.1, 0.01, 0.001, 0.0254)] == ["m", "dm", "cm", "mm", None]
    assert unit_of(0.01 * (1 + 1e-9)) == "cm"


def test_unreadable_stages_and_units_are_input_errors(tmp_path):
    (tmp_path / "bad.usda").write_text("#usda 1.0\n(((")
    with pytest.raises(InputError) as caught:
        open_stage(str(tmp_path / "bad.usda"), CTX)
    assert caught.value.code == "bad_header"
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageMetersPerUnit(stage, 0.3048)
    with pytest.raises(InputError, match="metersPerUnit 0.3048"):
        stage_units(stage, CTX)
