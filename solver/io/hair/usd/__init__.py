"""USD grooms (``.usda`` text, ``.usdc`` crate, ``.usd`` either): ``UsdGeom.BasisCurves`` prims, through ``usd-core``.

Read: every ``BasisCurves`` prim of the stage (or the one ``prim`` names, by name or path), in
prim order, strands concatenated. A curve
is ``curveVertexCounts`` points of ``points`` taken to world space by the prim's local-to-world
transform (the stage's default time). ``linear`` curves are the strands themselves; for
``cubic`` ones (bezier, bspline, catmullRom) the control points are read as the strand's
polyline, with a warning. ``widths`` become ``Hair.thickness`` (a width is a diameter,
thickness too) and ``primvars:displayColor`` becomes ``Hair.color``, each at vertex or
varying interpolation as they are, at uniform (one per curve) or constant (one for all)
expanded to every point. Every other numeric primvar becomes an attribute of the hairstyle
(:mod:`.primvars`), written back as a primvar; a primvar some prims lack, or string
primvars, are named in a warning and not kept; authored normals, velocities and
accelerations too (they describe the source's shape).

Units and axes: the coordinates stay in the stage's units and axes. The stage's
``metersPerUnit`` is the file's recorded length unit (:func:`recorded_units`, one of
:data:`~hairport.solver.model.units.UNITS`, like a ``.npz`` archive's): a read in other units
is refused (``units_mismatch``); a stage without a unit hairport names is refused too
(``bad_header``). ``upAxis`` is left to the input frame (``--up-axis`` or its inference, as for
every format: the body and the hair must share one frame).

Write: one ``/Groom`` ``Xform`` holding one ``linear`` ``BasisCurves`` prim ``/Groom/hair``:
counts, float32 points, widths (vertex) and ``displayColor`` (vertex) when the hairstyle has
them, every attribute as a primvar, ``metersPerUnit`` from the written units and ``upAxis`` Z when
the coordinates' up axis is +z, else Y (USD has no other). ``.usda`` is text,
``.usdc`` and ``.usd`` crate.

Bad input: bytes that USD cannot open (truncated, not USD) are ``bad_header`` naming USD's
own message; a stage without ``BasisCurves`` is ``empty_hair``; counts that disagree with the
points, negative counts, or a prim whose width or color count fits no interpolation are
``bad_index``; counts are checked against :class:`~.common.ReadLimits` before the points are
copied out of USD. USD parses in a child process under a heap limit and a time limit
(:mod:`~hairport.solver.io.sandbox`): a damaged crate file whose decoding would take gigabytes is one error, and
this process never holds more than the arrays the child hands back.

Other files: a stage naming any file (a sublayer, reference, payload, value clip or asset path) is
refused, ``external_reference``, before anything is composed, unless
``ReadLimits.allow_external_files`` (the command line: the stage is then composed from the file
itself, so relative names resolve beside it); see :mod:`~hairport.solver.io.usd.stage`. ``.usdz``
packages are not read (their extension is no hair format; their bytes under a ``.usd`` name are
not a stage: ``bad_header``).
"""

from __future__ import annotations

import os
from typing import BinaryIO

import numpy as np

from hairport.solver.io.hair.common import Animation, HairFormat, ReadContext, Strands, WriteOptions, write_through_file
from hairport.solver.io.hair.curves import CurvesPart, chosen_prims, join_parts
from hairport.solver.io.hair.sandboxed import read_bytes_in_child, read_in_child
from hairport.solver.io.hair.usd.primvars import read_primvar, write_primvars
from hairport.solver.io.usd.stage import (
    open_root_layer,
    open_stage,
    pxr_modules,
    root_layer_units,
    stage_units,
    usd_reason,
)
from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import Hair

#: the prim a written groom lives in
GROOM_PRIM = "/Groom"
CURVES_PRIM = "/Groom/hair"
#: primvars this reader turns into ``Hair`` fields or that override the prim's own widths and normals:
#: no attribute takes their names
RESERVED_PRIMVARS = ("displayColor", "widths", "normals")
#: authored attributes of a curves prim that describe its shape (a retarget makes them stale)
SHAPE_ATTRIBUTES = ("normals", "velocities", "accelerations")
#: the units a child is asked to read in when only the stage's own units are wanted: it answers
#: with a ``units_mismatch`` whose message is this followed by them
RECORDED_UNITS = "units:"


def _per_point(values: np.ndarray | None, interpolation: str, counts: np.ndarray, what: str, prim: str,
               ctx: ReadContext) -> np.ndarray | None:
    """Expand a primvar of ``interpolation`` to one row per point, or refuse a count that fits none."""
    if values is None or len(values) == 0:
        return None
    n_points, n_curves = int(counts.sum()), len(counts)
    if interpolation in ("vertex", "varying") and len(values) == n_points:
        return values
    if interpolation == "uniform" and len(values) == n_curves:
        return np.repeat(values, counts, axis=0)
    if interpolation == "constant" and len(values) == 1:
        return np.repeat(values, n_points, axis=0)
    raise ctx.error(f"{prim}: {len(values):,} {what} at {interpolation} interpolation for {n_curves:,} curves of "
                    f"{n_points:,} points", "bad_index")


def _read_curves(prim, ctx: ReadContext, totals: list[int]):
    """``(points (n, 3) float64 world, counts, thickness or None, color or None, warnings)`` of one BasisCurves prim."""
    Usd, UsdGeom, _, _, _ = pxr_modules()
    curves = UsdGeom.BasisCurves(prim)
    name = str(prim.GetPath())
    warnings: list[str] = []
    counts = np.asarray(curves.GetCurveVertexCountsAttr().Get() or [], dtype=np.int64)
    if np.any(counts < 0):
        raise ctx.error(f"{name}: a negative curveVertexCounts entry", "bad_index")
    totals[0] += len(counts)
    totals[1] += int(counts.sum())
    ctx.check_limit(totals[0], "strands")
    ctx.check_limit(totals[1], "particles")
    points = curves.GetPointsAttr().Get()
    points = np.zeros((0, 3)) if points is None else np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(points) != counts.sum():
        raise ctx.error(f"{name}: curveVertexCounts add up to {int(counts.sum()):,} points, the prim has "
                        f"{len(points):,}", "bad_index")
    kind = curves.GetTypeAttr().Get() or "cubic"
    if kind != "linear":
        basis = curves.GetBasisAttr().Get() or "bezier"
        warnings.append(f"{name}: {kind} {basis} curves: their control points are read as the strands' polylines")
    transform = np.asarray(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default()),
                           dtype=np.float64)
    # USD's matrices act on row vectors: world = [p, 1] M
    world = points @ transform[:3, :3] + transform[3, :3]
    widths = curves.GetWidthsAttr().Get()
    thickness = _per_point(None if widths is None else np.asarray(widths, dtype=np.float64),
                           curves.GetWidthsInterpolation(), counts, "widths", name, ctx)
    primvars = UsdGeom.PrimvarsAPI(prim)
    color = None
    display = primvars.GetPrimvar("displayColor")
    if display and display.HasValue():
        values = display.ComputeFlattened()
        color = _per_point(None if values is None else np.asarray(values, dtype=np.float64).reshape(-1, 3),
                           display.GetInterpolation(), counts, "displayColor values", name, ctx)
    attributes = {}
    for primvar in primvars.GetPrimvarsWithValues():
        primvar_name = str(primvar.GetPrimvarName())
        if primvar_name in RESERVED_PRIMVARS:
            continue
        found = read_primvar(primvar, counts, name, ctx)
        if isinstance(found, str):
            warnings.append(f"{name}: primvar {primvar_name!r} not kept: {found}")
        else:
            attributes[primvar_name] = found
    stale = [attribute for attribute in SHAPE_ATTRIBUTES if prim.GetAttribute(attribute).HasAuthoredValue()]
    if stale:
        warnings.append(f"{name}: {', '.join(stale)} not kept: they describe the source's shape, which a retarget "
                        "replaces")
    return CurvesPart(world, counts, thickness, color, attributes, warnings)


def read_stage(content: bytes | memoryview, ctx: ReadContext, suffix: str) -> Strands:
    """Every ``BasisCurves`` prim of a USD stage as :class:`~.common.Strands` (module notes), parsed
    by USD in a child process with bounded memory and time."""
    return read_bytes_in_child(__name__, content, suffix, ctx, "USD")


def parse_file(path: str, ctx: ReadContext) -> Strands:
    """The stage's strands (module notes); run by :mod:`~hairport.solver.io.sandbox` in its child."""
    _, _, _, _, Tf = pxr_modules()
    if ctx.units == RECORDED_UNITS:  # the root layer's alone: nothing composed (io.usd.stage notes)
        raise ctx.error(f"{RECORDED_UNITS}{root_layer_units(open_root_layer(path, ctx), ctx)}", "units_mismatch")
    stage = open_stage(path, ctx, ctx.limits.allow_external_files)
    try:
        return _strands_of(stage, ctx)
    except Tf.ErrorException as error:  # a damaged value deep in the file, met on reading it
        raise ctx.error(f"damaged USD data: {usd_reason(error, ctx)}", "bad_header") from None


def _strands_of(stage, ctx: ReadContext) -> Strands:
    _, UsdGeom, _, _, _ = pxr_modules()
    units = stage_units(stage, ctx)
    if units != ctx.units:
        raise ctx.error(f"the stage is in {units} (metersPerUnit), read as {ctx.units}", "units_mismatch")
    prims = [prim for prim in stage.Traverse() if prim.IsA(UsdGeom.BasisCurves)]
    if not prims:
        raise ctx.error("the stage has no BasisCurves prim: no hair", "empty_hair")
    prims = chosen_prims(prims, [[prim.GetName(), str(prim.GetPath())] for prim in prims], "BasisCurves prim", ctx)
    totals = [0, 0]
    parts = [_read_curves(prim, ctx, totals) for prim in prims]
    strands = join_parts(parts, "BasisCurves prims", ("widths", "displayColor", "primvar"))
    strands.up_axis = "+z" if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z else "+y"
    return strands


def recorded_units(path: str | os.PathLike[str]) -> str | None:
    """The units a USD stage records (its root layer's ``metersPerUnit``) by name; None if it cannot be
    read or records none of hairport's (the reader then says what is wrong). Read in a child, like the
    stage itself, from the root layer alone: nothing the file names is opened."""
    from hairport.solver.io.hair.common import ReadLimits

    source = os.fspath(path)
    try:
        read_in_child(__name__, source, os.path.getsize(source), ReadContext(source, ReadLimits(), RECORDED_UNITS), "USD")
    except OSError:
        return None
    except InputError as error:
        return error.problem[len(RECORDED_UNITS):] if error.code == "units_mismatch" and \
            error.problem.startswith(RECORDED_UNITS) else None
    return None


def write_stage(out: BinaryIO, hair: Hair, options: WriteOptions, suffix: str, animation: Animation | None = None
                ) -> None:
    """One linear ``BasisCurves`` prim with widths and displayColor when present (module notes); with an
    ``animation``, its points and extent time-sampled at the animation's time codes (the first frame's also as the
    default value, which readers of one frame take) and the stage's time range and rate set."""
    Usd, UsdGeom, Vt, Sdf, _ = pxr_modules()
    stage = Usd.Stage.CreateInMemory(f"groom{suffix}")
    UsdGeom.SetStageMetersPerUnit(stage, float(options.scale))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z if options.up_axis == "+z" else UsdGeom.Tokens.y)
    root = UsdGeom.Xform.Define(stage, GROOM_PRIM)
    stage.SetDefaultPrim(root.GetPrim())
    curves = UsdGeom.BasisCurves.Define(stage, CURVES_PRIM)
    curves.CreateTypeAttr(UsdGeom.Tokens.linear)
    curves.CreateCurveVertexCountsAttr(Vt.IntArray.FromNumpy(hair.counts.astype(np.int32)))
    points = (hair.points / options.scale).astype(np.float32)
    points_attribute = curves.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(points))
    extent_attribute = curves.CreateExtentAttr()
    if len(points):
        extent_attribute.Set(Vt.Vec3fArray.FromNumpy(np.stack([points.min(axis=0), points.max(axis=0)])))
    if animation is not None:
        stage.SetStartTimeCode(float(animation.times[0]))
        stage.SetEndTimeCode(float(animation.times[-1]))
        stage.SetTimeCodesPerSecond(float(animation.frames_per_second))
        for time, frame in zip(animation.times, animation.points, strict=True):
            frame = (np.asarray(frame) / options.scale).astype(np.float32)
            points_attribute.Set(Vt.Vec3fArray.FromNumpy(frame), float(time))
            if len(frame):
                extent_attribute.Set(Vt.Vec3fArray.FromNumpy(np.stack([frame.min(axis=0), frame.max(axis=0)])),
                                     float(time))
    if hair.thickness is not None:
        curves.CreateWidthsAttr(Vt.FloatArray.FromNumpy((hair.thickness / options.scale).astype(np.float32)))
        curves.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
    if hair.color is not None:
        display = curves.CreateDisplayColorPrimvar(UsdGeom.Tokens.vertex)
        display.Set(Vt.Vec3fArray.FromNumpy(hair.color.astype(np.float32)))
    write_primvars(curves.GetPrim(), hair.attributes)
    # .usd is written as crate (USD's default for it); .usda as text
    layer_format = {"format": "usda"} if suffix == ".usda" else {"format": "usdc"}
    write_through_file(out, suffix, lambda path: stage.GetRootLayer().Export(path, args=layer_format))


def _format(name: str) -> HairFormat:
    suffix = f".{name}"
    return HairFormat(
        name=name,
        read=lambda content, ctx: read_stage(content, ctx, suffix),
        write=lambda out, hair, options: write_stage(out, hair, options, suffix),
        write_frames=lambda out, hair, animation, options: write_stage(out, hair, options, suffix, animation),
        keeps_thickness=True,
        keeps_color=True,
        recorded_units=recorded_units,
        keeps_attribute=lambda attribute_name, attribute: attribute_name not in RESERVED_PRIMVARS,
        has_prims=True,
    )


#: the three USD extensions: the same reader and writer
FORMATS = tuple(_format(name) for name in ("usd", "usda", "usdc"))

