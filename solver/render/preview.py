"""Quick orthographic preview images of hairstyles on characters (Pillow only).

Each item ``(hair, character, highlight_mask, title)`` becomes a panel with two views side
by side: *front* (looking along -Z at the face; screen right = the character's left, +X)
and *side* (seen from the character's right, -X; screen right = +Z, the face points
right). The mesh is drawn as shaded light-grey triangles in painter's order (back faces
culled); strands as dark polylines, hidden where the body covers them; highlighted
particles (e.g. penetrating ones) as red dots on top of everything.

All items share one scale and framing (the bounding box of all hair, or of the meshes when
there is no hair) so that source and result can be compared pixel for pixel.

Speed: drawing polylines is a Python loop over strand pieces, acceptable for previews
only; above ``MAX_PREVIEW_STRANDS`` strands a seeded random subset of strands is drawn
(highlighted particles are always all drawn). 10^5 particles render in well under 2 s.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np
from PIL import Image, ImageDraw

from hairport.solver.adaptable import AdaptableHairstyle
from hairport.solver.model.character import Character
from hairport.solver.model.hair import Hair, particle_indices
from hairport.solver.pipeline import RetargetResult, penetrating_mask

#: panel size of one view in pixels (width, height)
VIEW_SIZE_PX = (360, 480)
#: at most this many strands are drawn per item (a seeded random subset above it)
MAX_PREVIEW_STRANDS = 3000
#: height of the title bar in pixels
TITLE_HEIGHT_PX = 18
#: items per row of the output image
MAX_ITEMS_PER_ROW = 4
#: margin around the framed content, as a fraction of its size, plus a fixed margin (m)
FRAME_MARGIN_FRACTION = 0.15
FRAME_MARGIN_M = 0.03
#: a particle counts as visible when it lies at most this far (m) behind the visible surface
VISIBILITY_TOLERANCE_M = 0.004
#: radius of highlight dots in pixels
HIGHLIGHT_RADIUS_PX = 1

BACKGROUND = (255, 255, 255)
MESH_LIGHT = np.array([236.0, 236.0, 236.0])
MESH_DARK = np.array([150.0, 150.0, 156.0])
HAIR_COLOR = np.array([70.0, 45.0, 25.0])
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
        Seed of that subset.

    Returns
    -------
    path : Path
    """
    path = Path(path)
    if not views:
        raise ValueError("render_preview: no views given")
    width, height = int(view_size[0]), int(view_size[1])
    centre, half = _frame(views)
    scale = min(width / (2.0 * half[0]), height / (2.0 * half[1]))  # pixels per meter

    n_items = len(views)
    per_row = min(n_items, MAX_ITEMS_PER_ROW)
    n_rows = -(-n_items // per_row)
    panel_w, panel_h = 2 * width, height + TITLE_HEIGHT_PX
    canvas = Image.new("RGB", (per_row * panel_w, n_rows * panel_h), BACKGROUND)
    for item_index, item in enumerate(views):
        hair, character, highlight, title = item
        if highlight is not None and hair is not None:
            highlight = np.asarray(highlight, dtype=bool)
            if highlight.shape != (hair.n_particles,):
                raise ValueError(f"highlight mask has shape {highlight.shape}, expected ({hair.n_particles},)")
        px = (item_index % per_row) * panel_w
        py = (item_index // per_row) * panel_h
        draw = ImageDraw.Draw(canvas)
        draw.text((px + 4, py + 3), str(title), fill=(0, 0, 0))
        for view_index, view in enumerate(("front", "side")):
            image = _render_view(view, hair, character, highlight, centre, scale, width, height, max_strands, seed)
            canvas.paste(image, (px + view_index * width, py + TITLE_HEIGHT_PX))
            ImageDraw.Draw(canvas).text((px + view_index * width + 4, py + TITLE_HEIGHT_PX + 2), view, fill=(120, 120, 120))
        draw = ImageDraw.Draw(canvas)
        draw.line([(px + panel_w - 1, py), (px + panel_w - 1, py + panel_h)], fill=(200, 200, 200))
    path.parent.mkdir(parents=True, exist_ok=True)
    canvas.save(path)
    return path


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


def _render_view(view, hair, character, highlight, centre, scale, width, height, max_strands, seed) -> Image.Image:
    image = np.empty((height, width, 3), dtype=np.uint8)
    image[:] = BACKGROUND
    face_id = np.full((height, width), -1, dtype=np.int64)
    plane = None
    if character is not None:
        face_id, plane, shade = _rasterize_mesh(character, view, centre, scale, width, height)
        covered = face_id >= 0
        image[covered] = shade[face_id[covered]]
    pil = Image.fromarray(image)
    if hair is not None and hair.n_particles:
        _draw_strands(pil, hair, view, centre, scale, width, height, face_id, plane, max_strands, seed)
        if highlight is not None and highlight.any():
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
    shade = (MESH_DARK + (MESH_LIGHT - MESH_DARK) * light).astype(np.uint8)
    return face_id, plane, shade


def _draw_strands(pil, hair: Hair, view, centre, scale, width, height, face_id, plane, max_strands, seed) -> None:
    strand_ids = np.arange(hair.n_strands)
    if hair.n_strands > max_strands:
        strand_ids = np.sort(np.random.default_rng(seed).choice(hair.n_strands, max_strands, replace=False))
    index = particle_indices(hair.offsets, strand_ids)
    counts = hair.counts[strand_ids]
    points = hair.points[index]
    pixel, depth = _project(points, view, centre, scale, width, height)

    # visibility against the mesh: in front of (or on) the face covering the pixel
    ij = np.round(pixel).astype(np.int64)
    on_image = (ij[:, 0] >= 0) & (ij[:, 0] < width) & (ij[:, 1] >= 0) & (ij[:, 1] < height)
    visible = np.ones(len(points), dtype=bool)
    if plane is not None:
        f = np.full(len(points), -1, dtype=np.int64)
        f[on_image] = face_id[ij[on_image, 1], ij[on_image, 0]]
        covered = f >= 0
        surface = np.einsum("ij,ij->i", plane[f[covered], :2], pixel[covered]) + plane[f[covered], 2]
        visible[covered] = depth[covered] >= surface - VISIBILITY_TOLERANCE_M

    # segments: particle i to i+1 within a strand; drawn when either end is visible
    offsets = np.concatenate([[0], np.cumsum(counts)])
    is_last = np.zeros(len(points), dtype=bool)
    is_last[offsets[1:] - 1] = True
    seg_start = np.flatnonzero(~is_last)
    seg_visible = visible[seg_start] | visible[seg_start + 1]
    # runs of consecutive visible segments of one strand
    prev_ok = np.zeros(len(seg_start), dtype=bool)
    prev_ok[1:] = seg_visible[:-1] & (seg_start[1:] == seg_start[:-1] + 1)
    next_ok = np.zeros(len(seg_start), dtype=bool)
    next_ok[:-1] = seg_visible[1:] & (seg_start[1:] == seg_start[:-1] + 1)
    run_first = seg_start[seg_visible & ~prev_ok]
    run_last = seg_start[seg_visible & ~next_ok] + 1

    strand_of = np.repeat(np.arange(len(strand_ids)), counts)
    if hair.color is not None:
        colors = np.clip(hair.color[index] * 255.0, 0, 255)
        run_color = colors[run_first]
    else:
        jitter = np.random.default_rng(seed + 1).uniform(0.7, 1.3, len(strand_ids))
        run_color = np.clip(HAIR_COLOR[None] * jitter[strand_of[run_first], None], 0, 255)
    run_color = [tuple(c) for c in run_color.astype(np.uint8).tolist()]
    draw = ImageDraw.Draw(pil)
    flat = pixel.tolist()
    for first, last, color in zip(run_first.tolist(), run_last.tolist(), run_color):
        draw.line([tuple(q) for q in flat[first : last + 1]], fill=color, width=1)


def write_result_preview(path: str | Path, adaptable: AdaptableHairstyle, result: RetargetResult,
                         target: Character) -> None:
    """PNG of a retarget: the source hairstyle on the source next to the result on the target, with
    the result's particles inside the target in red."""
    render_preview(path, [
        (adaptable.hair, adaptable.source, None, "source"),
        (result.hair, target, penetrating_mask(result.hair, target), f"result ({result.metrics['method']})"),
    ])
