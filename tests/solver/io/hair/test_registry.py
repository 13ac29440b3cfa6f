"""The registry and the public API of ``hairport.solver.io.hair``: every format through
read_hair / write_hair, units, limits, file names, atomic writes and damaged files."""

from __future__ import annotations

import os
import struct
import time
import tracemalloc
import warnings

import numpy as np
import pytest

from hairport.solver.io.hair import (
    ANIMATED_FORMATS,
    ERROR_CODES,
    EXTENSIONS,
    FORMATS,
    SUPPORTED_FORMATS,
    HairIOWarning,
    ReadLimits,
    format_for_path,
    hair_to_bytes,
    read_hair,
    read_hair_bytes,
    read_hair_report,
    write_hair,
    write_hair_frames,
)
from hairport.solver.io.hair.common import Animation
from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import Hair
from tests.solver.io.hair.samples import (
    WRITE_VARIANTS,
    data_bytes,
    expect_error,
    f32,
    hair_file_bytes,
    helix_hair,
    mutate,
    read_quietly,
    variant_path,
    write_bytes,
)


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


def test_data_and_hair_written_from_one_groom_read_equal(tmp_path, groom):
    with pytest.warns(HairIOWarning, match="cannot hold thickness or color"):
        write_hair(tmp_path / "g.data", groom)
    write_hair(tmp_path / "g.hair", groom)
    a, b = read_hair(tmp_path / "g.data"), read_hair(tmp_path / "g.hair")
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.offsets, b.offsets)
    assert a.thickness is None and b.thickness is not None


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


def test_an_empty_hairstyle_is_written_but_refused_on_reading(tmp_path):
    empty = Hair(np.zeros((0, 3)), np.zeros(1, dtype=np.int64))
    for fmt, ascii in WRITE_VARIANTS:
        path = variant_path(tmp_path, fmt, ascii, "empty")
        write_hair(path, empty, ascii=ascii)
        err = expect_error("empty_hair", read_hair_report, path)
        assert str(err).startswith(f"{path}: no ") and "there is no hair to retarget" in str(err)


@pytest.mark.parametrize("fmt, ascii", WRITE_VARIANTS)
def test_units_cm_written_and_read_back(tmp_path, fmt, ascii):
    hair = helix_hair(10, thickness=True)
    path = variant_path(tmp_path, fmt, ascii)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HairIOWarning)
        write_hair(path, hair, units="cm", ascii=ascii)
    back = read_hair(path, units="cm")
    np.testing.assert_allclose(back.points, hair.points, rtol=2e-7, atol=1e-12)
    if FORMATS[fmt].recorded_units is None:  # npz and USD refuse other units than theirs, tested below and in test_usd
        raw = read_quietly(path)  # the numbers in the file are centimeters
        np.testing.assert_allclose(raw.points, 100 * hair.points, rtol=2e-7)
    if fmt in ("hair", "ply", "npz", "usd", "usda", "usdc"):
        np.testing.assert_allclose(back.thickness, hair.thickness, rtol=2e-7)


def test_unknown_units(tmp_path):
    path = write_bytes(tmp_path, "a.data", data_bytes([np.zeros((2, 3))]))
    expect_error("unknown_units", read_hair, path, units="inch")
    expect_error("unknown_units", write_hair, tmp_path / "b.data", helix_hair(2), units="ft")


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


def test_values_too_large_for_float32_are_refused_when_writing(tmp_path):
    hair = Hair(np.array([[0.0, 0, 0], [1e36, 0, 0]]), np.array([0, 2]))
    expect_error("non_finite", write_hair, tmp_path / "big.data", hair, units="mm")
    assert list(tmp_path.iterdir()) == []


def test_unknown_extension(tmp_path):
    path = write_bytes(tmp_path, "groom.fbx", b"whatever")
    err = expect_error("unknown_format", read_hair, path)
    assert "'.fbx'" in str(err) and "groom.fbx" in str(err)
    assert all(f".{fmt}" in str(err) for fmt in SUPPORTED_FORMATS)
    expect_error("unknown_format", read_hair, write_bytes(tmp_path, "noext", b""))
    expect_error("unknown_format", write_hair, tmp_path / "out.fbx", helix_hair(2))
    expect_error("unknown_format", read_hair_bytes, b"", "fbx")


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


def test_bytes_format_from_the_source_name():
    data = hair_to_bytes(helix_hair(3), "hair")
    assert read_hair_bytes(data, None, source="upload.HAIR").n_strands == 3
    expect_error("unknown_format", read_hair_bytes, data, None, source="upload")


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


def test_ascii_flag_only_for_ply(tmp_path):
    with pytest.raises(ValueError, match="PLY only"):
        write_hair(tmp_path / "g.hair", helix_hair(2), ascii=True)


def test_writer_warns_about_dropped_attributes(tmp_path, groom):
    with pytest.warns(HairIOWarning, match="'obj' format cannot hold thickness"):
        write_hair(tmp_path / "g.obj", groom)
    with warnings.catch_warnings():
        warnings.simplefilter("error", HairIOWarning)
        write_hair(tmp_path / "g.hair", groom)
        write_hair(tmp_path / "g.ply", groom)


#: formats read in the sandbox's child process, and the mutations tried on each (Alembic's first dozen reach
#: a single check)
SANDBOXED_MUTATIONS = {"usd": 12, "usda": 12, "usdc": 12, "abc": 25}


@pytest.mark.integration  # a sandboxed child process per damaged USD or Alembic file
@pytest.mark.parametrize("fmt, ascii", WRITE_VARIANTS)
def test_damaged_files_give_input_errors(fmt, ascii):
    rng = np.random.default_rng(sum(map(ord, fmt)) + ascii)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HairIOWarning)
        data = hair_to_bytes(helix_hair(8, thickness=True, color=True), fmt, ascii=ascii)
        codes = set()
        # a USD or Alembic read is a child process (about 1 s): 12 mutations already reach several checks
        # (test_usd has the crate bomb, test_alembic its own mutated archives)
        for _ in range(SANDBOXED_MUTATIONS.get(fmt, 300)):
            try:
                read_hair_bytes(mutate(data, rng), fmt)
                codes.add("ok")
            except InputError as exc:
                codes.add(exc.code)
    assert codes <= {"ok", *ERROR_CODES}
    # the mutations reach more than one check (a text USD layer with a changed byte is nearly always
    # an invalid layer: one code in 12 tries)
    assert len(codes) >= (1 if fmt == "usda" else 2)


def exact_groom() -> Hair:
    """A groom every format gives back exactly.

    Coordinates on a grid of 1/256 m below 10 m (exact in float32 and in the 9 significant
    digits of the text formats), float32 thickness, and colors of 0 or 1 (the only values
    that both float32 and the 8-bit colors of PLY hold exactly).
    """
    hair = helix_hair(25, seed=5, thickness=True)
    rgb = np.random.default_rng(5).integers(0, 2, (hair.n_particles, 3)).astype(np.float64)
    return Hair(np.round(hair.points * 4096) / 256, hair.offsets, f32(hair.thickness), rgb)


# every registered format, and its text variant where it has one
REGISTERED_VARIANTS = [(name, False) for name in FORMATS] + [
    (name, True) for name, spec in FORMATS.items() if spec.has_ascii
]


def test_supported_formats_come_from_the_registry_in_the_documented_order():
    assert SUPPORTED_FORMATS == ("data", "hair", "ply", "npz", "obj", "usd", "usda", "usdc", "abc")
    assert tuple(FORMATS) == SUPPORTED_FORMATS
    assert all(spec.name == name for name, spec in FORMATS.items())
    assert EXTENSIONS == {".data": "data", ".hair": "hair", ".ply": "ply", ".npz": "npz", ".obj": "obj", ".usd": "usd",
                          ".usda": "usda", ".usdc": "usdc", ".abc": "abc"}
    assert sorted(REGISTERED_VARIANTS) == sorted(WRITE_VARIANTS)  # the tests' list covers them all


def test_what_each_format_keeps():
    kept = {name: (s.keeps_thickness, s.keeps_color, s.has_ascii) for name, s in FORMATS.items()}
    assert kept == {
        "data": (False, False, False),
        "hair": (True, True, False),
        "ply": (True, True, True),
        "npz": (True, True, False),
        "obj": (False, True, False),
        "usd": (True, True, False),
        "usda": (True, True, False),
        "usdc": (True, True, False),
        "abc": (True, True, False),
    }


@pytest.mark.parametrize("fmt, ascii", REGISTERED_VARIANTS)
def test_every_registered_format_round_trips_a_hairstyle_exactly(tmp_path, fmt, ascii):
    hair = exact_groom()
    spec = FORMATS[fmt]
    path = tmp_path / f"groom{spec.extension}"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HairIOWarning)  # formats without thickness or color
        write_hair(path, hair, ascii=ascii)
    back = read_hair(path)
    np.testing.assert_array_equal(back.points, hair.points)
    np.testing.assert_array_equal(back.offsets, hair.offsets)
    for name, kept in (("thickness", spec.keeps_thickness), ("color", spec.keeps_color)):
        if kept:
            np.testing.assert_array_equal(getattr(back, name), getattr(hair, name))
        else:
            assert getattr(back, name) is None


def test_format_for_path_knows_every_registered_extension_and_refuses_others():
    for extension, name in EXTENSIONS.items():
        assert format_for_path(f"some/dir/groom{extension}") == name
        assert format_for_path(f"GROOM{extension.upper()}") == name
        assert format_for_path("groom.bin", extension.upper()) == name
    err = expect_error("unknown_format", format_for_path, "groom.fbx")
    assert str(err) == (
        "groom.fbx: unknown hair file type (extension '.fbx'); "
        "supported extensions: .data, .hair, .ply, .npz, .obj, .usd, .usda, .usdc, .abc"
    )
    err = expect_error("unknown_format", format_for_path, "groom.data", "fbx")
    assert str(err) == "groom.data: unknown hair format 'fbx'; supported: data, hair, ply, npz, obj, usd, usda, usdc, abc"


#: two strands (of 2 and 4 points) with every point at one place
ZERO_LENGTH = Hair(np.tile([[0.1, 1.6, 0.02]], (6, 1)), np.array([0, 2, 6]))


@pytest.mark.parametrize("fmt, ascii", WRITE_VARIANTS)
def test_a_hairstyle_of_zero_length_strands_is_refused_in_every_format(fmt, ascii):
    data = hair_to_bytes(ZERO_LENGTH, fmt, ascii=ascii)
    err = expect_error("empty_hair", read_hair_bytes, data, fmt, source=f"flat.{fmt}")
    assert str(err) == (f"flat.{fmt}: every strand (2) has zero length (all its points at one place): there is no "
                        "hair to retarget (code empty_hair)")


@pytest.mark.parametrize(
    "fmt, data",
    [
        ("data", data_bytes([])),
        ("data", data_bytes([np.zeros((1, 3)), np.ones((1, 3)), np.zeros((0, 3))])),
        ("hair", hair_file_bytes([1, 1], np.arange(6.0).reshape(2, 3))),
        ("obj", b""),
        ("obj", b"v 0 0 0\nv 0 0 1\nl 1\nl 2\n"),
    ],
    ids=["data-0-strands", "data-one-point-strands", "hair-one-point-strands", "obj-empty", "obj-one-point-lines"],
)
def test_files_without_a_strand_of_two_points_are_refused(fmt, data):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        err = expect_error("empty_hair", read_hair_bytes, data, fmt, source=f"empty.{fmt}")
    assert str(err).startswith(f"empty.{fmt}: no ") and str(err).endswith("there is no hair to retarget (code "
                                                                          "empty_hair)")
    assert caught == []  # the error says it all: no warning about skipped strands first


def _animation_frames(hair: Hair, n_frames: int) -> list[np.ndarray]:
    """Each frame the groom bent a little further about the origin (every point moves differently)."""
    frames = []
    for number in range(n_frames):
        angle = 0.05 * number
        turn = np.array([[np.cos(angle), 0.0, np.sin(angle)], [0.0, 1.0, 0.0], [-np.sin(angle), 0.0, np.cos(angle)]])
        frames.append(hair.points @ turn.T + [0.0, 0.002 * number, 0.0])
    return frames


@pytest.mark.parametrize("fmt", ANIMATED_FORMATS)
def test_an_animation_reads_back_with_its_time_samples_and_attributes(tmp_path, fmt):
    from hairport.solver.model.hair import HairAttribute

    hair = helix_hair()
    hair = Hair(hair.points, hair.offsets, np.full(hair.n_particles, 8e-5), np.full((hair.n_particles, 3), 0.25),
                {"groom_guide": HairAttribute(np.arange(hair.n_strands, dtype=np.int32) % 2, "strand")})
    frames = _animation_frames(hair, 4)
    path = tmp_path / f"anim.{fmt}"
    write_hair_frames(path, hair, Animation(np.array([1001.0, 1002.0, 1003.0, 1005.0]), frames, 30.0), units="cm")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HairIOWarning)  # an Alembic archive's samples: the first is read
        first = read_hair(path, units="cm")
    assert np.abs(first.points - frames[0]).max() < 1e-6  # a reader of one frame takes the first
    assert np.allclose(first.thickness, 8e-5) and np.array_equal(first.attributes["groom_guide"].values,
                                                                  hair.attributes["groom_guide"].values)
    samples, seconds = time_samples(path, fmt)
    assert np.allclose(seconds, np.array([1001.0, 1002.0, 1003.0, 1005.0]) / 30.0)
    for sample, frame in zip(samples, frames, strict=True):
        assert np.abs(sample * 0.01 - frame).max() < 1e-6  # centimetres


def time_samples(path, fmt) -> tuple[list[np.ndarray], np.ndarray]:
    """Every time sample of the written curves' points (file units) and its time in seconds, read by the library."""
    if fmt == "abc":
        from alembic3d import Abc, AbcGeom

        curves = Abc.IArchive(str(path)).getTop().getChild("groom").getChild("hair")
        schema = AbcGeom.ICurves(curves, Abc.WrapExistingFlag.kWrapExisting).getSchema()
        seconds = np.array([schema.getTimeSampling().getSampleTime(i) for i in range(schema.getNumSamples())])
        return [np.array(schema.getValue(Abc.ISampleSelector(t)).getPositions()) for t in seconds], seconds
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(str(path))
    attribute = UsdGeom.BasisCurves(stage.GetPrimAtPath("/Groom/hair")).GetPointsAttr()
    times = attribute.GetTimeSamples()
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (times[0], times[-1])
    return [np.array(attribute.Get(t)) for t in times], np.array(times) / stage.GetTimeCodesPerSecond()


def test_a_format_of_one_frame_refuses_an_animation(tmp_path):
    hair = helix_hair()
    with pytest.raises(InputError) as caught:
        write_hair_frames(tmp_path / "anim.npz", hair, Animation(np.arange(2.0), _animation_frames(hair, 2)))
    assert caught.value.code == "unknown_format" and "one frame" in caught.value.problem
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError):
        Animation(np.array([2.0, 1.0]), _animation_frames(hair, 2))
