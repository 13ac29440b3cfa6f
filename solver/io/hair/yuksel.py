"""Cem Yuksel's HAIR files (``.hair``).

Layout: a 128-byte header (``"HAIR"``, hair count, point count, array flags, default
segments / thickness / transparency / color, 88-byte info string), then the arrays the flags
announce, in the order segments (``uint16`` per strand, points - 1), points (``float32`` x3),
thickness, transparency, color (``float32`` x3).

All five flags are read. Thickness and color are kept in ``Hair.thickness`` /
``Hair.color`` only when their array flag is set: the header defaults are always present in
a HAIR file (the reference library fills them in), so they say nothing about the hairstyle
and are not expanded to per-point arrays. A transparency array becomes the float32 per-point
attribute ``transparency`` (:data:`TRANSPARENCY`), which the writer writes back; no other
attribute has a place in the format. Strands
of zero segments are kept in the :class:`~.common.Strands` and dropped by the shared read
step.
"""

from __future__ import annotations

from typing import BinaryIO

import numpy as np

from hairport.solver.io.hair.common import (
    UINT16_MAX,
    UINT32_MAX,
    HairFormat,
    ReadContext,
    Strands,
    WriteOptions,
    check_finite,
    check_fits,
    no_trailing,
    require_bytes,
    to_float32,
)
from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import VERTEX, Hair, HairAttribute

HAIR_MAGIC = b"HAIR"
HAIR_HEADER_BYTES = 128
HAIR_INFO_BYTES = 88
HAIR_SEGMENTS_BIT = 1
HAIR_POINTS_BIT = 2
HAIR_THICKNESS_BIT = 4
HAIR_TRANSPARENCY_BIT = 8
HAIR_COLORS_BIT = 16
HAIR_KNOWN_BITS = (
    HAIR_SEGMENTS_BIT
    | HAIR_POINTS_BIT
    | HAIR_THICKNESS_BIT
    | HAIR_TRANSPARENCY_BIT
    | HAIR_COLORS_BIT
)
HAIR_MAX_SEGMENTS = UINT16_MAX  # segments are uint16
HAIR_INFO = b"hairport"
HAIR_HEADER_DTYPE = np.dtype(
    [
        ("magic", "S4"),
        ("hair_count", "<u4"),
        ("point_count", "<u4"),
        ("arrays", "<u4"),
        ("d_segments", "<u4"),
        ("d_thickness", "<f4"),
        ("d_transparency", "<f4"),
        ("d_color", "<f4", (3,)),
        ("info", f"S{HAIR_INFO_BYTES}"),
    ]
)
assert HAIR_HEADER_DTYPE.itemsize == HAIR_HEADER_BYTES
# Written as the header default when the hairstyle has no thickness: a typical human hair
# diameter (the reference library's own default, 1.0 file unit, would be a 1 m hair).
TYPICAL_HAIR_THICKNESS_M = 7e-5
HAIR_DEFAULT_TRANSPARENCY = 0.0
HAIR_DEFAULT_COLOR = (1.0, 1.0, 1.0)  # the reference library's default
#: the attribute a transparency array is read into and written from
TRANSPARENCY = "transparency"


def read_yuksel(buf: bytes | memoryview, ctx: ReadContext) -> Strands:
    """Parse a HAIR file: header, then the arrays its flags announce.

    Returns
    -------
    strands : Strands
        ``points (N, 3) float32``, ``counts (S,) int64``, ``thickness (N,) float32`` and
        ``color (N, 3) float32`` when their flags are set.
    """
    size = len(buf)
    require_bytes(ctx, HAIR_HEADER_BYTES, size, "the HAIR header")
    header = np.frombuffer(buf, dtype=HAIR_HEADER_DTYPE, count=1)[0]
    if bytes(header["magic"]) != HAIR_MAGIC:
        raise ctx.error("not a HAIR file (the first four bytes are not 'HAIR')", "bad_header")
    n_strands = int(header["hair_count"])
    n_points = int(header["point_count"])
    flags = int(header["arrays"])
    if flags & ~HAIR_KNOWN_BITS:
        raise ctx.error(
            f"unknown array flags 0x{flags & ~HAIR_KNOWN_BITS:x} in the header", "bad_header"
        )
    if not flags & HAIR_POINTS_BIT:
        raise ctx.error("the header announces no points array", "bad_header")
    layout = array_layout(flags, n_strands, n_points)
    end = HAIR_HEADER_BYTES + sum(nbytes for _, nbytes, _ in layout)
    require_bytes(ctx, end, size, f"a HAIR file of {n_strands:,} strands and {n_points:,} points")
    no_trailing(ctx, end, size)
    ctx.check_limit(n_strands, "strands")
    ctx.check_limit(n_points, "particles")
    arrays: dict[str, np.ndarray] = {}
    pos = HAIR_HEADER_BYTES
    for name, nbytes, dtype in layout:
        arrays[name] = np.frombuffer(buf, dtype=dtype, count=nbytes // dtype.itemsize, offset=pos)
        pos += nbytes
    counts = strand_counts(
        arrays.get("segments"), int(header["d_segments"]), n_strands, n_points, ctx
    )
    strands = Strands(
        points=arrays["points"].reshape(-1, 3),
        counts=counts,
        thickness=arrays.get("thickness"),
        color=None if "color" not in arrays else arrays["color"].reshape(-1, 3),
    )
    if TRANSPARENCY in arrays:
        check_finite(arrays[TRANSPARENCY], counts, TRANSPARENCY, ctx)
        strands.add_attribute(TRANSPARENCY, arrays[TRANSPARENCY], VERTEX)
    return strands


def keeps_attribute(name: str, attribute: HairAttribute) -> bool:
    """Only a scalar per-point ``transparency`` has a place in a HAIR file."""
    return name == TRANSPARENCY and attribute.domain == VERTEX and attribute.components == 1 and \
        attribute.values.dtype.kind in "biuf"


def array_layout(flags: int, n_strands: int, n_points: int) -> list[tuple[str, int, np.dtype]]:
    """(name, byte size, dtype) of every array the flags announce, in file order."""
    f32 = np.dtype("<f4")
    candidates = [
        (HAIR_SEGMENTS_BIT, "segments", 2 * n_strands, np.dtype("<u2")),
        (HAIR_POINTS_BIT, "points", 12 * n_points, f32),
        (HAIR_THICKNESS_BIT, "thickness", 4 * n_points, f32),
        (HAIR_TRANSPARENCY_BIT, TRANSPARENCY, 4 * n_points, f32),
        (HAIR_COLORS_BIT, "color", 12 * n_points, f32),
    ]
    return [(name, nbytes, dtype) for bit, name, nbytes, dtype in candidates if flags & bit]


def strand_counts(
    segments: np.ndarray | None, d_segments: int, n_strands: int, n_points: int, ctx: ReadContext
) -> np.ndarray:
    """Points per strand from the segments array, or from the header default without one.

    Parameters
    ----------
    segments : (S,) uint16 or None
    d_segments : int
        The header's default segments per strand.
    n_strands, n_points : int
        The header's counts.
    ctx : ReadContext

    Returns
    -------
    counts : (S,) int64

    Raises
    ------
    InputError
        ``bad_header`` when the counts do not add up to ``n_points``.
    """
    if segments is None:
        counts = np.full(n_strands, d_segments + 1, dtype=np.int64)
        total = n_strands * (d_segments + 1)
        where = f"{n_strands:,} strands of the default {d_segments:,} segments"
    else:
        counts = segments.astype(np.int64) + 1
        total = int(counts.sum())
        where = "the segments array"
    if total != n_points:
        raise ctx.error(
            f"{where} make(s) {total:,} points but the header declares {n_points:,}", "bad_header"
        )
    return counts


def write_yuksel(f: BinaryIO, hair: Hair, options: WriteOptions) -> None:
    """Write header, segments, points and the thickness and color the hairstyle has."""
    scale = options.scale
    check_fits(hair, UINT32_MAX, UINT32_MAX, "hair")
    if hair.n_strands and int(hair.counts.max()) - 1 > HAIR_MAX_SEGMENTS:
        bad = int(np.argmax(hair.counts))
        raise InputError(
            f"strand {bad} has {int(hair.counts[bad]) - 1:,} segments; the HAIR format holds at "
            f"most {HAIR_MAX_SEGMENTS:,} per strand",
            code="too_large",
        )
    header = np.zeros(1, dtype=HAIR_HEADER_DTYPE)
    flags = HAIR_SEGMENTS_BIT | HAIR_POINTS_BIT
    flags |= HAIR_THICKNESS_BIT if hair.thickness is not None else 0
    flags |= HAIR_COLORS_BIT if hair.color is not None else 0
    transparency = hair.attributes.get(TRANSPARENCY)
    flags |= HAIR_TRANSPARENCY_BIT if transparency is not None else 0
    header["magic"] = HAIR_MAGIC
    header["hair_count"] = hair.n_strands
    header["point_count"] = hair.n_particles
    header["arrays"] = flags
    header["d_segments"] = 0
    header["d_thickness"] = TYPICAL_HAIR_THICKNESS_M / scale
    header["d_transparency"] = HAIR_DEFAULT_TRANSPARENCY
    header["d_color"] = HAIR_DEFAULT_COLOR
    header["info"] = HAIR_INFO
    f.write(header.tobytes())
    f.write((hair.counts - 1).astype("<u2").tobytes())
    f.write(to_float32(hair.points / scale, "coordinate").tobytes())
    if hair.thickness is not None:
        f.write(to_float32(hair.thickness / scale, "thickness").tobytes())
    if transparency is not None:
        f.write(to_float32(transparency.values, TRANSPARENCY).tobytes())
    if hair.color is not None:
        f.write(to_float32(hair.color, "color").tobytes())


FORMAT = HairFormat("hair", read_yuksel, write_yuksel, keeps_thickness=True, keeps_color=True,
                    keeps_attribute=keeps_attribute)
