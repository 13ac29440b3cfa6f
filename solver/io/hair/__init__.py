"""Readers and writers for strand hair files: the format registry and the public API.

Formats (``SUPPORTED_FORMATS``, chosen from the file extension unless given), one module
each (a package when the format needs several), where its layout is described:

``data``  USC-HairSalon (:mod:`.data`), float32 points only.
``hair``  Cem Yuksel's HAIR (:mod:`.yuksel`), with thickness and color arrays.
``ply``   Polyline PLY, ``ascii``, ``binary_little_endian`` or ``binary_big_endian``
          (:mod:`.ply`; header and bodies in :mod:`.ply.header`, :mod:`.ply.ascii_body`,
          :mod:`.ply.binary_body`).
``npz``   hairport's own archive (:mod:`.npz`), float64 and exact.
``obj``   Wavefront OBJ polylines (:mod:`.obj`).
``usd``, ``usda``, ``usdc``  USD ``BasisCurves`` (:mod:`.usd`, through usd-core), with
          widths and displayColor (primvars in :mod:`.usd.primvars`; the stage opened by
          :mod:`hairport.solver.io.usd`, shared with the character reader); the stage's
          metersPerUnit is its recorded unit.
``abc``   Alembic ``ICurves`` (:mod:`.alembic`, through the optional ``alembic3d``; parameters
          in :mod:`.alembic.params`), in Unreal Engine's groom convention.

Attributes: every per-strand and per-point array a file holds beyond positions, thickness and
colour (UVs, ids, group ids, transparency, custom primvars) is read into ``Hair.attributes`` and
written back by the formats that hold it (``npz``, ``ply``, ``usd*``, ``abc``; ``hair`` holds
transparency only); writing to a format that cannot hold something warns once, naming it.

Each format module (a format package's ``__init__``) exports ``FORMAT``, a
:class:`~.common.HairFormat` naming its reader, its writer and what the format keeps;
:data:`FORMATS` below lists them, and everything else (the format names, the extensions, the
writer's warnings) is derived from it. A new format is one new module (or package), imported
here and entered in :data:`FORMATS`. The machinery every format shares (limits, reports, the
checks) is in :mod:`.common`; what the formats of several curves prims or objects share (USD,
Alembic) in :mod:`.curves`, their child process in :mod:`.sandboxed`.

Units: hairport works in meters. ``read_hair(..., units="cm")`` multiplies coordinates and
thickness by :func:`~hairport.solver.model.units.unit_scale`; ``write_hair(..., units="cm")``
divides by it. The ``.npz`` archive records its units and refuses to be read with other
units (code ``"units_mismatch"``).

Short strands: USC-HairSalon files mark scalp positions without hair by strands of a
single point, and HAIR files may have strands of zero segments. Every reader of a foreign
format (``data``, ``hair``, ``ply``, ``obj``) drops strands of fewer than two points, counts
them, and says so: :func:`read_hair_report` returns the count in
:attr:`ReadReport.skipped_strands` (and which file strands were kept in
:attr:`ReadReport.kept_strands`); :func:`read_hair` emits a :class:`HairIOWarning`. The
``npz`` reader is strict (its writer never makes short strands): code ``"short_strand"``.

No hair: a file left without a strand of two points (none in it, or only short ones), or
whose every strand has zero length (all its points at one place), is refused by every
reader with code ``"empty_hair"``; there is nothing to retarget, and nothing downstream
(preprocessing, the artifact, the API) has to cope with an empty hairstyle.

Bad input: every reader checks counts against the bytes present and against
:class:`ReadLimits` before it allocates anything sized by the file's counts, and raises
:class:`~hairport.solver.model.errors.InputError` naming the source with one of the codes in
``ERROR_CODES``. Writers go through :func:`~hairport.solver.model.files.atomic_write`, so a
failed write leaves no partial file.

Other files: a read opens nothing but the file it is given. A USD stage naming another file
(sublayer, reference, payload, value clip, asset path) is refused with code
``external_reference`` before anything is composed, unless ``ReadLimits.allow_external_files``
(the command line, reading the user's own files: the stage is then composed from the file
itself); see :mod:`hairport.solver.io.external`. No other hair format names files.
"""

from __future__ import annotations

import io
import os
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

import numpy as np

from hairport.solver.io.hair.alembic import FORMAT as ALEMBIC
from hairport.solver.io.hair.common import (
    ERROR_CODES,
    Animation,
    HairFormat,
    HairIOWarning,
    ReadContext,
    ReadLimits,
    ReadReport,
    WriteOptions,
    finish_read,
)
from hairport.solver.io.hair.data import FORMAT as DATA
from hairport.solver.io.hair.npz import FORMAT as NPZ
from hairport.solver.io.hair.obj import FORMAT as OBJ
from hairport.solver.io.hair.ply import FORMAT as PLY
from hairport.solver.io.hair.usd import FORMATS as USD_FORMATS
from hairport.solver.io.hair.yuksel import FORMAT as YUKSEL_HAIR
from hairport.solver.model.errors import PARSER_FAILURES, InputError, parser_failure
from hairport.solver.model.files import atomic_write
from hairport.solver.model.frame import parse_axis
from hairport.solver.model.hair import Hair
from hairport.solver.model.units import unit_scale

__all__ = [
    "ERROR_CODES",
    "EXTENSIONS",
    "FORMATS",
    "SUPPORTED_FORMATS",
    "HairIOWarning",
    "ReadLimits",
    "ReadReport",
    "format_for_path",
    "hair_to_bytes",
    "read_hair",
    "read_hair_bytes",
    "read_hair_bytes_report",
    "read_hair_report",
    "write_hair",
]

#: every format, by name, in the order the API and the docs list them
FORMATS: dict[str, HairFormat] = {spec.name: spec for spec in (DATA, YUKSEL_HAIR, PLY, NPZ, OBJ, *USD_FORMATS, ALEMBIC)}
#: the formats that hold a hairstyle's points time-sampled (:func:`write_hair_frames`)
ANIMATED_FORMATS = tuple(name for name, spec in FORMATS.items() if spec.write_frames is not None)
SUPPORTED_FORMATS: tuple[str, ...] = tuple(FORMATS)
EXTENSIONS: dict[str, str] = {spec.extension: name for name, spec in FORMATS.items()}
# the formats with a text variant, as the writer names them when ascii=True is misused
_ASCII_FORMATS = " and ".join(name.upper() for name, spec in FORMATS.items() if spec.has_ascii)


def recorded_units(path: str | os.PathLike[str], format: str | None = None) -> str | None:
    """The length unit a hair file of ``format`` (default: from the extension) records (an ``.npz``
    archive's, a USD stage's ``metersPerUnit``), or None: the format records none, the file
    cannot be read, or the format is unknown."""
    try:
        fmt = FORMATS[format_for_path(path, format)]
    except InputError:
        return None
    return None if fmt.recorded_units is None else fmt.recorded_units(os.fspath(path))


def format_for_path(path: str | os.PathLike[str], format: str | None = None) -> str:
    """The format of a hair file: ``format`` if given, else from the extension.

    Raises
    ------
    InputError
        Code ``"unknown_format"``.
    """
    source = os.fspath(path)
    if format is not None:
        name = format.lower().lstrip(".")
        if name not in SUPPORTED_FORMATS:
            raise InputError(
                f"unknown hair format {format!r}; supported: {', '.join(SUPPORTED_FORMATS)}",
                source,
                "unknown_format",
            )
        return name
    suffix = Path(source).suffix.lower()
    if suffix not in EXTENSIONS:
        what = f"extension {suffix!r}" if suffix else "no extension"
        raise InputError(
            f"unknown hair file type ({what}); supported extensions: {', '.join(EXTENSIONS)}",
            source,
            "unknown_format",
        )
    return EXTENSIONS[suffix]


def read_hair(
    path: str | os.PathLike[str],
    *,
    units: str = "m",
    limits: ReadLimits = ReadLimits(),
    format: str | None = None,
    prim: str | None = None,
) -> Hair:
    """Read a hairstyle file, in meters.

    Strands of fewer than two points are dropped with a :class:`HairIOWarning` (see the
    module notes); :func:`read_hair_report` says the same in data.

    Parameters
    ----------
    path : str or PathLike
    units : str
        Length unit of the file's coordinates: ``m``, ``dm``, ``cm`` or ``mm``.
    limits : ReadLimits
        Including ``allow_external_files`` (default False: a USD stage naming another file is
        refused, ``external_reference``).
    format : str, optional
        One of ``SUPPORTED_FORMATS``; from the extension when omitted.
    prim : str, optional
        USD and Alembic: read only the curves prim or object of this name or path (code
        ``unknown_prim`` when there is none, and for formats without prims).

    Returns
    -------
    hair : Hair

    Raises
    ------
    InputError
        Naming the file, with a code from ``ERROR_CODES``.
    """
    report = read_hair_report(path, units=units, limits=limits, format=format, prim=prim)
    _emit_warnings(report)
    return report.hair


def read_hair_report(
    path: str | os.PathLike[str],
    *,
    units: str = "m",
    limits: ReadLimits = ReadLimits(),
    format: str | None = None,
    prim: str | None = None,
) -> ReadReport:
    """Like :func:`read_hair`, but return the hairstyle with what the reader did."""
    source = os.fspath(path)
    fmt = format_for_path(source, format)
    unit_scale(units)
    _check_prim(fmt, prim, source)
    content = _read_file(source, limits)
    return _parse(content, fmt, ReadContext(source, limits, units, prim, path=source))


def read_hair_bytes(
    data: bytes | bytearray | memoryview,
    format: str | None,
    *,
    units: str = "m",
    limits: ReadLimits = ReadLimits(),
    source: str = "<bytes>",
    prim: str | None = None,
) -> Hair:
    """Read a hairstyle from the bytes of a file (an upload), in meters.

    Parameters
    ----------
    data : bytes-like
    format : str or None
        One of ``SUPPORTED_FORMATS``; ``None`` to take it from the extension of ``source``.
    units, limits
        As for :func:`read_hair`.
    source : str
        Name used in messages (e.g. the uploaded file name).
    """
    report = read_hair_bytes_report(data, format, units=units, limits=limits, source=source, prim=prim)
    _emit_warnings(report)
    return report.hair


def read_hair_bytes_report(
    data: bytes | bytearray | memoryview,
    format: str | None,
    *,
    units: str = "m",
    limits: ReadLimits = ReadLimits(),
    source: str = "<bytes>",
    prim: str | None = None,
) -> ReadReport:
    """Like :func:`read_hair_bytes`, but return the hairstyle with what the reader did."""
    fmt = format_for_path(source, format)
    unit_scale(units)
    _check_prim(fmt, prim, source)
    view = memoryview(data).cast("B")
    if limits.max_bytes is not None and len(view) > limits.max_bytes:
        raise InputError(
            f"{len(view):,} bytes, above the limit of {limits.max_bytes:,} (ReadLimits.max_bytes)",
            source,
            "too_large",
        )
    return _parse(view, fmt, ReadContext(source, limits, units, prim))


def write_hair(
    path: str | os.PathLike[str],
    hair: Hair,
    *,
    units: str = "m",
    format: str | None = None,
    ascii: bool = False,
    up_axis: str = "+y",
) -> None:
    """Write a hairstyle atomically (temporary file in the same directory, then rename).

    Parameters
    ----------
    path : str or PathLike
    hair : Hair
        In meters.
    units : str
        Length unit to write: ``m``, ``dm``, ``cm`` or ``mm``.
    format : str, optional
        One of ``SUPPORTED_FORMATS``; from the extension when omitted.
    ascii : bool
        PLY only: write ``format ascii 1.0`` instead of binary little-endian.
    up_axis : str
        The axis of the coordinates that points up, recorded by the formats that record one
        (USD's ``upAxis``: ``+z`` is ``Z``, anything else ``Y``; the ``.npz`` archive).

    Raises
    ------
    InputError
        Unknown format, or a hairstyle the format cannot hold (code ``"too_large"``).
    OSError
        The file system refused; no partial file is left behind.
    """
    fmt = format_for_path(path, format)
    writer = _writer(fmt, hair, units, ascii, os.fspath(path), up_axis)
    atomic_write(path, writer)


def write_hair_frames(
    path: str | os.PathLike[str],
    hair: Hair,
    animation: Animation,
    *,
    units: str = "m",
    format: str | None = None,
    up_axis: str = "+y",
) -> None:
    """Write a hairstyle's layout with time-sampled points, atomically, in a format that holds animation
    (:data:`ANIMATED_FORMATS`).

    Parameters
    ----------
    path : str or PathLike
    hair : Hair
        The layout, thickness, colour and attributes (meters); its points are not written.
    animation : Animation
        Every frame's points (meters) and time code.
    units, format, up_axis
        As :func:`write_hair`'s.

    Raises
    ------
    InputError
        ``unknown_format`` for a format that holds one frame, or any of :func:`write_hair`'s.
    """
    fmt = format_for_path(path, format)
    if FORMATS[fmt].write_frames is None:
        raise InputError(f"a {fmt!r} file holds one frame: write an animation as {', '.join(ANIMATED_FORMATS)}, or "
                         "one file per frame", os.fspath(path), "unknown_format")
    for points in animation.points:
        if np.shape(points) != hair.points.shape:
            raise ValueError(f"a frame has points of shape {np.shape(points)}, the hairstyle {hair.points.shape}")
    atomic_write(path, _writer(fmt, hair, units, False, os.fspath(path), up_axis, animation))


def hair_to_bytes(hair: Hair, format: str, *, units: str = "m", ascii: bool = False, up_axis: str = "+y") -> bytes:
    """The bytes :func:`write_hair` would write (for downloads)."""
    fmt = format_for_path("<bytes>", format)
    writer = _writer(fmt, hair, units, ascii, "<bytes>", up_axis)
    buffer = io.BytesIO()
    writer(buffer)
    return buffer.getvalue()


def _check_prim(fmt: str, prim: str | None, source: str) -> None:
    if prim is not None and not FORMATS[fmt].has_prims:
        with_prims = ", ".join(name for name, spec in FORMATS.items() if spec.has_prims)
        raise InputError(f"no curves prim named {prim!r}: a prim selects one of a {with_prims} file; a {fmt!r} file "
                         "has none", source, "unknown_prim")


def _read_file(source: str, limits: ReadLimits) -> bytes:
    try:
        with open(source, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            if limits.max_bytes is not None and size > limits.max_bytes:
                raise InputError(
                    f"the file has {size:,} bytes, above the limit of {limits.max_bytes:,} "
                    "(ReadLimits.max_bytes)",
                    source,
                    "too_large",
                )
            return f.read()
    except OSError as exc:
        raise InputError(
            f"cannot read the file: {exc.strerror or exc}", source, "unreadable"
        ) from exc


def _parse(buf: bytes | memoryview, fmt: str, ctx: ReadContext) -> ReadReport:
    try:
        return finish_read(FORMATS[fmt].read(buf, ctx), fmt, ctx)
    except PARSER_FAILURES as error:
        raise parser_failure(error, ctx.source) from None


def _emit_warnings(report: ReadReport) -> None:
    # stacklevel 3: the warning points at the caller of read_hair / read_hair_bytes
    for note in report.warnings:
        warnings.warn(f"{report.source}: {note}", HairIOWarning, stacklevel=3)


def _writer(
    fmt: str, hair: Hair, units: str, ascii: bool, target: str, up_axis: str = "+y", animation: Animation | None = None
) -> Callable[[BinaryIO], None]:
    """A function that writes ``hair`` to a binary file; checks everything it can first."""
    if not isinstance(hair, Hair):
        raise TypeError(f"expected a Hair, got {type(hair).__name__}")
    scale = unit_scale(units)
    spec = FORMATS[fmt]
    if ascii and not spec.has_ascii:
        raise ValueError(f"ascii=True applies to {_ASCII_FORMATS} only, not {fmt!r}")
    dropped = []
    if hair.thickness is not None and not spec.keeps_thickness:
        dropped.append("thickness")
    if hair.color is not None and not spec.keeps_color:
        dropped.append("color")
    left_out = [name for name, attribute in hair.attributes.items() if not spec.keeps_attribute(name, attribute)]
    if left_out:
        dropped.append(f"attribute{'s' if len(left_out) > 1 else ''} {', '.join(map(repr, left_out))}")
    if dropped:
        # stacklevel 3: the warning points at the caller of write_hair / hair_to_bytes
        warnings.warn(
            f"{target}: the {fmt!r} format cannot hold {' or '.join(dropped)}; not written",
            HairIOWarning,
            stacklevel=3,
        )
    if left_out:
        kept = {name: attribute for name, attribute in hair.attributes.items() if name not in left_out}
        hair = Hair(hair.points, hair.offsets, hair.thickness, hair.color, kept)
    options = WriteOptions(units, scale, ascii, parse_axis(up_axis, "up axis"))
    if animation is not None:
        return lambda f: spec.write_frames(f, hair, animation, options)
    return lambda f: spec.write(f, hair, options)
