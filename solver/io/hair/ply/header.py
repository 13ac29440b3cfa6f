"""The PLY header, and the records a parsed PLY file is made of.

A PLY file starts with an ASCII header (``ply``, ``format <encoding> 1.0``, then ``element
<name> <count>`` lines each followed by its ``property <type> <name>`` or ``property list
<count type> <item type> <name>`` lines, ``end_header``) and continues with a body of the
announced elements, record by record, in ASCII or in binary (:mod:`.ascii_body`,
:mod:`.binary_body`). This module parses the header into :class:`PlyElement` records and
checks the announced counts against the body's size and the :class:`~.common.ReadLimits`
before a body reader allocates anything.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from hairport.solver.io.hair.common import ReadContext
from hairport.solver.model.errors import InputError

PLY_MAGIC_LINE = b"ply\n"
PLY_MAX_HEADER_BYTES = 1 << 20
# encoding -> numpy byte order of a binary body (None: ASCII)
PLY_ENCODINGS: dict[str, str | None] = {
    "ascii": None,
    "binary_little_endian": "<",
    "binary_big_endian": ">",
}
PLY_TYPES: dict[str, str] = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip
# elements whose records are strands: their count is checked against ReadLimits.max_strands
PLY_STRAND_ELEMENTS = ("strand", "strands", "curve", "curves", "polyline", "polylines", "hair")


@dataclass(frozen=True)
class PlyProperty:
    """One property; ``count_dtype`` is set for a list property."""

    name: str
    dtype: np.dtype
    count_dtype: np.dtype | None = None

    @property
    def is_list(self) -> bool:
        return self.count_dtype is not None


@dataclass
class PlyElement:
    """One element of the header: its name, record count and properties in file order."""

    name: str
    count: int
    properties: list[PlyProperty] = field(default_factory=list)


@dataclass(frozen=True)
class PlyList:
    """Values of a list property: ``lengths (E,) int64`` and all items concatenated."""

    lengths: np.ndarray
    values: np.ndarray


# element name -> property name -> (E,) values or a PlyList
PlyValues = dict[str, dict[str, np.ndarray | PlyList]]


def parse_header(
    buf: bytes | memoryview, ctx: ReadContext
) -> tuple[str, list[PlyElement], int]:
    """Parse the header: (encoding, elements, byte offset of the body).

    Raises
    ------
    InputError
        ``bad_header`` (naming the header line), or ``truncated`` when the file ends inside
        the header.
    """
    head = bytes(buf[:PLY_MAX_HEADER_BYTES])
    if len(head) < len(PLY_MAGIC_LINE) and PLY_MAGIC_LINE.startswith(head):
        raise ctx.error("the file ends inside the PLY magic line", "truncated")
    if not re.match(rb"ply\r?\n", head):
        raise ctx.error("not a PLY file (it does not start with a 'ply' line)", "bad_header")
    end = re.search(rb"\nend_header[ \t]*(\r\n|\n)", head)
    if end is None:
        if len(head) < PLY_MAX_HEADER_BYTES:
            raise ctx.error("the PLY header has no end_header line", "truncated")
        raise ctx.error(f"no end_header in the first {PLY_MAX_HEADER_BYTES:,} bytes", "bad_header")
    try:
        lines = head[: end.start()].decode("ascii").splitlines()[1:]
    except UnicodeDecodeError:
        raise ctx.error("the PLY header is not ASCII text", "bad_header") from None
    encoding = None
    elements: list[PlyElement] = []
    for number, line in enumerate(lines, start=2):
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        try:
            if words[0] == "format":
                encoding = _format_line(words, ctx)
            elif words[0] == "element":
                elements.append(_element_line(words, elements, ctx))
            elif words[0] == "property":
                _property_line(words, elements, encoding, ctx)
            else:
                raise ctx.error(f"unknown keyword {words[0]!r}", "bad_header")
        except InputError as exc:
            raise ctx.error(f"PLY header line {number}: {exc.problem}", exc.code) from None
    if encoding is None:
        raise ctx.error("the PLY header has no format line", "bad_header")
    return encoding, elements, end.end()


def _format_line(words: list[str], ctx: ReadContext) -> str:
    if len(words) != 3 or words[1] not in PLY_ENCODINGS:
        raise ctx.error(
            f"unsupported format {' '.join(words[1:])!r}; "
            f"expected one of {', '.join(PLY_ENCODINGS)}",
            "bad_header",
        )
    return words[1]


def _element_line(words: list[str], elements: list[PlyElement], ctx: ReadContext) -> PlyElement:
    if len(words) != 3 or not words[2].isdigit():
        raise ctx.error(f"malformed element line {' '.join(words)!r}", "bad_header")
    if any(e.name == words[1] for e in elements):
        raise ctx.error(f"element {words[1]!r} appears twice", "bad_header")
    return PlyElement(words[1], int(words[2]))


def _property_line(
    words: list[str], elements: list[PlyElement], encoding: str | None, ctx: ReadContext
) -> None:
    if not elements:
        raise ctx.error("a property before any element", "bad_header")
    if encoding is None:
        raise ctx.error("a property before the format line", "bad_header")
    byte_order = PLY_ENCODINGS[encoding] or "<"

    def dtype(name: str) -> np.dtype:
        if name not in PLY_TYPES:
            raise ctx.error(f"unknown property type {name!r}", "bad_header")
        return np.dtype(byte_order + PLY_TYPES[name])

    if len(words) == 5 and words[1] == "list":
        count_dtype = dtype(words[2])
        if count_dtype.kind == "f":
            raise ctx.error(f"list length type {words[2]!r} is not an integer type", "bad_header")
        prop = PlyProperty(words[4], dtype(words[3]), count_dtype)
    elif len(words) == 3:
        prop = PlyProperty(words[2], dtype(words[1]))
    else:
        raise ctx.error(f"malformed property line {' '.join(words)!r}", "bad_header")
    element = elements[-1]
    if any(p.name == prop.name for p in element.properties):
        raise ctx.error(
            f"property {prop.name!r} appears twice in element {element.name!r}", "bad_header"
        )
    element.properties.append(prop)


def check_counts(
    elements: list[PlyElement], available: int, unit: str, per_item: int, ctx: ReadContext
) -> None:
    """Counts against the body size (minimum record sizes), then against the limits.

    Parameters
    ----------
    elements : list of PlyElement
    available : int
        Size of the body in ``unit``.
    unit : str
        ``"bytes"`` (binary: a record takes at least its scalars and list lengths) or
        ``"numbers"`` (ASCII: a record takes at least ``per_item`` numbers a property).
    per_item : int
    ctx : ReadContext

    Raises
    ------
    InputError
        ``truncated``, then ``too_large``.
    """
    needed = 0
    for element in elements:
        if unit == "bytes":
            record = sum((p.count_dtype or p.dtype).itemsize for p in element.properties)
        else:
            record = len(element.properties) * per_item
        needed += element.count * record
    if needed > available:
        raise ctx.error(
            f"the header's element counts need at least {needed:,} {unit} of data but the body "
            f"has {available:,}",
            "truncated",
        )
    for element in elements:
        if element.name == "vertex":
            ctx.check_limit(element.count, "particles")
        elif element.name in PLY_STRAND_ELEMENTS:
            ctx.check_limit(element.count, "strands")


def list_item_positions(list_starts: list[int], list_lengths: list[int], stride: int) -> tuple[np.ndarray, np.ndarray]:
    """Where every item of every list of a property is, in a body walked record by record.

    Parameters
    ----------
    list_starts : list of int
        Position of each list's first item (a byte offset, or a token index).
    list_lengths : list of int
        Items of each list.
    stride : int
        Distance between consecutive items (an item's byte size, or 1 token).

    Returns
    -------
    lengths : (E,) int64
        ``list_lengths`` as an array.
    positions : (sum(lengths),) int64
        The items' positions, list after list.
    """
    lengths = np.array(list_lengths, dtype=np.int64)
    starts = np.repeat(np.array(list_starts, dtype=np.int64), lengths)
    within = np.arange(len(starts), dtype=np.int64) - np.repeat(
        np.cumsum(lengths) - lengths, lengths
    )
    return lengths, starts + within * stride
