"""USC-HairSalon ``.data`` files (:mod:`hairport.solver.io.hair.data`)."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from hairport.solver.io.hair import (
    HairIOWarning,
    ReadLimits,
    read_hair,
    read_hair_bytes,
    read_hair_bytes_report,
    read_hair_report,
    write_hair,
)
from hairport.solver.io.hair.common import ReadContext
from hairport.solver.io.hair.data import read_data, strand_counts
from tests.solver.io.hair.samples import data_bytes, expect_error, f32, helix_hair, write_bytes

CONTEXT = ReadContext("s.data", ReadLimits(), "m")


def test_written_data_file_matches_independent_encoding(tmp_path):
    hair = helix_hair(7)
    write_hair(tmp_path / "g.data", hair)
    expected = data_bytes([hair.strand(s) for s in range(hair.n_strands)])
    assert (tmp_path / "g.data").read_bytes() == expected


def test_cm_data_file_read_in_cm_gives_meters(tmp_path):
    strand = np.array([[0.0, 170.0, 5.0], [1.0, 160.0, 5.0], [2.5, 150.0, 4.0]])
    path = write_bytes(tmp_path, "cm.data", data_bytes([strand]))
    np.testing.assert_allclose(read_hair(path, units="cm").points, strand / 100, rtol=1e-15)
    np.testing.assert_allclose(read_hair(path, units="mm").points, strand / 1000, rtol=1e-15)
    np.testing.assert_array_equal(read_hair(path).points, strand)


def test_data_one_point_strands_are_skipped_counted_and_warned(tmp_path):
    rng = np.random.default_rng(3)
    counts = [5, 1, 3, 1, 1, 2, 0]
    strands = [rng.normal(size=(n, 3)) for n in counts]
    path = write_bytes(tmp_path, "salon.data", data_bytes(strands))
    report = read_hair_report(path)
    assert report.strands_in_file == 7
    assert report.skipped_strands == 4 and report.skipped_particles == 3
    np.testing.assert_array_equal(report.kept_strands, [0, 2, 5])
    np.testing.assert_array_equal(report.hair.counts, [5, 3, 2])
    np.testing.assert_array_equal(
        report.hair.points, f32(np.concatenate([strands[0], strands[2], strands[5]]))
    )
    with pytest.warns(HairIOWarning, match=r"salon\.data: skipped 4 strand"):
        read_hair(path)


def test_negative_counts_in_data(tmp_path):
    expect_error("bad_header", read_hair_bytes, struct.pack("<i", -3), "data")
    expect_error("bad_header", read_hair_bytes, struct.pack("<2i", 1, -1), "data")


def test_nan_in_data(tmp_path):
    strands = [np.zeros((3, 3)), np.array([[0, 0, 0], [1, np.nan, 0]])]
    path = write_bytes(tmp_path, "nan.data", data_bytes(strands))
    err = expect_error("non_finite", read_hair, path)
    assert "nan.data" in str(err) and "point 4 (strand 1)" in str(err)


def test_data_uniform_fast_path_and_walk_agree():
    uniform = helix_hair(50, min_points=9, max_points=9)
    strands = [uniform.strand(s) for s in range(50)]
    fast = read_hair_bytes(data_bytes(strands), "data")
    # the same strands with one point dropped from the last one force the per-strand walk
    walked = read_hair_bytes(data_bytes(strands[:-1] + [strands[-1][:-1]]), "data")
    np.testing.assert_array_equal(fast.points[:-1], walked.points)
    np.testing.assert_array_equal(fast.offsets[:-1], walked.offsets[:-1])


def test_data_uniform_layout_with_a_lying_count_is_not_misread():
    """Sizes that fit ``S`` strands of the first length, but a later count differs."""
    a = np.arange(6.0).reshape(2, 3)
    data = data_bytes([a, np.zeros((1, 3)), a[[0, 1, 0]]])  # 2 + 1 + 3 points = 3 strands of 2
    report = read_hair_bytes_report(data, "data")
    np.testing.assert_array_equal(report.hair.counts, [2, 3])
    assert report.skipped_strands == 1


def test_read_data_gives_the_file_floats_and_counts():
    strands = [np.arange(6.0).reshape(2, 3), np.arange(9.0).reshape(3, 3) + 0.5]
    raw = read_data(data_bytes(strands), CONTEXT)
    assert raw.points.dtype == np.float32
    np.testing.assert_array_equal(raw.points, np.concatenate(strands))
    assert raw.counts.tolist() == [2, 3]
    assert raw.thickness is None and raw.color is None and not raw.strict


def test_strand_counts_uniform_varied_and_empty():
    uniform = data_bytes([np.zeros((4, 3))] * 3)
    assert strand_counts(uniform, 3, CONTEXT).tolist() == [4, 4, 4]
    varied = data_bytes([np.zeros((n, 3)) for n in (2, 0, 5, 1)])
    counts = strand_counts(varied, 4, CONTEXT)
    assert counts.dtype == np.int64 and counts.tolist() == [2, 0, 5, 1]
    assert strand_counts(data_bytes([]), 0, CONTEXT).tolist() == []


def test_strand_counts_truncated_and_trailing():
    varied = data_bytes([np.zeros((n, 3)) for n in (2, 0, 5, 1)])  # counts at bytes 4, 32, 36, 100
    err = expect_error("truncated", strand_counts, varied[:38], 4, CONTEXT)
    assert "the file ends at byte 38, inside the point count of strand 2 of 4" in str(err)
    err = expect_error("truncated", strand_counts, varied[:-1], 4, CONTEXT)
    assert "strand 3 of 4 declares 1 points, which run past the end of the file (byte 115)" in str(err)
    err = expect_error("trailing_data", strand_counts, varied + b"\0", 4, CONTEXT)
    assert "1 unexpected byte(s) after the data, which ends at byte 116" in str(err)
