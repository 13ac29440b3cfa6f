"""Quick orthographic preview images of hairstyles on characters (Pillow only).

Each item ``(hair, character, highlight_mask, title)`` becomes a panel with two views side
by side: *front* (looking along -Z at the face; screen right = the character's left, +X)
and *side* (seen from the character's right, -X; screen right = +Z, the face points
right). Panels fill rows of ``MAX_ITEMS_PER_ROW`` (two: four views in a row read at a
README's width). The mesh is drawn as shaded light-grey triangles in painter's order (back
faces culled); strands as lit, depth-cued, anti-aliased hair hidden where the body covers
them (:mod:`.strands`); highlighted particles (e.g. penetrating ones) as red dots on top of
everything. Views are drawn at ``SUPERSAMPLE`` times their size and reduced (smooth
silhouettes, thin strands).

All items share one scale and framing (the bounding box of all hair, or of the meshes when
there is no hair): the same body is drawn at the same pixels in every panel, and a source
next to a bigger target shows their real difference in size.

Speed: numpy work proportional to the strands' projected length, plus one Pillow polygon
call per visible triangle, once per character and view; above ``MAX_PREVIEW_STRANDS``
strands a seeded random subset of strands is drawn (highlighted particles are always all
drawn). The demo's four panels of 3,000 long strands on MakeHuman bodies take 1.2-1.5 s on
2 cores.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from hairport.solver.adaptable import AdaptableHairstyle
from hairport.solver.model.character import Character
from hairport.solver.model.hair import Hair, particle_indices
from hairport.solver.pipeline import RetargetResult, penetrating_mask
from hairport.solver.render.strands import hair_layer

#: panel size of one view in pixels (width, height): two panels of two views make a
#: 1200 px row, shown at about 900 px in a README without losing the strands
VIEW_SIZE_PX = (300, 400)
#: views are drawn this many times larger and reduced (anti-aliasing)
SUPERSAMPLE = 2
#: at most this many strands are drawn per item (a seeded random subset above it)
MAX_PREVIEW_STRANDS = 4000
#: font sizes (px) of the panel titles and of the view labels: at 3/4 of the picture's
#: size (a README's width) they read as 17 and 13 px text
TITLE_FONT_PX = 22
LABEL_FONT_PX = 17
#: height of the title bar in pixels (the title's font and a margin)
TITLE_HEIGHT_PX = TITLE_FONT_PX + 12
#: items per row of the output image
MAX_ITEMS_PER_ROW = 2
#: margin around the framed content, as a fraction of its size, plus a fixed margin (m)
FRAME_MARGIN_FRACTION = 0.15
FRAME_MARGIN_M = 0.03
#: radius of highlight dots in pixels
HIGHLIGHT_RADIUS_PX = 1

BACKGROUND = (255, 255, 255)
TITLE_COLOR = (20, 20, 20)
LABEL_COLOR = (120, 120, 120)
SEPARATOR_COLOR = (200, 200, 200)
MESH_LIGHT = np.array([236.0, 236.0, 236.0])
MESH_DARK = np.array([150.0, 150.0, 156.0])
#: hair without colours of its own: a mid brown, each strand 0.7-1.3 times as bright
HAIR_COLOR = np.array([88.0, 56.0, 33.0])
STRAND_BRIGHTNESS = (0.7, 1.3)
HIGHLIGHT_COLOR = np.array([230, 20, 20], dtype=np.uint8)

# (screen u axis, screen v axis, toward-camera axis) per view, as world unit vectors
_VIEWS = {
    "front": (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])),
    "side": (np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]), np.array([-1.0, 0.0, 0.0])),
}

PreviewItem = tuple["Hair | None", "Character | None", "np.ndarray | None", str]


def render_preview(
    path: str | Path,
    views: Sequence[PreviewItem],
    *,
    view_size: tuple[int, int] = VIEW_SIZE_PX,
    max_strands: int = MAX_PREVIEW_STRANDS,
    seed: int = 0,
) -> Path:
    """Write a PNG with a front and a side view per item.

    Parameters
    ----------
    path : str or Path
        Output PNG file (parent directories are created).
    views : sequence of (hair, character, highlight_mask, title)
        ``hair`` : Hair or None; ``character`` : Character or None; ``highlight_mask`` :
        (N,) bool over the hair's particles, or None; ``title`` : str.
    view_size : (2,) int
        Pixels (width, height) of one view.
    max_strands : int
        Strands drawn per item at most (seeded random subset above it).
    seed : int
        Seed of that subset and of the strands' shades.

    Returns
    -------
    path : Path
    """
    path = Path(path)
    if not views:
        raise ValueError("render_preview: no views given")
    for hair, _, highlight, _ in views:
        if highlight is not None and hair is not None and np.shape(highlight) != (hair.n_particles,):
            raise ValueError(f"highlight mask has shape {np.shape(highlight)}, expected ({hair.n_particles},)")
    width, height = int(view_size[0]), int(view_size[1])
    centre, half = _frame(views)
    scale = min(width / (2.0 * half[0]), height / (2.0 * half[1]))  # pixels per meter

    per_row, (panel_w, panel_h), size = preview_layout(len(views), (width, height))
    canvas = Image.new("RGB", size, BACKGROUND)
    draw = ImageDraw.Draw(canvas)
    title_font, label_font = _font(TITLE_FONT_PX), _font(LABEL_FONT_PX)
    meshes = {}  # one rasterisation per character and view: panels share the framing
    for item_index, (hair, character, highlight, title) in enumerate(views):
        px = (item_index % per_row) * panel_w
        py = (item_index // per_row) * panel_h
        if highlight is not None:
            highlight = np.asarray(highlight, dtype=bool)
        for view_index, view in enumerate(("front", "side")):
            if character is not None and (id(character), view) not in meshes:
                meshes[id(character), view] = _rasterize_mesh(character, view, centre, SUPERSAMPLE * scale,
                                                              SUPERSAMPLE * width, SUPERSAMPLE * height)
            mesh = meshes.get((id(character), view))
            image = _render_view(view, hair, mesh, highlight, centre, scale, width, height, max_strands, seed)
            canvas.paste(image, (px + view_index * width, py + TITLE_HEIGHT_PX))
            draw.text((px + view_index * width + 6, py + TITLE_HEIGHT_PX + 4), view, fill=LABEL_COLOR, font=label_font)
        draw.text((px + 6, py + (TITLE_HEIGHT_PX - TITLE_FONT_PX) // 2), str(title), fill=TITLE_COLOR, font=title_font)
        draw.line([(px + panel_w - 1, py), (px + panel_w - 1, py + panel_h)], fill=SEPARATOR_COLOR)
        draw.line([(px, py + panel_h - 1), (px + panel_w, py + panel_h - 1)], fill=SEPARATOR_COLOR)
    path.parent.mkdir(parents=True, exist_ok=True)
    canvas.save(path)
    return path


def preview_layout(n_items: int, view_size: tuple[int, int] = VIEW_SIZE_PX):
    """Where the panels of ``n_items`` items go.

    Returns
    -------
    per_row : int
        Items per row.
    panel : (2,) int
        Pixels (width, height) of one item's panel (two views under a title bar).
    size : (2,) int
        Pixels (width, height) of the whole picture.
    """
    width, height = int(view_size[0]), int(view_size[1])
    per_row = max(1, min(n_items, MAX_ITEMS_PER_ROW))
    n_rows = -(-n_items // per_row)
    panel = (2 * width, height + TITLE_HEIGHT_PX)
    return per_row, panel, (per_row * panel[0], n_rows * panel[1])


def _font(size: int):
    """Pillow's own scalable font (Aileron, shipped inside Pillow) at ``size`` pixels: no system font
    needed (a Pillow built without FreeType falls back to its small bitmap font)."""
    return ImageFont.load_default(size=size)


def _frame(views: Sequence[PreviewItem]) -> tuple[np.ndarray, np.ndarray]:
    """World centre (3,) and half-extents (2,) (screen u, v; u shared by x and z) to show."""
    boxes = [(h.points.min(0), h.points.max(0)) for h, _, _, _ in views if h is not None and h.n_particles]
    if not boxes:
        boxes = [(c.vertices.min(0), c.vertices.max(0)) for _, c, _, _ in views if c is not None]
    if not boxes:
        return np.zeros(3), np.array([1.0, 1.0])
    lo = np.min([b[0] for b in boxes], axis=0)
    hi = np.max([b[1] for b in boxes], axis=0)
    centre = 0.5 * (lo + hi)
    size = hi - lo
    half_u = 0.5 * max(size[0], size[2]) * (1 + FRAME_MARGIN_FRACTION) + FRAME_MARGIN_M
    half_v = 0.5 * size[1] * (1 + FRAME_MARGIN_FRACTION) + FRAME_MARGIN_M
    return centre, np.array([half_u, half_v])


def _project(points: np.ndarray, view: str, centre: np.ndarray, scale: float, width: int, height: int):
    """Pixel coordinates (n, 2) and depth (n,) (larger = closer to the camera)."""
    u_axis, v_axis, toward = _VIEWS[view]
    rel = points - centre
    pixel = np.stack([width / 2.0 + (rel @ u_axis) * scale, height / 2.0 - (rel @ v_axis) * scale], axis=1)
    return pixel, rel @ toward


def _render_view(view, hair, mesh, highlight, centre, scale, width, height, max_strands, seed) -> Image.Image:
    """One view (width x height), drawn at ``SUPERSAMPLE`` times the size and reduced; ``mesh`` is
    :func:`_rasterize_mesh` of the character at that size, or None."""
    big_w, big_h, big_scale = width * SUPERSAMPLE, height * SUPERSAMPLE, scale * SUPERSAMPLE
    image = np.empty((big_h, big_w, 3), dtype=np.float32)
    image[:] = BACKGROUND
    surface = np.full((big_h, big_w), -np.inf)
    if mesh is not None:
        face_id, plane, shade = mesh
        covered = face_id >= 0
        image[covered] = shade[face_id[covered]]
        y, x = np.nonzero(covered)
        f = face_id[covered]
        surface[covered] = plane[f, 0] * x + plane[f, 1] * y + plane[f, 2]
    if hair is not None and hair.n_particles:
        points, counts, base = _strands(hair, max_strands, seed)
        pixel, depth = _project(points, view, centre, big_scale, big_w, big_h)
        color, alpha = hair_layer(points, counts, base, pixel, depth, _VIEWS[view], surface)
        image += alpha[..., None] * (color - image)
    pil = Image.fromarray(np.clip(np.round(image), 0, 255).astype(np.uint8)).reduce(SUPERSAMPLE)
    if hair is not None and highlight is not None and highlight.any():
        array = np.asarray(pil).copy()
        pixel, _ = _project(hair.points[highlight], view, centre, scale, width, height)
        ij = np.round(pixel).astype(np.int64)
        r = HIGHLIGHT_RADIUS_PX
        for dx in range(-r, r + 1):
            for dy in range(-r, r + 1):
                x, y = ij[:, 0] + dx, ij[:, 1] + dy
                ok = (x >= 0) & (x < width) & (y >= 0) & (y < height)
                array[y[ok], x[ok]] = HIGHLIGHT_COLOR
        pil = Image.fromarray(array)
    return pil


def _strands(hair: Hair, max_strands: int, seed: int):
    """The strands drawn: their points (n, 3), counts (k,) and colour (n, 3) 0-255 (the hair's own
    colours, else ``HAIR_COLOR`` with a seeded brightness per strand)."""
    strand_ids = np.arange(hair.n_strands)
    if hair.n_strands > max_strands:
        strand_ids = np.sort(np.random.default_rng(seed).choice(hair.n_strands, max_strands, replace=False))
    index = particle_indices(hair.offsets, strand_ids)
    counts = hair.counts[strand_ids]
    if hair.color is not None:
        base = np.clip(hair.color[index] * 255.0, 0, 255)
    else:
        brightness = np.random.default_rng(seed + 1).uniform(*STRAND_BRIGHTNESS, hair.n_strands)[strand_ids]
        base = HAIR_COLOR[None] * np.repeat(brightness, counts)[:, None]
    return hair.points[index], counts, base


def _rasterize_mesh(character: Character, view, centre, scale, width, height):
    """Painter's-order face-id image (H, W) int64 (-1 = background), depth planes and face shades.

    Returns
    -------
    face_id : (H, W) int64
    plane : (F, 3) float64
        Depth of face f at pixel (x, y) is ``plane[f, 0] * x + plane[f, 1] * y + plane[f, 2]``.
    shade : (F, 3) uint8
    """
    _, _, toward = _VIEWS[view]
    vertices, faces = character.vertices, character.faces
    pixel, depth = _project(vertices, view, centre, scale, width, height)
    corners = vertices[faces]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    norm = np.linalg.norm(normal, axis=1)
    facing = (normal @ toward) / np.where(norm > 0, norm, 1.0)
    p = pixel[faces]  # (F, 3, 2)
    inside = (p[..., 0].max(1) >= 0) & (p[..., 0].min(1) < width) & (p[..., 1].max(1) >= 0) & (p[..., 1].min(1) < height)
    keep = np.flatnonzero((facing > 0) & inside)
    face_depth = depth[faces].mean(1)
    order = keep[np.argsort(face_depth[keep], kind="stable")]  # far first

    ids = Image.new("I", (width, height), 0)
    draw = ImageDraw.Draw(ids)
    flat = p[order].reshape(len(order), 6).tolist()
    for f, xy in zip((order + 1).tolist(), flat):
        draw.polygon(xy, fill=f)
    face_id = np.asarray(ids, dtype=np.int64) - 1

    # depth plane of every face in pixel coordinates: solve [x y 1] @ plane = depth per corner
    a = np.concatenate([p, np.ones(p.shape[:2] + (1,))], axis=2)  # (F, 3, 3)
    d = depth[faces]
    plane = np.zeros((len(faces), 3))
    det = np.linalg.det(a)
    good = np.abs(det) > 1e-9
    plane[good] = np.linalg.solve(a[good], d[good][..., None])[..., 0]
    plane[~good, 2] = face_depth[~good]

    light = np.clip(facing, 0.0, 1.0)[:, None]
    shade = (MESH_LIGHT - MESH_DARK) * light + MESH_DARK
    return face_id, plane, shade.astype(np.uint8)


def write_result_preview(path: str | Path, adaptable: AdaptableHairstyle, result: RetargetResult,
                         target: Character) -> None:
    """PNG of a retarget: the source hairstyle on the source next to the result on the target, with
    the result's particles inside the target in red."""
    render_preview(path, [
        (adaptable.hair, adaptable.source, None, "source"),
        (result.hair, target, penetrating_mask(result.hair, target) if result.inside is None else result.inside,
         f"result ({result.metrics['method']})"),
    ])
