"""The body of an ASCII PLY file.

The whole body is parsed as one array of numbers (float64, which holds every PLY integer
type exactly), then cut into elements: in one reshape when every record has the first
record's list lengths, else by a walk over the records. Integer properties must be whole
numbers in their type's range.
"""

from __future__ import annotations

import numpy as np

from hairport.solver.io.hair.common import ReadContext, parse_numbers
from hairport.solver.io.hair.ply.header import (
    PlyElement,
    PlyList,
    PlyProperty,
    PlyValues,
    check_counts,
    list_item_positions,
)


def read_ascii_body(
    buf: bytes | memoryview, pos: int, elements: list[PlyElement], ctx: ReadContext
) -> PlyValues:
    """Parse the ASCII body as one array of numbers, then cut it into elements.

    Raises
    ------
    InputError
        ``truncated``, ``too_large``, ``bad_value``, ``trailing_data``.
    """
    body = bytes(buf[pos:])
    # every number takes at least two bytes (a digit and a separator) except the last
    check_counts(elements, (len(body) + 1) // 2, "numbers", 1, ctx)
    tokens = parse_numbers(body, np.float64, "the PLY body", ctx)
    check_counts(elements, len(tokens), "numbers", 1, ctx)
    values: PlyValues = {}
    t = 0
    for element in elements:
        values[element.name], t = _element(tokens, t, element, ctx)
    if t < len(tokens):
        raise ctx.error(
            f"{len(tokens) - t:,} number(s) left after the last element", "trailing_data"
        )
    return values


def _element(
    tokens: np.ndarray, t: int, element: PlyElement, ctx: ReadContext
) -> tuple[dict, int]:
    """One element's values from ``tokens[t:]``, and the index after them."""
    props = element.properties
    if not props:
        return {}, t
    lengths = _first_lengths(tokens, t, element, ctx)
    width = len(props) + sum(lengths.values())
    end = t + element.count * width
    table = tokens[t:end].reshape(-1, width) if end <= len(tokens) else None
    if table is not None and _uniform(table, props, lengths):
        values: dict = {}
        col = 0
        for p in props:
            if p.is_list:
                n = lengths[p.name]
                items = table[:, col + 1 : col + 1 + n].reshape(-1)
                values[p.name] = PlyList(
                    np.full(element.count, n, dtype=np.int64), cast(items, p, element, ctx)
                )
                col += 1 + n
            else:
                values[p.name] = cast(table[:, col], p, element, ctx)
                col += 1
        return values, end
    return _walk(tokens, t, element, ctx)


def _first_lengths(
    tokens: np.ndarray, t: int, element: PlyElement, ctx: ReadContext
) -> dict[str, int]:
    """The list lengths of the element's first record."""
    lengths: dict[str, int] = {}
    if element.count == 0:
        return {p.name: 0 for p in element.properties if p.is_list}
    for p in element.properties:
        if t >= len(tokens):
            raise ctx.error(f"the file ends inside element {element.name!r}", "truncated")
        if p.is_list:
            n = list_length(tokens[t], element, ctx)
            lengths[p.name] = n
            t += 1 + n
        else:
            t += 1
    return lengths


def _uniform(table: np.ndarray, props: list[PlyProperty], lengths: dict[str, int]) -> bool:
    """Whether every row of ``table`` has the list lengths of the first record."""
    col = 0
    for p in props:
        if p.is_list:
            if not (table[:, col] == lengths[p.name]).all():
                return False
            col += 1 + lengths[p.name]
        else:
            col += 1
    return True


def _walk(
    tokens: np.ndarray, t: int, element: PlyElement, ctx: ReadContext
) -> tuple[dict, int]:
    """One element's values, record by record (lists of varying lengths)."""
    scalar_at: dict[str, list[int]] = {p.name: [] for p in element.properties if not p.is_list}
    list_at: dict[str, list[int]] = {p.name: [] for p in element.properties if p.is_list}
    list_len: dict[str, list[int]] = {p.name: [] for p in element.properties if p.is_list}
    size = len(tokens)
    for r in range(element.count):
        for p in element.properties:
            if t >= size:
                raise ctx.error(
                    f"the file ends inside record {r:,} of element {element.name!r}", "truncated"
                )
            if p.is_list:
                n = list_length(tokens[t], element, ctx)
                list_at[p.name].append(t + 1)
                list_len[p.name].append(n)
                t += 1 + n
            else:
                scalar_at[p.name].append(t)
                t += 1
        if t > size:
            raise ctx.error(
                f"record {r:,} of element {element.name!r} runs past the end of the file",
                "truncated",
            )
    values: dict = {}
    for p in element.properties:
        if not p.is_list:
            values[p.name] = cast(
                tokens[np.array(scalar_at[p.name], dtype=np.int64)], p, element, ctx
            )
            continue
        lengths, positions = list_item_positions(list_at[p.name], list_len[p.name], 1)
        values[p.name] = PlyList(lengths, cast(tokens[positions], p, element, ctx))
    return values, t


def list_length(token: float, element: PlyElement, ctx: ReadContext) -> int:
    """A list length read as a number: a whole, non-negative count (else ``bad_value``)."""
    if not (np.isfinite(token) and token >= 0 and token == int(token)):
        raise ctx.error(
            f"list length {token!r} in element {element.name!r} is not a count", "bad_value"
        )
    return int(token)


def cast(
    values: np.ndarray, prop: PlyProperty, element: PlyElement, ctx: ReadContext
) -> np.ndarray:
    """Numbers parsed as float64 to the property's type; integers must be whole and in range.

    Parameters
    ----------
    values : (K,) float64
    prop : PlyProperty
    element : PlyElement
        For the message.
    ctx : ReadContext

    Returns
    -------
    values : (K,) the property's dtype, native byte order

    Raises
    ------
    InputError
        ``bad_value``.
    """
    dtype = prop.dtype.newbyteorder("=")
    if dtype.kind == "f":
        return values.astype(dtype)
    info = np.iinfo(dtype)
    ok = (
        np.isfinite(values)
        & (values == np.round(values))
        & (values >= info.min)
        & (values <= info.max)
    )
    if not ok.all():
        bad = values[np.argmin(ok)]
        raise ctx.error(
            f"property {prop.name!r} of element {element.name!r} holds {bad!r}, not a {dtype.name}",
            "bad_value",
        )
    return values.astype(dtype)
