"""Several curves prims or objects: the ones asked for, joined into one set of strands."""

import numpy as np
import pytest

from hairport.solver.io.hair.common import ReadContext, ReadLimits
from hairport.solver.io.hair.curves import CurvesPart, chosen_prims, join_parts
from hairport.solver.model.errors import InputError

CTX = ReadContext("g.usda", ReadLimits(), "m")


def part(n_curves: int, thickness: bool, attributes: dict) -> CurvesPart:
    points = np.arange(n_curves * 6.0).reshape(-1, 3)
    return CurvesPart(points, np.full(n_curves, 2), np.ones(len(points)) if thickness else None, None, attributes,
                      [f"note {n_curves}"])


def test_parts_join_and_what_some_lack_is_named():
    first = part(1, True, {"id": (np.array([4], np.int32), "strand", ""), "x": (np.zeros(2), "vertex", "")})
    second = part(2, False, {"id": (np.array([5, 6], np.int32), "strand", ""), "x": (np.zeros(4, np.float32), "vertex", "")})
    strands = join_parts([first, second], "prims", ("widths", "displayColor", "primvar"))
    assert strands.counts.tolist() == [2, 2, 2] and strands.thickness is None
    assert strands.attributes["id"].values.tolist() == [4, 5, 6] and "x" not in strands.attributes
    assert strands.warnings == ["note 1", "note 2", "widths on some prims only: dropped",
                                "primvar 'x' has different types or domains on different prims: not kept"]


def test_prims_are_chosen_by_name_or_path():
    names = [["a", "/g/a"], ["b", "/g/b"]]
    assert chosen_prims(["A", "B"], names, "prim", CTX) == ["A", "B"]
    asked = ReadContext("g.usda", ReadLimits(), "m", "/g/b")
    assert chosen_prims(["A", "B"], names, "prim", asked) == ["B"]
    with pytest.raises(InputError, match="the file has '/g/a', '/g/b'") as caught:
        chosen_prims(["A", "B"], names, "prim", ReadContext("g.usda", ReadLimits(), "m", "c"))
    assert caught.value.code == "unknown_prim"
