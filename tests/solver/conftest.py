"""Fixtures shared by the solver tests: the two toy bodies and the closest-point queries of the first."""

from __future__ import annotations

import pytest

from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.character import Character
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
