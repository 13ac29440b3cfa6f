"""Cem Yuksel's ``.hair`` files (:mod:`hairport.solver.io.hair.yuksel`)."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from hairport.solver.io.hair import (
    ReadLimits,
    hair_to_bytes,
    read_hair,
    read_hair_bytes,
    read_hair_bytes_report,
    read_hair_report,
    write_hair,
)
from hairport.solver.io.hair.common import ReadContext
from hairport.solver.io.hair.yuksel import TYPICAL_HAIR_THICKNESS_M, array_layout, strand_counts
from tests.solver.io.hair.samples import expect_error, f32, hair_file_bytes, helix_hair, long_strand_hair, write_bytes

CONTEXT = ReadContext("s.hair", ReadLimits(), "m")


#: strands longer than the default per-strand limit (format round trips of 2^16 points)
LONG_STRANDS = ReadLimits(max_strand_particles=100_000)


def test_hair_keeps_thickness_and_color(tmp_path, groom):
    write_hair(tmp_path / "g.hair", groom)
    back = read_hair(tmp_path / "g.hair")
    np.testing.assert_array_equal(back.thickness, f32(groom.thickness))
    np.testing.assert_array_equal(back.color, f32(groom.color))


def test_written_hair_file_layout(tmp_path, groom):
    write_hair(tmp_path / "g.hair", groom)
    raw = (tmp_path / "g.hair").read_bytes()
    magic, n_strands, n_points, flags = struct.unpack_from("<4s3I", raw)
    assert (magic, n_strands, n_points, flags) == (b"HAIR", 40, groom.n_particles, 1 | 2 | 4 | 16)
    assert raw[40:48] == b"hairport"
    assert len(raw) == 128 + 2 * 40 + groom.n_particles * (12 + 4 + 12)
    segments = np.frombuffer(raw, "<u2", 40, 128)
    np.testing.assert_array_equal(segments, groom.counts - 1)


def test_hair_zero_segment_strands_are_skipped_with_their_attributes(tmp_path):
    counts = np.array([3, 1, 2, 1])
    points = np.arange(21, dtype=float).reshape(7, 3)
    thickness = np.arange(7) + 10.0
    color = np.linspace(0, 1, 21).reshape(7, 3)
    path = write_bytes(
        tmp_path, "z.hair", hair_file_bytes(counts, points, thickness=thickness, color=color)
    )
    report = read_hair_report(path)
    assert (report.skipped_strands, report.skipped_particles) == (2, 2)
    keep = np.array([0, 1, 2, 4, 5])
    np.testing.assert_array_equal(report.hair.points, points[keep])
    np.testing.assert_array_equal(report.hair.thickness, thickness[keep])
    np.testing.assert_array_equal(report.hair.color, f32(color[keep]))


def test_hair_without_segments_array_uses_default_segments(tmp_path):
    points = np.random.default_rng(0).normal(size=(15, 3))
    data = hair_file_bytes([5, 5, 5], points, segments_array=False, d_segments=4)
    hair = read_hair_bytes(data, "hair")
    np.testing.assert_array_equal(hair.offsets, [0, 5, 10, 15])
    np.testing.assert_array_equal(hair.points, f32(points))
    assert hair.thickness is None and hair.color is None  # header defaults are not expanded


def test_hair_transparency_is_read_into_an_attribute_and_written_back(tmp_path):
    points = np.arange(12.0).reshape(4, 3)
    data = hair_file_bytes([2, 2], points, transparency=[0.1, 0.2, 0.3, 0.4], color=np.ones((4, 3)))
    report = read_hair_bytes_report(data, "hair")
    assert report.hair.color.shape == (4, 3) and report.hair.thickness is None and report.warnings == ()
    transparency = report.hair.attributes["transparency"]
    assert transparency.domain == "vertex" and transparency.values.dtype == np.float32
    np.testing.assert_array_equal(transparency.values, np.float32([0.1, 0.2, 0.3, 0.4]))
    again = read_hair_bytes(hair_to_bytes(report.hair, "hair"), "hair")
    np.testing.assert_array_equal(again.attributes["transparency"].values, transparency.values)
    bad = hair_file_bytes([2, 2], points, transparency=[0.1, np.nan, 0.3, 0.4])
    expect_error("non_finite", read_hair_bytes, bad, "hair")


@pytest.mark.parametrize(
    "kwargs, code, words",
    [
        ({"magic": b"HAIX"}, "bad_header", "HAIR"),
        ({"flags": 1 | 2 | 64}, "bad_header", "unknown array flags"),
        ({"flags": 1}, "bad_header", "no points"),
        ({"point_count": 7}, "truncated", "needs"),  # announces more points than present
        ({"segments_array": False, "d_segments": 3}, "bad_header", "make(s) 8 points"),
    ],
)
def test_hair_bad_headers(kwargs, code, words):
    data = hair_file_bytes([3, 3], np.zeros((6, 3)), **kwargs)
    err = expect_error(code, read_hair_bytes, data, "hair", source="bad.hair")
    assert words in str(err) and "bad.hair" in str(err)


def test_hair_segments_disagreeing_with_point_count():
    data = hair_file_bytes([3, 3], np.zeros((6, 3)), point_count=5)[:-12]
    expect_error("bad_header", read_hair_bytes, data, "hair")


def test_inf_in_hair_points_and_thickness():
    points = np.zeros((4, 3))
    bad_points = points.copy()
    bad_points[2, 0] = np.inf
    expect_error("non_finite", read_hair_bytes, hair_file_bytes([2, 2], bad_points), "hair")
    data = hair_file_bytes([2, 2], points, thickness=[1, 1, np.nan, 1])
    err = expect_error("non_finite", read_hair_bytes, data, "hair")
    assert "thickness" in str(err)


def test_hair_format_segment_limit(tmp_path):
    expect_error("too_large", write_hair, tmp_path / "long.hair", long_strand_hair(65_537))
    write_hair(tmp_path / "ok.hair", long_strand_hair(65_536))
    assert read_hair(tmp_path / "ok.hair", limits=LONG_STRANDS).counts[0] == 65_536


def test_array_layout_sizes_in_file_order():
    f4 = np.dtype("<f4")
    assert array_layout(1 | 2 | 4 | 8 | 16, 3, 10) == [
        ("segments", 6, np.dtype("<u2")),
        ("points", 120, f4),
        ("thickness", 40, f4),
        ("transparency", 40, f4),
        ("color", 120, f4),
    ]
    assert array_layout(2 | 16, 3, 10) == [("points", 120, f4), ("color", 120, f4)]


def test_strand_counts_from_segments_or_the_default():
    counts = strand_counts(np.array([1, 0, 4], dtype="<u2"), 99, 3, 8, CONTEXT)
    assert counts.dtype == np.int64 and counts.tolist() == [2, 1, 5]
    assert strand_counts(None, 3, 2, 8, CONTEXT).tolist() == [4, 4]
    err = expect_error("bad_header", strand_counts, None, 3, 2, 9, CONTEXT)
    assert "2 strands of the default 3 segments make(s) 8 points but the header declares 9" in str(err)


def test_header_defaults_written_without_thickness_or_color():
    raw = hair_to_bytes(helix_hair(3), "hair", units="mm")
    magic, n_strands, n_points, flags, d_segments, d_thickness, d_alpha, *d_color, info = struct.unpack_from(
        "<4s4I5f88s", raw
    )
    assert (magic, n_strands, flags, d_segments) == (b"HAIR", 3, 1 | 2, 0)
    assert d_thickness == float(np.float32(TYPICAL_HAIR_THICKNESS_M / 0.001))  # 0.07 mm
    assert (d_alpha, d_color) == (0.0, [1.0, 1.0, 1.0])
    assert info.rstrip(b"\0") == b"hairport"
    assert len(raw) == 128 + 2 * 3 + 12 * n_points
