"""Hair readers run in the sandbox's child (:mod:`~hairport.solver.io.sandbox`): their strands as arrays
there, and back as :class:`~.common.Strands` here."""

from __future__ import annotations

import importlib
import json
import os
import tempfile

import numpy as np

from hairport.solver.io.external import ALLOW_EXTERNAL_FILES
from hairport.solver.io.hair.common import ReadContext, ReadLimits, Strands, check_finite
from hairport.solver.io.sandbox import run_in_child

#: the hair readers whose ``parse_file(path, ctx) -> Strands`` runs in a child
HAIR_PARSERS = ("hairport.solver.io.hair.usd", "hairport.solver.io.hair.alembic")


def read_in_child(parser: str, source: str, size: int, ctx: ReadContext, library: str) -> Strands:
    """``parser.parse_file(source, ctx)`` (a :class:`Strands`) run in a child under the limits."""
    limits = ctx.limits
    arguments = {"name": os.path.basename(ctx.source), "units": ctx.units, "max_strands": limits.max_strands,
                 "max_particles": limits.max_particles, "prim": ctx.prim,
                 "allow_external_files": limits.allow_external_files}
    arguments["parser"] = parser
    return strands_of(run_in_child(__name__, "strands_arrays", source, size, arguments, ctx.source, library))


def read_bytes_in_child(parser: str, content: bytes | memoryview, suffix: str, ctx: ReadContext,
                        library: str) -> Strands:
    """:func:`read_in_child` of a file's bytes (written to a scratch file of extension ``suffix``), its
    values then checked to be finite. With ``ctx.limits.allow_external_files`` the file they were read
    from (``ctx.path``), if any, is parsed instead, so that what it names relative to itself is found."""
    if ctx.limits.allow_external_files and ctx.path is not None:
        strands = read_in_child(parser, ctx.path, len(content), ctx, library)
    else:
        with tempfile.TemporaryDirectory(prefix="hairport-read-") as folder:
            source = os.path.join(folder, f"groom{suffix}")
            with open(source, "wb") as handle:
                handle.write(content)
            strands = read_in_child(parser, source, len(content), ctx, library)
    check_finite(strands.points, strands.counts, "coordinate", ctx)
    if strands.thickness is not None:
        check_finite(strands.thickness, strands.counts, "width", ctx)
    if strands.color is not None:
        check_finite(strands.color, strands.counts, "color", ctx)
    return strands


def strands_arrays(source: str, parser: str, name: str, units: str, max_strands: int, max_particles: int,
                   prim: str | None = None, allow_external_files: bool = ALLOW_EXTERNAL_FILES) -> dict[str, np.ndarray]:
    """In the child: ``parser.parse_file`` of ``source`` as arrays (:func:`strands_of` reverses it)."""
    if parser not in HAIR_PARSERS:
        raise ValueError(f"unknown hair parser {parser!r}")
    limits = ReadLimits(max_strands=max_strands, max_particles=max_particles, allow_external_files=allow_external_files)
    ctx = ReadContext(name, limits, units, prim)
    strands = importlib.import_module(parser).parse_file(source, ctx)
    arrays = {"points": strands.points, "counts": strands.counts, "warnings": np.array(strands.warnings, dtype=str),
              "attributes": np.array(json.dumps([(name, attribute.domain, attribute.role)
                                                 for name, attribute in strands.attributes.items()]))}
    arrays.update({f"attribute_{index}": attribute.values for index, attribute in enumerate(strands.attributes.values())})
    if strands.thickness is not None:
        arrays["thickness"] = strands.thickness
    if strands.color is not None:
        arrays["color"] = strands.color
    if strands.up_axis is not None:
        arrays["up_axis"] = np.array(strands.up_axis)
    return arrays


def strands_of(found: dict[str, np.ndarray]) -> Strands:
    """The :class:`Strands` of :func:`strands_arrays`."""
    strands = Strands(found["points"], found["counts"], found.get("thickness"), found.get("color"),
                      [str(text) for text in found["warnings"]])
    for index, (name, domain, role) in enumerate(json.loads(str(found["attributes"]))):
        strands.add_attribute(name, found[f"attribute_{index}"], domain, role)
    if "up_axis" in found:
        strands.up_axis = str(found["up_axis"])
    return strands
