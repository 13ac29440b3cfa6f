"""A hairstyle's attributes as USD primvars, and back.

Read: every primvar of a ``BasisCurves`` prim with a value, other than the ones the reader
turns into thickness and colour, becomes an attribute of the same name (namespaces kept:
``primvars:ns:uv`` is ``ns:uv``): ``vertex``, ``varying`` and ``faceVarying`` interpolation
per point, ``uniform`` per curve, ``constant`` repeated for every curve. Indexed primvars are
flattened; a primvar of ``elementSize`` k > 1 has k values a row. USD's role (``color3f``,
``texCoord2f``, ``normal3f``, ``point3f``, ``vector3f``) becomes the attribute's role.
String and token primvars are named in a warning and not kept.

Write: a per-point attribute is a ``vertex`` primvar, a per-strand one ``uniform``, of the
USD type its dtype, width and role name (:func:`usd_type_name`); dtypes USD has no type for
(int8, int16, uint16) are widened exactly to ``int``/``uint``; rows wider than USD's vector
types are written with ``elementSize``.
"""

from __future__ import annotations

import numpy as np

from hairport.solver.io.hair.common import ReadContext
from hairport.solver.model.hair import STRAND, VERTEX, HairAttribute

#: numpy dtype name -> USD scalar type name
USD_SCALAR = {
    "float32": "float", "float64": "double", "float16": "half", "int32": "int", "int64": "int64",
    "uint32": "uint", "uint64": "uint64", "uint8": "uchar", "bool": "bool",
}  # fmt: skip
#: dtypes USD has no type for, widened exactly
WIDENED = {"int8": "int32", "int16": "int32", "uint16": "uint32"}
#: scalar types that have 2-, 3- and 4-vectors, and their role suffix
VECTOR_SUFFIX = {"float": "f", "double": "d", "half": "h", "int": "i"}
#: hairport role -> (USD role type prefix, the widths it exists for)
ROLE_TYPES = {
    "color": ("color", (3, 4)),
    "texcoord": ("texCoord", (2, 3)),
    "normal": ("normal", (3,)),
    "point": ("point", (3,)),
    "vector": ("vector", (3,)),
}
#: USD's role names (``Sdf.ValueTypeName.role``) -> hairport's
ROLE_OF_USD = {"Color": "color", "TextureCoordinate": "texcoord", "Normal": "normal", "Point": "point",
               "Vector": "vector"}
#: interpolation of a primvar -> the attribute's domain
DOMAIN_OF = {"vertex": VERTEX, "varying": VERTEX, "faceVarying": VERTEX, "uniform": STRAND, "constant": STRAND}


def usd_type_name(attribute: HairAttribute) -> tuple[str, int, np.dtype]:
    """The USD array type name, element size and dtype an attribute is written with.

    Returns
    -------
    type_name : str
        e.g. ``"texCoord2f[]"``.
    element_size : int
        1, or the row width when no USD vector type is that wide.
    dtype : np.dtype
        The values' dtype, widened where USD has no type for it.
    """
    dtype = np.dtype(WIDENED.get(attribute.values.dtype.name, attribute.values.dtype.name))
    scalar = USD_SCALAR[dtype.name]
    k = attribute.components
    if attribute.values.ndim == 1:
        return f"{scalar}[]", 1, dtype
    if scalar in VECTOR_SUFFIX and 2 <= k <= 4:
        suffix = VECTOR_SUFFIX[scalar]
        prefix, widths = ROLE_TYPES.get(attribute.role, ("", ()))
        if k in widths and suffix != "i":
            return f"{prefix}{k}{suffix}[]", 1, dtype
        return f"{scalar}{k}[]", 1, dtype
    return f"{scalar}[]", k, dtype


def write_primvars(prim, attributes: dict[str, HairAttribute]) -> None:
    """Author every attribute as a primvar of ``prim`` (module notes)."""
    from pxr import Sdf, UsdGeom

    primvars = UsdGeom.PrimvarsAPI(prim)
    for name, attribute in attributes.items():
        type_name, element_size, dtype = usd_type_name(attribute)
        value_type = Sdf.ValueTypeNames.Find(type_name)
        interpolation = UsdGeom.Tokens.vertex if attribute.domain == VERTEX else UsdGeom.Tokens.uniform
        primvar = primvars.CreatePrimvar(name, value_type, interpolation, element_size)
        values = attribute.values.astype(dtype, copy=False)
        if element_size > 1:
            values = values.reshape(-1)
        primvar.Set(type(value_type.defaultValue).FromNumpy(np.ascontiguousarray(values)))


def read_primvar(primvar, counts: np.ndarray, where: str, ctx: ReadContext) -> tuple[np.ndarray, str, str] | str:
    """``(values, domain, role)`` of one primvar of a curves prim, or why its type cannot be kept.

    Parameters
    ----------
    primvar : UsdGeom.Primvar
    counts : (C,) int64
        Points of every curve of the prim.
    where : str
        The prim's path, for messages.
    ctx : ReadContext

    Returns
    -------
    (values, domain, role), values (rows, ...) with rows the prim's points or curves, or a
    reason in words (not numbers).

    Raises
    ------
    InputError
        ``bad_attribute``: a count that fits no interpolation.
    """
    type_name = primvar.GetTypeName()
    if not type_name.isArray:
        return f"a single {type_name} value, not an array"
    values = primvar.ComputeFlattened()
    try:
        values = np.asarray(values)
    except (TypeError, ValueError):
        return f"{type_name} values are not numbers"
    if values.dtype.kind not in "biuf":
        return f"{type_name} values are not numbers"
    interpolation = primvar.GetInterpolation()
    element_size = max(1, int(primvar.GetElementSize()))
    n_points, n_curves = int(counts.sum()), len(counts)
    rows = len(values) // element_size if values.ndim >= 1 else 0
    values = values.reshape(rows, -1) if element_size > 1 or values.ndim > 2 else values
    if values.ndim == 2 and values.shape[1] == 1:
        values = values[:, 0]
    role = ROLE_OF_USD.get(type_name.role, "")
    domain = DOMAIN_OF.get(interpolation)
    if domain == VERTEX and rows == n_points:
        return values, VERTEX, role
    if interpolation == "uniform" and rows == n_curves:
        return values, STRAND, role
    if interpolation == "constant" and rows == 1:
        return np.repeat(values, n_curves, axis=0), STRAND, role
    raise ctx.error(f"{where}: primvar {primvar.GetPrimvarName()!r} has {rows:,} values at {interpolation} "
                    f"interpolation for {n_curves:,} curves of {n_points:,} points", "bad_attribute")
