"""Strands drawn as shaded hair in one preview view (numpy, and a compiled kernel that splats the
samples; the picture is composed in :mod:`.preview`).

Every segment is lit as a thin cylinder (Kajiya-Kay: the diffuse term is the sine of the
angle between tangent and light, the highlight depends on tangent and half vector, so hair
that turns away from the light darkens and a band of sheen runs across the crown), darkened
with distance from the camera (a depth cue that separates the front strands from the ones
behind), then sampled about once per pixel along its projection. Samples behind the body are
dropped. The others are blended per pixel by *weighted order-independent transparency*: the
pixel's colour is the mean of its samples weighted by ``exp(SOFT_DEPTH * nearness)`` (the
nearest strands dominate without sorting), its opacity grows with the number of samples.
Drawn at a higher resolution than shown and reduced, this gives thin anti-aliased strands.

Cost: ``O(segments)`` numpy work for the shading and ``O(samples)`` compiled work for the splat
(samples = total projected length in pixels, at most :data:`MAX_SAMPLES`), with no per-sample
arrays. The numpy reference of the splat (:func:`_splat_numpy`, tested equal) makes the samples
as arrays, in chunks of about :data:`CHUNK_SAMPLES` (bounded memory), and accumulates them by
``np.bincount``; it took ~0.17 s a view of a 10^5-particle groom where the kernel takes a few ms.
"""

from __future__ import annotations

import numpy as np

from hairport.solver.jit import kernel, warms

#: light direction in view coordinates (screen right, screen up, toward the camera): from the
#: upper left and in front, the usual portrait key light
LIGHT_VIEW = np.array([-0.45, 0.6, 0.66])
#: shading of a hair colour (unitless multipliers): ambient + diffuse * sin(tangent, light)
AMBIENT = 0.3
DIFFUSE = 0.85
#: strength and sharpness of the highlight (Kajiya-Kay: sin(tangent, half vector)^SHININESS)
SPECULAR = 0.4
SHININESS = 80.0
SPECULAR_COLOR = np.array([255.0, 244.0, 225.0])
#: the farthest hair is darkened by this fraction (linear in depth between nearest and farthest)
DEPTH_DARKEN = 0.6
#: the depth cue spans at least this depth (m, about a head's): thin or flat hair is not darkened
#: across a few millimetres
MIN_DEPTH_SPAN_M = 0.1
#: weight of a sample is exp(SOFT_DEPTH * nearness), nearness in [0, 1]: at 8 the nearest
#: samples outweigh the farthest 3000 to 1, so front strands cover the ones behind them
SOFT_DEPTH = 8.0
#: opacity of one sample; a pixel with n samples has opacity 1 - (1 - SAMPLE_OPACITY)^n (one
#: strand crossing a supersampled pixel shows as a thin line, a dense lock as solid hair)
SAMPLE_OPACITY = 0.8
#: a sample counts as visible when it lies at most this far (m) behind the body's surface
#: (flat triangles cut a few millimetres off curved skin, and roots sit on it)
VISIBILITY_TOLERANCE_M = 0.004
#: samples made at once, about (runs of whole segments): bounds the per-sample arrays at ~100 MB
CHUNK_SAMPLES = 1 << 21
#: at most this many samples in one view (~0.4 s): longer projections are sampled more sparsely
MAX_SAMPLES = 1 << 23


def shade_segments(tangent: np.ndarray, base: np.ndarray, axes: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
    """Lit colour of hair segments.

    Parameters
    ----------
    tangent : (M, 3) float64
        Unit world tangents (zero rows for degenerate segments).
    base : (M, 3) float64
        Hair colour per segment, 0-255.
    axes : (u, v, toward) of (3,) float64
        The view's screen right, screen up and toward-camera world unit vectors.

    Returns
    -------
    color : (M, 3) float64
        0-255, not clipped.
    """
    u, v, toward = axes
    light = LIGHT_VIEW[0] * u + LIGHT_VIEW[1] * v + LIGHT_VIEW[2] * toward
    light = light / np.linalg.norm(light)
    half = light + toward
    half = half / np.linalg.norm(half)
    cos_light = tangent @ light
    cos_half = tangent @ half
    diffuse = np.sqrt(np.clip(1.0 - cos_light**2, 0.0, 1.0))
    specular = np.clip(1.0 - cos_half**2, 0.0, 1.0) ** (0.5 * SHININESS)
    return base * (AMBIENT + DIFFUSE * diffuse)[:, None] + SPECULAR * specular[:, None] * SPECULAR_COLOR


def hair_layer(
    points: np.ndarray,
    counts: np.ndarray,
    base: np.ndarray,
    pixel: np.ndarray,
    depth: np.ndarray,
    axes: tuple[np.ndarray, np.ndarray, np.ndarray],
    surface_depth: np.ndarray,
    compiled: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """The hair of one view as a colour image and an opacity image.

    Parameters
    ----------
    points : (N, 3) float64
        World positions of the drawn strands' particles, strand after strand.
    counts : (S,) int64
        Particles per drawn strand (sum N).
    base : (N, 3) float64
        Hair colour per particle, 0-255 (a segment takes its first particle's).
    pixel : (N, 2) float64
        Image coordinates (x right, y down) of the particles.
    depth : (N,) float64
        Toward-camera coordinate (m, larger = nearer).
    axes : (u, v, toward) of (3,) float64
        The view's axes (lighting).
    surface_depth : (H, W) float64
        Depth of the body at every pixel, ``-inf`` where there is none.
    compiled : bool
        Splat the samples with the compiled kernel (default) or with the numpy reference.

    Returns
    -------
    color : (H, W, 3) float32
        Blended hair colour, 0-255 (meaningless where alpha is 0).
    alpha : (H, W) float32
        Opacity in [0, 1].
    """
    height, width = surface_depth.shape
    sums = np.zeros((4, height * width))  # weight, weight * red, weight * green, weight * blue
    hits = np.zeros(height * width)
    is_last = np.zeros(len(points), dtype=bool)
    is_last[np.cumsum(counts) - 1] = True
    start = np.flatnonzero(~is_last)
    if len(start):
        near = depth.max()
        far = min(depth.min(), near - MIN_DEPTH_SPAN_M)
        extent = np.abs(pixel[start + 1] - pixel[start]).max(axis=1)  # (M,) pixels along the longer axis
        step = max(1.0, float(extent.sum()) / MAX_SAMPLES)
        # samples per segment: one per ``step`` pixels, clipped to the image's size
        n = np.minimum(np.ceil(extent / step), 2 * (width + height)).astype(np.int64) + 1
        per_segment = _segment_inks(points, depth, base, start, axes, near, far)
        if compiled:
            _splat(np.ascontiguousarray(pixel, dtype=np.float64), np.ascontiguousarray(depth, dtype=np.float64), start,
                   n, per_segment, np.ascontiguousarray(surface_depth, dtype=np.float64), sums, hits)
        else:
            _splat_numpy(pixel, depth, start, n, per_segment, surface_depth, sums, hits)
    color = (sums[1:] / np.where(sums[0] > 0, sums[0], 1.0)).T.reshape(height, width, 3).astype(np.float32)
    alpha = (1.0 - (1.0 - SAMPLE_OPACITY) ** hits).reshape(height, width).astype(np.float32)
    return color, alpha


def _segment_inks(points, depth, base, start, axes, near, far):
    """What each segment ``start -> start + 1`` adds to a pixel it covers: its blending weight and its
    weighted lit colour, ``(4, M) float64`` (weight, weight * red, green, blue).

    The depth cue and the weight are taken at the segment's middle (segments are short)."""
    segment = points[start + 1] - points[start]
    length = np.linalg.norm(segment, axis=1, keepdims=True)
    tangent = segment / np.where(length > 0, length, 1.0)
    nearness = np.clip((0.5 * (depth[start] + depth[start + 1]) - far) / (near - far), 0.0, 1.0)
    weight = np.exp(SOFT_DEPTH * nearness)
    lit = shade_segments(tangent, base[start], axes) * (1.0 - DEPTH_DARKEN * (1.0 - nearness))[:, None]
    return np.ascontiguousarray(np.concatenate([weight[:, None], weight[:, None] * lit], axis=1).T)


def _splat_numpy(pixel, depth, start, n, per_segment, surface_depth, sums, hits):
    """:func:`_splat`'s reference: the samples made in numpy, about :data:`CHUNK_SAMPLES` at a time,
    accumulated by ``np.bincount``."""
    size = sums.shape[1]
    cuts = np.searchsorted(np.cumsum(n), np.arange(CHUNK_SAMPLES, n.sum(), CHUNK_SAMPLES))
    for first, last in zip(np.r_[0, cuts], np.r_[cuts, len(start)]):
        if first == last:
            continue
        flat, owner = _samples(pixel, depth, start[first:last], n[first:last], surface_depth)
        for k in range(4):
            sums[k] += np.bincount(flat, per_segment[k, first:last][owner], minlength=size)
        hits += np.bincount(flat, minlength=size)


@kernel
def _splat(pixel, depth, start, n, per_segment, surface_depth, sums, hits):
    """Add every visible sample of the segments ``start -> start + 1`` (``n`` evenly spaced on each, in
    float32 as :func:`_samples`) to the pixel sums ``(4, H * W)`` and sample counts ``(H * W,)``."""
    height, width = surface_depth.shape
    for m in range(start.shape[0]):
        i = start[m]
        x0, y0, z0 = np.float32(pixel[i, 0]), np.float32(pixel[i, 1]), np.float32(depth[i])
        dx = np.float32(pixel[i + 1, 0]) - x0
        dy = np.float32(pixel[i + 1, 1]) - y0
        dz = np.float32(depth[i + 1]) - z0
        spacing = np.float32(max(n[m] - 1, 1))
        for j in range(n[m]):
            fraction = np.float32(j) / spacing
            x = np.int64(np.rint(x0 + fraction * dx))
            y = np.int64(np.rint(y0 + fraction * dy))
            if x < 0 or x >= width or y < 0 or y >= height:
                continue
            if z0 + fraction * dz < surface_depth[y, x] - VISIBILITY_TOLERANCE_M:
                continue
            flat = y * width + x
            for k in range(4):
                sums[k, flat] += per_segment[k, m]
            hits[flat] += 1.0


@warms
def _warm() -> None:
    _splat(np.zeros((2, 2)), np.zeros(2), np.zeros(1, np.int64), np.full(1, 2, np.int64), np.ones((4, 1)),
           np.zeros((2, 2)), np.zeros((4, 4)), np.zeros(4))


def _samples(pixel, depth, start, n, surface_depth):
    """Visible samples along the segments ``start -> start + 1``, ``n`` evenly spaced on each.

    Parameters
    ----------
    pixel : (N, 2) float64
    depth : (N,) float64
    start : (M,) int64
    n : (M,) int64
        Samples per segment (>= 1; both ends when >= 2).
    surface_depth : (H, W) float64

    Returns
    -------
    flat : (K,) int64
        Pixel index ``y * W + x`` of each visible sample.
    owner : (K,) int32
        Index into ``start`` of the sample's segment.
    """
    height, width = surface_depth.shape
    # per segment: start x, y, depth and their changes to the end (float32: pixels and metres
    # to well under a pixel and a micrometre, half the memory traffic)
    begin = np.concatenate([pixel[start], depth[start, None]], axis=1).astype(np.float32)
    delta = np.concatenate([pixel[start + 1], depth[start + 1, None]], axis=1).astype(np.float32) - begin
    owner = np.repeat(np.arange(len(start), dtype=np.int32), n)
    fraction = np.arange(len(owner), dtype=np.float32) - np.repeat((np.cumsum(n) - n).astype(np.float32), n)
    fraction /= np.repeat(np.maximum(n - 1, 1).astype(np.float32), n)
    sample = np.repeat(begin, n, axis=0)
    sample += fraction[:, None] * np.repeat(delta, n, axis=0)  # (K, 3): x, y, depth
    x = np.rint(sample[:, 0]).astype(np.int32)
    y = np.rint(sample[:, 1]).astype(np.int32)
    keep = (x >= 0) & (x < width) & (y >= 0) & (y < height)
    flat = np.where(keep, y * width + x, 0)
    # hidden behind the body: more than the tolerance deeper than the surface at that pixel
    keep &= sample[:, 2] >= surface_depth.ravel()[flat] - VISIBILITY_TOLERANCE_M
    return flat[keep], owner[keep]
