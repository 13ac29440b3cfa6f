"""Polyline PLY hair files (``.ply``): which vertices form which strand, and the writer.

The header and the ASCII and binary bodies are read by :mod:`.header`,
:mod:`.ascii_body` and :mod:`.binary_body`; this module interprets the parsed elements as
strands. The reader accepts, in this order of precedence:

(a) an element ``strand`` (or ``strands``, ``curve``, ``curves``, ``polyline``, ``hair``)
    with a list property of vertex indices (e.g. ``property list uchar int vertex_indices``),
    one list per strand, root first;
(b) the same element with a scalar count: ``nsegs`` / ``segments`` (points - 1, the
    convention of the ``hairutil`` tool) or ``npoints`` / ``num_points`` / ``vertex_count``
    (points), strands being consecutive runs of vertices;
(c) a per-vertex integer property naming the strand (``strand_id``, ``strand``,
    ``strand_index``, ``curve_id``, ``hair_id``); each strand's vertices must be consecutive;
(d) an element ``edge`` with ``vertex1`` / ``vertex2`` joining consecutive vertices; maximal
    chains form strands.

When (b) and (d) are both present the edges must agree with the strands. Per-vertex
``thickness`` (or ``width``) and ``red`` / ``green`` / ``blue`` (integers scaled by their
type's maximum, floats taken as [0, 1]) are the hairstyle's thickness and color; every other
scalar property of the vertices (``alpha``, UVs, ids ...) and of the strand element becomes an
attribute, written back as it was read (:mod:`.attributes`).

The writer writes ``binary_little_endian`` (``ascii=True`` for ASCII)::

    element vertex N      float x, y, z [, float thickness] [, uchar red, green, blue] [, attributes]
    element strand S      ushort nsegs   (uint when a strand has more than 65,535 segments) [, attributes]
    element edge N-S      int vertex1, vertex2

that is the layout of ``hairutil`` (strand structure in ``nsegs``) plus edges, so that
general viewers (MeshLab, Blender, Open3D) show the strands as polylines. Colors are
quantized to 8 bits, as every PLY viewer expects; use ``.hair`` or ``.npz`` to keep them
exactly.
"""

from __future__ import annotations

from typing import BinaryIO

import numpy as np

from hairport.solver.io.hair.common import (
    ASCII_DOUBLE,
    ASCII_FLOAT,
    INT32_MAX,
    UINT16_MAX,
    HairFormat,
    ReadContext,
    Strands,
    WriteOptions,
    check_fits,
    to_float32,
    write_rows,
)
from hairport.solver.io.hair.ply.ascii_body import read_ascii_body
from hairport.solver.io.hair.ply.attributes import attribute_columns, read_attributes, writable
from hairport.solver.io.hair.ply.binary_body import read_binary_body
from hairport.solver.io.hair.ply.header import (
    PLY_ENCODINGS,
    PLY_STRAND_ELEMENTS,
    PLY_TYPES,
    PlyList,
    PlyValues,
    parse_header,
)
from hairport.solver.model.hair import STRAND, VERTEX, Hair

PLY_INDEX_LISTS = ("vertex_indices", "vertex_index", "indices")
PLY_SEGMENT_COUNTS = ("nsegs", "segments", "num_segments", "segment_count")
PLY_POINT_COUNTS = (
    "npoints",
    "num_points",
    "point_count",
    "vertex_count",
    "num_vertices",
    "nverts",
)
PLY_STRAND_IDS = ("strand_id", "strand", "strand_index", "strand_idx", "curve_id", "hair_id")
PLY_THICKNESS = ("thickness", "width")
PLY_COLORS = ("red", "green", "blue")
NSEGS_SHORT_MAX = UINT16_MAX  # above it the writer declares nsegs uint instead of ushort
COLOR_MAX = int(np.iinfo(np.uint8).max)  # the writer quantizes colors to uchar


def read_ply(buf: bytes | memoryview, ctx: ReadContext) -> Strands:
    """Parse the header and the body, then find the strands (layouts (a)-(d))."""
    encoding, elements, body_at = parse_header(buf, ctx)
    if encoding == "ascii":
        values = read_ascii_body(buf, body_at, elements, ctx)
    else:
        values = read_binary_body(buf, body_at, elements, PLY_ENCODINGS[encoding], ctx)
    return strands_from_elements(values, ctx)


def strands_from_elements(values: PlyValues, ctx: ReadContext) -> Strands:
    """Interpret the parsed elements as strands (layouts (a)-(d) of the module notes).

    Returns
    -------
    strands : Strands
        ``points (N, 3)`` (in strand order for layout (a)), ``counts (S,) int64``, and the
        vertices' thickness and color when present.

    Raises
    ------
    InputError
        ``bad_header`` (no vertex positions, no strand structure), ``bad_index``.
    """
    vertex = values.get("vertex")
    if vertex is None or not all(
        k in vertex and not isinstance(vertex[k], PlyList) for k in "xyz"
    ):
        raise ctx.error(
            "the PLY file has no element 'vertex' with properties x, y, z", "bad_header"
        )
    points = np.stack([vertex["x"], vertex["y"], vertex["z"]], axis=1)
    n = len(points)
    thickness = vertex_thickness(vertex)
    color = vertex_color(vertex)
    used_by_vertex = {"x", "y", "z", *(PLY_COLORS if color is not None else ())}
    used_by_vertex |= {next(k for k in PLY_THICKNESS if k in vertex)} if thickness is not None else set()
    strand_name = next((name for name in PLY_STRAND_ELEMENTS if name in values), None)
    strand = values.get(strand_name, {}) if strand_name else {}
    edges = values.get("edge")
    index_name = next((k for k in (*PLY_INDEX_LISTS, *strand) if isinstance(strand.get(k), PlyList)), None)
    if index_name is not None:
        index_list = strand[index_name]
        index = index_list.values.astype(np.int64)
        if len(index) and (index.min() < 0 or index.max() >= n):
            bad = int(index[(index < 0) | (index >= n)][0])
            raise ctx.error(
                f"element {strand_name!r} refers to vertex {bad}, but there are {n:,}", "bad_index"
            )
        points = points[index]
        thickness = None if thickness is None else thickness[index]
        color = None if color is None else color[index]
        found = Strands(points, index_list.lengths, thickness, color)
        read_attributes(vertex, used_by_vertex, VERTEX, index, found)
        read_attributes(strand, {index_name}, STRAND, None, found)
        return found
    counts = counts_from_strand_element(strand, strand_name, n, ctx)
    if counts is not None:
        if edges is not None:
            check_edges_agree(edges, counts, n, ctx)
        count_name = next(k for k in (*PLY_SEGMENT_COUNTS, *PLY_POINT_COUNTS) if k in strand)
        found = Strands(points, counts, thickness, color)
        read_attributes(vertex, used_by_vertex, VERTEX, None, found)
        read_attributes(strand, {count_name}, STRAND, None, found)
        return found
    if (id_name := next((k for k in PLY_STRAND_IDS if k in vertex), None)) is not None:
        counts = counts_from_ids(vertex[id_name], id_name, ctx)
        used_by_vertex.add(id_name)
    elif edges is not None:
        counts = counts_from_edges(edges, n, ctx)
    else:
        raise ctx.error(
            "the PLY file does not say which vertices form which strand: expected an element "
            f"{PLY_STRAND_ELEMENTS[0]!r} (a vertex index list or 'nsegs'), a per-vertex "
            f"'{PLY_STRAND_IDS[0]}', or an element 'edge'",
            "bad_header",
        )
    found = Strands(points, counts, thickness, color)
    read_attributes(vertex, used_by_vertex, VERTEX, None, found)
    return found


def vertex_thickness(vertex: dict) -> np.ndarray | None:
    """``(N,) float64`` from the first thickness property present, else ``None``."""
    name = next((k for k in PLY_THICKNESS if k in vertex), None)
    return None if name is None else np.asarray(vertex[name], dtype=np.float64)


def vertex_color(vertex: dict) -> np.ndarray | None:
    """``(N, 3) float64`` in [0, 1]: integers divided by their type's maximum, floats as they are."""
    if not all(k in vertex for k in PLY_COLORS):
        return None
    channels = []
    for k in PLY_COLORS:
        c = np.asarray(vertex[k])
        full = np.iinfo(c.dtype).max if c.dtype.kind in "iu" else 1.0
        channels.append(c.astype(np.float64) / full)
    return np.stack(channels, axis=1)


def counts_from_strand_element(
    strand: dict, strand_name: str | None, n: int, ctx: ReadContext
) -> np.ndarray | None:
    """Layout (b): ``(S,) int64`` points per strand from a segment or point count, else ``None``."""
    name = next((k for k in (*PLY_SEGMENT_COUNTS, *PLY_POINT_COUNTS) if k in strand), None)
    if name is None:
        return None
    counts = np.asarray(strand[name], dtype=np.int64)
    if name in PLY_SEGMENT_COUNTS:
        counts = counts + 1
    if len(counts) and counts.min() < 0:
        raise ctx.error(f"element {strand_name!r} has a negative {name!r}", "bad_index")
    if int(counts.sum()) != n:
        raise ctx.error(
            f"the strands of element {strand_name!r} ({name!r}) hold {int(counts.sum()):,} points "
            f"but there are {n:,} vertices",
            "bad_index",
        )
    return counts


def counts_from_ids(ids: np.ndarray, name: str, ctx: ReadContext) -> np.ndarray:
    """Layout (c): ``(S,) int64`` lengths of the runs of equal strand ids (each id one run)."""
    ids = np.asarray(ids)
    if len(ids) == 0:
        return np.zeros(0, dtype=np.int64)
    starts = np.concatenate([[0], np.flatnonzero(ids[1:] != ids[:-1]) + 1])
    if len(np.unique(ids[starts])) != len(starts):
        raise ctx.error(f"the vertices of one {name!r} are not consecutive", "bad_index")
    return np.diff(np.append(starts, len(ids))).astype(np.int64)


def _edges(edges: dict, n: int, ctx: ReadContext) -> tuple[np.ndarray, np.ndarray]:
    """``vertex1``, ``vertex2`` as ``(E,) int64``; every edge joins consecutive vertices."""
    if not all(k in edges and not isinstance(edges[k], PlyList) for k in ("vertex1", "vertex2")):
        raise ctx.error("element 'edge' needs properties vertex1 and vertex2", "bad_header")
    a = np.asarray(edges["vertex1"], dtype=np.int64)
    b = np.asarray(edges["vertex2"], dtype=np.int64)
    for v in (a, b):
        if len(v) and (v.min() < 0 or v.max() >= n):
            raise ctx.error(f"an edge refers to a vertex outside 0..{n - 1}", "bad_index")
    if not (np.abs(a - b) == 1).all():
        bad = int(np.argmax(np.abs(a - b) != 1))
        raise ctx.error(
            f"edge {bad} joins vertices {int(a[bad])} and {int(b[bad])}; strand edges must join "
            "consecutive vertices",
            "bad_index",
        )
    return a, b


def counts_from_edges(edges: dict, n: int, ctx: ReadContext) -> np.ndarray:
    """Layout (d): ``(S,) int64`` lengths of the maximal chains of edges (lone vertices: 1)."""
    a, b = _edges(edges, n, ctx)
    linked = np.zeros(max(n - 1, 0), dtype=bool)
    linked[np.minimum(a, b)] = True
    starts = np.concatenate([[0], np.flatnonzero(~linked) + 1]) if n else np.zeros(0, np.int64)
    return np.diff(np.append(starts, n)).astype(np.int64)


def check_edges_agree(edges: dict, counts: np.ndarray, n: int, ctx: ReadContext) -> None:
    """Layouts (b) and (d) together: the edges are exactly the strands' segments."""
    a, b = _edges(edges, n, ctx)
    linked = np.zeros(max(n - 1, 0), dtype=bool)
    linked[np.minimum(a, b)] = True
    expected = np.ones(max(n - 1, 0), dtype=bool)
    ends = np.cumsum(counts)[:-1] - 1  # last point of every strand but the final one
    expected[ends[(ends >= 0) & (ends < n - 1)]] = False
    if len(a) != int(expected.sum()) or not np.array_equal(linked, expected):
        raise ctx.error("the 'edge' element disagrees with the strand element", "bad_index")


def write_ply(f: BinaryIO, hair: Hair, options: WriteOptions) -> None:
    """Write vertices, ``nsegs`` per strand and the edges (module notes), binary or ASCII."""
    check_fits(hair, INT32_MAX, INT32_MAX, "ply")
    columns = vertex_columns(hair, options.scale)
    columns += attribute_columns(hair.attributes_of(VERTEX), {name for name, _, _ in columns})
    nsegs = hair.counts - 1
    nsegs_type = "ushort" if not len(nsegs) or nsegs.max() <= NSEGS_SHORT_MAX else "uint"
    strand_columns = [("nsegs", nsegs_type, nsegs)]
    strand_columns += attribute_columns(hair.attributes_of(STRAND), {"nsegs"})
    edges = edge_starts(hair)  # edge k joins vertices edges[k] and edges[k] + 1
    edge_columns = [("vertex1", "int", edges), ("vertex2", "int", edges + 1)]
    encoding = "ascii" if options.ascii else "binary_little_endian"
    lines = ["ply", f"format {encoding} 1.0", "comment written by hairport"]
    for element, count, element_columns in (("vertex", hair.n_particles, columns),
                                            ("strand", hair.n_strands, strand_columns),
                                            ("edge", len(edges), edge_columns)):
        lines.append(f"element {element} {count}")
        lines += [f"property {ply_type} {name}" for name, ply_type, _ in element_columns]
    lines.append("end_header")
    f.write(("\n".join(lines) + "\n").encode("ascii"))
    for element_columns in (columns, strand_columns, edge_columns):
        if options.ascii:
            write_rows(f, [values for _, _, values in element_columns],
                       [_ascii_format(t) for _, t, _ in element_columns])
            continue
        record = np.dtype([(name, "<" + PLY_TYPES[ply_type]) for name, ply_type, _ in element_columns])
        table = np.empty(len(element_columns[0][2]), dtype=record)
        for name, _, values in element_columns:
            table[name] = values
        f.write(table.tobytes())


def edge_starts(hair: Hair) -> np.ndarray:
    """(N-S,) little-endian int32: the first vertex of every segment."""
    starts = np.ones(hair.n_particles, dtype=bool)
    starts[hair.offsets[1:] - 1] = False  # a strand's last vertex starts no segment
    return np.flatnonzero(starts).astype("<i4")


def vertex_columns(hair: Hair, scale: float) -> list[tuple[str, str, np.ndarray]]:
    """(property name, PLY type, (N,) values) of every vertex property the writer writes."""
    points = to_float32(hair.points / scale, "coordinate")
    columns = [(axis, "float", points[:, i]) for i, axis in enumerate("xyz")]
    if hair.thickness is not None:
        columns.append(("thickness", "float", to_float32(hair.thickness / scale, "thickness")))
    if hair.color is not None:
        rgb = np.rint(np.clip(hair.color, 0.0, 1.0) * COLOR_MAX).astype(np.uint8)
        columns += [(name, "uchar", rgb[:, i]) for i, name in enumerate(PLY_COLORS)]
    return columns


def _ascii_format(ply_type: str) -> str:
    code = PLY_TYPES[ply_type]
    return "%d" if code[0] != "f" else ASCII_DOUBLE if code == "f8" else ASCII_FLOAT


#: property names the layout uses, which no attribute may take (the reader would read them as layout)
RESERVED = {
    VERTEX: ("x", "y", "z", *PLY_THICKNESS, *PLY_COLORS, *PLY_STRAND_IDS),
    STRAND: (*PLY_INDEX_LISTS, *PLY_SEGMENT_COUNTS, *PLY_POINT_COUNTS),
}

FORMAT = HairFormat(
    "ply", read_ply, write_ply, keeps_thickness=True, keeps_color=True, has_ascii=True,
    keeps_attribute=lambda name, attribute: writable(name, attribute, RESERVED),
)
