"""The sandbox: a child under a heap limit whose input errors come back, named after the upload."""

import numpy as np
import pytest

from hairport.solver.io.sandbox import run_in_child
from hairport.solver.model.errors import InputError
from hairport.solver.synthetic import toy
from tests.solver.io.character.usd_samples import write_scene


def test_a_child_hands_back_arrays_and_its_input_errors(tmp_path):
    path = tmp_path / "toy.usda"
    write_scene(path, toy.toy_character(name="toy"))
    arguments = {"name": "upload.usda", "max_vertices": 10**6, "max_faces": 10**6, "mesh_name": None}
    found = run_in_child("hairport.solver.io.character.usd", "mesh_arrays", str(path), path.stat().st_size,
                         arguments, "upload.usda", "USD")
    assert found["vertices"].shape[1] == 3 and found["faces"].dtype == np.int64 and str(found["units"]) == "cm"
    with pytest.raises(InputError) as caught:
        run_in_child("hairport.solver.io.character.usd", "mesh_arrays", str(path), path.stat().st_size,
                     {**arguments, "max_vertices": 3}, "upload.usda", "USD")
    assert caught.value.code == "too_large" and caught.value.source == "upload.usda"


def test_an_unknown_parser_is_refused_by_the_child(tmp_path):
    with pytest.raises(InputError) as caught:
        run_in_child("os", "system", "x", 1, {}, "x", "USD")
    assert caught.value.code == "too_large"  # the child exits without running anything


def test_every_parser_the_child_may_import_is_a_module_with_one_of_its_functions():
    import importlib

    from hairport.solver.io.sandbox import FUNCTIONS, PARSERS

    found = {parser: [name for name in FUNCTIONS if callable(getattr(importlib.import_module(parser), name, None))]
             for parser in PARSERS}
    assert found == {"hairport.solver.io.hair.sandboxed": ["strands_arrays"],
                     "hairport.solver.io.character.usd": ["mesh_arrays", "mesh_frames"],
                     "hairport.solver.io.character.alembic": ["mesh_frames"]}
