"""Binary PLY bodies (:mod:`hairport.solver.io.hair.ply.binary_body`)."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from hairport.solver.io.hair import ReadLimits
from hairport.solver.io.hair.common import ReadContext
from hairport.solver.io.hair.ply.binary_body import gather, read_binary_body, uniform_lists
from hairport.solver.io.hair.ply.header import parse_header
from tests.solver.io.hair.samples import expect_error, ply_bytes, xyz_props

CONTEXT = ReadContext("b.ply", ReadLimits(), "m")


def body_values(encoding: str, elements: list) -> dict:
    """A PLY file from ``ply_bytes``, its header parsed and its binary body read."""
    data = ply_bytes(encoding, elements)
    _, parsed, body_at = parse_header(data, CONTEXT)
    byte_order = ">" if encoding == "binary_big_endian" else "<"
    return read_binary_body(data, body_at, parsed, byte_order, CONTEXT)


@pytest.mark.parametrize("lists", [[[0, 1, 2], [3, 4, 5]], [[0, 1, 2], [3, 4]]], ids=["uniform", "varied"])
@pytest.mark.parametrize("encoding", ["binary_little_endian", "binary_big_endian"])
def test_binary_body_lists_and_scalars(encoding, lists):
    values = body_values(
        encoding,
        [("strand", 2, [("vertex_indices", ("list", "ushort", "int"), lists), ("flag", "short", [-7, 8])])],
    )["strand"]
    assert values["vertex_indices"].lengths.tolist() == [len(item) for item in lists]
    assert values["vertex_indices"].values.tolist() == sum(lists, [])
    assert values["flag"].tolist() == [-7, 8]


def test_uniform_lists_read_only_equal_lengths():
    for lists, uniform in (([[0, 1], [2, 3]], True), ([[0, 1], [2]], False), ([[], []], False)):
        data = ply_bytes("binary_little_endian", [("s", 2, [("i", ("list", "uchar", "int"), lists)])])
        _, elements, body_at = parse_header(data, CONTEXT)
        read = uniform_lists(data, body_at, elements[0], "<")
        assert (read is not None) == uniform
        if uniform:
            table, end = read
            assert end == len(data) and table["i"].values.tolist() == [0, 1, 2, 3]


def test_scalar_table_big_endian():
    points = np.array([[0.5, -1.0, 2.0], [3.0, 4.25, -5.5]])
    values = body_values("binary_big_endian", [("vertex", 2, xyz_props(points))])["vertex"]
    np.testing.assert_array_equal(np.stack([values[a] for a in "xyz"], axis=1), points)


def test_negative_list_length_and_records_past_the_end():
    head = b"ply\nformat binary_little_endian 1.0\nelement strand 1\nproperty list char int i\nend_header\n"
    _, elements, body_at = parse_header(head, CONTEXT)
    err = expect_error("bad_header", read_binary_body, head + b"\xff", body_at, elements, "<", CONTEXT)
    assert "record 0 of element 'strand' has a negative list length" in str(err)
    short = head + b"\x05" + bytes(8)  # five items announced, two present
    err = expect_error("truncated", read_binary_body, short, body_at, elements, "<", CONTEXT)
    assert "record 0 of element 'strand' runs past the end of the file" in str(err)
    whole = head + b"\x02" + bytes(8)
    assert read_binary_body(whole, body_at, elements, "<", CONTEXT)["strand"]["i"].values.tolist() == [0, 0]
    err = expect_error("trailing_data", read_binary_body, whole + bytes(3), body_at, elements, "<", CONTEXT)
    assert "3 unexpected byte(s)" in str(err)


def test_gather_values_at_byte_offsets():
    raw = np.frombuffer(struct.pack(">hHi", -2, 7, 123456), dtype=np.uint8)
    assert gather(raw, np.array([0], dtype=np.int64), np.dtype(">i2")).tolist() == [-2]
    assert gather(raw, np.array([0, 2], dtype=np.int64), np.dtype(">u2")).tolist() == [65534, 7]
    assert gather(raw, np.array([4], dtype=np.int64), np.dtype(">i4")).tolist() == [123456]
