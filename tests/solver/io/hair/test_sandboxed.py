"""Hair readers in the sandbox's child: strands to arrays and back, and only the known parsers."""

import numpy as np
import pytest

from hairport.solver.io.hair.common import Strands
from hairport.solver.io.hair.sandboxed import strands_arrays, strands_of


def test_strands_come_back_from_their_arrays_with_attributes(monkeypatch, tmp_path):
    strands = Strands(np.arange(12.0).reshape(4, 3), np.array([2, 2]), np.ones(4), None, ["a note"])
    strands.add_attribute("ns:id", np.array([5, 6], np.int16), "strand")
    strands.add_attribute("uv", np.zeros((4, 2), np.float32), "vertex", "texcoord")
    import hairport.solver.io.hair.usd as usd

    monkeypatch.setattr(usd, "parse_file", lambda source, ctx: strands)
    back = strands_of(strands_arrays(str(tmp_path / "x.usda"), "hairport.solver.io.hair.usd", "x.usda", "m", 10, 10))
    np.testing.assert_array_equal(back.points, strands.points)
    assert back.color is None and back.warnings == ["a note"]
    assert [(name, a.domain, a.role, a.values.dtype.name) for name, a in back.attributes.items()] == [
        ("ns:id", "strand", "", "int16"), ("uv", "vertex", "texcoord", "float32")]


def test_only_the_known_parsers_run():
    with pytest.raises(ValueError, match="unknown hair parser"):
        strands_arrays("x", "os", "x", "m", 1, 1)


def test_every_known_hair_parser_is_a_module_with_parse_file():
    import importlib

    from hairport.solver.io.hair.sandboxed import HAIR_PARSERS

    assert HAIR_PARSERS == ("hairport.solver.io.hair.usd", "hairport.solver.io.hair.alembic")
    assert all(callable(importlib.import_module(parser).parse_file) for parser in HAIR_PARSERS)
