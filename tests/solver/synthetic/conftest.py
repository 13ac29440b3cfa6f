"""Fixtures of the synthetic-character tests: the MakeHuman assets (or a skip) and presets, the toys and their grooms."""

from __future__ import annotations

from pathlib import Path

import pytest

from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.character import Character
from hairport.solver.synthetic.groom import STYLES
from hairport.solver.synthetic.makehuman import PRESETS, build_preset
from hairport.solver.synthetic.toy import toy_character
from tests.solver.synthetic.makehuman_fixtures import makehuman_assets
from tests.solver.synthetic.toy_fixtures import PRESET_B, toy_grooms


@pytest.fixture(scope="session")
def assets() -> Path:
    return makehuman_assets()


@pytest.fixture(scope="session")
def presets(assets) -> dict:
    return {name: build_preset(name, assets) for name in PRESETS}


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
def grooms(toy_a, query_a) -> dict:
    return toy_grooms(toy_a, query_a, STYLES)
