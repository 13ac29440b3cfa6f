"""Fixtures shared by the solver tests: the two toy bodies and the closest-point queries of the first; the
MakeHuman average female and a 150-strand fringe groom on her."""

from __future__ import annotations

import pytest

from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.character import Character
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import PRESETS, build_character
from hairport.solver.synthetic.toy import toy_character
from tests.solver.synthetic.toy_fixtures import PRESET_B


@pytest.fixture(scope="module")
def toy_a() -> Character:
    return toy_character()


@pytest.fixture(scope="module")
def toy_b() -> Character:
    return toy_character(**PRESET_B, name="toy-b")


@pytest.fixture(scope="module")
def query_a(toy_a) -> MeshQuery:
    return MeshQuery(toy_a.vertices, toy_a.faces)


@pytest.fixture(scope="module")
def female():
    return build_character(PRESETS["average-female"])


@pytest.fixture(scope="module")
def fringe(female):
    return generate_groom(female, "fringe", 150, 24, seed=3)
