"""Alembic grooms (``.abc``): ``ICurves`` objects, through the ``alembic3d`` bindings (an optional extra).

Read: every ``ICurves`` object of the archive (or the one ``prim`` names, by name or full path),
in depth-first order, strands concatenated,
positions of the first time sample taken to world space by the ``IXform`` objects above it.
``linear`` curves are the strands; for cubic or variable-order ones the control points are
read as the strand's polyline, with a warning. Unreal Engine's groom convention (Epic's
"Alembic for Grooms" specification) is read as it is meant: ``groom_width`` (else the schema's
widths) becomes the thickness, ``groom_color`` the colour; every other geometry parameter
(``groom_guide``, ``groom_group_id``, ``groom_id``, ``groom_root_uv``, Houdini's ``Cd``, Maya's
custom attributes ...) and the schema's UVs become attributes (:mod:`.params`). The
convention's general properties (``groom_version_major``/``minor``, ``groom_tool``,
``groom_properties``) are not attributes: the writer writes its own. Normals and velocities are
not kept (they describe the source's shape). Alembic records no length unit.

Write: one ``IXform`` ``groom`` holding one linear, non-periodic ``ICurves`` ``hair``, in Unreal's
convention: float32 positions, widths (vertex) and ``groom_width`` when the hairstyle has a
thickness, ``groom_color`` (vertex, C3f) when it has a colour, every attribute as a geometry
parameter, and ``groom_version_major``/``groom_version_minor`` (int16, constant, the required
properties) and ``groom_tool``.

The bindings are unofficial (PyPI ``alembic3d``, BSD-3, wheels for CPython 3.10-3.14 on Linux
x86_64, Windows and macOS arm64): an optional extra, ``pip install 'hairport[alembic]'``; without
it reading or writing ``.abc`` is one clear error (code ``format_unavailable``). Parsing runs in
a memory- and time-limited child (:mod:`~hairport.solver.io.sandbox`), like USD's.
"""

from __future__ import annotations

import importlib.util
from contextlib import contextmanager
from typing import BinaryIO

import numpy as np

from hairport import __version__
from hairport.solver.io.hair.alembic.params import imath_array, numpy_copy, read_param, writable_dtype, write_param
from hairport.solver.io.hair.common import Animation, HairFormat, ReadContext, Strands, WriteOptions, write_through_file
from hairport.solver.io.hair.curves import CurvesPart, chosen_prims, join_parts
from hairport.solver.io.hair.sandboxed import read_bytes_in_child
from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import HairAttribute

#: the optional dependency and the extra that installs it
ALEMBIC_MODULE = "alembic3d"
ALEMBIC_EXTRA = "alembic"
UNAVAILABLE = "format_unavailable"
#: Unreal's groom convention: the version of Epic's specification written, and its property names
GROOM_VERSION = (1, 4)
GROOM_VERSION_MAJOR = "groom_version_major"
GROOM_VERSION_MINOR = "groom_version_minor"
GROOM_TOOL = "groom_tool"
GROOM_WIDTH = "groom_width"
GROOM_COLOR = "groom_color"
GROOM_GUIDE = "groom_guide"
#: general properties of the convention, rewritten by the writer rather than carried
GROOM_GENERAL = (GROOM_VERSION_MAJOR, GROOM_VERSION_MINOR, GROOM_TOOL, "groom_properties")
#: names no attribute may take: the writer writes them from the hairstyle's own fields
RESERVED = (*GROOM_GENERAL, GROOM_WIDTH, GROOM_COLOR)
#: the attribute the schema's UVs are read into
UV_ATTRIBUTE = "uv"
GROOM_OBJECT = "groom"
CURVES_OBJECT = "hair"


def require_alembic(source: str = "<bytes>") -> None:
    """Raise ``format_unavailable`` naming the extra when the Alembic bindings are not installed."""
    if importlib.util.find_spec(ALEMBIC_MODULE) is None:
        raise InputError(
            f"reading and writing Alembic (.abc) needs the optional bindings {ALEMBIC_MODULE}: "
            f"pip install 'hairport[{ALEMBIC_EXTRA}]'",
            source,
            UNAVAILABLE,
        )


def _modules():
    import imath
    from alembic3d import Abc, AbcGeom

    return Abc, AbcGeom, imath


def read_archive(content: bytes | memoryview, ctx: ReadContext) -> Strands:
    """Every ``ICurves`` of an Alembic archive as :class:`~.common.Strands` (module notes), parsed in a
    limited child."""
    require_alembic(ctx.source)
    return read_bytes_in_child(__name__, content, ".abc", ctx, "Alembic")


def parse_file(path: str, ctx: ReadContext) -> Strands:
    """The archive's strands (module notes); run by :mod:`~hairport.solver.io.sandbox` in its child."""
    _, AbcGeom, _ = _modules()
    with opened_archive(path, ctx) as archive:
        found = []
        _collect_curves(archive.getTop(), found, AbcGeom)
        if not found:
            raise ctx.error("the archive has no ICurves object: no hair", "empty_hair")
        found = chosen_prims(found, [[obj.getName(), obj.getFullName()] for obj in found], "ICurves object", ctx)
        totals = [0, 0]
        parts = [_read_curves(curves, ctx, totals) for curves in found]
    return join_parts(parts, "curves objects", ("widths", GROOM_COLOR, "parameter"))


@contextmanager
def opened_archive(path: str, ctx: ReadContext):
    """The archive at ``path`` (in the sandbox's child); a file the bindings cannot open, or damage met while the
    block reads it, is ``bad_header`` (an :class:`InputError` the block raises passes as it is)."""
    Abc, _, _ = _modules()
    try:
        archive = Abc.IArchive(path)
    except Exception as error:  # the bindings raise a bare RuntimeError or Exception for any damage
        raise ctx.error(f"not a readable Alembic archive: {_first_line(error)}", "bad_header") from None
    try:
        yield archive
    except InputError:
        raise
    except Exception as error:  # damage met while reading values
        raise ctx.error(f"damaged Alembic data: {_first_line(error)}", "bad_header") from None


def _first_line(error: Exception) -> str:
    text = str(error).strip().splitlines()
    return text[0][:200] if text else type(error).__name__


def _collect_curves(obj, found: list, AbcGeom) -> None:
    for child in obj.children:
        if AbcGeom.ICurves.matches(child.getHeader()):
            found.append(child)
        _collect_curves(child, found, AbcGeom)


def _world_matrix(obj) -> np.ndarray:
    """(4, 4) float64: the product of the first samples of the ``IXform`` objects above ``obj``
    (row vectors: world = [p, 1] M), up to one that does not inherit its parent's."""
    Abc, AbcGeom, _ = _modules()
    matrix = np.eye(4)
    parent = obj.getParent()
    while parent is not None and parent.valid() and parent.getName() != "ABC":
        if AbcGeom.IXform.matches(parent.getHeader()):
            schema = AbcGeom.IXform(parent, Abc.WrapExistingFlag.kWrapExisting).getSchema()
            local = schema.getValue().getMatrix()
            matrix = matrix @ np.array([[local[r][c] for c in range(4)] for r in range(4)])
            if not schema.getInheritsXforms():
                break
        parent = parent.getParent()
    return matrix


def _read_curves(obj, ctx: ReadContext, totals: list[int]) -> CurvesPart:
    """Points (world, file units), counts, thickness, colour, attributes and warnings of one ``ICurves``."""
    Abc, AbcGeom, _ = _modules()
    where = obj.getFullName()
    schema = AbcGeom.ICurves(obj, Abc.WrapExistingFlag.kWrapExisting).getSchema()
    warnings: list[str] = []
    if schema.getNumSamples() > 1:
        warnings.append(f"{where}: {schema.getNumSamples()} time samples: the first is read")
    sample = schema.getValue()
    counts = numpy_copy(sample.getCurvesNumVertices()).astype(np.int64)
    if np.any(counts < 0):
        raise ctx.error(f"{where}: a negative vertex count", "bad_index")
    totals[0] += len(counts)
    totals[1] += int(counts.sum())
    ctx.check_limit(totals[0], "strands")
    ctx.check_limit(totals[1], "particles")
    points = numpy_copy(sample.getPositions()).astype(np.float64).reshape(-1, 3)
    if len(points) != counts.sum():
        raise ctx.error(f"{where}: the curves' vertex counts add up to {int(counts.sum()):,} points, the object has "
                        f"{len(points):,}", "bad_index")
    kind = str(sample.getType())
    if kind != "kLinear":
        warnings.append(f"{where}: {kind[1:].lower()} curves: their control points are read as the strands' polylines")
    matrix = _world_matrix(obj)
    points = points @ matrix[:3, :3] + matrix[3, :3]
    params = {}
    arb = schema.getArbGeomParams()
    if arb is not None and arb.valid():
        for index in range(arb.getNumProperties()):
            header = arb.getPropertyHeader(index)
            if header.getName() in GROOM_GENERAL:
                continue
            found = read_param(arb, header, counts, where, ctx)
            if isinstance(found, str):
                warnings.append(f"{where}: parameter {header.getName()!r} not kept: {found}")
            else:
                params[header.getName()] = found
    geom = Abc.ICompoundProperty(obj.getProperties(), ".geom")
    for key, getter in ((".widths", schema.getWidthsParam), (UV_ATTRIBUTE, schema.getUVsParam)):
        param = getter()
        if param is not None and param.valid():
            found = read_param(geom, param.getHeader(), counts, where, ctx)
            if not isinstance(found, str):
                params.setdefault(key, found)
    normals = schema.getNormalsParam()
    if normals is not None and normals.valid():
        warnings.append(f"{where}: normals not kept: they describe the source's shape, which a retarget replaces")
    thickness = _take(params, GROOM_WIDTH, ".widths", counts, where, warnings)
    color = params.pop(GROOM_COLOR, None)
    return CurvesPart(points, counts, thickness,
                      None if color is None else _per_point(color, counts).astype(np.float64).reshape(-1, 3),
                      params, warnings)


def _take(params: dict, preferred: str, fallback: str, counts: np.ndarray, where: str,
          warnings: list[str]) -> np.ndarray | None:
    """Unreal's precedence: ``groom_width`` over the schema's widths, one per point."""
    first, second = params.pop(preferred, None), params.pop(fallback, None)
    if first is not None and second is not None and \
            not np.array_equal(_per_point(first, counts), _per_point(second, counts)):
        warnings.append(f"{where}: {preferred} and the schema's widths differ: {preferred} is read, as Unreal does")
    chosen = first if first is not None else second
    if chosen is None:
        return None
    widths = _per_point(chosen, counts)
    return (widths if widths.ndim == 1 else widths[:, 0]).astype(np.float64)


def _per_point(found: tuple, counts: np.ndarray) -> np.ndarray:
    """A parameter's rows, one per point (a per-curve one repeated along its curve)."""
    values, domain, _ = found
    return values if domain == "vertex" else np.repeat(values, counts, axis=0)


def write_archive(out: BinaryIO, hair, options: WriteOptions) -> None:
    """One linear ``ICurves`` in Unreal's groom convention (module notes)."""
    require_alembic()
    # the archive is finished when _write_file returns and its objects are released
    write_through_file(out, ".abc", lambda path: _write_file(path, hair, options))


def write_animated_archive(out: BinaryIO, hair, animation: Animation, options: WriteOptions) -> None:
    """:func:`write_archive` with the curves' positions sampled at the animation's times (acyclic time sampling, in
    seconds: time code over frames per second); widths, colour and attributes are the first sample's."""
    require_alembic()
    write_through_file(out, ".abc", lambda path: _write_file(path, hair, options, animation))


def _write_file(path: str, hair, options: WriteOptions, animation: Animation | None = None) -> None:
    # every array stays in a local until its sample is set: a sample holds a pointer to the array's
    # memory, not a reference to the array
    Abc, AbcGeom, imath = _modules()
    archive = Abc.OArchive(path)
    parent = AbcGeom.OXform(archive.getTop(), GROOM_OBJECT)
    if animation is None:
        curves = AbcGeom.OCurves(parent, CURVES_OBJECT)
    else:
        from alembic3d import AbcCoreAbstract

        seconds = AbcCoreAbstract.TimeVector()
        for time in animation.times / animation.frames_per_second:
            seconds.append(float(time))
        sampling = AbcCoreAbstract.TimeSampling(
            AbcCoreAbstract.TimeSamplingType(AbcCoreAbstract.AcyclicFlag()), seconds)
        curves = AbcGeom.OCurves(parent, CURVES_OBJECT, archive.addTimeSampling(sampling))
    schema = curves.getSchema()
    first = hair.points if animation is None else np.asarray(animation.points[0])
    positions = imath_array((first / options.scale).astype(np.float32), "V3fArray")
    counts = imath_array(hair.counts.astype(np.int32), "IntArray")
    vertex, constant = AbcGeom.GeometryScope.kVertexScope, AbcGeom.GeometryScope.kConstantScope
    if hair.thickness is not None:
        widths = imath_array((hair.thickness / options.scale).astype(np.float32), "FloatArray")
        sample = AbcGeom.OCurvesSchemaSample(positions, counts, AbcGeom.CurveType.kLinear,
                                             AbcGeom.CurvePeriodicity.kNonPeriodic,
                                             AbcGeom.OFloatGeomParamSample(widths, vertex))
    else:
        sample = AbcGeom.OCurvesSchemaSample(positions, counts, AbcGeom.CurveType.kLinear,
                                             AbcGeom.CurvePeriodicity.kNonPeriodic)
    schema.set(sample)
    for frame in [] if animation is None else animation.points[1:]:
        moved = imath_array((np.asarray(frame) / options.scale).astype(np.float32), "V3fArray")
        schema.set(AbcGeom.OCurvesSchemaSample(moved, counts, AbcGeom.CurveType.kLinear,
                                               AbcGeom.CurvePeriodicity.kNonPeriodic))
    arb = schema.getArbGeomParams()
    for name, value in zip((GROOM_VERSION_MAJOR, GROOM_VERSION_MINOR), GROOM_VERSION, strict=True):
        version = imath.ShortArray(1)
        version[0] = value
        AbcGeom.OInt16GeomParam(arb, name, False, constant, 1).set(AbcGeom.OInt16GeomParamSample(version, constant))
    tool = imath.StringArray(1)
    tool[0] = f"hairport {__version__}"
    AbcGeom.OStringGeomParam(arb, GROOM_TOOL, False, constant, 1).set(AbcGeom.OStringGeomParamSample(tool, constant))
    if hair.thickness is not None:
        write_param(arb, GROOM_WIDTH, HairAttribute((hair.thickness / options.scale).astype(np.float32), "vertex"))
    if hair.color is not None:
        write_param(arb, GROOM_COLOR, HairAttribute(hair.color.astype(np.float32), "vertex", "color"))
    for name, attribute in hair.attributes.items():
        write_param(arb, name, attribute)


def keeps_attribute(name: str, attribute: HairAttribute) -> bool:
    """Attributes Alembic holds exactly here (:mod:`.params`), under names the convention leaves free."""
    return name not in RESERVED and writable_dtype(attribute.values) is not None


FORMAT = HairFormat("abc", read_archive, write_archive, keeps_thickness=True, keeps_color=True,
                    keeps_attribute=keeps_attribute, has_prims=True, write_frames=write_animated_archive)
