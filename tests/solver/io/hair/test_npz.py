"""hairport's ``.npz`` hair archive (:mod:`hairport.solver.io.hair.npz`)."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest

from hairport.solver.io.hair import hair_to_bytes, read_hair, read_hair_bytes, read_hair_bytes_report, write_hair
from tests.solver.io.hair.samples import expect_error, helix_hair, npz_bytes


def test_npz_keeps_everything_exactly(tmp_path, groom):
    write_hair(tmp_path / "g.npz", groom)
    back = read_hair(tmp_path / "g.npz")
    for name in ("points", "offsets", "thickness", "color"):
        np.testing.assert_array_equal(getattr(back, name), getattr(groom, name))


def test_npz_refuses_other_units(tmp_path):
    write_hair(tmp_path / "g.npz", helix_hair(3), units="mm")
    err = expect_error("units_mismatch", read_hair, tmp_path / "g.npz")
    assert "units='mm'" in str(err)


def test_npz_is_strict_about_short_strands(tmp_path):
    buffer = io.BytesIO()
    np.savez(
        buffer,
        format=np.array("hairport-hair"),
        version=np.array(1),
        points=np.zeros((3, 3)),
        offsets=np.array([0, 2, 3]),
    )
    err = expect_error("short_strand", read_hair_bytes, buffer.getvalue(), "npz")
    assert "strand 1 has 1 point" in str(err)


@pytest.mark.parametrize(
    "arrays, code, words",
    [
        ({"format": None}, "bad_header", "no array(s) format"),
        ({"format": np.array("something-else")}, "bad_header", "not a hairport hair archive"),
        ({"version": np.array(3)}, "bad_header", "version 3"),
        ({"points": np.zeros((4, 2))}, "bad_header", "points must be (N, 3)"),
        (
            {"points": np.zeros((4, 3), dtype=np.int32)},
            "bad_header",
            "points must be (N, 3) floats",
        ),
        ({"offsets": np.array([0.0, 2.0, 4.0])}, "bad_header", "offsets must be (S+1,) integers"),
        ({"offsets": np.array([0, 3, 2, 4])}, "bad_offsets", "never decrease"),
        ({"offsets": np.array([0, 2, 5])}, "bad_offsets", "end at the point count 4"),
        ({"thickness": np.zeros(3)}, "bad_header", "thickness must be (4,)"),
        ({"color": np.zeros((4, 3), dtype=object)}, "bad_header", "Python objects"),
        ({"units": np.array("furlong")}, "bad_header", "unknown units"),
        ({"up_axis": np.array("+w")}, "bad_header", "unknown up axis '+w'"),
        ({"attributes": np.array("[{")}, "bad_header", "not a JSON list"),
        ({"attributes": np.array('[{"name": "uv", "domain": "vertex"}]')}, "bad_header", "'attribute_0' is missing"),
        ({"attributes": np.array('[{"name": "uv", "domain": "vertex"}]'), "attribute_0": np.zeros(3)},
         "bad_attribute", "'uv' (vertex) must be (4,)"),
        ({"attributes": np.array('[{"name": "g", "domain": "strand"}]'), "attribute_0": np.array(["a", "b"])},
         "bad_attribute", "'g' (strand) must be (2,)"),
        ({"attributes": np.array('[{"name": "g", "domain": "strand", "role": "x"}]'), "attribute_0": np.zeros(2)},
         "bad_header", "not a JSON list"),
        ({"attributes": np.array('[{"name": "g", "domain": "strand"}]'), "attribute_0": np.array([0, np.inf])},
         "non_finite", "attribute 'g' has a non-finite value"),
    ],
)
def test_npz_bad_archives(arrays, code, words):
    err = expect_error(code, read_hair_bytes, npz_bytes(**arrays), "npz", source="bad.npz")
    assert words in str(err)


def test_npz_marker_may_be_bytes():
    hair = read_hair_bytes(npz_bytes(format=np.array(b"hairport-hair")), "npz")
    np.testing.assert_array_equal(hair.offsets, [0, 2, 4])


def test_npz_unknown_members_are_reported():
    report = read_hair_bytes_report(npz_bytes(extra=np.arange(3)), "npz")
    assert report.warnings == ("ignored unknown array(s) extra",)


def test_npz_member_shorter_than_its_header():
    data = npz_bytes()
    source = zipfile.ZipFile(io.BytesIO(data))
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as out:
        for name in source.namelist():
            payload = source.read(name)
            out.writestr(name, payload[:-8] if name == "points.npy" else payload)
    expect_error("truncated", read_hair_bytes, buffer.getvalue(), "npz")


def test_nan_in_npz():
    buffer = io.BytesIO()
    np.savez(
        buffer,
        format=np.array("hairport-hair"),
        version=np.array(1),
        points=np.array([[0, 0, 0], [0, np.inf, 0.0]]),
        offsets=np.array([0, 2]),
    )
    expect_error("non_finite", read_hair_bytes, buffer.getvalue(), "npz")


def test_written_archive_members_in_file_units():
    hair = helix_hair(3, thickness=True)
    with np.load(io.BytesIO(hair_to_bytes(hair, "npz", units="cm"))) as arrays:
        assert sorted(arrays.files) == ["format", "offsets", "points", "thickness", "units", "up_axis", "version"]
        assert (str(arrays["format"]), int(arrays["version"]), str(arrays["units"])) == ("hairport-hair", 2, "cm")
        np.testing.assert_array_equal(arrays["points"], hair.points / 0.01)
        np.testing.assert_array_equal(arrays["thickness"], hair.thickness / 0.01)
        np.testing.assert_array_equal(arrays["offsets"], hair.offsets)


def test_archive_in_cm_read_in_cm():
    hair = helix_hair(3, thickness=True, color=True)
    back = read_hair_bytes(hair_to_bytes(hair, "npz", units="cm"), "npz", units="cm")
    np.testing.assert_array_equal(back.points, hair.points / 0.01 * 0.01)
    np.testing.assert_array_equal(back.color, hair.color)


def test_recorded_units_are_read_without_the_arrays(tmp_path, groom):
    from hairport.solver.io.hair.npz import recorded_units

    write_hair(tmp_path / "cm.npz", groom, units="cm")
    assert recorded_units(tmp_path / "cm.npz") == "cm"
    np.savez(tmp_path / "none.npz", format=np.array("hairport-hair"), version=np.array(1), points=groom.points,
             offsets=groom.offsets)
    assert recorded_units(tmp_path / "none.npz") is None
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    assert recorded_units(tmp_path / "junk.npz") is None and recorded_units(tmp_path / "missing.npz") is None
    np.savez(tmp_path / "odd.npz", units=np.array("furlong"))
    assert recorded_units(tmp_path / "odd.npz") is None
