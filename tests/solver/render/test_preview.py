"""Tests for solver/render/preview.py: the preview image of grooms on their bodies."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.character import Character
from hairport.solver.render.preview import render_preview
from hairport.solver.synthetic.toy import toy_character
from tests.solver.synthetic.toy_fixtures import PRESET_B, toy_grooms


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
    return toy_grooms(toy_a, query_a, ("long", "curly"))


def test_render_preview(tmp_path, grooms, toy_a, toy_b, query_a):
    hair = grooms["long"]
    inside = query_a.signed_distance(hair.points).distance < 0.004
    path = render_preview(
        tmp_path / "sub" / "preview.png",
        [(hair, toy_a, inside, "source"), (grooms["curly"], toy_b, None, "other"), (None, toy_a, None, "bare")],
        view_size=(200, 260),
    )
    image = Image.open(path)
    assert image.size[0] == 3 * 2 * 200 and image.size[1] > 260
    pixels = np.asarray(image.convert("RGB")).reshape(-1, 3)
    assert ((pixels[:, 0] > 200) & (pixels[:, 1] < 60)).any()  # red highlight dots
    assert len(np.unique(pixels, axis=0)) > 20  # mesh shading and strands, not a blank image
