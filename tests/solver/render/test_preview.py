"""Preview pictures: panels of a front and a side view, two panels a row, one scale for all, lit hair,
penetrating particles in red."""

import numpy as np
import pytest
from PIL import Image

from hairport.solver.model.character import Character
from hairport.solver.model.hair import Hair
from hairport.solver.options import RetargetOptions
from hairport.solver.pipeline import preprocess, retarget
from hairport.solver.render.preview import (
    HIGHLIGHT_COLOR,
    LABEL_FONT_PX,
    MAX_ITEMS_PER_ROW,
    TITLE_FONT_PX,
    TITLE_HEIGHT_PX,
    VIEW_SIZE_PX,
    preview_layout,
    render_preview,
    write_result_preview,
)
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
    # two panels a row: the third starts a second row
    assert image.size == (2 * 2 * 100, 2 * (120 + TITLE_HEIGHT_PX)) == preview_layout(3, (100, 120))[2]
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
    assert Image.open(tmp_path / "r.png").size == (2 * 2 * VIEW_SIZE_PX[0], VIEW_SIZE_PX[1] + TITLE_HEIGHT_PX)


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
    assert image.size == (2 * 2 * 200, 2 * (260 + TITLE_HEIGHT_PX))
    pixels = np.asarray(image.convert("RGB")).reshape(-1, 3)
    assert ((pixels[:, 0] > 200) & (pixels[:, 1] < 60)).any()  # red highlight dots
    assert len(np.unique(pixels, axis=0)) > 20  # mesh shading and strands, not a blank image


def body_mask(pixels: np.ndarray) -> np.ndarray:
    """(H, W) bool: the grey body of a view (no hue, not the white background), below the view's label
    and above the panel's bottom line."""
    pixels = pixels.astype(np.float64)
    mask = (np.ptp(pixels, axis=2) < 12) & (pixels.mean(axis=2) < 250)
    mask[:LABEL_FONT_PX + 10] = mask[-1] = False
    return mask


def view_pixels(png, item: int, view: int, view_size) -> np.ndarray:
    """The pixels of one view (0 front, 1 side) of one item of a picture of several items."""
    width, height = view_size
    _, (panel_w, panel_h), _ = preview_layout(item + 1, view_size)
    x = (item % MAX_ITEMS_PER_ROW) * panel_w + view * width
    y = (item // MAX_ITEMS_PER_ROW) * panel_h + TITLE_HEIGHT_PX
    with Image.open(png) as image:
        return np.asarray(image.convert("RGB"))[y:y + height, x:x + width]


def test_every_panel_has_one_scale_so_a_bigger_body_looks_bigger(tmp_path):
    """The same body is drawn at the same pixels in every panel, whatever hair it carries, and a body
    1.25 times as large is drawn 1.25 times as tall: one framing for all panels."""
    small = toy.toy_character()
    feet = small.vertices[:, 1].min()
    scaled = small.vertices.copy()
    scaled[:, 1] = feet + 1.25 * (scaled[:, 1] - feet)
    scaled[:, [0, 2]] *= 1.25
    big = Character(scaled, small.faces, name="big")
    size = (160, 320)  # the width sets the scale: room above and below the bodies
    path = render_preview(tmp_path / "scale.png", [(None, small, None, "small"), (None, big, None, "big"),
                                                   (None, small, None, "small again")], view_size=size)
    masks = [body_mask(view_pixels(path, item, 0, size)) for item in range(3)]
    assert np.array_equal(masks[0], masks[2])
    rows = [np.flatnonzero(mask.any(axis=1)) for mask in masks]
    heights = [r[-1] - r[0] + 1 for r in rows[:2]]
    assert rows[0][-1] == rows[1][-1]  # both stand on the same floor line
    assert abs(heights[1] / heights[0] - 1.25) < 0.03, heights
    # framed on the hair, the body with hair and the bare body still match wherever no hair covers it
    hair = generate_groom(small, "short", 30, 6, seed=1)
    path = render_preview(tmp_path / "hair.png", [(None, small, None, "bare"), (hair, small, None, "hair")],
                          view_size=size)
    bare, haired = (view_pixels(path, item, 0, size) for item in range(2))
    hair_pixels = np.ptp(haired.astype(float), axis=2) >= 12
    differ = body_mask(bare) != body_mask(haired)
    assert hair_pixels.sum() > 50 and differ.sum() < 0.03 * body_mask(bare).sum(), (differ.sum(), hair_pixels.sum())


def line_hair(z: float, y: float = 0.35) -> Hair:
    """One horizontal strand of 5 particles at height ``y`` and depth ``z`` (m)."""
    points = np.stack([np.linspace(-0.08, 0.08, 5), np.full(5, y), np.full(5, z)], axis=1)
    return Hair(points, np.array([0, 5]))


def test_strands_behind_the_body_are_hidden_and_in_front_are_lit(tmp_path):
    character = toy.toy_character()
    head_y = np.percentile(character.vertices[:, 1], 95)
    size = (160, 200)
    front, back = line_hair(character.vertices[:, 2].max() + 0.02, head_y), line_hair(
        character.vertices[:, 2].min() - 0.02, head_y)
    path = render_preview(tmp_path / "depth.png", [(front, character, None, "front"), (back, character, None, "back"),
                                                  (None, character, None, "none")], view_size=size)
    hue = [np.ptp(view_pixels(path, item, 0, size).astype(float), axis=2) >= 12 for item in range(3)]
    assert hue[0].sum() > 20 and hue[2].sum() == 0
    # behind the head the strand shows only where it sticks out left and right of it
    assert 0 < hue[1].sum() < 0.8 * hue[0].sum()


def test_hair_is_shaded_not_one_flat_colour(tmp_path, grooms, toy_a):
    path = render_preview(tmp_path / "lit.png", [(grooms["long"], toy_a, None, "long")], view_size=(200, 260))
    pixels = view_pixels(path, 0, 0, (200, 260)).astype(float)
    hair = np.ptp(pixels, axis=2) >= 20
    brightness = pixels[hair].mean(axis=1)
    assert hair.sum() > 500
    assert np.percentile(brightness, 90) - np.percentile(brightness, 10) > 25


def test_titles_are_large_enough_to_read(tmp_path, scene):
    character, hair = scene
    path = render_preview(tmp_path / "t.png", [(hair, character, None, "Hg title")], view_size=(200, 200))
    with Image.open(path) as image:
        bar = np.asarray(image.convert("L"))[:TITLE_HEIGHT_PX, :200]
    ink = np.flatnonzero((bar < 100).any(axis=1))
    # the letters span most of the font size (Pillow's fixed bitmap font is 11 px whatever is asked)
    assert ink[-1] - ink[0] + 1 >= 0.7 * TITLE_FONT_PX >= 15
