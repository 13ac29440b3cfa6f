"""Wavefront OBJ polylines (:mod:`hairport.solver.io.hair.obj`)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from hairport.solver.io.hair import ReadLimits, hair_to_bytes, read_hair_bytes, read_hair_bytes_report
from hairport.solver.io.hair.common import ReadContext
from hairport.solver.io.hair.obj import polylines, vertices
from hairport.solver.model.hair import Hair
from tests.solver.io.hair.samples import expect_error

CONTEXT = ReadContext("s.obj", ReadLimits(), "m")


def test_obj_polylines_with_relative_indices_texture_forms_and_faces():
    text = b"# two strands and a face\no hair\nv 0 0 0\nv 0 0 1\nv 0 0 2\nl 1 2 3\n"
    text += b"v 1 0 0\nv 1 0 1\nl -2/1 -1/2\nf 1 2 3\n"
    report = read_hair_bytes_report(text, "obj")
    np.testing.assert_array_equal(report.hair.offsets, [0, 3, 5])
    np.testing.assert_array_equal(report.hair.points[3:], [[1, 0, 0], [1, 0, 1]])
    assert report.warnings == ("ignored 1 'f' record(s)",)


def test_obj_vertex_colors():
    hair = read_hair_bytes(b"v 0 0 0 1 0 0\nv 0 0 1 0 1 0\nl 1 2\n", "obj")
    np.testing.assert_array_equal(hair.color, [[1, 0, 0], [0, 1, 0]])


@pytest.mark.parametrize(
    "text, code",
    [
        (b"v 0 0 0\nv 0 0 1\nl 0 1\n", "bad_index"),
        (b"v 0 0 0\nv 0 0 1\nl 1 3\n", "bad_index"),
        (b"v 0 0 0\nv 0 0 1\nl 1 x\n", "bad_value"),
        (b"v 0 0 0\nv 0 0\nl 1 2\n", "bad_value"),
        (b"v 0 0 zero\nv 0 0 1\nl 1 2\n", "bad_value"),
    ],
)
def test_obj_bad_input(text, code):
    expect_error(code, read_hair_bytes, text, "obj")


def test_nan_in_obj():
    expect_error("non_finite", read_hair_bytes, b"v 0 0 0\nv nan 1 1\nl 1 2\n", "obj")


def test_written_obj_text():
    hair = Hair(np.array([[0, 0, 0], [0, 0, 0.5], [1, 0, 0], [1, 0, 0.25], [1, 0, 0.5]]), np.array([0, 2, 5]))
    assert hair_to_bytes(hair, "obj").decode("ascii").splitlines() == [
        "# written by hairport: v lines, then one polyline (l line) per strand, root first",
        "v 0 0 0",
        "v 0 0 0.5",
        "v 1 0 0",
        "v 1 0 0.25",
        "v 1 0 0.5",
        "l 1 2",
        "l 3 4 5",
    ]


def test_polylines_resolve_relative_indices():
    index, lengths = polylines([b"1 2 3", b"-2 -1"], np.array([3, 5]), 5, CONTEXT)
    assert index.tolist() == [0, 1, 2, 3, 4] and lengths.tolist() == [3, 2]
    index, _ = polylines([b"2/7 1/8"], np.array([2]), 2, CONTEXT)
    assert index.tolist() == [1, 0]
    err = expect_error("bad_index", polylines, [b"1 -3"], np.array([2]), 2, CONTEXT)
    assert "an 'l' line refers to a vertex outside 1..2" in str(err)


def test_vertices_with_weight_or_color():
    points, color = vertices([b"1 2 3 1", b"4 5 6 1"], CONTEXT)
    assert points.tolist() == [[1, 2, 3], [4, 5, 6]] and color is None
    points, color = vertices([b"1 2 3 0.5 0.25 1"], CONTEXT)
    assert points.tolist() == [[1, 2, 3]] and color.tolist() == [[0.5, 0.25, 1.0]]
    err = expect_error("bad_value", vertices, [b"1 2", b"3 4"], CONTEXT)
    assert "'v' lines have 2 values" in str(err)


def _no_warning_read(data: bytes, code: str):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        err = expect_error(code, read_hair_bytes, data, "obj", source="x.obj")
    assert caught == []
    return str(err)


@pytest.mark.parametrize("seed", range(5))
def test_random_bytes_are_one_not_text_error(seed):
    garbage = np.random.default_rng(seed).integers(1, 256, 20_000, dtype=np.uint8).tobytes()  # no NUL byte
    message = _no_warning_read(garbage, "not_text")
    assert message.startswith("x.obj: line ") and message.endswith("is not an OBJ record: a binary or damaged file, "
                                                                   "not OBJ text (code not_text)")
    assert len(message) <= 200  # the bad line is shown escaped and cut to 16 bytes, not echoed


def test_a_nul_byte_or_an_undecodable_record_is_not_text():
    message = _no_warning_read(b"v 0 0 0\nv 0 0 1\nl 1 2\n\0\0\0", "not_text")
    assert message == "x.obj: byte 22 is a NUL byte: a binary file, not OBJ text (code not_text)"
    message = _no_warning_read(b"v 0 0 0\nv 0 0 1\nl 1 2\n\xff\xfe\xfdabc 1 2\n", "not_text")
    assert message.startswith("x.obj: line 4 ('\\xff\\xfe\\xfdabc 1 2') is not an OBJ record")


def test_an_obj_without_polylines_is_empty_hair():
    message = _no_warning_read(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "empty_hair")
    assert message == ("x.obj: no polyline ('l') records (3 vertices, 1 faces: a mesh, not hair): there is no hair "
                       "to retarget (code empty_hair)")
    message = _no_warning_read(b"# only a comment\n", "empty_hair")
    assert "no polyline ('l') records (0 vertices)" in message


def test_latin1_comments_and_a_byte_order_mark_are_text():
    hair = read_hair_bytes(b"\xef\xbb\xbf# cr\xe9\xe9 par l'artiste\nv 0 0 0\nv 0 0 1\nl 1 2\n", "obj")
    assert hair.counts.tolist() == [2]


def test_ignored_records_are_one_warning():
    tags = ("a", "b", "c", "d", "e", "f", "f", "k", "h", "g")  # "g" (groups) is ignored quietly
    kinds = b"".join(f"{tag} 1 2 3\n".encode() for tag in tags)
    report = read_hair_bytes_report(b"v 0 0 0\nv 0 0 1\nl 1 2\n" + kinds, "obj")
    assert report.warnings == ("ignored 1 'a' record(s), 1 'b' record(s), 1 'c' record(s), 1 'd' record(s), "
                               "1 'e' record(s) and 4 record(s) of 3 other kind(s)",)
