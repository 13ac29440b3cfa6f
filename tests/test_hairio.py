"""Readers and writers of hair files: round trips, units, layouts and bad input.

The files under test are made here: small helical grooms, and hand-built bytes from small
independent encoders (``data_bytes``, ``hair_file_bytes``, ``ply_bytes``) so that readers
are not only checked against their own writers.
"""

from __future__ import annotations

import io
import os
import struct
import time
import tracemalloc
import warnings
import zipfile

import numpy as np
import pytest

from hairport.solver.io.hair import (
    ERROR_CODES,
    SUPPORTED_FORMATS,
    HairIOWarning,
    ReadLimits,
    hair_to_bytes,
    read_hair,
    read_hair_bytes,
    read_hair_bytes_report,
    read_hair_report,
    write_hair,
)
from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import Hair

# every (format, ascii) pair the writer can produce
WRITE_VARIANTS = [
    ("data", False),
    ("hair", False),
    ("ply", False),
    ("ply", True),
    ("npz", False),
    ("obj", False),
]
BINARY_FORMATS = ["data", "hair", "ply", "npz"]


# --------------------------------------------------------------------------------------------
# Synthetic inputs
# --------------------------------------------------------------------------------------------


def helix_hair(
    n_strands: int = 40,
    *,
    seed: int = 0,
    min_points: int = 2,
    max_points: int = 25,
    thickness: bool = False,
    color: bool = False,
) -> Hair:
    """Helical strands hanging from random roots on a 10 cm sphere, in meters."""
    rng = np.random.default_rng(seed)
    counts = rng.integers(min_points, max_points + 1, n_strands)
    offsets = np.concatenate([[0], np.cumsum(counts)])
    n = int(offsets[-1])
    t = np.arange(n) - np.repeat(offsets[:-1], counts)
    roots = rng.normal(size=(n_strands, 3))
    roots = 0.1 * roots / np.linalg.norm(roots, axis=1, keepdims=True)
    phase = np.repeat(rng.uniform(0, 2 * np.pi, n_strands), counts)
    points = np.repeat(roots, counts, axis=0) + np.stack(
        [0.01 * np.cos(0.4 * t + phase), 0.01 * np.sin(0.4 * t + phase), -0.004 * t], axis=1
    )
    thick = 8e-5 * (1.0 - 0.5 * t / max_points) if thickness else None
    rgb = rng.uniform(0, 1, (n, 3)) if color else None
    return Hair(points, offsets, thick, rgb)


def f32(values: np.ndarray) -> np.ndarray:
    """The float64 values a float32 file gives back."""
    return np.asarray(values, dtype=np.float32).astype(np.float64)


def data_bytes(strands: list[np.ndarray], n_strands: int | None = None) -> bytes:
    """USC-HairSalon bytes, encoded strand by strand with struct."""
    out = [struct.pack("<i", len(strands) if n_strands is None else n_strands)]
    for strand in strands:
        strand = np.asarray(strand, dtype=np.float64).reshape(-1, 3)
        out.append(struct.pack("<i", len(strand)))
        out.append(struct.pack(f"<{3 * len(strand)}f", *strand.ravel()))
    return b"".join(out)


def hair_file_bytes(
    counts,
    points,
    *,
    segments_array: bool = True,
    d_segments: int = 0,
    thickness=None,
    transparency=None,
    color=None,
    magic: bytes = b"HAIR",
    hair_count: int | None = None,
    point_count: int | None = None,
    flags: int | None = None,
) -> bytes:
    """Cem Yuksel HAIR bytes from the format description (header packed with struct)."""
    counts = np.asarray(counts)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if flags is None:
        flags = 2 | (1 if segments_array else 0)
        flags |= 4 if thickness is not None else 0
        flags |= 8 if transparency is not None else 0
        flags |= 16 if color is not None else 0
    header = struct.pack(
        "<4s4I5f88s",
        magic,
        len(counts) if hair_count is None else hair_count,
        len(points) if point_count is None else point_count,
        flags,
        d_segments,
        1.0,
        0.0,
        0.5,
        0.4,
        0.3,
        b"test",
    )
    assert len(header) == 128
    body = b""
    if segments_array:
        body += (counts - 1).astype("<u2").tobytes()
    body += points.astype("<f4").tobytes()
    for extra in (thickness, transparency, color):
        if extra is not None:
            body += np.asarray(extra, dtype="<f4").tobytes()
    return header + body


PLY_STRUCT = {
    "uchar": "B",
    "char": "b",
    "ushort": "H",
    "short": "h",
    "int": "i",
    "uint": "I",
    "float": "f",
    "double": "d",
}


def ply_bytes(encoding: str, elements: list[tuple[str, int, list[tuple]]]) -> bytes:
    """A PLY file, record by record.

    ``elements`` holds ``(name, count, properties)``; a property is ``(name, type, values)``
    or ``(name, ("list", count_type, item_type), list_of_lists)``.
    """
    lines = ["ply", f"format {encoding} 1.0", "comment made by test_hairio"]
    for name, count, props in elements:
        lines.append(f"element {name} {count}")
        for prop_name, kind, _ in props:
            if isinstance(kind, tuple):
                lines.append(f"property list {kind[1]} {kind[2]} {prop_name}")
            else:
                lines.append(f"property {kind} {prop_name}")
    lines.append("end_header")
    head = ("\n".join(lines) + "\n").encode("ascii")
    order = ">" if encoding == "binary_big_endian" else "<"
    body = []
    for _, count, props in elements:
        for r in range(count):
            if encoding == "ascii":
                tokens = []
                for _, kind, values in props:
                    if isinstance(kind, tuple):
                        tokens += [str(len(values[r]))] + [repr(v) for v in values[r]]
                    else:
                        tokens.append(
                            repr(values[r].item() if hasattr(values[r], "item") else values[r])
                        )
                body.append((" ".join(tokens) + "\n").encode("ascii"))
            else:
                for _, kind, values in props:
                    if isinstance(kind, tuple):
                        items = list(values[r])
                        body.append(struct.pack(order + PLY_STRUCT[kind[1]], len(items)))
                        body.append(struct.pack(order + PLY_STRUCT[kind[2]] * len(items), *items))
                    else:
                        body.append(struct.pack(order + PLY_STRUCT[kind], values[r]))
    return head + b"".join(body)


def xyz_props(points: np.ndarray) -> list[tuple]:
    return [(axis, "float", [float(v) for v in points[:, i]]) for i, axis in enumerate("xyz")]


def write_bytes(tmp_path, name: str, data: bytes):
    path = tmp_path / name
    path.write_bytes(data)
    return path


def read_quietly(path, **kwargs) -> Hair:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HairIOWarning)
        return read_hair(path, **kwargs)


def expect_error(code: str, func, *args, **kwargs) -> InputError:
    with pytest.raises(InputError) as info, warnings.catch_warnings():
        warnings.simplefilter("ignore", HairIOWarning)
        func(*args, **kwargs)
    assert info.value.code == code, f"expected {code!r}, got {info.value.code!r}: {info.value}"
    return info.value


@pytest.fixture
def groom() -> Hair:
    return helix_hair(40, thickness=True, color=True)


def variant_path(tmp_path, fmt: str, ascii: bool, stem: str = "groom"):
    return tmp_path / f"{stem}{'_ascii' if ascii else ''}.{fmt}"


# --------------------------------------------------------------------------------------------
# Round trips
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("fmt, ascii", WRITE_VARIANTS)
def test_round_trip_points_and_offsets(tmp_path, groom, fmt, ascii):
    path = variant_path(tmp_path, fmt, ascii)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HairIOWarning)  # .data/.obj drop thickness
        write_hair(path, groom, ascii=ascii)
    back = read_hair(path)
    assert back.n_strands == 40 and back.n_particles == groom.n_particles
    np.testing.assert_array_equal(back.offsets, groom.offsets)
    if fmt == "npz":
        np.testing.assert_array_equal(back.points, groom.points)  # float64, lossless
    else:
        # float32 files give back exactly the float32 rounding of every coordinate
        np.testing.assert_array_equal(
            back.points.astype(np.float32), groom.points.astype(np.float32)
        )
        assert np.abs(back.points - groom.points).max() <= 1e-7 * np.abs(groom.points).max()


def test_hair_keeps_thickness_and_color(tmp_path, groom):
    write_hair(tmp_path / "g.hair", groom)
    back = read_hair(tmp_path / "g.hair")
    np.testing.assert_array_equal(back.thickness, f32(groom.thickness))
    np.testing.assert_array_equal(back.color, f32(groom.color))


def test_npz_keeps_everything_exactly(tmp_path, groom):
    write_hair(tmp_path / "g.npz", groom)
    back = read_hair(tmp_path / "g.npz")
    for name in ("points", "offsets", "thickness", "color"):
        np.testing.assert_array_equal(getattr(back, name), getattr(groom, name))


@pytest.mark.parametrize("ascii", [False, True])
def test_ply_keeps_thickness_exactly_and_color_to_8_bits(tmp_path, groom, ascii):
    write_hair(tmp_path / "g.ply", groom, ascii=ascii)
    back = read_hair(tmp_path / "g.ply")
    np.testing.assert_array_equal(back.thickness, f32(groom.thickness))
    assert np.abs(back.color - groom.color).max() <= 0.5 / 255 + 1e-12


def test_data_and_hair_written_from_one_groom_read_equal(tmp_path, groom):
    with pytest.warns(HairIOWarning, match="no thickness or color"):
        write_hair(tmp_path / "g.data", groom)
    write_hair(tmp_path / "g.hair", groom)
    a, b = read_hair(tmp_path / "g.data"), read_hair(tmp_path / "g.hair")
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.offsets, b.offsets)
    assert a.thickness is None and b.thickness is not None


def test_ascii_and_binary_ply_read_equal(tmp_path, groom):
    write_hair(tmp_path / "a.ply", groom, ascii=True)
    write_hair(tmp_path / "b.ply", groom)
    assert (tmp_path / "a.ply").read_bytes().split(b"\n")[1] == b"format ascii 1.0"
    assert (tmp_path / "b.ply").read_bytes().split(b"\n")[1] == b"format binary_little_endian 1.0"
    a, b = read_hair(tmp_path / "a.ply"), read_hair(tmp_path / "b.ply")
    for name in ("points", "offsets", "thickness", "color"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_written_data_file_matches_independent_encoding(tmp_path):
    hair = helix_hair(7)
    write_hair(tmp_path / "g.data", hair)
    expected = data_bytes([hair.strand(s) for s in range(hair.n_strands)])
    assert (tmp_path / "g.data").read_bytes() == expected


def test_written_hair_file_layout(tmp_path, groom):
    write_hair(tmp_path / "g.hair", groom)
    raw = (tmp_path / "g.hair").read_bytes()
    magic, n_strands, n_points, flags = struct.unpack_from("<4s3I", raw)
    assert (magic, n_strands, n_points, flags) == (b"HAIR", 40, groom.n_particles, 1 | 2 | 4 | 16)
    assert raw[40:48] == b"hairport"
    assert len(raw) == 128 + 2 * 40 + groom.n_particles * (12 + 4 + 12)
    segments = np.frombuffer(raw, "<u2", 40, 128)
    np.testing.assert_array_equal(segments, groom.counts - 1)


def test_written_ply_header_layout(tmp_path, groom):
    write_hair(tmp_path / "g.ply", groom)
    head = (tmp_path / "g.ply").read_bytes().split(b"end_header\n")[0].decode().splitlines()
    n, s = groom.n_particles, groom.n_strands
    assert head[3:] == [
        f"element vertex {n}",
        "property float x",
        "property float y",
        "property float z",
        "property float thickness",
        "property uchar red",
        "property uchar green",
        "property uchar blue",
        f"element strand {s}",
        "property ushort nsegs",
        f"element edge {n - s}",
        "property int vertex1",
        "property int vertex2",
    ]


@pytest.mark.parametrize("fmt, ascii", WRITE_VARIANTS)
def test_read_hair_bytes_equals_read_hair(tmp_path, fmt, ascii):
    hair = helix_hair(12)
    data = hair_to_bytes(hair, fmt, ascii=ascii)
    path = tmp_path / f"g.{fmt}"
    write_hair(path, hair, ascii=ascii)
    assert path.read_bytes() == data or fmt == "npz"  # zip member timestamps differ
    a, b = read_hair(path), read_hair_bytes(data, fmt, source="upload")
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.offsets, b.offsets)


def test_empty_hairstyle_round_trips_with_a_warning(tmp_path):
    empty = Hair(np.zeros((0, 3)), np.zeros(1, dtype=np.int64))
    for fmt, ascii in WRITE_VARIANTS:
        path = variant_path(tmp_path, fmt, ascii, "empty")
        write_hair(path, empty, ascii=ascii)
        report = read_hair_report(path)
        assert report.hair.n_strands == 0 and report.hair.n_particles == 0
        assert any("no strand" in w for w in report.warnings)


# --------------------------------------------------------------------------------------------
# Units
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("fmt, ascii", WRITE_VARIANTS)
def test_units_cm_written_and_read_back(tmp_path, fmt, ascii):
    hair = helix_hair(10, thickness=True)
    path = variant_path(tmp_path, fmt, ascii)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HairIOWarning)
        write_hair(path, hair, units="cm", ascii=ascii)
    back = read_hair(path, units="cm")
    np.testing.assert_allclose(back.points, hair.points, rtol=2e-7, atol=1e-12)
    if fmt != "npz":  # npz refuses other units, tested below
        raw = read_quietly(path)  # the numbers in the file are centimeters
        np.testing.assert_allclose(raw.points, 100 * hair.points, rtol=2e-7)
    if fmt in ("hair", "ply", "npz"):
        np.testing.assert_allclose(back.thickness, hair.thickness, rtol=2e-7)


def test_cm_data_file_read_in_cm_gives_meters(tmp_path):
    strand = np.array([[0.0, 170.0, 5.0], [1.0, 160.0, 5.0], [2.5, 150.0, 4.0]])
    path = write_bytes(tmp_path, "cm.data", data_bytes([strand]))
    np.testing.assert_allclose(read_hair(path, units="cm").points, strand / 100, rtol=1e-15)
    np.testing.assert_allclose(read_hair(path, units="mm").points, strand / 1000, rtol=1e-15)
    np.testing.assert_array_equal(read_hair(path).points, strand)


def test_unknown_units(tmp_path):
    path = write_bytes(tmp_path, "a.data", data_bytes([np.zeros((2, 3))]))
    expect_error("unknown_units", read_hair, path, units="inch")
    expect_error("unknown_units", write_hair, tmp_path / "b.data", helix_hair(2), units="ft")


def test_npz_refuses_other_units(tmp_path):
    write_hair(tmp_path / "g.npz", helix_hair(3), units="mm")
    err = expect_error("units_mismatch", read_hair, tmp_path / "g.npz")
    assert "units='mm'" in str(err)


# --------------------------------------------------------------------------------------------
# Short strands
# --------------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------------
# .hair flags
# --------------------------------------------------------------------------------------------


def test_hair_without_segments_array_uses_default_segments(tmp_path):
    points = np.random.default_rng(0).normal(size=(15, 3))
    data = hair_file_bytes([5, 5, 5], points, segments_array=False, d_segments=4)
    hair = read_hair_bytes(data, "hair")
    np.testing.assert_array_equal(hair.offsets, [0, 5, 10, 15])
    np.testing.assert_array_equal(hair.points, f32(points))
    assert hair.thickness is None and hair.color is None  # header defaults are not expanded


def test_hair_transparency_is_read_checked_and_dropped(tmp_path):
    points = np.zeros((4, 3))
    data = hair_file_bytes([2, 2], points, transparency=[0.1, 0.2, 0.3, 0.4], color=np.ones((4, 3)))
    report = read_hair_bytes_report(data, "hair")
    assert report.hair.color.shape == (4, 3) and report.hair.thickness is None
    assert any("transparency" in w for w in report.warnings)
    with pytest.warns(HairIOWarning, match="transparency"):
        read_hair_bytes(data, "hair")
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


# --------------------------------------------------------------------------------------------
# Truncated files, trailing data, oversized headers
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "fmt, ascii", [("data", False), ("hair", False), ("ply", False), ("ply", True), ("npz", False)]
)
def test_truncated_files(tmp_path, fmt, ascii):
    hair = helix_hair(30, thickness=True, color=True)
    full = tmp_path / f"full.{fmt}"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HairIOWarning)
        write_hair(full, hair, ascii=ascii)
    data = full.read_bytes()
    cuts = {1, 2, 3, 5, 64, 127, 129, len(data) // 3, len(data) // 2, len(data) - 7}
    if not ascii:  # in text, a cut inside the last number leaves a shorter number: not detectable
        cuts.add(len(data) - 1)
    for cut in sorted(cuts):
        path = write_bytes(tmp_path, f"cut_{cut}.{fmt}", data[:cut])
        err = expect_error("truncated", read_hair, path)
        assert f"cut_{cut}.{fmt}" in str(err)


@pytest.mark.parametrize("fmt", ["data", "hair", "ply"])
def test_trailing_data(tmp_path, fmt):
    hair = helix_hair(5)
    data = hair_to_bytes(hair, fmt) + b"\x00\x00\x00\x00"
    err = expect_error("trailing_data", read_hair_bytes, data, fmt, source=f"x.{fmt}")
    assert "4 unexpected byte(s)" in str(err)


def test_trailing_numbers_in_ascii_ply():
    data = hair_to_bytes(helix_hair(5), "ply", ascii=True) + b"1 2 3\n"
    expect_error("trailing_data", read_hair_bytes, data, "ply")


def _fast_and_small(func) -> tuple[float, int]:
    tracemalloc.start()
    start = time.perf_counter()
    try:
        func()
    finally:
        elapsed = time.perf_counter() - start
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    return elapsed, peak


@pytest.mark.parametrize(
    "fmt, data",
    [
        ("data", struct.pack("<i", 2**31 - 1) + bytes(16)),  # 2^31-1 strands in a 20-byte file
        ("data", struct.pack("<2i", 1, 2**31 - 1) + bytes(12)),  # one strand of 2^31-1 points
        (
            "hair",
            hair_file_bytes([2], np.zeros((2, 3)), hair_count=2**32 - 1, point_count=2**32 - 1),
        ),
        ("hair", hair_file_bytes([2], np.zeros((2, 3)), point_count=2**32 - 1)),
        (
            "ply",
            b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000\n"
            b"property float x\nproperty float y\nproperty float z\nend_header\n" + bytes(24),
        ),
        (
            "ply",
            b"ply\nformat ascii 1.0\nelement vertex 1000000000000\n"
            b"property float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n",
        ),
        (
            "ply",
            b"ply\nformat binary_little_endian 1.0\nelement strand 3000000000\n"
            b"property list int int vertex_indices\nend_header\n" + bytes(64),
        ),
    ],
)
def test_huge_counts_fail_at_once_without_allocating(fmt, data):
    def read():
        err = expect_error("truncated", read_hair_bytes, data, fmt, source=f"huge.{fmt}")
        assert "huge" in str(err)

    elapsed, peak = _fast_and_small(read)
    assert elapsed < 0.5
    assert peak < 2_000_000  # bytes


@pytest.mark.parametrize("fmt", ["data", "hair", "ply", "npz", "obj"])
def test_counts_above_limits(fmt):
    data = hair_to_bytes(helix_hair(20, min_points=3, max_points=5), fmt)
    err = expect_error("too_large", read_hair_bytes, data, fmt, limits=ReadLimits(max_strands=19))
    assert "max_strands" in str(err)
    err = expect_error("too_large", read_hair_bytes, data, fmt, limits=ReadLimits(max_particles=59))
    assert "max_particles" in str(err)
    read_hair_bytes(data, fmt, limits=ReadLimits(max_strands=20, max_particles=100))


def test_byte_limit(tmp_path):
    path = tmp_path / "g.data"
    write_hair(path, helix_hair(5))
    size = path.stat().st_size
    expect_error("too_large", read_hair, path, limits=ReadLimits(max_bytes=size - 1))
    expect_error(
        "too_large",
        read_hair_bytes,
        path.read_bytes(),
        "data",
        limits=ReadLimits(max_bytes=size - 1),
    )
    assert read_hair(path, limits=ReadLimits(max_bytes=size)).n_strands == 5


def test_negative_counts_in_data(tmp_path):
    expect_error("bad_header", read_hair_bytes, struct.pack("<i", -3), "data")
    expect_error("bad_header", read_hair_bytes, struct.pack("<2i", 1, -1), "data")


# --------------------------------------------------------------------------------------------
# Non-finite values
# --------------------------------------------------------------------------------------------


def test_nan_in_data(tmp_path):
    strands = [np.zeros((3, 3)), np.array([[0, 0, 0], [1, np.nan, 0]])]
    path = write_bytes(tmp_path, "nan.data", data_bytes(strands))
    err = expect_error("non_finite", read_hair, path)
    assert "nan.data" in str(err) and "point 4 (strand 1)" in str(err)


def test_inf_in_hair_points_and_thickness():
    points = np.zeros((4, 3))
    bad_points = points.copy()
    bad_points[2, 0] = np.inf
    expect_error("non_finite", read_hair_bytes, hair_file_bytes([2, 2], bad_points), "hair")
    data = hair_file_bytes([2, 2], points, thickness=[1, 1, np.nan, 1])
    err = expect_error("non_finite", read_hair_bytes, data, "hair")
    assert "thickness" in str(err)


def test_nan_in_ascii_ply_obj_and_npz():
    ply = ply_bytes(
        "ascii",
        [
            ("vertex", 2, xyz_props(np.array([[0, 0, 0], [np.nan, 1, 1]]))),
            ("strand", 1, [("nsegs", "ushort", [1])]),
        ],
    )
    expect_error("non_finite", read_hair_bytes, ply, "ply")
    expect_error("non_finite", read_hair_bytes, b"v 0 0 0\nv nan 1 1\nl 1 2\n", "obj")
    buffer = io.BytesIO()
    np.savez(
        buffer,
        format=np.array("hairport-hair"),
        version=np.array(1),
        points=np.array([[0, 0, 0], [0, np.inf, 0.0]]),
        offsets=np.array([0, 2]),
    )
    expect_error("non_finite", read_hair_bytes, buffer.getvalue(), "npz")


def test_values_too_large_for_float32_are_refused_when_writing(tmp_path):
    hair = Hair(np.array([[0.0, 0, 0], [1e36, 0, 0]]), np.array([0, 2]))
    expect_error("non_finite", write_hair, tmp_path / "big.data", hair, units="mm")
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------------------------
# Formats and file names
# --------------------------------------------------------------------------------------------


def test_unknown_extension(tmp_path):
    path = write_bytes(tmp_path, "groom.abc", b"whatever")
    err = expect_error("unknown_format", read_hair, path)
    assert "'.abc'" in str(err) and "groom.abc" in str(err)
    assert all(f".{fmt}" in str(err) for fmt in SUPPORTED_FORMATS)
    expect_error("unknown_format", read_hair, write_bytes(tmp_path, "noext", b""))
    expect_error("unknown_format", write_hair, tmp_path / "out.abc", helix_hair(2))
    expect_error("unknown_format", read_hair_bytes, b"", "usd")


def test_format_argument_overrides_extension(tmp_path):
    hair = helix_hair(4)
    path = tmp_path / "groom.bin"
    write_hair(path, hair, format="data")
    np.testing.assert_array_equal(read_hair(path, format=".DATA").offsets, hair.offsets)


def test_uppercase_extension(tmp_path):
    write_hair(tmp_path / "G.HAIR", helix_hair(4))
    assert read_hair(tmp_path / "G.HAIR").n_strands == 4


def test_missing_file_is_an_input_error(tmp_path):
    err = expect_error("unreadable", read_hair, tmp_path / "nowhere.data")
    assert "nowhere.data" in str(err)


def test_content_of_another_format(tmp_path):
    data = hair_to_bytes(helix_hair(3), "data")
    expect_error("bad_header", read_hair_bytes, data + bytes(200), "hair")
    expect_error("bad_header", read_hair_bytes, data, "ply")
    expect_error("bad_header", read_hair_bytes, data, "npz")


# --------------------------------------------------------------------------------------------
# Atomic writes and writer limits
# --------------------------------------------------------------------------------------------


def test_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "groom.hair"
    write_hair(path, helix_hair(3))
    before = path.read_bytes()
    too_big = Hair(np.array([[0.0, 0, 0], [1e36, 0, 0]]), np.array([0, 2]))
    expect_error("non_finite", write_hair, path, too_big, units="mm")
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["groom.hair"]


def test_write_replaces_existing_file(tmp_path):
    path = tmp_path / "groom.data"
    write_hair(path, helix_hair(3))
    write_hair(path, helix_hair(8))
    assert read_hair(path).n_strands == 8
    assert sorted(p.name for p in tmp_path.iterdir()) == ["groom.data"]


def test_written_file_has_ordinary_permissions(tmp_path):
    path = tmp_path / "groom.npz"
    write_hair(path, helix_hair(3))
    umask = os.umask(0)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask


def test_hair_format_segment_limit(tmp_path):
    long = Hair(np.zeros((65_537, 3)) + np.arange(65_537)[:, None], np.array([0, 65_537]))
    expect_error("too_large", write_hair, tmp_path / "long.hair", long)
    ok = Hair(long.points[:-1], np.array([0, 65_536]))
    write_hair(tmp_path / "ok.hair", ok)
    assert read_hair(tmp_path / "ok.hair").counts[0] == 65_536
    write_hair(tmp_path / "long.ply", long)  # PLY switches nsegs to uint
    assert b"property uint nsegs" in (tmp_path / "long.ply").read_bytes()[:400]
    assert read_hair(tmp_path / "long.ply").counts[0] == 65_537


def test_ascii_flag_only_for_ply(tmp_path):
    with pytest.raises(ValueError, match="PLY only"):
        write_hair(tmp_path / "g.hair", helix_hair(2), ascii=True)


def test_writer_warns_about_dropped_attributes(tmp_path, groom):
    with pytest.warns(HairIOWarning, match="'obj' format has no thickness"):
        write_hair(tmp_path / "g.obj", groom)
    with warnings.catch_warnings():
        warnings.simplefilter("error", HairIOWarning)
        write_hair(tmp_path / "g.hair", groom)
        write_hair(tmp_path / "g.ply", groom)


# --------------------------------------------------------------------------------------------
# PLY layouts from other tools
# --------------------------------------------------------------------------------------------

PLY_ENCODINGS = ["ascii", "binary_little_endian", "binary_big_endian"]


def strands_of(counts, seed=0) -> tuple[np.ndarray, np.ndarray]:
    counts = np.asarray(counts)
    points = f32(np.random.default_rng(seed).normal(size=(int(counts.sum()), 3)))
    return points, np.concatenate([[0], np.cumsum(counts)])


@pytest.mark.parametrize("encoding", PLY_ENCODINGS)
@pytest.mark.parametrize("counts", [[4, 4, 4], [3, 5, 2, 6]], ids=["uniform", "varied"])
def test_ply_vertex_index_lists(encoding, counts):
    points, offsets = strands_of(counts)
    lists = [list(range(offsets[s], offsets[s + 1])) for s in range(len(counts))]
    lists[1] = lists[1][::-1]  # indices need not run in file order
    data = ply_bytes(
        encoding,
        [
            ("vertex", len(points), xyz_props(points)),
            ("curve", len(counts), [("vertex_indices", ("list", "uchar", "int"), lists)]),
        ],
    )
    hair = read_hair_bytes(data, "ply")
    np.testing.assert_array_equal(hair.offsets, offsets)
    np.testing.assert_array_equal(hair.points, points[np.concatenate(lists)])


def test_ply_index_out_of_range():
    points, _ = strands_of([2])
    data = ply_bytes(
        "ascii",
        [
            ("vertex", 2, xyz_props(points)),
            ("strand", 1, [("vertex_indices", ("list", "uchar", "int"), [[0, 2]])]),
        ],
    )
    err = expect_error("bad_index", read_hair_bytes, data, "ply")
    assert "vertex 2" in str(err)


@pytest.mark.parametrize("encoding", PLY_ENCODINGS)
def test_ply_hairutil_nsegs_layout(encoding):
    """hairutil writes ``element strand`` with ``ushort nsegs`` and uchar colors."""
    counts = [3, 2, 5]
    points, offsets = strands_of(counts)
    rgb = np.random.default_rng(1).integers(0, 256, (10, 3))
    props = xyz_props(points) + [
        (c, "uchar", [int(v) for v in rgb[:, i]]) for i, c in enumerate(("red", "green", "blue"))
    ]
    data = ply_bytes(
        encoding, [("vertex", 10, props), ("strand", 3, [("nsegs", "ushort", [2, 1, 4])])]
    )
    hair = read_hair_bytes(data, "ply")
    np.testing.assert_array_equal(hair.offsets, offsets)
    np.testing.assert_array_equal(hair.points, points)
    np.testing.assert_allclose(hair.color, rgb / 255)


def test_ply_point_count_property_and_float_colors():
    points, offsets = strands_of([2, 3])
    props = xyz_props(points) + [
        ("red", "float", [0.25] * 5),
        ("green", "float", [0.5] * 5),
        ("blue", "float", [1.0] * 5),
    ]
    data = ply_bytes(
        "binary_little_endian",
        [("vertex", 5, props), ("strands", 2, [("vertex_count", "int", [2, 3])])],
    )
    hair = read_hair_bytes(data, "ply")
    np.testing.assert_array_equal(hair.offsets, offsets)
    np.testing.assert_array_equal(hair.color, np.tile([0.25, 0.5, 1.0], (5, 1)))


def test_ply_strand_counts_must_cover_the_vertices():
    points, _ = strands_of([2, 3])
    data = ply_bytes(
        "ascii", [("vertex", 5, xyz_props(points)), ("strand", 2, [("nsegs", "ushort", [1, 1])])]
    )
    err = expect_error("bad_index", read_hair_bytes, data, "ply")
    assert "hold 4 points but there are 5 vertices" in str(err)


@pytest.mark.parametrize("encoding", PLY_ENCODINGS)
def test_ply_per_vertex_strand_id(encoding):
    points, offsets = strands_of([3, 2, 4])
    ids = [7, 7, 7, 2, 2, 9, 9, 9, 9]
    data = ply_bytes(encoding, [("vertex", 9, xyz_props(points) + [("strand_id", "int", ids)])])
    hair = read_hair_bytes(data, "ply")
    np.testing.assert_array_equal(hair.offsets, offsets)
    np.testing.assert_array_equal(hair.points, points)


def test_ply_strand_id_must_be_consecutive():
    points, _ = strands_of([4])
    data = ply_bytes(
        "ascii", [("vertex", 4, xyz_props(points) + [("strand_id", "int", [0, 0, 1, 0])])]
    )
    expect_error("bad_index", read_hair_bytes, data, "ply")


@pytest.mark.parametrize("encoding", PLY_ENCODINGS)
def test_ply_edges_only(encoding):
    points, _ = strands_of([3, 1, 2])  # vertex 3 is on no edge: a one-point strand
    v1, v2 = [4, 0, 1], [5, 1, 2]  # any order
    data = ply_bytes(
        encoding,
        [
            ("vertex", 6, xyz_props(points)),
            ("edge", 3, [("vertex1", "int", v1), ("vertex2", "int", v2)]),
        ],
    )
    report = read_hair_bytes_report(data, "ply")
    np.testing.assert_array_equal(report.hair.offsets, [0, 3, 5])
    np.testing.assert_array_equal(report.hair.points, points[[0, 1, 2, 4, 5]])
    assert report.skipped_strands == 1


def test_ply_edges_must_join_consecutive_vertices():
    points, _ = strands_of([4])
    data = ply_bytes(
        "ascii",
        [
            ("vertex", 4, xyz_props(points)),
            ("edge", 2, [("vertex1", "int", [0, 1]), ("vertex2", "int", [1, 3])]),
        ],
    )
    err = expect_error("bad_index", read_hair_bytes, data, "ply")
    assert "consecutive" in str(err)


def test_ply_edges_disagreeing_with_strands():
    points, _ = strands_of([2, 2])
    data = ply_bytes(
        "ascii",
        [
            ("vertex", 4, xyz_props(points)),
            ("strand", 2, [("nsegs", "ushort", [1, 1])]),
            ("edge", 3, [("vertex1", "int", [0, 1, 2]), ("vertex2", "int", [1, 2, 3])]),
        ],
    )
    expect_error("bad_index", read_hair_bytes, data, "ply")


def test_ply_other_elements_and_properties_are_skipped():
    """A mesh in the same file (faces of varying size) and unknown properties."""
    points, offsets = strands_of([2, 3])
    props = xyz_props(points) + [("nx", "float", [0.0] * 5), ("quality", "double", [1.5] * 5)]
    faces = [[0, 1, 2], [1, 2, 3, 4]]
    data = ply_bytes(
        "binary_little_endian",
        [
            ("vertex", 5, props),
            (
                "face",
                2,
                [("vertex_indices", ("list", "uchar", "int"), faces), ("flag", "uchar", [1, 2])],
            ),
            ("strand", 2, [("nsegs", "ushort", [1, 2])]),
        ],
    )
    hair = read_hair_bytes(data, "ply")
    np.testing.assert_array_equal(hair.offsets, offsets)


ASCII_PLY = b"ply\nformat ascii 1.0\n"
XYZ = b"property float x\nproperty float y\nproperty float z\n"


@pytest.mark.parametrize(
    "header, code",
    [
        (b"ply\nformat binary_middle_endian 1.0\nend_header\n", "bad_header"),
        (
            ASCII_PLY + b"element vertex 1\n" + XYZ[:-17] + b"end_header\n1 2\n",
            "bad_header",
        ),  # no z
        (ASCII_PLY + b"element vertex 2\n" + XYZ + b"end_header\n0 0 0 1 1 1\n", "bad_header"),
        (ASCII_PLY + b"element vertex 1\nproperty quad x\nend_header\n", "bad_header"),
        (ASCII_PLY + b"element vertex -1\nend_header\n", "bad_header"),
        (ASCII_PLY + b"property float x\nend_header\n", "bad_header"),
        (
            ASCII_PLY + b"element vertex 1\nproperty float x\nproperty float x\nend_header\n",
            "bad_header",
        ),
        (ASCII_PLY + b"element vertex 2\nproperty float x\n", "truncated"),  # no end_header
        (ASCII_PLY + b"element v 2\nproperty float x\nend_header\n1 zwei\n", "bad_value"),
        (ASCII_PLY + b"element v 1\nproperty uchar x\nend_header\n300\n", "bad_value"),
        (ASCII_PLY + b"element v 1\nproperty int x\nend_header\n1.5\n", "bad_value"),
        (b"PLY\nformat ascii 1.0\nend_header\n", "bad_header"),
    ],
)
def test_ply_bad_headers_and_values(header, code):
    err = expect_error(code, read_hair_bytes, header, "ply", source="bad.ply")
    assert str(err).startswith("bad.ply: ")


def test_ply_alpha_is_dropped_with_a_warning():
    points, _ = strands_of([2])
    data = ply_bytes(
        "ascii",
        [
            ("vertex", 2, xyz_props(points) + [("alpha", "uchar", [1, 2])]),
            ("strand", 1, [("nsegs", "ushort", [1])]),
        ],
    )
    with pytest.warns(HairIOWarning, match="alpha"):
        read_hair_bytes(data, "ply")


def test_ply_crlf_header():
    points, _ = strands_of([2])
    data = ply_bytes(
        "ascii", [("vertex", 2, xyz_props(points)), ("strand", 1, [("nsegs", "ushort", [1])])]
    )
    hair = read_hair_bytes(data.replace(b"\n", b"\r\n"), "ply")
    np.testing.assert_array_equal(hair.points, points)


# --------------------------------------------------------------------------------------------
# npz
# --------------------------------------------------------------------------------------------


def npz_bytes(**arrays) -> bytes:
    base = {
        "format": np.array("hairport-hair"),
        "version": np.array(1),
        "points": np.zeros((4, 3)),
        "offsets": np.array([0, 2, 4]),
    }
    base.update(arrays)
    buffer = io.BytesIO()
    np.savez(buffer, **{k: v for k, v in base.items() if v is not None})
    return buffer.getvalue()


@pytest.mark.parametrize(
    "arrays, code, words",
    [
        ({"format": None}, "bad_header", "no array(s) format"),
        ({"format": np.array("something-else")}, "bad_header", "not a hairport hair archive"),
        ({"version": np.array(2)}, "bad_header", "version 2"),
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


# --------------------------------------------------------------------------------------------
# OBJ
# --------------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------------
# Paths through the readers that only large or unusual files take
# --------------------------------------------------------------------------------------------


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
    a = np.zeros((2, 3))
    data = data_bytes([a, np.zeros((1, 3)), np.zeros((3, 3))])  # 2 + 1 + 3 points = 3 strands of 2
    report = read_hair_bytes_report(data, "data")
    np.testing.assert_array_equal(report.hair.counts, [2, 3])
    assert report.skipped_strands == 1


# --------------------------------------------------------------------------------------------
# Damaged files: a clear error or a hairstyle, never another exception
# --------------------------------------------------------------------------------------------


def mutate(data: bytes, rng: np.random.Generator) -> bytes:
    """Overwrite, delete, insert or bit-flip bytes at a few random places."""
    out = bytearray(data)
    for _ in range(int(rng.integers(1, 6))):
        at = int(rng.integers(0, len(out)))
        op = int(rng.integers(0, 4))
        if op == 0:
            out[at] = int(rng.integers(0, 256))
        elif op == 1:
            del out[at : at + int(rng.integers(1, 20))]
        elif op == 2:
            out[at:at] = rng.integers(0, 256, int(rng.integers(1, 10))).astype(np.uint8).tobytes()
        else:
            out[at] ^= 1 << int(rng.integers(0, 8))
    return bytes(out)


@pytest.mark.parametrize("fmt, ascii", WRITE_VARIANTS)
def test_damaged_files_give_input_errors(fmt, ascii):
    rng = np.random.default_rng(sum(map(ord, fmt)) + ascii)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HairIOWarning)
        data = hair_to_bytes(helix_hair(8, thickness=True, color=True), fmt, ascii=ascii)
        codes = set()
        for _ in range(300):
            try:
                read_hair_bytes(mutate(data, rng), fmt)
                codes.add("ok")
            except InputError as exc:
                codes.add(exc.code)
    assert codes <= {"ok", *ERROR_CODES}
    assert len(codes) >= 2  # the mutations reach more than one check


def test_bytes_format_from_the_source_name():
    data = hair_to_bytes(helix_hair(3), "hair")
    assert read_hair_bytes(data, None, source="upload.HAIR").n_strands == 3
    expect_error("unknown_format", read_hair_bytes, data, None, source="upload")
