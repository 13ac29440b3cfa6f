"""Wavefront OBJ polylines (``.obj``).

Layout: ``v x y z [r g b]`` lines and ``l i j k ...`` lines (1-based indices, negative ones
relative to the vertices so far, ``i/t`` forms accepted), one ``l`` line per strand, root
first. Faces and other records are ignored with one warning (normals, texture and parameter
coordinates, object and group names, smoothing groups and materials quietly). The format
has no thickness; vertex colors are kept.

A file that is not OBJ text is refused with one error, not read as an empty groom: a NUL
byte or a record that does not start with a word (``not_text``: binary or damaged data);
no ``v`` or no ``l`` records (``empty_hair``: nothing to retarget, e.g. a mesh OBJ with
faces only).
"""

from __future__ import annotations

import re
from typing import BinaryIO

import numpy as np

from hairport.solver.io.hair.common import (
    ASCII_CHUNK_ROWS,
    ASCII_FLOAT,
    HairFormat,
    ReadContext,
    Strands,
    WriteOptions,
    parse_numbers,
    to_float32,
    write_rows,
)
from hairport.solver.model.hair import EMPTY_HAIR, Hair

OBJ_IGNORED_QUIETLY = {b"vn", b"vt", b"vp", b"o", b"g", b"s", b"usemtl", b"mtllib"}
#: what starts every OBJ record: a word of ASCII letters, digits and underscores
OBJ_RECORD_TAG = re.compile(rb"[A-Za-z_][A-Za-z0-9_]*")
#: code of the error for bytes that are not OBJ text
NOT_TEXT = "not_text"
#: the UTF-8 byte order mark some editors write before the first record
UTF8_BOM = b"\xef\xbb\xbf"
#: record kinds the one "ignored" warning names; the rest are counted together
MAX_NAMED_IGNORED = 5
#: bytes of a bad record shown in a message (escaped), enough to recognise it
SHOWN_BYTES = 16


def read_obj(buf: bytes | memoryview, ctx: ReadContext) -> Strands:
    """Gather the ``v`` and ``l`` lines, then parse each kind as one block of numbers.

    Returns
    -------
    strands : Strands
        ``points (N, 3) float64`` in polyline order (a vertex used twice appears twice),
        ``counts (S,) int64``, ``color (N, 3) float64`` when the ``v`` lines have six values.
    """
    data = bytes(buf)
    nul = data.find(b"\0")
    if nul >= 0:
        raise ctx.error(f"byte {nul:,} is a NUL byte: a binary file, not OBJ text (code {NOT_TEXT})", NOT_TEXT)
    if data.startswith(UTF8_BOM):
        data = data[len(UTF8_BOM):]
    v_rows: list[bytes] = []
    l_rows: list[bytes] = []
    l_base: list[int] = []
    ignored: dict[str, int] = {}
    for number, line in enumerate(data.splitlines(), start=1):
        words = line.split(None, 1)
        if not words or words[0].startswith(b"#"):
            continue
        tag = words[0]
        rest = words[1] if len(words) > 1 else b""
        if tag == b"v":
            v_rows.append(rest)
        elif tag == b"l":
            l_rows.append(rest)
            l_base.append(len(v_rows))
        elif OBJ_RECORD_TAG.fullmatch(tag) is None:
            shown = repr(line[:SHOWN_BYTES])[2:-1]
            raise ctx.error(f"line {number:,} ('{shown}') is not an OBJ record: a binary or damaged file, "
                            f"not OBJ text (code {NOT_TEXT})", NOT_TEXT)
        elif tag not in OBJ_IGNORED_QUIETLY:
            key = tag.decode("ascii")
            ignored[key] = ignored.get(key, 0) + 1
    if not l_rows:
        faces = f", {ignored['f']:,} faces: a mesh, not hair" if ignored.get("f") else ""
        raise ctx.error(f"no polyline ('l') records ({len(v_rows):,} vertices{faces}): there is no hair to "
                        f"retarget (code {EMPTY_HAIR})", EMPTY_HAIR)
    ctx.check_limit(len(l_rows), "strands")
    ctx.check_limit(len(v_rows), "particles")
    points, color = vertices(v_rows, ctx)
    index, lengths = polylines(l_rows, np.array(l_base, dtype=np.int64), len(points), ctx)
    notes = [ignored_note(ignored)] if ignored else []
    return Strands(points[index], lengths, None, None if color is None else color[index], notes)


def ignored_note(ignored: dict[str, int]) -> str:
    """One warning for every ignored record kind: ``ignored 3 'f' record(s), 1 'p' record(s)``."""
    kinds = sorted(ignored.items())
    named = ", ".join(f"{count:,} '{tag}' record(s)" for tag, count in kinds[:MAX_NAMED_IGNORED])
    rest = sum(count for _, count in kinds[MAX_NAMED_IGNORED:])
    more = f" and {rest:,} record(s) of {len(kinds) - MAX_NAMED_IGNORED} other kind(s)" if rest else ""
    return f"ignored {named}{more}"


def vertices(rows: list[bytes], ctx: ReadContext) -> tuple[np.ndarray, np.ndarray | None]:
    """Positions and colors of the ``v`` lines (without their tag).

    Returns
    -------
    points : (V, 3) float64
    color : (V, 3) float64 or None
        When every line has six values.
    """
    widths = np.fromiter((len(r.split()) for r in rows), dtype=np.int64, count=len(rows))
    if len(rows) and (widths != widths[0]).any():
        raise ctx.error("'v' lines have differing numbers of values", "bad_value")
    width = int(widths[0]) if len(rows) else 3
    if width not in (3, 4, 6):
        raise ctx.error(
            f"'v' lines have {width} values; expected x y z [w] or x y z r g b", "bad_value"
        )
    values = parse_numbers(b"\n".join(rows), np.float64, "the 'v' lines", ctx).reshape(-1, width)
    color = values[:, 3:6] if width == 6 else None
    return values[:, :3], color


def polylines(
    rows: list[bytes], base: np.ndarray, n_vertices: int, ctx: ReadContext
) -> tuple[np.ndarray, np.ndarray]:
    """0-based vertex indices of the ``l`` lines (without their tag).

    Parameters
    ----------
    rows : list of bytes
    base : (L,) int64
        Vertices defined before each line (what negative indices count back from).
    n_vertices : int
    ctx : ReadContext

    Returns
    -------
    index : (K,) int64
        All lines' indices, concatenated.
    lengths : (L,) int64
        Indices per line.
    """
    block = b"\n".join(rows)
    if b"/" in block:
        block = re.sub(rb"/\S*", b"", block)
    lengths = np.fromiter((len(r.split()) for r in rows), dtype=np.int64, count=len(rows))
    index = parse_numbers(block, np.int64, "the 'l' lines", ctx)
    if len(index) != int(lengths.sum()):
        raise ctx.error("an 'l' line holds something other than vertex indices", "bad_value")
    if (index == 0).any():
        raise ctx.error("vertex index 0 in an 'l' line (OBJ indices start at 1)", "bad_index")
    index = np.where(index > 0, index - 1, np.repeat(base, lengths) + index)
    if len(index) and (index.min() < 0 or index.max() >= n_vertices):
        raise ctx.error(f"an 'l' line refers to a vertex outside 1..{n_vertices}", "bad_index")
    return index, lengths


def write_obj(f: BinaryIO, hair: Hair, options: WriteOptions) -> None:
    """Write every point as a ``v`` line (with its color), then one ``l`` line per strand."""
    f.write(b"# written by hairport: v lines, then one polyline (l line) per strand, root first\n")
    points = to_float32(hair.points / options.scale, "coordinate")
    columns = [points[:, 0], points[:, 1], points[:, 2]]
    formats = [ASCII_FLOAT] * 3
    if hair.color is not None:
        columns += [hair.color[:, i].astype(np.float32) for i in range(3)]
        formats += [ASCII_FLOAT] * 3
    write_rows(f, columns, formats, prefix="v ")
    n = hair.n_particles
    if n == 0:
        return
    last = np.zeros(n, dtype=bool)
    last[hair.offsets[1:] - 1] = True
    first = hair.is_root
    for start in range(0, n, ASCII_CHUNK_ROWS):
        stop = min(start + ASCII_CHUNK_ROWS, n)
        template = np.where(first[start:stop], "l %d", "%d")
        template = np.char.add(template, np.where(last[start:stop], "\n", " "))
        text = "".join(template.tolist()) % tuple(range(start + 1, stop + 1))
        f.write(text.encode("ascii"))


FORMAT = HairFormat("obj", read_obj, write_obj, keeps_thickness=False, keeps_color=True)
