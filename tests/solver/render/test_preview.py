"""Preview pictures: panels of a front and a side view, penetrating particles in red."""

import numpy as np
import pytest
from PIL import Image

from hairport.solver.render.preview import HIGHLIGHT_COLOR, TITLE_HEIGHT_PX, render_preview, write_result_preview
from hairport.solver.synthetic import toy
from hairport.solver.synthetic.groom import generate_groom


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
    from hairport.solver.options import RetargetOptions
    from hairport.solver.pipeline import preprocess, retarget

    character, hair = scene
    adaptable = preprocess(character, hair)
    result = retarget(adaptable, character, RetargetOptions(method="root-translate"))
    write_result_preview(tmp_path / "r.png", adaptable, result, character)
    assert Image.open(tmp_path / "r.png").size == (2 * 2 * 360, 480 + TITLE_HEIGHT_PX)
