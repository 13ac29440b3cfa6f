"""USD grooms (``.usda`` text, ``.usdc`` crate, ``.usd`` either): ``UsdGeom.BasisCurves`` prims, through ``usd-core``.

Read: every ``BasisCurves`` prim of the stage, in prim order, strands concatenated. A curve
is ``curveVertexCounts`` points of ``points`` taken to world space by the prim's local-to-world
transform (the stage's default time). ``linear`` curves are the strands themselves; for
``cubic`` ones (bezier, bspline, catmullRom) the control points are read as the strand's
polyline, with a warning. ``widths`` become ``Hair.thickness`` (a width is a diameter,
thickness too) and ``primvars:displayColor`` becomes ``Hair.color``, each at vertex or
varying interpolation as they are, at uniform (one per curve) or constant (one for all)
expanded to every point. Other primvars are named in a warning and not kept.

Units and axes: the coordinates stay in the stage's units and axes. The stage's
``metersPerUnit`` is the file's recorded length unit (:func:`recorded_units`, one of
:data:`~hairport.solver.model.units.UNITS`, like a ``.npz`` archive's): a read in other units
is refused (``units_mismatch``); a stage without a unit hairport names is refused too
(``bad_header``). ``upAxis`` is left to the input frame (``--up-axis`` or its inference, as for
every format: the body and the hair must share one frame).

Write: one ``/Groom`` ``Xform`` holding one ``linear`` ``BasisCurves`` prim ``/Groom/hair``:
counts, float32 points, widths (vertex) and ``displayColor`` (vertex) when the hairstyle has
them, ``metersPerUnit`` from the written units and ``upAxis`` Y. ``.usda`` is text,
``.usdc`` and ``.usd`` crate.

Bad input: bytes that USD cannot open (truncated, not USD) are ``bad_header`` naming USD's
own message; a stage without ``BasisCurves`` is ``empty_hair``; counts that disagree with the
points, negative counts, or a prim whose width or color count fits no interpolation are
``bad_index``; counts are checked against :class:`~.common.ReadLimits` before the points are
copied out of USD. USD parses in a child process (``python -m hairport.solver.io.hair.usd``)
under a heap limit and a time limit (:data:`CHILD_BASE_BYTES`, :data:`CHILD_SECONDS`): a
damaged crate file whose decoding would take gigabytes is one error, and this process never
holds more than the arrays the child hands back.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
from typing import BinaryIO

import numpy as np

from hairport.solver.io.hair.common import HairFormat, ReadContext, Strands, WriteOptions, check_finite
from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import Hair
from hairport.solver.model.units import METERS_PER_UNIT

#: the prim a written groom lives in
GROOM_PRIM = "/Groom"
CURVES_PRIM = "/Groom/hair"
#: a stage's metersPerUnit names a hairport unit when it is within this relative distance of it
UNIT_TOLERANCE = 1e-6
#: primvars this reader turns into ``Hair`` fields (the others are named in a warning)
KEPT_PRIMVARS = ("displayColor",)
#: USD parses in a child process under a heap limit and a time limit: a damaged crate file can
#: make USD's decoder allocate without bound (a mutated 2 KB file took 5 GB and 6 s here). The
#: limit is this much for Python and USD themselves ...
CHILD_BASE_BYTES = 768 * 2**20
#: ... plus this many times the file's size (a crate file's arrays expand a few times at most:
#: floats are stored raw, only integer arrays are compressed), at least CHILD_MIN_DATA_BYTES
CHILD_BYTES_PER_FILE_BYTE = 100
CHILD_MIN_DATA_BYTES = 256 * 2**20
#: seconds a child may parse before it is stopped (code ``too_large``)
CHILD_SECONDS = 60
#: the child's exit status when it reports an input error (its code and message on stdout, JSON)
CHILD_INPUT_ERROR = 3
#: the units a child is asked to read in when only the stage's own units are wanted: it answers
#: with a ``units_mismatch`` whose message is this followed by them
RECORDED_UNITS = "units:"


def _pxr():
    """``(Usd, UsdGeom, Vt, Sdf, Tf)``; usd-core is a dependency, imported only where USD is read or written."""
    from pxr import Sdf, Tf, Usd, UsdGeom, Vt

    return Usd, UsdGeom, Vt, Sdf, Tf


def unit_of(meters_per_unit: float) -> str | None:
    """The name in :data:`METERS_PER_UNIT` of a stage's ``metersPerUnit``, or None."""
    for name, scale in METERS_PER_UNIT.items():
        if abs(meters_per_unit - scale) <= UNIT_TOLERANCE * scale:
            return name
    return None


def _open_stage(path: str, ctx: ReadContext):
    """The stage of the USD file at ``path``."""
    Usd, _, _, _, Tf = _pxr()
    try:
        stage = Usd.Stage.Open(path, Usd.Stage.LoadAll)
    except Tf.ErrorException as error:
        raise ctx.error(f"not a readable USD stage: {_reason(error, ctx)}", "bad_header") from None
    if stage is None:
        raise ctx.error("not a readable USD stage", "bad_header")
    return stage


def _reason(error: Exception, ctx: ReadContext) -> str:
    """USD's own reason (quoted after its source locations), our temporary file's name replaced by the source's."""
    try:
        text = str(error)
    except UnicodeError:  # USD quotes the damaged bytes themselves
        text = ""
    reasons = re.findall(r" : '(.*?)'(?= Error in |$)", " ".join(text.split()))
    reason = reasons[0] if reasons else "unknown"
    reason = re.sub(r"/\S*hairport-usd-\S*?/groom\.usd[ac]?", os.path.basename(ctx.source), reason)
    return reason[:200]


def _stage_units(stage, ctx: ReadContext) -> str:
    _, UsdGeom, _, _, _ = _pxr()
    meters = float(UsdGeom.GetStageMetersPerUnit(stage))
    unit = unit_of(meters)
    if unit is None:
        known = ", ".join(f"{name} ({scale:g})" for name, scale in METERS_PER_UNIT.items())
        raise ctx.error(f"the stage's metersPerUnit {meters:g} is none of hairport's units: {known}", "bad_header")
    return unit


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
    Usd, UsdGeom, _, _, _ = _pxr()
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
    dropped = sorted(p.GetPrimvarName() for p in primvars.GetPrimvarsWithValues()
                     if p.GetPrimvarName() not in KEPT_PRIMVARS)
    if dropped:
        warnings.append(f"{name}: primvars not kept: {', '.join(dropped)}")
    return world, counts, thickness, color, warnings


def read_stage(content: bytes | memoryview, ctx: ReadContext, suffix: str) -> Strands:
    """Every ``BasisCurves`` prim of a USD stage as :class:`~.common.Strands` (module notes), parsed
    by USD in a child process with bounded memory and time."""
    with tempfile.TemporaryDirectory(prefix="hairport-usd-") as folder:
        source = os.path.join(folder, f"groom{suffix}")
        with open(source, "wb") as handle:
            handle.write(content)
        strands = _read_in_child(source, len(content), ctx)
    check_finite(strands.points, strands.counts, "coordinate", ctx)
    if strands.thickness is not None:
        check_finite(strands.thickness, strands.counts, "width", ctx)
    if strands.color is not None:
        check_finite(strands.color, strands.counts, "color", ctx)
    return strands


def _read_in_child(source: str, size: int, ctx: ReadContext) -> Strands:
    """:func:`_strands_of` the USD file ``source`` of ``size`` bytes, run by :func:`_child_main` under
    its heap and time limits; the child's input errors raised here."""
    heap = CHILD_BASE_BYTES + max(CHILD_MIN_DATA_BYTES, CHILD_BYTES_PER_FILE_BYTE * size)
    with tempfile.TemporaryDirectory(prefix="hairport-usd-") as folder:
        result = os.path.join(folder, "strands.npz")
        command = [sys.executable, "-m", "hairport.solver.io.hair.usd", source, result, ctx.units,
                   str(ctx.limits.max_strands), str(ctx.limits.max_particles), str(heap), os.path.basename(ctx.source)]
        try:
            child = subprocess.run(command, capture_output=True, timeout=CHILD_SECONDS, check=False)
        except subprocess.TimeoutExpired:
            raise ctx.error(f"USD took more than {CHILD_SECONDS} s to read the stage: refused", "too_large") from None
        if child.returncode == CHILD_INPUT_ERROR:
            problem = json.loads(child.stdout)
            raise ctx.error(problem["message"], problem["code"])
        if child.returncode != 0:
            raise ctx.error(f"USD could not read the stage within {heap // 2**20} MB (a damaged or hostile file; "
                            f"exit status {child.returncode})", "too_large")
        with np.load(result, allow_pickle=False) as arrays:
            found = {name: arrays[name] for name in arrays.files}
    warnings = [str(text) for text in found.pop("warnings")]
    return Strands(found["points"], found["counts"], found.get("thickness"), found.get("color"), warnings)


def _child_main(argv: list[str]) -> int:
    """``python -m hairport.solver.io.hair.usd SOURCE RESULT UNITS MAX_STRANDS MAX_PARTICLES HEAP NAME``."""
    import resource

    source, result, units, max_strands, max_particles, heap, name = argv
    resource.setrlimit(resource.RLIMIT_DATA, (int(heap), int(heap)))
    from hairport.solver.io.hair.common import ReadLimits

    ctx = ReadContext(name, ReadLimits(max_strands=int(max_strands), max_particles=int(max_particles)), units)
    _, _, _, _, Tf = _pxr()
    try:
        stage = _open_stage(source, ctx)
        try:
            strands = _strands_of(stage, ctx)
        except Tf.ErrorException as error:  # a damaged value deep in the file, met on reading it
            raise ctx.error(f"damaged USD data: {_reason(error, ctx)}", "bad_header") from None
    except InputError as error:
        sys.stdout.write(json.dumps({"code": error.code, "message": error.problem}))
        return CHILD_INPUT_ERROR
    arrays = {"points": strands.points, "counts": strands.counts, "warnings": np.array(strands.warnings, dtype=str)}
    if strands.thickness is not None:
        arrays["thickness"] = strands.thickness
    if strands.color is not None:
        arrays["color"] = strands.color
    np.savez(result, **arrays)
    return 0


def _strands_of(stage, ctx: ReadContext) -> Strands:
    _, UsdGeom, _, _, _ = _pxr()
    units = _stage_units(stage, ctx)
    if ctx.units == RECORDED_UNITS:
        raise ctx.error(f"{RECORDED_UNITS}{units}", "units_mismatch")
    if units != ctx.units:
        raise ctx.error(f"the stage is in {units} (metersPerUnit), read as {ctx.units}", "units_mismatch")
    prims = [prim for prim in stage.Traverse() if prim.IsA(UsdGeom.BasisCurves)]
    if not prims:
        raise ctx.error("the stage has no BasisCurves prim: no hair", "empty_hair")
    totals = [0, 0]
    parts = [_read_curves(prim, ctx, totals) for prim in prims]
    counts = np.concatenate([part[1] for part in parts])
    points = np.concatenate([part[0] for part in parts])
    warnings = [text for part in parts for text in part[4]]

    def joined(index: int, what: str):
        present = [part[index] is not None for part in parts]
        if not any(present):
            return None
        if not all(present):
            warnings.append(f"{what} on some prims only: dropped")
            return None
        return np.concatenate([part[index] for part in parts])

    return Strands(points, counts, joined(2, "widths"), joined(3, "displayColor"), warnings)


def recorded_units(path: str | os.PathLike[str]) -> str | None:
    """The units a USD stage records (its ``metersPerUnit``) by name; None if it cannot be read or
    records none of hairport's (the reader then says what is wrong). Read in a child, like the
    stage itself."""
    from hairport.solver.io.hair.common import ReadLimits

    source = os.fspath(path)
    try:
        _read_in_child(source, os.path.getsize(source), ReadContext(source, ReadLimits(), RECORDED_UNITS))
    except OSError:
        return None
    except InputError as error:
        return error.problem[len(RECORDED_UNITS):] if error.code == "units_mismatch" and \
            error.problem.startswith(RECORDED_UNITS) else None
    return None


def write_stage(out: BinaryIO, hair: Hair, options: WriteOptions, suffix: str) -> None:
    """One linear ``BasisCurves`` prim with widths and displayColor when present (module notes)."""
    Usd, UsdGeom, Vt, Sdf, _ = _pxr()
    stage = Usd.Stage.CreateInMemory(f"groom{suffix}")
    UsdGeom.SetStageMetersPerUnit(stage, float(options.scale))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    root = UsdGeom.Xform.Define(stage, GROOM_PRIM)
    stage.SetDefaultPrim(root.GetPrim())
    curves = UsdGeom.BasisCurves.Define(stage, CURVES_PRIM)
    curves.CreateTypeAttr(UsdGeom.Tokens.linear)
    curves.CreateCurveVertexCountsAttr(Vt.IntArray.FromNumpy(hair.counts.astype(np.int32)))
    points = (hair.points / options.scale).astype(np.float32)
    curves.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(points))
    if len(points):
        curves.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([points.min(axis=0), points.max(axis=0)])))
    if hair.thickness is not None:
        curves.CreateWidthsAttr(Vt.FloatArray.FromNumpy((hair.thickness / options.scale).astype(np.float32)))
        curves.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
    if hair.color is not None:
        display = curves.CreateDisplayColorPrimvar(UsdGeom.Tokens.vertex)
        display.Set(Vt.Vec3fArray.FromNumpy(hair.color.astype(np.float32)))
    with tempfile.TemporaryDirectory(prefix="hairport-usd-") as folder:
        path = os.path.join(folder, f"groom{suffix}")
        # .usd is written as crate (USD's default for it); .usda as text
        stage.GetRootLayer().Export(path, args={"format": "usda"} if suffix == ".usda" else {"format": "usdc"})
        with open(path, "rb") as handle:
            out.write(handle.read())


def _format(name: str) -> HairFormat:
    suffix = f".{name}"
    return HairFormat(
        name=name,
        read=lambda content, ctx: read_stage(content, ctx, suffix),
        write=lambda out, hair, options: write_stage(out, hair, options, suffix),
        keeps_thickness=True,
        keeps_color=True,
        recorded_units=recorded_units,
    )


#: the three USD extensions: the same reader and writer
FORMATS = tuple(_format(name) for name in ("usd", "usda", "usdc"))


if __name__ == "__main__":
    sys.exit(_child_main(sys.argv[1:]))
