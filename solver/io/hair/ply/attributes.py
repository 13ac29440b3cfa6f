"""A hairstyle's attributes as PLY properties, and back.

Per-point attributes are properties of element ``vertex``, per-strand ones of element
``strand``, beside the properties the strand layout itself uses. A PLY property holds one
number, so an attribute of ``k`` values a row is written as ``k`` properties ``<name>_0`` ...
``<name>_<k-1>``, and the reader joins such a run (consecutive, one type, no property
``<name>`` beside it) back into one attribute. PLY has no 64-bit integers and no booleans:
booleans are written as ``uchar`` (read back as ``uint8``), 64-bit integers as ``int``/``uint``
when every value fits (else the attribute is not written, and the writer says so). Roles
(colour, texture coordinate ...) have no place in PLY and are not kept.
"""

from __future__ import annotations

import re

import numpy as np

from hairport.solver.io.hair.common import Strands
from hairport.solver.io.hair.ply.header import PlyList
from hairport.solver.model.hair import HairAttribute

#: numpy dtype (native order) -> the PLY type the writer declares
PLY_TYPE_OF = {
    "int8": "char", "uint8": "uchar", "int16": "short", "uint16": "ushort",
    "int32": "int", "uint32": "uint", "float32": "float", "float64": "double",
}  # fmt: skip
#: dtypes PLY has no type for, and the one written instead when the values fit it exactly
NARROWED = {"bool": "uint8", "int64": "int32", "uint64": "uint32", "float16": "float32"}
_COMPONENT = re.compile(r"(.+)_(\d+)")


def ply_dtype(values: np.ndarray) -> np.dtype | None:
    """The dtype ``values`` are written in (None: PLY cannot hold them exactly)."""
    name = values.dtype.name
    if name in PLY_TYPE_OF:
        return values.dtype
    narrow = NARROWED.get(name)
    if narrow is None:
        return None
    if values.dtype.kind in "iu" and values.size:
        info = np.iinfo(narrow)
        if values.min() < info.min or values.max() > info.max:
            return None
    return np.dtype(narrow)


def property_names(name: str, attribute: HairAttribute) -> list[str]:
    """The PLY properties of one attribute: its name, or ``<name>_<i>`` for each of its values."""
    if attribute.values.ndim == 1:
        return [name]
    return [f"{name}_{i}" for i in range(attribute.components)]


def attribute_columns(attributes: dict[str, HairAttribute], taken: set[str]) -> list[tuple[str, str, np.ndarray]]:
    """``(property name, PLY type, (rows,) values)`` of every attribute of one element.

    Parameters
    ----------
    attributes : dict of str to HairAttribute
        The attributes of one domain, each writable (:func:`writable`).
    taken : set of str
        Property names the element already has.
    """
    columns = []
    for name, attribute in attributes.items():
        dtype = ply_dtype(attribute.values)
        values = attribute.values.astype(dtype, copy=False).reshape(len(attribute.values), -1)
        for i, prop in enumerate(property_names(name, attribute)):
            columns.append((prop, PLY_TYPE_OF[dtype.name], values[:, i]))
    return columns


def writable(name: str, attribute: HairAttribute, reserved: dict[str, tuple[str, ...]]) -> bool:
    """Whether PLY holds ``attribute`` exactly under its name.

    Parameters
    ----------
    reserved : dict of domain to tuple of str
        Property names the layout uses on the domain's element (those are refused: the reader
        would take them for positions, colours or strand structure).
    """
    names = property_names(name, attribute)
    return ply_dtype(attribute.values) is not None and not set(names) & set(reserved[attribute.domain])


def read_attributes(element: dict, used: set[str], domain: str, rows: np.ndarray | None, strands: Strands) -> None:
    """Add every property of ``element`` not in ``used`` to ``strands`` as a ``domain`` attribute.

    Parameters
    ----------
    element : dict of property name to (E,) values or PlyList
        One parsed element, properties in file order.
    used : set of str
        Properties the strand layout has read (positions, thickness, colours, counts, ids).
    domain : str
    rows : (R,) int64 or None
        The element's rows in strand order (layout (a) reorders vertices); None: as they are.
    strands : Strands
    """
    names = [name for name in element if name not in used]
    lists = [name for name in names if isinstance(element[name], PlyList)]
    if lists:
        strands.warnings.append(f"{domain} list propert{'ies' if len(lists) > 1 else 'y'} {', '.join(lists)} "
                                "dropped: an attribute has a fixed number of values a row")
    scalars = [name for name in names if name not in lists]
    for name, parts in _joined(scalars, element):
        values = element[parts[0]] if len(parts) == 1 else np.stack([element[p] for p in parts], axis=1)
        values = np.asarray(values)
        if values.dtype.byteorder not in "=|":
            values = values.astype(values.dtype.newbyteorder("="))
        strands.add_attribute(name, values if rows is None else values[rows], domain)


def _joined(names: list[str], element: dict) -> list[tuple[str, list[str]]]:
    """``(attribute name, its properties)``: runs ``<base>_0 .. <base>_<k-1>`` (k >= 2) of one dtype
    joined into one attribute, every other property on its own."""
    out: list[tuple[str, list[str]]] = []
    i = 0
    while i < len(names):
        match = _COMPONENT.fullmatch(names[i])
        if match and match[2] == "0" and match[1] not in element:
            base, run = match[1], [names[i]]
            while i + len(run) < len(names) and names[i + len(run)] == f"{base}_{len(run)}" and \
                    np.asarray(element[names[i + len(run)]]).dtype == np.asarray(element[names[i]]).dtype:
                run.append(names[i + len(run)])
            if len(run) >= 2:
                out.append((base, run))
                i += len(run)
                continue
        out.append((names[i], [names[i]]))
        i += 1
    return out
