"""What the readers of formats with several curves prims or objects (USD, Alembic) share: choosing
the ones asked for, and joining them into one :class:`~.common.Strands`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hairport.solver.io.hair.common import ReadContext, Strands


@dataclass
class CurvesPart:
    """What one curves prim (USD) or object (Alembic) holds, in file units, before the parts are joined.

    Attributes
    ----------
    points : (n, 3) float64
        World positions.
    counts : (c,) int64
    thickness, color : (n,) / (n, 3) float64 or None
    attributes : dict of str to (values, domain, role)
    warnings : list of str
    """

    points: np.ndarray
    counts: np.ndarray
    thickness: np.ndarray | None
    color: np.ndarray | None
    attributes: dict
    warnings: list[str]


def join_parts(parts: list[CurvesPart], kind: str, names: tuple[str, str, str]) -> Strands:
    """One :class:`Strands` of the parts, strands part after part.

    Thickness, colour or an attribute that some parts lack, or that differs in dtype, width,
    domain or role between parts, is dropped and named in a warning.

    Parameters
    ----------
    parts : list of CurvesPart
    kind : str
        What a part is, for the warnings ("BasisCurves prims").
    names : (str, str, str)
        What the file calls thickness, colour and an attribute, for the warnings.
    """
    warnings = [text for part in parts for text in part.warnings]

    def joined(field: str, what: str):
        present = [getattr(part, field) is not None for part in parts]
        if not any(present):
            return None
        if not all(present):
            warnings.append(f"{what} on some {kind} only: dropped")
            return None
        return np.concatenate([getattr(part, field) for part in parts])

    strands = Strands(np.concatenate([part.points for part in parts]), np.concatenate([part.counts for part in parts]),
                      joined("thickness", names[0]), joined("color", names[1]), warnings)
    for name in dict.fromkeys(name for part in parts for name in part.attributes):
        found = [part.attributes.get(name) for part in parts]
        if any(item is None for item in found):
            warnings.append(f"{names[2]} {name!r} on some {kind} only: not kept")
            continue
        if len({(values.dtype.str, values.shape[1:], domain, role) for values, domain, role in found}) > 1:
            warnings.append(f"{names[2]} {name!r} has different types or domains on different {kind}: not kept")
            continue
        _, domain, role = found[0]
        strands.add_attribute(name, np.concatenate([values for values, _, _ in found]), domain, role)
    return strands


def chosen_prims(found: list, names: list[str], kind: str, ctx: ReadContext) -> list:
    """The items of ``found`` (prims or objects, named by ``names``: each a list of the name and the path
    it may be asked by) that ``ctx.prim`` asks for: all when it is None.

    Raises
    ------
    InputError
        ``unknown_prim``, listing what the file has.
    """
    if ctx.prim is None:
        return found
    chosen = [item for item, aliases in zip(found, names, strict=True) if ctx.prim in aliases]
    if not chosen:
        have = ", ".join(repr(aliases[-1]) for aliases in names[:20]) or "none"
        raise ctx.error(f"no {kind} named {ctx.prim!r}; the file has {have}", "unknown_prim")
    return chosen
