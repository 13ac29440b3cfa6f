"""The body of a binary PLY file (``binary_little_endian`` or ``binary_big_endian``).

Elements without list properties are fixed-size records: one structured ``frombuffer`` each.
Elements with list properties are read the same way when every record has the first
record's list lengths (e.g. all strands of one length); otherwise the records are walked
once to find where every value is, and the values are gathered in one vectorized step.
"""

from __future__ import annotations

import struct

import numpy as np

from hairport.solver.io.hair.common import ReadContext, no_trailing, require_bytes
from hairport.solver.io.hair.ply.header import PlyElement, PlyList, PlyValues, check_counts, list_item_positions


def read_binary_body(
    buf: bytes | memoryview, pos: int, elements: list[PlyElement], byte_order: str, ctx: ReadContext
) -> PlyValues:
    """Every element's values, from byte ``pos`` of ``buf`` to its end.

    Parameters
    ----------
    buf : bytes-like
        The whole file.
    pos : int
        Where the body starts.
    elements : list of PlyElement
    byte_order : str
        ``"<"`` or ``">"``.
    ctx : ReadContext

    Raises
    ------
    InputError
        ``truncated``, ``too_large``, ``bad_header`` (negative list length),
        ``trailing_data``.
    """
    size = len(buf)
    check_counts(elements, size - pos, "bytes", 0, ctx)
    values: PlyValues = {}
    for element in elements:
        if not any(p.is_list for p in element.properties):
            values[element.name], pos = _table(buf, pos, element, ctx)
        else:
            values[element.name], pos = _lists(buf, pos, element, byte_order, ctx)
    no_trailing(ctx, pos, size)
    return values


def _table(
    buf: bytes | memoryview, pos: int, element: PlyElement, ctx: ReadContext
) -> tuple[dict, int]:
    """An element of scalar properties only: one structured read."""
    if not element.properties:
        return {}, pos
    record = np.dtype([(p.name, p.dtype) for p in element.properties])
    end = pos + element.count * record.itemsize
    require_bytes(ctx, end, len(buf), f"element {element.name!r}")
    table = np.frombuffer(buf, dtype=record, count=element.count, offset=pos)
    return {p.name: table[p.name] for p in element.properties}, end


def _lists(
    buf: bytes | memoryview, pos: int, element: PlyElement, byte_order: str, ctx: ReadContext
) -> tuple[dict, int]:
    """An element with list properties: one vectorized read when every record has the first
    record's list lengths (e.g. all strands of one length), else a walk over the records."""
    uniform = uniform_lists(buf, pos, element, byte_order)
    if uniform is not None:
        return uniform
    size = len(buf)
    unpack = {
        p.name: struct.Struct(byte_order + p.count_dtype.char).unpack_from  # char = struct code
        for p in element.properties
        if p.is_list
    }
    scalar_at: dict[str, list[int]] = {p.name: [] for p in element.properties if not p.is_list}
    list_at: dict[str, list[int]] = {p.name: [] for p in element.properties if p.is_list}
    list_len: dict[str, list[int]] = {p.name: [] for p in element.properties if p.is_list}
    for r in range(element.count):
        for p in element.properties:
            if not p.is_list:
                scalar_at[p.name].append(pos)
                pos += p.dtype.itemsize
                continue
            if pos + p.count_dtype.itemsize > size:
                raise ctx.error(
                    f"the file ends inside record {r:,} of element {element.name!r}", "truncated"
                )
            n = unpack[p.name](buf, pos)[0]
            if n < 0:
                raise ctx.error(
                    f"record {r:,} of element {element.name!r} has a negative list length",
                    "bad_header",
                )
            pos += p.count_dtype.itemsize
            list_at[p.name].append(pos)
            list_len[p.name].append(n)
            pos += n * p.dtype.itemsize
        if pos > size:
            raise ctx.error(
                f"record {r:,} of element {element.name!r} runs past the end of the file",
                "truncated",
            )
    raw = np.frombuffer(buf, dtype=np.uint8)
    values: dict = {}
    for p in element.properties:
        if not p.is_list:
            values[p.name] = gather(raw, np.array(scalar_at[p.name], dtype=np.int64), p.dtype)
            continue
        lengths, positions = list_item_positions(list_at[p.name], list_len[p.name], p.dtype.itemsize)
        values[p.name] = PlyList(lengths, gather(raw, positions, p.dtype))
    return values, pos


def uniform_lists(
    buf: bytes | memoryview, pos: int, element: PlyElement, byte_order: str
) -> tuple[dict, int] | None:
    """Read the element as fixed-size records if every list has the first record's length.

    Correct by induction: a record starts where the table says as long as every earlier
    record had the guessed lengths, and all of them are checked.

    Returns
    -------
    values, end : dict, int
        Or ``None`` when the lists' lengths vary (or the first is empty, or the records
        would run past the end): then the caller walks the records.
    """
    size = len(buf)
    if element.count == 0:
        return {
            p.name: (
                PlyList(np.zeros(0, np.int64), np.zeros(0, p.dtype))
                if p.is_list
                else np.zeros(0, p.dtype)
            )
            for p in element.properties
        }, pos
    fields: list[tuple] = []
    lengths: dict[str, int] = {}
    at = pos
    for p in element.properties:
        if not p.is_list:
            fields.append((p.name, p.dtype))
            at += p.dtype.itemsize
            continue
        if at + p.count_dtype.itemsize > size:
            return None
        n = int(np.frombuffer(buf, dtype=p.count_dtype, count=1, offset=at)[0])
        if n <= 0:
            return None
        lengths[p.name] = n
        fields += [(f"{p.name}#count", p.count_dtype), (p.name, p.dtype, (n,))]
        at += p.count_dtype.itemsize + n * p.dtype.itemsize
    record = np.dtype(fields)
    end = pos + element.count * record.itemsize
    if end > size:
        return None
    table = np.frombuffer(buf, dtype=record, count=element.count, offset=pos)
    if not all((table[f"{name}#count"] == n).all() for name, n in lengths.items()):
        return None
    values: dict = {}
    for p in element.properties:
        if p.is_list:
            n = lengths[p.name]
            values[p.name] = PlyList(
                np.full(element.count, n, dtype=np.int64), table[p.name].reshape(-1)
            )
        else:
            values[p.name] = table[p.name]
    return values, end


def gather(raw: np.ndarray, starts: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """Values of ``dtype`` at the given byte offsets of ``raw``.

    Parameters
    ----------
    raw : (B,) uint8
    starts : (K,) int64
        Byte offset of each value.
    dtype : numpy dtype
        With its byte order.

    Returns
    -------
    values : (K,) dtype
    """
    index = starts[:, None] + np.arange(dtype.itemsize, dtype=np.int64)
    return raw[index].view(dtype).reshape(-1)
