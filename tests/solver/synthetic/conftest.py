"""Fixtures of the synthetic-character tests: the MakeHuman assets (or a skip) and presets, the toy grooms."""

from __future__ import annotations

from pathlib import Path

import pytest

from hairport.solver.synthetic.groom import STYLES
from hairport.solver.synthetic.makehuman import PRESETS, build_preset
from tests.solver.synthetic.makehuman_fixtures import makehuman_assets
from tests.solver.synthetic.toy_fixtures import toy_grooms


@pytest.fixture(scope="session")
def assets() -> Path:
    return makehuman_assets()


@pytest.fixture(scope="session")
def presets(assets) -> dict:
    return {name: build_preset(name, assets) for name in PRESETS}


@pytest.fixture(scope="module")
def grooms(toy_a, query_a) -> dict:
    return toy_grooms(toy_a, query_a, STYLES)
