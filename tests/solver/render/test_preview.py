"""Preview pictures: panels of a front and a side view, penetrating particles in red."""

import numpy as np
import pytest
from PIL import Image

from hairport.solver.options import RetargetOptions
from hairport.solver.pipeline import preprocess, retarget
from hairport.solver.render.preview import HIGHLIGHT_COLOR, TITLE_HEIGHT_PX, render_preview, write_result_preview
from hairport.solver.synthetic import toy
from hairport.solver.synthetic.groom import generate_groom
from tests.solver.synthetic.toy_fixtures import toy_grooms


@pytest.fixture(scope="module")
def scene():
    character = toy.toy_character()
    return character, generate_groom(character, "short", 20, 6, seed=0)


def test_panels_and_size(tmp_path, scene):
    character, hair = scene
    path = render_preview(tmp_path / "a" / "p.png", [(hair, character, None, "one"), (hair, character, None, "two"),
                                                   (None, character, None, "body only")], view_size=(100, 120))
    image = Image.open(path)
    assert image.size == (3 * 2 * 100, 120 + TITLE_HEIGHT_PX)
    pixels = np.asarray(image.convert("RGB"))
    assert (pixels != 255).any(axis=2).mean() > 0.05  # something was drawn
    assert not np.all(pixels == HIGHLIGHT_COLOR, axis=2).any()


def test_highlighted_particles_are_red(tmp_path, scene):
    character, hair = scene
    mask = np.zeros(hair.n_particles, dtype=bool)
    mask[hair.n_particles // 2] = True
    pixels = np.asarray(Image.open(render_preview(tmp_path / "p.png", [(hair, character, mask, "red")],
                                                  view_size=(100, 120))).convert("RGB"))
    assert np.all(pixels == HIGHLIGHT_COLOR, axis=2).sum() >= 2


def test_bad_calls_are_refused(tmp_path, scene):
    character, hair = scene
    with pytest.raises(ValueError, match="no views"):
        render_preview(tmp_path / "p.png", [])
    with pytest.raises(ValueError, match=r"highlight mask has shape \(3,\)"):
        render_preview(tmp_path / "p.png", [(hair, character, np.zeros(3, dtype=bool), "x")])
    assert not (tmp_path / "p.png").exists()


def test_a_retarget_preview(tmp_path, scene):
    character, hair = scene
    adaptable = preprocess(character, hair)
    result = retarget(adaptable, character, RetargetOptions(method="root-translate"))
    write_result_preview(tmp_path / "r.png", adaptable, result, character)
    assert Image.open(tmp_path / "r.png").size == (2 * 2 * 360, 480 + TITLE_HEIGHT_PX)


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
