"""Fixtures of the mesh tests: the MakeHuman body."""

import numpy as np
import pytest


@pytest.fixture(scope="session")
def makehuman_body():
    """``(vertices (V, 3) float64, faces (F, 3) int64)`` of the MakeHuman "average-female" preset
    (skipped without the asset cache)."""
    from hairport.solver.synthetic.assets import fetch_makehuman_assets
    from hairport.solver.synthetic.makehuman import build_preset

    assets = fetch_makehuman_assets(offline_ok=True)
    if assets is None:
        pytest.skip("MakeHuman assets unavailable")
    character = build_preset("average-female", assets)
    return np.asarray(character.vertices, float), np.asarray(character.faces, np.int64)
