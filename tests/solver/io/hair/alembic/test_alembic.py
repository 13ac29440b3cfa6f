"""Alembic grooms (:mod:`hairport.solver.io.hair.alembic`): DCC exports in and out, Unreal's groom
convention, world transforms, attributes, bad input, the optional bindings."""

from __future__ import annotations

import numpy as np
import pytest

from hairport.solver.io.hair import alembic, hair_to_bytes, read_hair_bytes_report, read_hair_report, write_hair
from hairport.solver.model.hair import Hair, HairAttribute
from tests.solver.io.hair.abc_samples import CONSTANT, UNIFORM, VERTEX, general_properties, write_groom
from tests.solver.io.hair.samples import expect_error, helix_hair, mutate

#: integration, not unit: every Alembic read runs in a sandboxed child process
pytestmark = pytest.mark.integration

POINTS = np.array([[0, 0, 0], [0, 0, 1], [0, 0, 2], [1, 0, 0], [1, 0, 1.5]], dtype=np.float32)


def test_unreal_convention_is_read_as_unreal_reads_it(tmp_path):
    path = tmp_path / "unreal.abc"
    write_groom(path, POINTS, [3, 2], translate=(10, 20, 30), widths=[9.0] * 5, params=[
        ("groom_width", "OFloatGeomParam", "FloatArray", [0.01, 0.02, 0.03, 0.04, 0.05], VERTEX),
        ("groom_color", "OC3fGeomParam", "C3fArray", [[1, 0, 0], [0, 1, 0]], UNIFORM),
        ("groom_guide", "OInt16GeomParam", "ShortArray", [0, 1], UNIFORM),
        ("groom_group_id", "OInt32GeomParam", "IntArray", [3], CONSTANT),
        ("groom_root_uv", "OV2fGeomParam", "V2fArray", [[0.5, 0.25], [0.75, 0.125]], UNIFORM),
    ])
    report = read_hair_report(path, units="cm")
    hair = report.hair
    np.testing.assert_allclose(hair.points, (POINTS + [10, 20, 30]) * 0.01, atol=1e-9)
    np.testing.assert_allclose(hair.thickness, np.float32([0.01, 0.02, 0.03, 0.04, 0.05]) * 0.01, rtol=1e-7)
    np.testing.assert_array_equal(hair.color, [[1, 0, 0]] * 3 + [[0, 1, 0]] * 2)
    assert list(hair.attributes) == ["groom_guide", "groom_group_id", "groom_root_uv"]
    assert hair.attributes["groom_guide"].values.dtype == np.int16
    np.testing.assert_array_equal(hair.attributes["groom_guide"].values, [0, 1])
    np.testing.assert_array_equal(hair.attributes["groom_group_id"].values, [3, 3])  # constant: one per curve
    assert hair.attributes["groom_root_uv"].domain == "strand"
    assert any("groom_width and the schema's widths differ" in text for text in report.warnings)


def test_a_houdini_export_without_the_convention_keeps_its_own_attributes(tmp_path):
    path = tmp_path / "houdini.abc"
    write_groom(path, POINTS, [3, 2], curve_type="kCubic", widths=[0.5], width_scope=CONSTANT, version=None, params=[
        ("Cd", "OC3fGeomParam", "C3fArray", [[0.25, 0.5, 1]] * 5, VERTEX),
        ("clump", "OFloatGeomParam", "FloatArray", [1.5, 2.5], UNIFORM),
    ])
    report = read_hair_report(path)
    assert report.hair.color is None
    np.testing.assert_array_equal(report.hair.thickness, [0.5] * 5)
    assert report.hair.attributes["Cd"].role == "color" and report.hair.attributes["Cd"].values.dtype == np.float32
    np.testing.assert_array_equal(report.hair.attributes["clump"].values, np.float32([1.5, 2.5]))
    assert any("cubic curves: their control points" in text for text in report.warnings)


def test_hairport_writes_unreal_convention_with_every_attribute(tmp_path):
    hair = helix_hair(n_strands=5)
    rng = np.random.default_rng(2)
    attributes = {
        "groom_guide": HairAttribute((np.arange(5) % 2).astype(np.int16), "strand"),
        "groom_id": HairAttribute(np.arange(5, dtype=np.int32), "strand"),
        "groom_root_uv": HairAttribute(rng.random((5, 2)).astype(np.float32), "strand", "texcoord"),
        "density": HairAttribute(rng.random(hair.n_particles), "vertex"),
        "matrix": HairAttribute(rng.random((5, 16)).astype(np.float32), "strand"),
    }
    hair = Hair(hair.points, hair.offsets, rng.random(hair.n_particles) * 1e-4,
                rng.random((hair.n_particles, 3)).astype(np.float32), attributes)
    path = tmp_path / "out.abc"
    write_hair(path, hair, units="cm")
    assert general_properties(path) == {"groom_version_major": ("kInt16POD", 1),
                                        "groom_version_minor": ("kInt16POD", 4),
                                        "groom_tool": ("kStringPOD", general_properties(path)["groom_tool"][1])}
    back = read_hair_report(path, units="cm")
    assert back.warnings == ()
    np.testing.assert_array_equal((back.hair.points / 0.01).astype(np.float32), (hair.points / 0.01).astype(np.float32))
    np.testing.assert_allclose(back.hair.thickness, hair.thickness, rtol=1e-7)
    np.testing.assert_array_equal(back.hair.color, hair.color)
    for name, attribute in attributes.items():
        got = back.hair.attributes[name]
        assert (got.domain, got.role, got.values.dtype) == (attribute.domain, attribute.role, attribute.values.dtype)
        np.testing.assert_array_equal(got.values, attribute.values)


def test_bad_alembic_input_gets_one_clear_error_each(tmp_path):
    expect_error("bad_header", read_hair_bytes_report, b"not alembic at all", "abc")
    good = hair_to_bytes(helix_hair(n_strands=3), "abc")
    expect_error("bad_header", read_hair_bytes_report, good[: len(good) // 2], "abc")
    empty = tmp_path / "empty.abc"
    from alembic3d import Abc, AbcGeom

    archive = Abc.OArchive(str(empty))
    AbcGeom.OXform(archive.getTop(), "nothing")
    del archive
    expect_error("empty_hair", read_hair_bytes_report, empty.read_bytes(), "abc")
    nan = tmp_path / "nan.abc"
    write_groom(nan, np.array([[0, 0, 0], [0, np.nan, 1]], dtype=np.float32), [2])
    expect_error("non_finite", read_hair_report, nan)
    wrong = tmp_path / "wrong.abc"
    write_groom(wrong, POINTS, [3, 2], params=[("clump", "OFloatGeomParam", "FloatArray", [1.0, 2.0, 3.0], UNIFORM)])
    error = expect_error("bad_attribute", read_hair_report, wrong)
    assert "'clump' has 3 values at uni scope for 2 curves" in str(error)


def test_mutated_archives_are_refused_cleanly_or_read(tmp_path):
    good = hair_to_bytes(helix_hair(n_strands=4), "abc")
    rng = np.random.default_rng(7)
    for _ in range(12):
        try:
            read_hair_bytes_report(mutate(good, rng), "abc", source="m.abc")
        except Exception as error:  # noqa: BLE001 - the assertion names what escaped
            assert type(error).__name__ == "InputError", repr(error)


def test_without_the_bindings_abc_is_one_error_naming_the_extra(monkeypatch):
    monkeypatch.setattr(alembic.importlib.util, "find_spec", lambda name: None)
    error = expect_error("format_unavailable", read_hair_bytes_report, b"x", "abc", source="g.abc")
    assert "pip install 'hairport[alembic]'" in str(error)
    with pytest.raises(Exception, match=r"hairport\[alembic\]"):
        hair_to_bytes(helix_hair(n_strands=2), "abc")


def test_one_curves_object_is_read_by_name_or_path(tmp_path):
    path = tmp_path / "g.abc"
    write_groom(path, POINTS, [3, 2])
    assert read_hair_report(path, prim="curves").hair.n_strands == 2
    assert read_hair_report(path, prim="/groom_xform/curves").hair.n_strands == 2
    assert "'/groom_xform/curves'" in str(expect_error("unknown_prim", read_hair_report, path, prim="hair"))
