"""Alembic geometry parameters (``arbGeomParams``, widths, UVs) as numpy arrays and hair attributes, and back.

Read: a parameter's values come out of the binding as numpy, in the dtype of its plain old data
type (:data:`POD_DTYPES`; the binding widens some, e.g. ``C3f`` to float64, which is undone
exactly); indexed parameters are expanded through their indices (checked to be in range); a
parameter of ``arrayExtent`` k holds k of its type a row. Its scope gives the attribute's domain:
vertex, varying and face-varying one row per point, uniform one per curve, constant one for
all (repeated per curve). Its role comes from hairport's own metadata key (:data:`ROLE_KEY`,
written by the writer) or from Alembic's interpretation (``rgb``/``rgba`` colour, ``normal``,
``point``, ``vector``).

Write: float32, float64 and int32 as scalars, 2- and 3-vectors, through arrays the binding
shares with numpy; bool, int8, uint8, int16, uint16 and uint32 scalars (the last five set element
by element): other integer dtypes are narrowed
or widened to int32 where every value fits (else the attribute is not kept), float16 widened to
float32; rows of other widths are scalar arrays of ``arrayExtent`` k.
"""

from __future__ import annotations

import numpy as np

from hairport.solver.io.hair.common import ReadContext
from hairport.solver.model.hair import ROLES, STRAND, VERTEX, HairAttribute

#: Alembic's plain old data types -> numpy
POD_DTYPES = {
    "kBooleanPOD": "bool", "kUint8POD": "uint8", "kInt8POD": "int8", "kUint16POD": "uint16",
    "kInt16POD": "int16", "kUint32POD": "uint32", "kInt32POD": "int32", "kUint64POD": "uint64",
    "kInt64POD": "int64", "kFloat16POD": "float16", "kFloat32POD": "float32", "kFloat64POD": "float64",
}  # fmt: skip
#: the property metadata key that records a hairport role beside Alembic's interpretation
ROLE_KEY = "hairportRole"
ROLE_OF_INTERPRETATION = {"rgb": "color", "rgba": "color", "normal": "normal", "point": "point", "vector": "vector"}
#: Alembic's scope names in property metadata -> domain
SCOPE_DOMAINS = {"vtx": VERTEX, "var": VERTEX, "fvr": VERTEX, "uni": STRAND, "con": STRAND}
#: (dtype, values a row) -> (imath array type, AbcGeom geometry parameter type), for types the binding
#: shares with numpy
WRITABLE = {
    ("float32", 1): ("FloatArray", "OFloatGeomParam"), ("float32", 2): ("V2fArray", "OV2fGeomParam"),
    ("float32", 3): ("V3fArray", "OV3fGeomParam"), ("float64", 1): ("DoubleArray", "ODoubleGeomParam"),
    ("float64", 2): ("V2dArray", "OV2dGeomParam"), ("float64", 3): ("V3dArray", "OV3dGeomParam"),
    ("int32", 1): ("IntArray", "OInt32GeomParam"), ("int32", 2): ("V2iArray", "OV2iGeomParam"),
    ("int32", 3): ("V3iArray", "OV3iGeomParam"), ("uint8", 1): ("UnsignedCharArray", "OUcharGeomParam"),
    ("bool", 1): ("BoolArray", "OBooleanGeomParam"), ("int8", 1): ("SignedCharArray", "OCharGeomParam"),
    ("int16", 1): ("ShortArray", "OInt16GeomParam"), ("uint16", 1): ("UnsignedShortArray", "OUInt16GeomParam"),
    ("uint32", 1): ("UnsignedIntArray", "OUInt32GeomParam"),
}  # fmt: skip
#: imath arrays the binding hands numpy as a copy, not a view: filled element by element (about a
#: microsecond each: fine for per-strand ids and flags, the usual users of these types)
ELEMENTWISE = ("BoolArray", "SignedCharArray", "ShortArray", "UnsignedShortArray", "UnsignedIntArray")
#: float32 3-vectors of these roles are written as colours (C3f, interpretation rgb)
COLOR_PARAM = ("C3fArray", "OC3fGeomParam")


def _modules():
    import imath
    from alembic3d import Abc, AbcGeom

    return Abc, AbcGeom, imath


#: colour channels a colour array exposes as float arrays (numpy reads those through their buffer; the
#: colour array itself only element by element, about 5 us a point)
COLOR_CHANNELS = ("r", "g", "b", "a")


def numpy_copy(array) -> np.ndarray:
    """A numpy copy of a binding array, made while this function holds the array: a view of a
    temporary would outlive the memory it shows. Colour arrays are read channel by channel."""
    if hasattr(array, "r") and hasattr(array, "g"):
        channels = [getattr(array, name) for name in COLOR_CHANNELS if hasattr(array, name)]
        return np.stack([np.array(channel, copy=True) for channel in channels], axis=1)
    return np.array(array, copy=True)


def writable_dtype(values: np.ndarray) -> np.dtype | None:
    """The dtype an attribute is written in, or None when Alembic cannot hold it exactly here."""
    dtype = values.dtype
    if (dtype.name, 1) in WRITABLE:
        return dtype
    if dtype.name == "float16":
        return np.dtype("float32")
    if dtype.kind in "iu":
        info = np.iinfo(np.int32)
        if values.size == 0 or (values.min() >= info.min and values.max() <= info.max):
            return np.dtype("int32")
    return None


def imath_array(values: np.ndarray, type_name: str):
    """An imath array of ``type_name`` holding ``values`` ((n,) or (n, k)), filled through numpy."""
    _, _, imath = _modules()
    array = getattr(imath, type_name)(len(values))
    if type_name in ELEMENTWISE:
        for index, value in enumerate(values.tolist()):
            array[index] = value
    elif len(values):
        np.asarray(array)[...] = values
    return array


def write_param(parent, name: str, attribute: HairAttribute) -> None:
    """Author one attribute as a geometry parameter of ``parent`` (an ``arbGeomParams`` compound)."""
    Abc, AbcGeom, imath = _modules()
    from alembic3d import AbcCoreAbstract

    dtype = writable_dtype(attribute.values)
    values = attribute.values.astype(dtype, copy=False)
    k = attribute.components
    if (dtype.name, k) in WRITABLE:
        (array_type, param_type), extent = WRITABLE[(dtype.name, k)], 1
    else:  # a row of k scalars
        (array_type, param_type), extent, values = WRITABLE[(dtype.name, 1)], k, values.reshape(-1)
    array = imath_array(values, array_type)
    if attribute.role == "color" and (dtype.name, k) == ("float32", 3):
        array_type, param_type = COLOR_PARAM
        array = getattr(imath, array_type)(array)
    scope = AbcGeom.GeometryScope.kVertexScope if attribute.domain == VERTEX else AbcGeom.GeometryScope.kUniformScope
    metadata = AbcCoreAbstract.MetaData()
    metadata.set(ROLE_KEY, attribute.role or "none")
    param = getattr(AbcGeom, param_type)(parent, name, False, scope, extent, Abc.Argument(metadata))
    param.set(getattr(AbcGeom, f"{param_type}Sample")(array, scope))


def read_param(parent, header, counts: np.ndarray, where: str, ctx: ReadContext) -> tuple[np.ndarray, str, str] | str:
    """``(values, domain, role)`` of one geometry parameter, or why it cannot be kept (not numbers, not an array).

    Parameters
    ----------
    parent : ICompoundProperty
        The ``arbGeomParams`` (or the schema) holding it.
    header : PropertyHeader
    counts : (C,) int64
        Points of every curve.
    where : str
        The object's path, for messages.
    ctx : ReadContext

    Raises
    ------
    InputError
        ``bad_attribute``: an index out of range, or a count that fits no scope.
    """
    name = header.getName()
    values = _values(parent, header, where, ctx)
    if isinstance(values, str):
        return values
    metadata = header.getMetaData()
    scope = metadata.get("geoScope")
    n_points, n_curves = int(counts.sum()), len(counts)
    recorded = metadata.get(ROLE_KEY)  # "" when absent
    if recorded == "none":
        role = ""
    elif recorded and recorded in ROLES:
        role = recorded
    else:
        role = ROLE_OF_INTERPRETATION.get(metadata.get("interpretation"), "")
    domain = SCOPE_DOMAINS.get(scope)
    rows = len(values)
    if domain == VERTEX or (domain is None and rows == n_points):
        if rows == n_points:
            return values, VERTEX, role
    elif scope == "uni" or (domain is None and rows == n_curves):
        if rows == n_curves:
            return values, STRAND, role
    elif scope == "con" or domain is None:
        if rows == 1:
            return np.repeat(values, n_curves, axis=0), STRAND, role
    raise ctx.error(f"{where}: parameter {name!r} has {rows:,} values at {scope or 'no'} scope for {n_curves:,} "
                    f"curves of {n_points:,} points", "bad_attribute")


def _values(parent, header, where: str, ctx: ReadContext) -> np.ndarray | str:
    """The parameter's rows, indices expanded, in its own dtype; or why not."""
    Abc, _, _ = _modules()
    name = header.getName()
    pod = str(header.getDataType().getPod())
    if pod not in POD_DTYPES:
        return f"{pod[1:-3].lower()} values are not numbers"
    if header.isCompound():  # an indexed parameter: .vals and .indices
        compound = Abc.ICompoundProperty(parent, name)
        values = numpy_copy(Abc.IArrayProperty(compound, ".vals").getValue())
        indices = numpy_copy(Abc.IArrayProperty(compound, ".indices").getValue()).astype(np.int64)
        if len(indices) and (indices.min() < 0 or indices.max() >= len(values)):
            raise ctx.error(f"{where}: parameter {name!r} has an index outside its {len(values):,} values", "bad_attribute")
        values = values[indices]
    elif header.isArray():
        values = numpy_copy(Abc.IArrayProperty(parent, name).getValue())
    else:
        return "a single value, not one per point or curve"
    values = values.astype(POD_DTYPES[pod], copy=False)
    extent = int(header.getMetaData().get("arrayExtent") or 1)
    if extent > 1:
        width = values.shape[1] if values.ndim == 2 else 1
        if len(values) % extent:
            raise ctx.error(f"{where}: parameter {name!r} has {len(values):,} values, not a multiple of its "
                            f"arrayExtent {extent}", "bad_attribute")
        values = values.reshape(len(values) // extent, extent * width)
    return values
