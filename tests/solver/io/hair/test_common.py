"""What the format modules share (:mod:`hairport.solver.io.hair.common`)."""

from __future__ import annotations

import io

import numpy as np

from hairport.solver.io.hair import ReadLimits
from hairport.solver.io.hair.common import (
    ASCII_CHUNK_ROWS,
    ASCII_FLOAT,
    INT32_MAX,
    UINT16_MAX,
    UINT32_MAX,
    HairFormat,
    ReadContext,
    Strands,
    check_finite,
    check_fits,
    finish_read,
    no_trailing,
    parse_numbers,
    require_bytes,
    to_float32,
    write_rows,
)
from tests.solver.io.hair.samples import expect_error, helix_hair

CONTEXT = ReadContext("x.test", ReadLimits(max_strands=3, max_particles=10), "m")


def test_integer_limits_of_the_binary_formats():
    assert (UINT16_MAX, INT32_MAX, UINT32_MAX) == (65_535, 2_147_483_647, 4_294_967_295)


def test_finish_read_drops_short_strands_and_converts_units():
    points = np.arange(24, dtype=np.float32).reshape(8, 3)
    thickness = np.arange(8.0)
    raw = Strands(points, np.array([3, 1, 0, 4]), thickness=thickness, warnings=["a note"])
    report = finish_read(raw, "data", ReadContext("x.data", ReadLimits(), "cm"))
    keep = [0, 1, 2, 4, 5, 6, 7]
    assert report.hair.offsets.tolist() == [0, 3, 7]
    np.testing.assert_array_equal(report.hair.points, points[keep].astype(np.float64) * 0.01)
    np.testing.assert_array_equal(report.hair.thickness, thickness[keep] * 0.01)
    assert report.hair.color is None
    assert (report.strands_in_file, report.skipped_strands, report.skipped_particles) == (4, 2, 1)
    assert report.kept_strands.tolist() == [0, 3]
    assert (report.format, report.source) == ("data", "x.data")
    assert report.warnings[0] == "a note"
    assert report.warnings[1].startswith("skipped 2 strand(s) with fewer than 2 points (1 point(s));")


def test_finish_read_strict_and_empty():
    strict = Strands(np.zeros((3, 3)), np.array([2, 1]), strict=True)
    err = expect_error("short_strand", finish_read, strict, "npz", CONTEXT)
    assert str(err) == "x.test: strand 1 has 1 point(s); every strand needs at least 2"
    err = expect_error("empty_hair", finish_read, Strands(np.zeros((1, 3)), np.array([1])), "obj", CONTEXT)
    assert str(err) == "x.test: no strand of two or more points: there is no hair to retarget (code empty_hair)"


def test_finish_read_refuses_hair_whose_every_strand_has_zero_length():
    flat = Strands(np.ones((5, 3)), np.array([2, 3]))
    err = expect_error("empty_hair", finish_read, flat, "data", CONTEXT)
    assert "every strand (2) has zero length" in str(err) and "(code empty_hair)" in str(err)
    # one strand that moves is hair: the zero-length one is kept as it is
    moving = Strands(np.array([[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 1e-6]]), np.array([2, 2]))
    assert finish_read(moving, "data", CONTEXT).hair.counts.tolist() == [2, 2]


def test_check_finite_names_the_first_bad_point_and_its_strand():
    values = np.zeros((6, 3))
    values[4, 2] = np.nan
    values[5, 0] = np.inf
    err = expect_error("non_finite", check_finite, values, np.array([2, 2, 2]), "color", CONTEXT)
    assert str(err) == "x.test: point 4 (strand 2) has a non-finite color (NaN or inf)"
    err = expect_error("non_finite", check_finite, np.array([0, 1, np.inf]), np.array([1, 2]), "thickness", CONTEXT)
    assert "point 2 (strand 1) has a non-finite thickness" in str(err)
    check_finite(np.ones(6), np.array([6]), "thickness", CONTEXT)


def test_byte_checks_and_limits():
    require_bytes(CONTEXT, 10, 10, "the header")
    err = expect_error("truncated", require_bytes, CONTEXT, 11, 10, "the header")
    assert str(err) == "x.test: the header needs 11 bytes but the file has 10"
    no_trailing(CONTEXT, 10, 10)
    err = expect_error("trailing_data", no_trailing, CONTEXT, 8, 10)
    assert str(err) == "x.test: 2 unexpected byte(s) after the data, which ends at byte 8"
    CONTEXT.check_limit(3, "strands")
    CONTEXT.check_limit(10, "particles")
    err = expect_error("too_large", CONTEXT.check_limit, 4, "strands")
    assert "declares 4 strands, above the limit of 3 (ReadLimits.max_strands)" in str(err)
    err = expect_error("too_large", CONTEXT.check_limit, 11, "particles")
    assert "declares 11 particles, above the limit of 10 (ReadLimits.max_particles)" in str(err)


def test_parse_numbers():
    numbers = parse_numbers(b" 1 2.5\n-3e2\t4 ", np.float64, "the body", CONTEXT)
    assert numbers.dtype == np.float64 and numbers.tolist() == [1.0, 2.5, -300.0, 4.0]
    assert parse_numbers(b"7 -8", np.int64, "the body", CONTEXT).tolist() == [7, -8]
    empty = parse_numbers(b" \n ", np.int64, "the body", CONTEXT)
    assert empty.dtype == np.int64 and empty.shape == (0,)
    err = expect_error("bad_value", parse_numbers, b"1 two 3", np.float64, "the body", CONTEXT)
    assert str(err) == "x.test: the body hold(s) something that is not a number"


def test_check_fits_and_to_float32():
    hair = helix_hair(3, min_points=2, max_points=2)
    check_fits(hair, 3, 6, "data")
    expect_error("too_large", check_fits, hair, 2, 6, "data")
    err = expect_error("too_large", check_fits, hair, 3, 5, "hair")
    assert str(err) == "3 strands / 6 points do not fit the 'hair' format"
    out = to_float32(np.array([1.0, 0.1, -2.5]), "thickness")
    assert out.dtype == np.dtype("<f4") and out.flags.c_contiguous
    assert out.tolist() == [1.0, float(np.float32(0.1)), -2.5]
    err = expect_error("non_finite", to_float32, np.array([1.0, 4e38]), "thickness")
    assert str(err) == "a thickness is not finite or too large for float32"
    expect_error("non_finite", to_float32, np.array([np.nan]), "coordinate")


def test_write_rows():
    f = io.BytesIO()
    write_rows(f, [np.array([1, 2]), np.float32([0.1, 2.5])], ["%d", ASCII_FLOAT], prefix="v ")
    assert f.getvalue() == b"v 1 0.100000001\nv 2 2.5\n"
    n = ASCII_CHUNK_ROWS + 3  # more than one chunk
    f = io.BytesIO()
    write_rows(f, [np.arange(n)], ["%d"])
    assert f.getvalue() == "".join(f"{i}\n" for i in range(n)).encode("ascii")
    f = io.BytesIO()
    write_rows(f, [], [])
    assert f.getvalue() == b""


def test_hair_format_extension():
    spec = HairFormat("abc", read=None, write=None, keeps_thickness=False, keeps_color=True)
    assert spec.extension == ".abc" and spec.has_ascii is False
