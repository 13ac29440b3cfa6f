"""USD grooms (:mod:`hairport.solver.io.hair.usd`): BasisCurves in and out, stage units and transforms, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, Vt

from hairport.solver.io.hair import ReadLimits, read_hair_bytes_report, read_hair_report, recorded_units, write_hair
from hairport.solver.model.hair import Hair, HairAttribute
from tests.solver.io.hair.samples import expect_error, helix_hair

#: integration, not unit: every USD read runs in a sandboxed child process
pytestmark = pytest.mark.integration

USD_FORMATS = ("usda", "usdc", "usd")


def stage_bytes(tmp_path, build, name="groom.usda", meters_per_unit=0.01, up="Z") -> bytes:
    """The bytes of a stage made by ``build(stage)``, in ``meters_per_unit`` and ``up`` axis."""
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
    UsdGeom.SetStageUpAxis(stage, up)
    build(stage)
    path = tmp_path / name
    stage.GetRootLayer().Export(str(path))
    return path.read_bytes()


def linear_curves(stage, path, counts, points, widths=None, width_interpolation="vertex"):
    curves = UsdGeom.BasisCurves.Define(stage, path)
    curves.CreateTypeAttr("linear")
    curves.CreateCurveVertexCountsAttr(Vt.IntArray([int(c) for c in counts]))
    curves.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, p)) for p in points]))
    if widths is not None:
        curves.CreateWidthsAttr(Vt.FloatArray([float(w) for w in widths]))
        curves.SetWidthsInterpolation(width_interpolation)
    return curves


@pytest.mark.parametrize("fmt", USD_FORMATS)
def test_round_trip_keeps_points_widths_and_colours_to_float32(tmp_path, fmt):
    hair = helix_hair(n_strands=7, thickness=True, color=True)
    path = tmp_path / f"groom.{fmt}"
    write_hair(path, hair, units="cm")
    report = read_hair_report(path, units="cm")
    assert report.format == fmt and report.warnings == () and report.up_axis == "+y"
    np.testing.assert_array_equal(report.hair.offsets, hair.offsets)
    np.testing.assert_allclose(report.hair.points, hair.points, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(report.hair.thickness, hair.thickness, rtol=1e-6)
    np.testing.assert_allclose(report.hair.color, hair.color.astype(np.float32), rtol=0, atol=0)
    assert recorded_units(path) == "cm"
    header = path.read_bytes()[:8]
    assert header.startswith(b"#usda") if fmt == "usda" else header.startswith(b"PXR-USDC")


def test_stage_units_transforms_and_interpolations_are_honoured(tmp_path):
    """Centimetres, Z-up, curves under a scaled and translated Xform, uniform widths, a constant
    colour, a second cubic prim and an extra primvar: world positions in the stage's units."""
    first = np.array([[0, 0, 0], [0, 0, 1], [0, 0, 2], [1, 0, 0], [1, 0, 1.5]], dtype=np.float32)
    second = np.array([[0, 1, 0], [0, 1, 1], [0, 1, 2], [0, 1, 3]], dtype=np.float32)

    def build(stage):
        xform = UsdGeom.Xform.Define(stage, "/character/groom")
        xform.AddTranslateOp().Set(Gf.Vec3d(10, 20, 30))
        xform.AddScaleOp().Set(Gf.Vec3f(2, 2, 2))
        curves = linear_curves(stage, "/character/groom/a", [3, 2], first, [0.01, 0.02], "uniform")
        curves.CreateDisplayColorPrimvar("constant").Set(Vt.Vec3fArray([Gf.Vec3f(0.5, 0.25, 0.125)]))
        UsdGeom.PrimvarsAPI(curves.GetPrim()).CreatePrimvar("clump", Sdf.ValueTypeNames.FloatArray, "uniform").Set(
            Vt.FloatArray([1, 2]))
        cubic = UsdGeom.BasisCurves.Define(stage, "/character/b")
        cubic.CreateTypeAttr("cubic")
        cubic.CreateBasisAttr("bspline")
        cubic.CreateCurveVertexCountsAttr(Vt.IntArray([4]))
        cubic.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, p)) for p in second]))
        cubic.CreateWidthsAttr(Vt.FloatArray([0.03]))
        cubic.SetWidthsInterpolation("constant")
        cubic.CreateDisplayColorPrimvar("vertex").Set(Vt.Vec3fArray([Gf.Vec3f(1, 0, 0)] * 4))
        UsdGeom.PrimvarsAPI(cubic.GetPrim()).CreatePrimvar("clump", Sdf.ValueTypeNames.FloatArray, "constant").Set(
            Vt.FloatArray([7]))
        UsdGeom.PrimvarsAPI(cubic.GetPrim()).CreatePrimvar("only_here", Sdf.ValueTypeNames.IntArray, "uniform").Set(
            Vt.IntArray([1]))
        UsdGeom.PrimvarsAPI(cubic.GetPrim()).CreatePrimvar("label", Sdf.ValueTypeNames.StringArray, "uniform").Set(
            Vt.StringArray(["x"]))

    data = stage_bytes(tmp_path, build)
    report = read_hair_bytes_report(data, "usda", units="cm", source="groom.usda")
    hair = report.hair
    assert report.up_axis == "+z"
    np.testing.assert_array_equal(hair.counts, [3, 2, 4])
    expected = np.concatenate([first * 2 + [10, 20, 30], second]) * 0.01
    np.testing.assert_allclose(hair.points, expected, rtol=0, atol=1e-9)
    np.testing.assert_allclose(hair.thickness, np.array([0.01] * 3 + [0.02] * 2 + [0.03] * 4) * 0.01, rtol=1e-6)
    np.testing.assert_allclose(hair.color[:5], np.tile([0.5, 0.25, 0.125], (5, 1)))
    np.testing.assert_allclose(hair.color[5:], np.tile([1.0, 0.0, 0.0], (4, 1)))
    assert any("cubic bspline" in text and "/character/b" in text for text in report.warnings)
    assert list(hair.attributes) == ["clump"] and hair.attributes["clump"].domain == "strand"
    np.testing.assert_array_equal(hair.attributes["clump"].values, np.float32([1, 2, 7]))  # uniform, then constant
    assert any("'only_here' on some BasisCurves prims only" in text for text in report.warnings)
    assert any("'label' not kept" in text and "not numbers" in text for text in report.warnings)
    expect_error("units_mismatch", read_hair_bytes_report, data, "usda", units="m", source="groom.usda")


def test_bad_usd_input_gets_one_clear_error_each(tmp_path):
    good = stage_bytes(tmp_path, lambda s: linear_curves(s, "/h", [3], [[0, 0, 0], [0, 1, 0], [0, 2, 0]]))
    expect_error("bad_header", read_hair_bytes_report, b"not usd at all", "usda", units="cm")
    usdc = tmp_path / "g.usdc"
    write_hair(usdc, helix_hair(n_strands=3))
    error = expect_error("bad_header", read_hair_bytes_report, usdc.read_bytes()[:100], "usdc", source="g.usdc")
    assert "truncated" in str(error) and "hairport-read" not in str(error) and "groom.usdc" not in str(error)
    expect_error("empty_hair", read_hair_bytes_report,
                 stage_bytes(tmp_path, lambda s: UsdGeom.Mesh.Define(s, "/body")), "usda", units="cm")
    expect_error("bad_index", read_hair_bytes_report,
                 stage_bytes(tmp_path, lambda s: linear_curves(s, "/h", [4], [[0, 0, 0], [0, 1, 0]])), "usda", units="cm")

    def primvar_of_wrong_length(stage):
        curves = linear_curves(stage, "/h", [3], [[0, 0, 0], [0, 1, 0], [0, 2, 0]])
        UsdGeom.PrimvarsAPI(curves.GetPrim()).CreatePrimvar("uv", Sdf.ValueTypeNames.TexCoord2fArray, "vertex").Set(
            Vt.Vec2fArray([Gf.Vec2f(0, 0)] * 2))

    error = expect_error("bad_attribute", read_hair_bytes_report, stage_bytes(tmp_path, primvar_of_wrong_length),
                         "usda", units="cm")
    assert "/h: primvar 'uv' has 2 values at vertex interpolation for 1 curves of 3 points" in str(error)
    expect_error("bad_index", read_hair_bytes_report, stage_bytes(
        tmp_path, lambda s: linear_curves(s, "/h", [3], [[0, 0, 0], [0, 1, 0], [0, 2, 0]], [1, 2], "vertex")),
        "usda", units="cm")
    expect_error("non_finite", read_hair_bytes_report, stage_bytes(
        tmp_path, lambda s: linear_curves(s, "/h", [3], [[0, 0, 0], [0, np.nan, 0], [0, 2, 0]])), "usda", units="cm")
    # a count of 10^9 points is refused before anything the size of it is made
    huge = stage_bytes(tmp_path, lambda s: linear_curves(s, "/h", [10**9], [[0, 0, 0], [0, 1, 0]]))
    expect_error("too_large", read_hair_bytes_report, huge, "usda", units="cm", limits=ReadLimits())
    inches = stage_bytes(tmp_path, lambda s: linear_curves(s, "/h", [2], [[0, 0, 0], [0, 1, 0]]), meters_per_unit=0.0254)
    error = expect_error("bad_header", read_hair_bytes_report, inches, "usda")
    assert "0.0254" in str(error)
    assert read_hair_bytes_report(good, "usda", units="cm").hair.n_strands == 1


def test_a_crate_file_that_makes_usd_allocate_gigabytes_is_refused_in_bounded_memory():
    """A 3.3 KB mutation of a written .usdc (files/crate_bomb.usdc) made USD's decoder take 3.4 GB
    and 6.6 s in process; parsed in the memory-limited child it is one clear error, at once."""
    import resource
    import time
    from pathlib import Path

    data = (Path(__file__).parent / "files" / "crate_bomb.usdc").read_bytes()
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    began = time.perf_counter()
    error = expect_error("bad_header", read_hair_bytes_report, data, "usdc", source="bomb.usdc")
    assert "bad_alloc" in str(error) and "bomb.usdc" in str(error)
    assert time.perf_counter() - began < 10
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before < 200 * 1024  # KB: this process stayed small
    assert resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss < 2 * 1024 * 1024  # KB: the child stayed under 2 GB


@pytest.mark.parametrize("fmt", USD_FORMATS)
def test_written_stages_pass_usd_validation(tmp_path, fmt):
    """Every validator usd-core registers (UsdValidation, the successor of UsdUtils.ComplianceChecker)
    finds nothing in a written groom; a stage without its metadata shows that they do look."""
    from pxr import UsdValidation

    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    path = tmp_path / f"groom.{fmt}"
    hair = helix_hair(5, thickness=True, color=True)
    attributes = {"uv": HairAttribute(np.zeros((hair.n_particles, 2), np.float32), "vertex", "texcoord"),
                  "groom_guide": HairAttribute(np.ones(5, np.int16), "strand"),
                  "wide": HairAttribute(np.zeros((5, 9)), "strand")}
    write_hair(path, Hair(hair.points, hair.offsets, hair.thickness, hair.color, attributes), units="cm", up_axis="z")
    assert [error.GetMessage() for error in context.Validate(Usd.Stage.Open(str(path)))] == []
    bare = Usd.Stage.CreateInMemory()
    linear_curves(bare, "/h", [2], [[0, 0, 0], [0, 1, 0]])
    assert any("metersPerUnit" in error.GetMessage() or "upAxis" in error.GetMessage()
               for error in context.Validate(bare))


def test_one_prim_is_read_by_name_or_path_and_an_unknown_one_is_named(tmp_path):
    def two_prims(stage):
        linear_curves(stage, "/groom/bangs", [2], [[0, 0, 0], [0, 1, 0]])
        linear_curves(stage, "/groom/back", [3], [[1, 0, 0], [1, 1, 0], [1, 2, 0]])

    data = stage_bytes(tmp_path, two_prims)
    assert read_hair_bytes_report(data, "usda", units="cm").hair.n_strands == 2
    for prim in ("back", "/groom/back"):
        hair = read_hair_bytes_report(data, "usda", units="cm", prim=prim).hair
        assert hair.counts.tolist() == [3]
    error = expect_error("unknown_prim", read_hair_bytes_report, data, "usda", units="cm", prim="fringe")
    assert "'/groom/bangs', '/groom/back'" in str(error)
    expect_error("unknown_prim", read_hair_bytes_report, b"", "ply", prim="back")
