"""Alembic grooms written with the bindings directly (not hairport's writer), as DCC tools write them."""

from __future__ import annotations

import numpy as np

alembic3d = __import__("pytest").importorskip("alembic3d")  # the optional extra; the test extra installs it
import imath  # noqa: E402  (bundled with alembic3d)
from alembic3d import Abc, AbcGeom  # noqa: E402

VERTEX, UNIFORM, CONSTANT = (AbcGeom.GeometryScope.kVertexScope, AbcGeom.GeometryScope.kUniformScope,
                             AbcGeom.GeometryScope.kConstantScope)


ELEMENT_TYPES = {"C3fArray": "Color3f"}


def filled(type_name: str, values) -> object:
    """An imath array set element by element (as a DCC exporter would)."""
    values = np.asarray(values)
    array = getattr(imath, type_name)(len(values))
    element = getattr(imath, ELEMENT_TYPES.get(type_name, type_name[:-5]), None)
    for index, value in enumerate(values.tolist()):
        array[index] = element(*value) if isinstance(value, list) else value
    return array


def write_groom(path, points: np.ndarray, counts: np.ndarray, *, translate=(0.0, 0.0, 0.0), curve_type="kLinear",
                widths=None, width_scope=VERTEX, params=(), version=(1, 4), tool="test-dcc 1.0") -> None:
    """An archive /groom_xform (translated) / curves, with ``params`` = (name, geom param type, imath array
    type, values, scope) in its arbGeomParams and Unreal's general properties when ``version``."""
    archive = Abc.OArchive(str(path))
    xform = AbcGeom.OXform(archive.getTop(), "groom_xform")
    sample = AbcGeom.XformSample()
    sample.setTranslation(imath.V3d(*translate))
    xform.getSchema().set(sample)
    curves = AbcGeom.OCurves(xform, "curves")
    positions = filled("V3fArray", points)
    n_vertices = filled("IntArray", counts)
    kind = getattr(AbcGeom.CurveType, curve_type)
    # every array is held in a variable until its sample is set: a sample keeps a pointer, not a reference
    if widths is not None:
        width_values = filled("FloatArray", widths)
        sample = AbcGeom.OCurvesSchemaSample(positions, n_vertices, kind, AbcGeom.CurvePeriodicity.kNonPeriodic,
                                             AbcGeom.OFloatGeomParamSample(width_values, width_scope))
    else:
        sample = AbcGeom.OCurvesSchemaSample(positions, n_vertices, kind, AbcGeom.CurvePeriodicity.kNonPeriodic)
    curves.getSchema().set(sample)
    arb = curves.getSchema().getArbGeomParams()
    if version is not None:
        for name, value in zip(("groom_version_major", "groom_version_minor"), version, strict=True):
            held = filled("ShortArray", [value])
            AbcGeom.OInt16GeomParam(arb, name, False, CONSTANT, 1).set(AbcGeom.OInt16GeomParamSample(held, CONSTANT))
        held = filled("StringArray", [tool])
        AbcGeom.OStringGeomParam(arb, "groom_tool", False, CONSTANT, 1).set(AbcGeom.OStringGeomParamSample(held, CONSTANT))
    for name, param_type, array_type, values, scope in params:
        held = filled(array_type, values)
        getattr(AbcGeom, param_type)(arb, name, False, scope, 1).set(getattr(AbcGeom, f"{param_type}Sample")(held, scope))


def general_properties(path) -> dict:
    """The groom_version_major/minor and groom_tool of an archive's first curves."""
    archive = Abc.IArchive(str(path))
    found = []

    def walk(obj):
        for child in obj.children:
            if AbcGeom.ICurves.matches(child.getHeader()):
                found.append(child)
            walk(child)

    walk(archive.getTop())
    arb = AbcGeom.ICurves(found[0], Abc.WrapExistingFlag.kWrapExisting).getSchema().getArbGeomParams()
    out = {}
    for index in range(arb.getNumProperties()):
        header = arb.getPropertyHeader(index)
        if header.getName() in ("groom_version_major", "groom_version_minor", "groom_tool"):
            value = Abc.IArrayProperty(arb, header.getName()).getValue()
            out[header.getName()] = (str(header.getDataType().getPod()), value[0])
    return out
