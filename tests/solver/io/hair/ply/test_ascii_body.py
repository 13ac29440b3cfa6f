"""ASCII PLY bodies (:mod:`hairport.solver.io.hair.ply.ascii_body`)."""

from __future__ import annotations

import numpy as np
import pytest

from hairport.solver.io.hair import ReadLimits, hair_to_bytes, read_hair_bytes
from hairport.solver.io.hair.common import ReadContext
from hairport.solver.io.hair.ply.ascii_body import cast, list_length, read_ascii_body
from hairport.solver.io.hair.ply.header import PlyElement, PlyProperty, parse_header
from tests.solver.io.hair.samples import ASCII_PLY, expect_error, helix_hair, ply_bytes, xyz_props

CONTEXT = ReadContext("a.ply", ReadLimits(), "m")


def test_trailing_numbers_in_ascii_ply():
    data = hair_to_bytes(helix_hair(5), "ply", ascii=True) + b"1 2 3\n"
    expect_error("trailing_data", read_hair_bytes, data, "ply")


@pytest.mark.parametrize(
    "header",
    [
        ASCII_PLY + b"element v 2\nproperty float x\nend_header\n1 zwei\n",
        ASCII_PLY + b"element v 1\nproperty uchar x\nend_header\n300\n",
        ASCII_PLY + b"element v 1\nproperty int x\nend_header\n1.5\n",
    ],
)
def test_ply_bad_values(header):
    err = expect_error("bad_value", read_hair_bytes, header, "ply", source="bad.ply")
    assert str(err).startswith("bad.ply: ")


def test_nan_in_ascii_ply():
    ply = ply_bytes(
        "ascii",
        [
            ("vertex", 2, xyz_props(np.array([[0, 0, 0], [np.nan, 1, 1]]))),
            ("strand", 1, [("nsegs", "ushort", [1])]),
        ],
    )
    expect_error("non_finite", read_hair_bytes, ply, "ply")


@pytest.mark.parametrize("lists", [[[0, 1, 2], [3, 4, 5]], [[0, 1, 2], [3, 4]]], ids=["uniform", "varied"])
def test_ascii_body_lists_and_scalars(lists):
    data = ply_bytes(
        "ascii",
        [("strand", 2, [("vertex_indices", ("list", "uchar", "int"), lists), ("flag", "short", [-7, 8])])],
    )
    _, elements, body_at = parse_header(data, CONTEXT)
    values = read_ascii_body(data, body_at, elements, CONTEXT)["strand"]
    assert values["vertex_indices"].lengths.tolist() == [len(item) for item in lists]
    assert values["vertex_indices"].values.dtype == np.int32
    assert values["vertex_indices"].values.tolist() == sum(lists, [])
    assert values["flag"].dtype == np.int16 and values["flag"].tolist() == [-7, 8]


def test_ascii_body_runs_short():
    data = ply_bytes("ascii", [("strand", 2, [("vertex_indices", ("list", "uchar", "int"), [[0, 1], [2, 3, 4]])])])
    _, elements, body_at = parse_header(data, CONTEXT)
    err = expect_error("truncated", read_ascii_body, data[:-4], body_at, elements, CONTEXT)
    assert "record 1 of element 'strand' runs past the end of the file" in str(err)


def test_cast_to_the_property_type():
    element = PlyElement("vertex", 2)
    uchar = PlyProperty("red", np.dtype("u1"))
    out = cast(np.array([0.0, 255.0]), uchar, element, CONTEXT)
    assert out.dtype == np.uint8 and out.tolist() == [0, 255]
    err = expect_error("bad_value", cast, np.array([1.0, 256.0]), uchar, element, CONTEXT)
    assert "property 'red' of element 'vertex' holds" in str(err) and "not a uint8" in str(err)
    expect_error("bad_value", cast, np.array([np.nan]), uchar, element, CONTEXT)
    big_endian_float = PlyProperty("x", np.dtype(">f4"))
    out = cast(np.array([0.1]), big_endian_float, element, CONTEXT)
    assert out.dtype == np.dtype("=f4") and out[0] == np.float32(0.1)


def test_list_length_is_a_whole_count():
    element = PlyElement("strand", 1)
    assert list_length(3.0, element, CONTEXT) == 3
    for bad in (-1.0, 2.5, np.inf):
        err = expect_error("bad_value", list_length, bad, element, CONTEXT)
        assert "in element 'strand' is not a count" in str(err)
