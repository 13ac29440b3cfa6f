"""The PLY header and the checks of its counts (:mod:`hairport.solver.io.hair.ply.header`)."""

from __future__ import annotations

import numpy as np
import pytest

from hairport.solver.io.hair import ReadLimits, read_hair_bytes
from hairport.solver.io.hair.common import ReadContext
from hairport.solver.io.hair.ply.header import (
    PLY_MAX_HEADER_BYTES,
    PlyElement,
    PlyProperty,
    check_counts,
    list_item_positions,
    parse_header,
)
from tests.solver.io.hair.samples import ASCII_PLY, expect_error, ply_bytes, strands_of, xyz_props

CONTEXT = ReadContext("h.ply", ReadLimits(), "m")


def test_ply_crlf_header():
    points, _ = strands_of([2])
    data = ply_bytes(
        "ascii", [("vertex", 2, xyz_props(points)), ("strand", 1, [("nsegs", "ushort", [1])])]
    )
    hair = read_hair_bytes(data.replace(b"\n", b"\r\n"), "ply")
    np.testing.assert_array_equal(hair.points, points)


@pytest.mark.parametrize(
    "header, code",
    [
        (b"ply\nformat binary_middle_endian 1.0\nend_header\n", "bad_header"),
        (ASCII_PLY + b"element vertex 1\nproperty quad x\nend_header\n", "bad_header"),
        (ASCII_PLY + b"element vertex -1\nend_header\n", "bad_header"),
        (ASCII_PLY + b"property float x\nend_header\n", "bad_header"),
        (
            ASCII_PLY + b"element vertex 1\nproperty float x\nproperty float x\nend_header\n",
            "bad_header",
        ),
        (ASCII_PLY + b"element vertex 2\nproperty float x\n", "truncated"),  # no end_header
        (b"PLY\nformat ascii 1.0\nend_header\n", "bad_header"),
    ],
)
def test_ply_bad_headers(header, code):
    err = expect_error(code, read_hair_bytes, header, "ply", source="bad.ply")
    assert str(err).startswith("bad.ply: ")


def test_parse_header_elements_types_and_body_offset():
    head = (
        b"ply\nformat binary_big_endian 1.0\ncomment made here\nelement vertex 3\n"
        b"property float x\nproperty uchar red\nelement strand 1\n"
        b"property list uchar int vertex_indices\nend_header\n"
    )
    encoding, elements, body_at = parse_header(head + bytes(5), CONTEXT)
    assert encoding == "binary_big_endian" and body_at == len(head)
    assert [(e.name, e.count) for e in elements] == [("vertex", 3), ("strand", 1)]
    assert elements[0].properties == [PlyProperty("x", np.dtype(">f4")), PlyProperty("red", np.dtype("u1"))]
    (indices,) = elements[1].properties
    assert indices.is_list and not elements[0].properties[0].is_list
    assert (indices.count_dtype, indices.dtype) == (np.dtype("u1"), np.dtype(">i4"))


def test_parse_header_messages():
    quad = ASCII_PLY + b"element vertex 1\nproperty quad x\nend_header\n"
    err = expect_error("bad_header", parse_header, quad, CONTEXT)
    assert str(err) == "h.ply: PLY header line 4: unknown property type 'quad'"
    float_lengths = ASCII_PLY + b"element s 1\nproperty list float int i\nend_header\n"
    err = expect_error("bad_header", parse_header, float_lengths, CONTEXT)
    assert "list length type 'float' is not an integer type" in str(err)
    err = expect_error("truncated", parse_header, b"pl", CONTEXT)
    assert "the file ends inside the PLY magic line" in str(err)
    err = expect_error("bad_header", parse_header, b"ply\ncomment " + bytes(PLY_MAX_HEADER_BYTES), CONTEXT)
    assert "no end_header in the first 1,048,576 bytes" in str(err)
    err = expect_error("bad_header", parse_header, b"ply\nelement vertex 1\nend_header\n", CONTEXT)
    assert "the PLY header has no format line" in str(err)


def strand_file_elements() -> list[PlyElement]:
    f4, i4, u1 = np.dtype("<f4"), np.dtype("<i4"), np.dtype("u1")
    vertex = PlyElement("vertex", 4, [PlyProperty(axis, f4) for axis in "xyz"])
    strand = PlyElement("curve", 2, [PlyProperty("vertex_indices", i4, u1)])
    return [vertex, strand]


def test_check_counts_against_the_body_size():
    elements = strand_file_elements()
    check_counts(elements, 4 * 12 + 2 * 1, "bytes", 0, CONTEXT)  # just enough: empty lists
    err = expect_error("truncated", check_counts, elements, 49, "bytes", 0, CONTEXT)
    assert "need at least 50 bytes of data but the body has 49" in str(err)
    check_counts(elements, 4 * 3 + 2, "numbers", 1, CONTEXT)
    err = expect_error("truncated", check_counts, elements, 13, "numbers", 1, CONTEXT)
    assert "need at least 14 numbers of data but the body has 13" in str(err)


def test_check_counts_against_the_limits():
    elements = strand_file_elements()
    strands = ReadContext("h.ply", ReadLimits(max_strands=1), "m")
    err = expect_error("too_large", check_counts, elements, 100, "bytes", 0, strands)
    assert "the file declares 2 strands, above the limit of 1 (ReadLimits.max_strands)" in str(err)
    points = ReadContext("h.ply", ReadLimits(max_strands=2, max_particles=3), "m")
    err = expect_error("too_large", check_counts, elements, 100, "bytes", 0, points)
    assert "ReadLimits.max_particles" in str(err)


def test_list_item_positions():
    lengths, positions = list_item_positions([10, 30, 50], [2, 0, 3], 4)
    assert lengths.tolist() == [2, 0, 3] and positions.tolist() == [10, 14, 50, 54, 58]
    lengths, positions = list_item_positions([1, 5], [3, 1], 1)
    assert lengths.tolist() == [3, 1] and positions.tolist() == [1, 2, 3, 5]
    lengths, positions = list_item_positions([], [], 4)
    assert lengths.tolist() == [] and positions.tolist() == []
