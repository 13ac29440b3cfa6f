"""Readers and writers for strand hair files.

Formats (``SUPPORTED_FORMATS``, chosen from the file extension unless given):

``data``  USC-HairSalon: little-endian ``int32`` strand count, then per strand ``int32 n``
          and ``n * 3`` ``float32`` coordinates. Written as float32.
``hair``  Cem Yuksel's HAIR: a 128-byte header (``"HAIR"``, hair count, point count, array
          flags, default segments / thickness / transparency / color, 88-byte info string),
          then the arrays the flags announce, in the order segments (``uint16`` per strand,
          points - 1), points (``float32`` x3), thickness, transparency, color (``float32`` x3).
          All five flags are read. Thickness and color are kept in ``Hair.thickness`` /
          ``Hair.color`` only when their array flag is set: the header defaults are always
          present in a HAIR file (the reference library fills them in), so they say nothing
          about the hairstyle and are not expanded to per-point arrays. ``Hair`` has no
          transparency field: a transparency array is read, checked for finite values and
          dropped, with a warning in the :class:`ReadReport`.
``ply``   Polyline PLY, ``ascii``, ``binary_little_endian`` or ``binary_big_endian``. See
          "PLY layouts" below.
``npz``   hairport's own archive: ``format = "hairport-hair"``, ``version`` (int),
          ``units`` (str), ``points (N, 3)``, ``offsets (S+1,)``, optional ``thickness (N,)``
          and ``color (N, 3)``. Read with ``allow_pickle=False``; every array's shape and
          dtype is checked from its ``.npy`` header before its data are read.
``obj``   Wavefront OBJ polylines: ``v x y z [r g b]`` lines and ``l i j k ...`` lines
          (1-based indices, negative ones relative, ``i/t`` forms accepted). Faces and
          other records are ignored with a warning.

Units: hairport works in meters. ``read_hair(..., units="cm")`` multiplies coordinates and
thickness by :func:`~hairport.solver.units.unit_scale`; ``write_hair(..., units="cm")``
divides by it. The ``.npz`` archive records its units and refuses to be read with other
units (code ``"units_mismatch"``).

Short strands: USC-HairSalon files mark scalp positions without hair by strands of a
single point, and HAIR files may have strands of zero segments. Every reader of a foreign
format (``data``, ``hair``, ``ply``, ``obj``) drops strands of fewer than two points, counts
them, and says so: :func:`read_hair_report` returns the count in
:attr:`ReadReport.skipped_strands` (and which file strands were kept in
:attr:`ReadReport.kept_strands`); :func:`read_hair` emits a :class:`HairIOWarning`. The
``npz`` reader is strict (its writer never makes short strands): code ``"short_strand"``.

PLY layouts. The reader accepts, in this order of precedence:

(a) an element ``strand`` (or ``strands``, ``curve``, ``curves``, ``polyline``, ``hair``)
    with a list property of vertex indices (e.g. ``property list uchar int vertex_indices``),
    one list per strand, root first;
(b) the same element with a scalar count: ``nsegs`` / ``segments`` (points - 1, the
    convention of the ``hairutil`` tool) or ``npoints`` / ``num_points`` / ``vertex_count``
    (points), strands being consecutive runs of vertices;
(c) a per-vertex integer property naming the strand (``strand_id``, ``strand``,
    ``strand_index``, ``curve_id``, ``hair_id``); each strand's vertices must be consecutive;
(d) an element ``edge`` with ``vertex1`` / ``vertex2`` joining consecutive vertices; maximal
    chains form strands.

When (b) and (d) are both present the edges must agree with the strands. Per-vertex
``thickness`` (or ``width``) and ``red`` / ``green`` / ``blue`` (integers scaled by their
type's maximum, floats taken as [0, 1]) are kept.

The writer writes ``binary_little_endian`` (``ascii=True`` for ASCII)::

    element vertex N      float x, y, z [, float thickness] [, uchar red, green, blue]
    element strand S      ushort nsegs   (uint when a strand has more than 65,535 segments)
    element edge N-S      int vertex1, vertex2

that is the layout of ``hairutil`` (strand structure in ``nsegs``) plus edges, so that
general viewers (MeshLab, Blender, Open3D) show the strands as polylines. Colors are
quantized to 8 bits, as every PLY viewer expects; use ``.hair`` or ``.npz`` to keep them
exactly.

Bad input: every reader checks counts against the bytes present and against
:class:`ReadLimits` before it allocates anything sized by the file's counts, and raises
:class:`~hairport.solver.errors.InputError` naming the source with one of the codes in
``ERROR_CODES``. Writers write to a temporary file in the target directory and rename it
into place, so a failed write leaves no partial file.
"""

from __future__ import annotations

import contextlib
import io
import lzma
import os
import re
import struct
import uuid
import warnings
import zipfile
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

import numpy as np

from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import MIN_PARTICLES_PER_STRAND, Hair
from hairport.solver.model.units import METERS_PER_UNIT, unit_scale

__all__ = [
    "ERROR_CODES",
    "EXTENSIONS",
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

SUPPORTED_FORMATS: tuple[str, ...] = ("data", "hair", "ply", "npz", "obj")
EXTENSIONS: dict[str, str] = {f".{name}": name for name in SUPPORTED_FORMATS}

ERROR_CODES: dict[str, str] = {
    "unknown_format": "the extension or format name is not one of SUPPORTED_FORMATS",
    "unreadable": "the file could not be opened or read (OS error)",
    "truncated": "the file ends before the data its header or counts announce",
    "trailing_data": "bytes left over after the announced data (binary formats)",
    "too_large": "a count or the file size is above ReadLimits",
    "bad_header": "a header or structural field is malformed or inconsistent",
    "bad_value": "a value in a text format is not a number or not an integer where one is needed",
    "bad_index": "a vertex index or strand layout field is out of range or inconsistent",
    "bad_offsets": "npz offsets do not start at 0, end at N and increase",
    "non_finite": "a coordinate, thickness, transparency or color is NaN or infinite",
    "short_strand": "npz strand with fewer than two points (other formats skip them)",
    "units_mismatch": "an npz archive recorded in other units than the ones asked for",
}

# --- USC-HairSalon .data -----------------------------------------------------------------
DATA_HEADER_BYTES = 4  # int32 strand count
DATA_COUNT_BYTES = 4  # int32 points of one strand
DATA_POINT_BYTES = 12  # float32 x, y, z
_INT32 = struct.Struct("<i")
INT32_MAX = 2**31 - 1

# --- Cem Yuksel .hair --------------------------------------------------------------------
HAIR_MAGIC = b"HAIR"
HAIR_HEADER_BYTES = 128
HAIR_INFO_BYTES = 88
HAIR_SEGMENTS_BIT = 1
HAIR_POINTS_BIT = 2
HAIR_THICKNESS_BIT = 4
HAIR_TRANSPARENCY_BIT = 8
HAIR_COLORS_BIT = 16
HAIR_KNOWN_BITS = (
    HAIR_SEGMENTS_BIT
    | HAIR_POINTS_BIT
    | HAIR_THICKNESS_BIT
    | HAIR_TRANSPARENCY_BIT
    | HAIR_COLORS_BIT
)
HAIR_MAX_SEGMENTS = 2**16 - 1  # segments are uint16
UINT32_MAX = 2**32 - 1
HAIR_INFO = b"hairport"
HAIR_HEADER_DTYPE = np.dtype(
    [
        ("magic", "S4"),
        ("hair_count", "<u4"),
        ("point_count", "<u4"),
        ("arrays", "<u4"),
        ("d_segments", "<u4"),
        ("d_thickness", "<f4"),
        ("d_transparency", "<f4"),
        ("d_color", "<f4", (3,)),
        ("info", f"S{HAIR_INFO_BYTES}"),
    ]
)
assert HAIR_HEADER_DTYPE.itemsize == HAIR_HEADER_BYTES
# Written as the header default when the hairstyle has no thickness: a typical human hair
# diameter (the reference library's own default, 1.0 file unit, would be a 1 m hair).
TYPICAL_HAIR_THICKNESS_M = 7e-5
HAIR_DEFAULT_TRANSPARENCY = 0.0
HAIR_DEFAULT_COLOR = (1.0, 1.0, 1.0)  # the reference library's default

# --- PLY ---------------------------------------------------------------------------------
PLY_MAGIC_LINE = b"ply\n"
PLY_MAX_HEADER_BYTES = 1 << 20
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
PLY_STRAND_ELEMENTS = ("strand", "strands", "curve", "curves", "polyline", "polylines", "hair")
PLY_INDEX_LISTS = ("vertex_indices", "vertex_index", "indices")
PLY_SEGMENT_COUNTS = ("nsegs", "segments", "num_segments", "segment_count")
PLY_POINT_COUNTS = (
    "npoints",
    "num_points",
    "point_count",
    "vertex_count",
    "num_vertices",
    "nverts",
)
PLY_STRAND_IDS = ("strand_id", "strand", "strand_index", "strand_idx", "curve_id", "hair_id")
PLY_THICKNESS = ("thickness", "width")
PLY_COLORS = ("red", "green", "blue")
PLY_ASCII_FLOAT = "%.9g"  # enough digits to give back every float32 exactly
ASCII_CHUNK_ROWS = 1 << 16

# --- npz ---------------------------------------------------------------------------------
NPZ_FORMAT = "hairport-hair"
NPZ_VERSION = 1
NPZ_REQUIRED = ("format", "version", "points", "offsets")
NPZ_OPTIONAL = ("units", "thickness", "color")
NPZ_MAX_HEADER_BYTES = 10_000
ZIP_MAGIC = b"PK\x03\x04"
# what zipfile and numpy raise on a damaged member (bad deflate stream, unknown compression
# method or zip version, encryption, short data)
_ZIP_ERRORS = (
    ValueError,
    OSError,
    EOFError,
    zipfile.BadZipFile,
    NotImplementedError,
    RuntimeError,
    zlib.error,
    lzma.LZMAError,
)
NPY_HEADER_READERS = {(1, 0): "read_array_header_1_0", (2, 0): "read_array_header_2_0"}


@dataclass(frozen=True)
class ReadLimits:
    """Upper bounds a reader enforces before it allocates.

    Attributes
    ----------
    max_strands : int
        Strands the file may declare (short strands included).
    max_particles : int
        Points the file may declare (points of short strands included).
    max_bytes : int or None
        File size; ``None`` for no limit.
    """

    max_strands: int = 5_000_000
    max_particles: int = 50_000_000
    max_bytes: int | None = None


@dataclass(frozen=True, eq=False)
class ReadReport:
    """A hairstyle read from a file and what the reader did to get it.

    Attributes
    ----------
    hair : Hair
        In meters.
    format : str
        One of ``SUPPORTED_FORMATS``.
    source : str
        The file name (or the name given for bytes).
    strands_in_file : int
        Strands the file holds, short ones included.
    skipped_strands : int
        Strands of fewer than two points that were dropped.
    skipped_particles : int
        Points of the dropped strands.
    kept_strands : (S,) int64
        File index of every strand of ``hair``, in order.
    warnings : tuple of str
        Everything the reader dropped or could not keep, in words.
    """

    hair: Hair
    format: str
    source: str
    strands_in_file: int
    skipped_strands: int
    skipped_particles: int
    kept_strands: np.ndarray
    warnings: tuple[str, ...] = ()


class HairIOWarning(UserWarning):
    """Something a reader or writer dropped (short strands, transparency, attributes)."""


@dataclass
class _Strands:
    """What a format reader found, in file units, before short strands are dropped.

    Attributes
    ----------
    points : (N, 3) float32 or float64
    counts : (S,) int64
        Points per strand, possibly fewer than two.
    thickness : (N,) float or None
    color : (N, 3) float or None
    warnings : list of str
    strict : bool
        Short strands are an error instead of being skipped.
    """

    points: np.ndarray
    counts: np.ndarray
    thickness: np.ndarray | None = None
    color: np.ndarray | None = None
    warnings: list[str] = field(default_factory=list)
    strict: bool = False


@dataclass(frozen=True)
class _Context:
    source: str
    limits: ReadLimits
    units: str

    def error(self, problem: str, code: str) -> InputError:
        return InputError(problem, self.source, code)

    def check_limit(self, count: int, what: str) -> None:
        limit = self.limits.max_strands if what == "strands" else self.limits.max_particles
        if count > limit:
            raise self.error(
                f"the file declares {count:,} {what}, above the limit of {limit:,} "
                f"(ReadLimits.max_{what})",
                "too_large",
            )


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
    format : str, optional
        One of ``SUPPORTED_FORMATS``; from the extension when omitted.

    Returns
    -------
    hair : Hair

    Raises
    ------
    InputError
        Naming the file, with a code from ``ERROR_CODES``.
    """
    report = read_hair_report(path, units=units, limits=limits, format=format)
    _emit_warnings(report)
    return report.hair


def read_hair_report(
    path: str | os.PathLike[str],
    *,
    units: str = "m",
    limits: ReadLimits = ReadLimits(),
    format: str | None = None,
) -> ReadReport:
    """Like :func:`read_hair`, but return the hairstyle with what the reader did."""
    source = os.fspath(path)
    fmt = format_for_path(source, format)
    unit_scale(units)
    data = _read_file(source, limits)
    return _parse(data, fmt, _Context(source, limits, units))


def read_hair_bytes(
    data: bytes | bytearray | memoryview,
    format: str | None,
    *,
    units: str = "m",
    limits: ReadLimits = ReadLimits(),
    source: str = "<bytes>",
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
    report = read_hair_bytes_report(data, format, units=units, limits=limits, source=source)
    _emit_warnings(report)
    return report.hair


def read_hair_bytes_report(
    data: bytes | bytearray | memoryview,
    format: str | None,
    *,
    units: str = "m",
    limits: ReadLimits = ReadLimits(),
    source: str = "<bytes>",
) -> ReadReport:
    """Like :func:`read_hair_bytes`, but return the hairstyle with what the reader did."""
    fmt = format_for_path(source, format)
    unit_scale(units)
    view = memoryview(data).cast("B")
    if limits.max_bytes is not None and len(view) > limits.max_bytes:
        raise InputError(
            f"{len(view):,} bytes, above the limit of {limits.max_bytes:,} (ReadLimits.max_bytes)",
            source,
            "too_large",
        )
    return _parse(view, fmt, _Context(source, limits, units))


def write_hair(
    path: str | os.PathLike[str],
    hair: Hair,
    *,
    units: str = "m",
    format: str | None = None,
    ascii: bool = False,
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

    Raises
    ------
    InputError
        Unknown format, or a hairstyle the format cannot hold (code ``"too_large"``).
    OSError
        The file system refused; no partial file is left behind.
    """
    fmt = format_for_path(path, format)
    writer = _writer(fmt, hair, units, ascii, os.fspath(path))
    _atomic_write(Path(path), writer)


def hair_to_bytes(hair: Hair, format: str, *, units: str = "m", ascii: bool = False) -> bytes:
    """The bytes :func:`write_hair` would write (for downloads)."""
    fmt = format_for_path("<bytes>", format)
    writer = _writer(fmt, hair, units, ascii, "<bytes>")
    buffer = io.BytesIO()
    writer(buffer)
    return buffer.getvalue()


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


def _parse(buf: bytes | memoryview, fmt: str, ctx: _Context) -> ReadReport:
    strands = _READERS[fmt](buf, ctx)
    return _finish(strands, fmt, ctx)


def _finish(raw: _Strands, fmt: str, ctx: _Context) -> ReadReport:
    """Check values, drop short strands, convert to meters, build the ``Hair``."""
    counts = np.asarray(raw.counts, dtype=np.int64)
    _check_finite(raw.points, counts, "coordinate", ctx)
    if raw.thickness is not None:
        _check_finite(raw.thickness, counts, "thickness", ctx)
    if raw.color is not None:
        _check_finite(raw.color, counts, "color", ctx)
    keep = counts >= MIN_PARTICLES_PER_STRAND
    n_skipped = int(len(counts) - np.count_nonzero(keep))
    notes = list(raw.warnings)
    points, thickness, color = raw.points, raw.thickness, raw.color
    skipped_particles = 0
    if n_skipped:
        if raw.strict:
            bad = int(np.argmin(keep))
            raise ctx.error(
                f"strand {bad} has {int(counts[bad])} point(s); every strand needs at least "
                f"{MIN_PARTICLES_PER_STRAND}",
                "short_strand",
            )
        particle_keep = np.repeat(keep, counts)
        skipped_particles = int(len(particle_keep) - np.count_nonzero(particle_keep))
        points = points[particle_keep]
        thickness = None if thickness is None else thickness[particle_keep]
        color = None if color is None else color[particle_keep]
        notes.append(
            f"skipped {n_skipped:,} strand(s) with fewer than {MIN_PARTICLES_PER_STRAND} points "
            f"({skipped_particles:,} point(s)); USC-HairSalon files mark scalp positions "
            "without hair this way"
        )
    kept = counts[keep]
    if len(kept) == 0:
        notes.append("the file holds no strand of two or more points")
    offsets = np.zeros(len(kept) + 1, dtype=np.int64)
    np.cumsum(kept, out=offsets[1:])
    scale = unit_scale(ctx.units)
    points = np.asarray(points, dtype=np.float64)
    if scale != 1.0:
        points = points * scale
    if thickness is not None:
        thickness = np.asarray(thickness, dtype=np.float64) * scale
    hair = Hair(points.reshape(-1, 3), offsets, thickness, color)
    return ReadReport(
        hair=hair,
        format=fmt,
        source=ctx.source,
        strands_in_file=len(counts),
        skipped_strands=n_skipped,
        skipped_particles=skipped_particles,
        kept_strands=np.flatnonzero(keep).astype(np.int64),
        warnings=tuple(notes),
    )


def _check_finite(values: np.ndarray, counts: np.ndarray, what: str, ctx: _Context) -> None:
    finite = np.isfinite(values)
    if finite.all():
        return
    if finite.ndim > 1:
        finite = finite.all(axis=1)
    particle = int(np.argmin(finite))
    strand = int(np.searchsorted(np.cumsum(counts), particle, side="right"))
    raise ctx.error(
        f"point {particle} (strand {strand}) has a non-finite {what} (NaN or inf)", "non_finite"
    )


def _emit_warnings(report: ReadReport) -> None:
    for note in report.warnings:
        warnings.warn(f"{report.source}: {note}", HairIOWarning, stacklevel=3)


def _require_bytes(ctx: _Context, needed: int, size: int, what: str) -> None:
    if needed > size:
        raise ctx.error(f"{what} needs {needed:,} bytes but the file has {size:,}", "truncated")


def _no_trailing(ctx: _Context, end: int, size: int) -> None:
    if end < size:
        raise ctx.error(
            f"{size - end:,} unexpected byte(s) after the data, which ends at byte {end:,}",
            "trailing_data",
        )


def _read_data(buf: bytes | memoryview, ctx: _Context) -> _Strands:
    """Parse ``int32 S``, then per strand ``int32 n`` and ``n`` float32 triples."""
    size = len(buf)
    _require_bytes(ctx, DATA_HEADER_BYTES, size, "the strand count")
    n_strands = _INT32.unpack_from(buf, 0)[0]
    if n_strands < 0:
        raise ctx.error(f"the header declares a negative strand count ({n_strands})", "bad_header")
    _require_bytes(
        ctx,
        DATA_HEADER_BYTES + DATA_COUNT_BYTES * n_strands,
        size,
        f"a header of {n_strands:,} strands",
    )
    ctx.check_limit(n_strands, "strands")
    counts = _data_counts(buf, n_strands, ctx)
    ctx.check_limit(int(counts.sum()), "particles")
    words = np.frombuffer(buf, dtype="<f4", offset=DATA_HEADER_BYTES)
    count_words = np.zeros(len(counts) + 1, dtype=np.int64)
    np.cumsum(counts * 3 + 1, out=count_words[1:])
    is_point = np.ones(len(words), dtype=bool)
    is_point[count_words[:-1]] = False
    points = words[is_point].reshape(-1, 3)
    return _Strands(points, counts)


def _data_counts(buf: bytes | memoryview, n_strands: int, ctx: _Context) -> np.ndarray:
    """Points per strand, walking the interleaved counts; checks the file ends with the data.

    Each strand's position depends on all earlier counts, so the walk is sequential. When
    all strands have the first strand's length (resampled grooms) one vectorized check
    replaces it; otherwise a loop does integer arithmetic only (about 0.3 µs a strand).
    """
    size = len(buf)
    if n_strands == 0:
        _no_trailing(ctx, DATA_HEADER_BYTES, size)
        return np.zeros(0, dtype=np.int64)
    first = _INT32.unpack_from(buf, DATA_HEADER_BYTES)[0]
    stride = DATA_COUNT_BYTES + DATA_POINT_BYTES * first
    if first >= 0 and DATA_HEADER_BYTES + n_strands * stride == size:
        table = np.frombuffer(buf, dtype="<i4", offset=DATA_HEADER_BYTES).reshape(n_strands, -1)
        if (table[:, 0] == first).all():
            return np.full(n_strands, first, dtype=np.int64)
    unpack = _INT32.unpack_from
    counts = [0] * n_strands
    pos = DATA_HEADER_BYTES
    for s in range(n_strands):
        if pos + DATA_COUNT_BYTES > size:
            raise ctx.error(
                f"the file ends at byte {size:,}, inside the point count of strand {s:,} "
                f"of {n_strands:,}",
                "truncated",
            )
        n = unpack(buf, pos)[0]
        if n < 0:
            raise ctx.error(f"strand {s:,} declares a negative point count ({n})", "bad_header")
        counts[s] = n
        pos += DATA_COUNT_BYTES + DATA_POINT_BYTES * n
        if pos > size:
            raise ctx.error(
                f"strand {s:,} of {n_strands:,} declares {n:,} points, which run past the end "
                f"of the file (byte {size:,})",
                "truncated",
            )
    _no_trailing(ctx, pos, size)
    return np.array(counts, dtype=np.int64)


def _write_data(f: BinaryIO, hair: Hair, scale: float) -> None:
    _check_fits(hair, INT32_MAX, INT32_MAX, "data")
    counts = hair.counts
    words = np.empty(1 + hair.n_strands + 3 * hair.n_particles, dtype="<i4")
    words[0] = hair.n_strands
    count_at = 1 + np.arange(hair.n_strands, dtype=np.int64) + 3 * hair.offsets[:-1]
    is_point = np.ones(len(words), dtype=bool)
    is_point[0] = False
    is_point[count_at] = False
    words[count_at] = counts
    words.view("<f4")[is_point] = _to_float32(hair.points / scale, "coordinate").ravel()
    f.write(memoryview(words).cast("B"))


def _read_hair(buf: bytes | memoryview, ctx: _Context) -> _Strands:
    size = len(buf)
    _require_bytes(ctx, HAIR_HEADER_BYTES, size, "the HAIR header")
    header = np.frombuffer(buf, dtype=HAIR_HEADER_DTYPE, count=1)[0]
    if bytes(header["magic"]) != HAIR_MAGIC:
        raise ctx.error("not a HAIR file (the first four bytes are not 'HAIR')", "bad_header")
    n_strands = int(header["hair_count"])
    n_points = int(header["point_count"])
    flags = int(header["arrays"])
    if flags & ~HAIR_KNOWN_BITS:
        raise ctx.error(
            f"unknown array flags 0x{flags & ~HAIR_KNOWN_BITS:x} in the header", "bad_header"
        )
    if not flags & HAIR_POINTS_BIT:
        raise ctx.error("the header announces no points array", "bad_header")
    layout = _hair_array_layout(flags, n_strands, n_points)
    end = HAIR_HEADER_BYTES + sum(nbytes for _, nbytes, _ in layout)
    _require_bytes(ctx, end, size, f"a HAIR file of {n_strands:,} strands and {n_points:,} points")
    _no_trailing(ctx, end, size)
    ctx.check_limit(n_strands, "strands")
    ctx.check_limit(n_points, "particles")
    arrays: dict[str, np.ndarray] = {}
    pos = HAIR_HEADER_BYTES
    for name, nbytes, dtype in layout:
        arrays[name] = np.frombuffer(buf, dtype=dtype, count=nbytes // dtype.itemsize, offset=pos)
        pos += nbytes
    counts = _hair_counts(
        arrays.get("segments"), int(header["d_segments"]), n_strands, n_points, ctx
    )
    notes = []
    if "transparency" in arrays:
        _check_finite(arrays["transparency"], counts, "transparency", ctx)
        notes.append("the transparency array was dropped (Hair has no transparency)")
    return _Strands(
        points=arrays["points"].reshape(-1, 3),
        counts=counts,
        thickness=arrays.get("thickness"),
        color=None if "color" not in arrays else arrays["color"].reshape(-1, 3),
        warnings=notes,
    )


def _hair_array_layout(
    flags: int, n_strands: int, n_points: int
) -> list[tuple[str, int, np.dtype]]:
    """(name, byte size, dtype) of every array the flags announce, in file order."""
    f32 = np.dtype("<f4")
    candidates = [
        (HAIR_SEGMENTS_BIT, "segments", 2 * n_strands, np.dtype("<u2")),
        (HAIR_POINTS_BIT, "points", 12 * n_points, f32),
        (HAIR_THICKNESS_BIT, "thickness", 4 * n_points, f32),
        (HAIR_TRANSPARENCY_BIT, "transparency", 4 * n_points, f32),
        (HAIR_COLORS_BIT, "color", 12 * n_points, f32),
    ]
    return [(name, nbytes, dtype) for bit, name, nbytes, dtype in candidates if flags & bit]


def _hair_counts(
    segments: np.ndarray | None, d_segments: int, n_strands: int, n_points: int, ctx: _Context
) -> np.ndarray:
    if segments is None:
        counts = np.full(n_strands, d_segments + 1, dtype=np.int64)
        total = n_strands * (d_segments + 1)
        where = f"{n_strands:,} strands of the default {d_segments:,} segments"
    else:
        counts = segments.astype(np.int64) + 1
        total = int(counts.sum())
        where = "the segments array"
    if total != n_points:
        raise ctx.error(
            f"{where} make(s) {total:,} points but the header declares {n_points:,}", "bad_header"
        )
    return counts


def _write_hair_file(f: BinaryIO, hair: Hair, scale: float) -> None:
    _check_fits(hair, UINT32_MAX, UINT32_MAX, "hair")
    if hair.n_strands and int(hair.counts.max()) - 1 > HAIR_MAX_SEGMENTS:
        bad = int(np.argmax(hair.counts))
        raise InputError(
            f"strand {bad} has {int(hair.counts[bad]) - 1:,} segments; the HAIR format holds at "
            f"most {HAIR_MAX_SEGMENTS:,} per strand",
            code="too_large",
        )
    header = np.zeros(1, dtype=HAIR_HEADER_DTYPE)
    flags = HAIR_SEGMENTS_BIT | HAIR_POINTS_BIT
    flags |= HAIR_THICKNESS_BIT if hair.thickness is not None else 0
    flags |= HAIR_COLORS_BIT if hair.color is not None else 0
    header["magic"] = HAIR_MAGIC
    header["hair_count"] = hair.n_strands
    header["point_count"] = hair.n_particles
    header["arrays"] = flags
    header["d_segments"] = 0
    header["d_thickness"] = TYPICAL_HAIR_THICKNESS_M / scale
    header["d_transparency"] = HAIR_DEFAULT_TRANSPARENCY
    header["d_color"] = HAIR_DEFAULT_COLOR
    header["info"] = HAIR_INFO
    f.write(header.tobytes())
    f.write((hair.counts - 1).astype("<u2").tobytes())
    f.write(_to_float32(hair.points / scale, "coordinate").tobytes())
    if hair.thickness is not None:
        f.write(_to_float32(hair.thickness / scale, "thickness").tobytes())
    if hair.color is not None:
        f.write(_to_float32(hair.color, "color").tobytes())


@dataclass(frozen=True)
class _PlyProperty:
    """One property; ``count_dtype`` is set for a list property."""

    name: str
    dtype: np.dtype
    count_dtype: np.dtype | None = None

    @property
    def is_list(self) -> bool:
        return self.count_dtype is not None


@dataclass
class _PlyElement:
    name: str
    count: int
    properties: list[_PlyProperty] = field(default_factory=list)


@dataclass(frozen=True)
class _PlyList:
    """Values of a list property: ``lengths (E,) int64`` and all items concatenated."""

    lengths: np.ndarray
    values: np.ndarray


_PlyValues = dict[str, dict[str, "np.ndarray | _PlyList"]]


def _read_ply(buf: bytes | memoryview, ctx: _Context) -> _Strands:
    encoding, elements, body_at = _ply_header(buf, ctx)
    if encoding == "ascii":
        values = _ply_ascii_body(buf, body_at, elements, ctx)
    else:
        values = _ply_binary_body(buf, body_at, elements, PLY_ENCODINGS[encoding], ctx)
    return _ply_strands(values, ctx)


def _ply_header(buf: bytes | memoryview, ctx: _Context) -> tuple[str, list[_PlyElement], int]:
    """Parse the header: (encoding, elements, byte offset of the body)."""
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
    elements: list[_PlyElement] = []
    for number, line in enumerate(lines, start=2):
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        try:
            if words[0] == "format":
                encoding = _ply_format_line(words, ctx)
            elif words[0] == "element":
                elements.append(_ply_element_line(words, elements, ctx))
            elif words[0] == "property":
                _ply_property_line(words, elements, encoding, ctx)
            else:
                raise ctx.error(f"unknown keyword {words[0]!r}", "bad_header")
        except InputError as exc:
            raise ctx.error(f"PLY header line {number}: {exc.problem}", exc.code) from None
    if encoding is None:
        raise ctx.error("the PLY header has no format line", "bad_header")
    return encoding, elements, end.end()


def _ply_format_line(words: list[str], ctx: _Context) -> str:
    if len(words) != 3 or words[1] not in PLY_ENCODINGS:
        raise ctx.error(
            f"unsupported format {' '.join(words[1:])!r}; "
            f"expected one of {', '.join(PLY_ENCODINGS)}",
            "bad_header",
        )
    return words[1]


def _ply_element_line(words: list[str], elements: list[_PlyElement], ctx: _Context) -> _PlyElement:
    if len(words) != 3 or not words[2].isdigit():
        raise ctx.error(f"malformed element line {' '.join(words)!r}", "bad_header")
    if any(e.name == words[1] for e in elements):
        raise ctx.error(f"element {words[1]!r} appears twice", "bad_header")
    return _PlyElement(words[1], int(words[2]))


def _ply_property_line(
    words: list[str], elements: list[_PlyElement], encoding: str | None, ctx: _Context
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
        prop = _PlyProperty(words[4], dtype(words[3]), count_dtype)
    elif len(words) == 3:
        prop = _PlyProperty(words[2], dtype(words[1]))
    else:
        raise ctx.error(f"malformed property line {' '.join(words)!r}", "bad_header")
    element = elements[-1]
    if any(p.name == prop.name for p in element.properties):
        raise ctx.error(
            f"property {prop.name!r} appears twice in element {element.name!r}", "bad_header"
        )
    element.properties.append(prop)


def _ply_check_counts(
    elements: list[_PlyElement], available: int, unit: str, per_item: int, ctx: _Context
) -> None:
    """Counts against the body size (minimum record sizes), then against the limits."""
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


def _ply_binary_body(
    buf: bytes | memoryview, pos: int, elements: list[_PlyElement], byte_order: str, ctx: _Context
) -> _PlyValues:
    size = len(buf)
    _ply_check_counts(elements, size - pos, "bytes", 0, ctx)
    values: _PlyValues = {}
    for element in elements:
        if not any(p.is_list for p in element.properties):
            values[element.name], pos = _ply_binary_table(buf, pos, element, ctx)
        else:
            values[element.name], pos = _ply_binary_lists(buf, pos, element, byte_order, ctx)
    _no_trailing(ctx, pos, size)
    return values


def _ply_binary_table(
    buf: bytes | memoryview, pos: int, element: _PlyElement, ctx: _Context
) -> tuple[dict, int]:
    if not element.properties:
        return {}, pos
    record = np.dtype([(p.name, p.dtype) for p in element.properties])
    end = pos + element.count * record.itemsize
    _require_bytes(ctx, end, len(buf), f"element {element.name!r}")
    table = np.frombuffer(buf, dtype=record, count=element.count, offset=pos)
    return {p.name: table[p.name] for p in element.properties}, end


def _ply_binary_lists(
    buf: bytes | memoryview, pos: int, element: _PlyElement, byte_order: str, ctx: _Context
) -> tuple[dict, int]:
    """An element with list properties: one vectorized read when every record has the first
    record's list lengths (e.g. all strands of one length), else a walk over the records."""
    uniform = _ply_uniform_lists(buf, pos, element, byte_order)
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
            values[p.name] = _gather(raw, np.array(scalar_at[p.name], dtype=np.int64), p.dtype)
            continue
        lengths = np.array(list_len[p.name], dtype=np.int64)
        starts = np.repeat(np.array(list_at[p.name], dtype=np.int64), lengths)
        within = np.arange(len(starts), dtype=np.int64) - np.repeat(
            np.cumsum(lengths) - lengths, lengths
        )
        values[p.name] = _PlyList(
            lengths, _gather(raw, starts + within * p.dtype.itemsize, p.dtype)
        )
    return values, pos


def _ply_uniform_lists(
    buf: bytes | memoryview, pos: int, element: _PlyElement, byte_order: str
) -> tuple[dict, int] | None:
    """Read the element as fixed-size records if every list has the first record's length.

    Correct by induction: a record starts where the table says as long as every earlier
    record had the guessed lengths, and all of them are checked.
    """
    size = len(buf)
    if element.count == 0:
        return {
            p.name: (
                _PlyList(np.zeros(0, np.int64), np.zeros(0, p.dtype))
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
            values[p.name] = _PlyList(
                np.full(element.count, n, dtype=np.int64), table[p.name].reshape(-1)
            )
        else:
            values[p.name] = table[p.name]
    return values, end


def _gather(raw: np.ndarray, starts: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """Values of ``dtype`` at the given byte offsets of ``raw (B,) uint8``."""
    index = starts[:, None] + np.arange(dtype.itemsize, dtype=np.int64)
    return raw[index].view(dtype).reshape(-1)


def _ply_ascii_body(
    buf: bytes | memoryview, pos: int, elements: list[_PlyElement], ctx: _Context
) -> _PlyValues:
    """Parse the ASCII body as one array of numbers, then cut it into elements."""
    body = bytes(buf[pos:])
    # every number takes at least two bytes (a digit and a separator) except the last
    _ply_check_counts(elements, (len(body) + 1) // 2, "numbers", 1, ctx)
    tokens = _parse_numbers(body, np.float64, "the PLY body", ctx)
    _ply_check_counts(elements, len(tokens), "numbers", 1, ctx)
    values: _PlyValues = {}
    t = 0
    for element in elements:
        values[element.name], t = _ply_ascii_element(tokens, t, element, ctx)
    if t < len(tokens):
        raise ctx.error(
            f"{len(tokens) - t:,} number(s) left after the last element", "trailing_data"
        )
    return values


def _ply_ascii_element(
    tokens: np.ndarray, t: int, element: _PlyElement, ctx: _Context
) -> tuple[dict, int]:
    props = element.properties
    if not props:
        return {}, t
    lengths = _ply_ascii_first_lengths(tokens, t, element, ctx)
    width = len(props) + sum(lengths.values())
    end = t + element.count * width
    table = tokens[t:end].reshape(-1, width) if end <= len(tokens) else None
    if table is not None and _ascii_uniform(table, props, lengths):
        values: dict = {}
        col = 0
        for p in props:
            if p.is_list:
                n = lengths[p.name]
                items = table[:, col + 1 : col + 1 + n].reshape(-1)
                values[p.name] = _PlyList(
                    np.full(element.count, n, dtype=np.int64), _ascii_cast(items, p, element, ctx)
                )
                col += 1 + n
            else:
                values[p.name] = _ascii_cast(table[:, col], p, element, ctx)
                col += 1
        return values, end
    return _ply_ascii_walk(tokens, t, element, ctx)


def _ply_ascii_first_lengths(
    tokens: np.ndarray, t: int, element: _PlyElement, ctx: _Context
) -> dict[str, int]:
    lengths: dict[str, int] = {}
    if element.count == 0:
        return {p.name: 0 for p in element.properties if p.is_list}
    for p in element.properties:
        if t >= len(tokens):
            raise ctx.error(f"the file ends inside element {element.name!r}", "truncated")
        if p.is_list:
            n = _ascii_length(tokens[t], element, ctx)
            lengths[p.name] = n
            t += 1 + n
        else:
            t += 1
    return lengths


def _ascii_uniform(table: np.ndarray, props: list[_PlyProperty], lengths: dict[str, int]) -> bool:
    col = 0
    for p in props:
        if p.is_list:
            if not (table[:, col] == lengths[p.name]).all():
                return False
            col += 1 + lengths[p.name]
        else:
            col += 1
    return True


def _ply_ascii_walk(
    tokens: np.ndarray, t: int, element: _PlyElement, ctx: _Context
) -> tuple[dict, int]:
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
                n = _ascii_length(tokens[t], element, ctx)
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
            values[p.name] = _ascii_cast(
                tokens[np.array(scalar_at[p.name], dtype=np.int64)], p, element, ctx
            )
            continue
        lengths = np.array(list_len[p.name], dtype=np.int64)
        starts = np.repeat(np.array(list_at[p.name], dtype=np.int64), lengths)
        within = np.arange(len(starts), dtype=np.int64) - np.repeat(
            np.cumsum(lengths) - lengths, lengths
        )
        values[p.name] = _PlyList(lengths, _ascii_cast(tokens[starts + within], p, element, ctx))
    return values, t


def _ascii_length(token: float, element: _PlyElement, ctx: _Context) -> int:
    if not (np.isfinite(token) and token >= 0 and token == int(token)):
        raise ctx.error(
            f"list length {token!r} in element {element.name!r} is not a count", "bad_value"
        )
    return int(token)


def _ascii_cast(
    values: np.ndarray, prop: _PlyProperty, element: _PlyElement, ctx: _Context
) -> np.ndarray:
    """Numbers parsed as float64 to the property's type; integers must be whole and in range."""
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


def _ply_strands(values: _PlyValues, ctx: _Context) -> _Strands:
    """Interpret the parsed elements as strands (layouts (a)-(d) of the module notes)."""
    vertex = values.get("vertex")
    if vertex is None or not all(
        k in vertex and not isinstance(vertex[k], _PlyList) for k in "xyz"
    ):
        raise ctx.error(
            "the PLY file has no element 'vertex' with properties x, y, z", "bad_header"
        )
    points = np.stack([vertex["x"], vertex["y"], vertex["z"]], axis=1)
    n = len(points)
    thickness = _ply_thickness(vertex)
    color = _ply_color(vertex)
    notes = (
        ["the vertex property 'alpha' was dropped (Hair has no transparency)"]
        if "alpha" in vertex
        else []
    )
    strand_name = next((name for name in PLY_STRAND_ELEMENTS if name in values), None)
    strand = values.get(strand_name, {}) if strand_name else {}
    edges = values.get("edge")
    index_list = next(
        (strand[k] for k in (*PLY_INDEX_LISTS, *strand) if isinstance(strand.get(k), _PlyList)),
        None,
    )
    if index_list is not None:
        index = index_list.values.astype(np.int64)
        if len(index) and (index.min() < 0 or index.max() >= n):
            bad = int(index[(index < 0) | (index >= n)][0])
            raise ctx.error(
                f"element {strand_name!r} refers to vertex {bad}, but there are {n:,}", "bad_index"
            )
        points = points[index]
        thickness = None if thickness is None else thickness[index]
        color = None if color is None else color[index]
        return _Strands(points, index_list.lengths, thickness, color, notes)
    counts = _ply_counts_from_strand_element(strand, strand_name, n, ctx)
    if counts is not None:
        if edges is not None:
            _ply_check_edges_agree(edges, counts, n, ctx)
    elif (id_name := next((k for k in PLY_STRAND_IDS if k in vertex), None)) is not None:
        counts = _ply_counts_from_ids(vertex[id_name], id_name, ctx)
    elif edges is not None:
        counts = _ply_counts_from_edges(edges, n, ctx)
    else:
        raise ctx.error(
            "the PLY file does not say which vertices form which strand: expected an element "
            f"{PLY_STRAND_ELEMENTS[0]!r} (a vertex index list or 'nsegs'), a per-vertex "
            f"'{PLY_STRAND_IDS[0]}', or an element 'edge'",
            "bad_header",
        )
    return _Strands(points, counts, thickness, color, notes)


def _ply_thickness(vertex: dict) -> np.ndarray | None:
    name = next((k for k in PLY_THICKNESS if k in vertex), None)
    return None if name is None else np.asarray(vertex[name], dtype=np.float64)


def _ply_color(vertex: dict) -> np.ndarray | None:
    if not all(k in vertex for k in PLY_COLORS):
        return None
    channels = []
    for k in PLY_COLORS:
        c = np.asarray(vertex[k])
        full = np.iinfo(c.dtype).max if c.dtype.kind in "iu" else 1.0
        channels.append(c.astype(np.float64) / full)
    return np.stack(channels, axis=1)


def _ply_counts_from_strand_element(
    strand: dict, strand_name: str | None, n: int, ctx: _Context
) -> np.ndarray | None:
    name = next((k for k in (*PLY_SEGMENT_COUNTS, *PLY_POINT_COUNTS) if k in strand), None)
    if name is None:
        return None
    counts = np.asarray(strand[name], dtype=np.int64)
    if name in PLY_SEGMENT_COUNTS:
        counts = counts + 1
    if len(counts) and counts.min() < 0:
        raise ctx.error(f"element {strand_name!r} has a negative {name!r}", "bad_index")
    if int(counts.sum()) != n:
        raise ctx.error(
            f"the strands of element {strand_name!r} ({name!r}) hold {int(counts.sum()):,} points "
            f"but there are {n:,} vertices",
            "bad_index",
        )
    return counts


def _ply_counts_from_ids(ids: np.ndarray, name: str, ctx: _Context) -> np.ndarray:
    ids = np.asarray(ids)
    if len(ids) == 0:
        return np.zeros(0, dtype=np.int64)
    starts = np.concatenate([[0], np.flatnonzero(ids[1:] != ids[:-1]) + 1])
    if len(np.unique(ids[starts])) != len(starts):
        raise ctx.error(f"the vertices of one {name!r} are not consecutive", "bad_index")
    return np.diff(np.append(starts, len(ids))).astype(np.int64)


def _ply_edges(edges: dict, n: int, ctx: _Context) -> tuple[np.ndarray, np.ndarray]:
    if not all(k in edges and not isinstance(edges[k], _PlyList) for k in ("vertex1", "vertex2")):
        raise ctx.error("element 'edge' needs properties vertex1 and vertex2", "bad_header")
    a = np.asarray(edges["vertex1"], dtype=np.int64)
    b = np.asarray(edges["vertex2"], dtype=np.int64)
    for v in (a, b):
        if len(v) and (v.min() < 0 or v.max() >= n):
            raise ctx.error(f"an edge refers to a vertex outside 0..{n - 1}", "bad_index")
    if not (np.abs(a - b) == 1).all():
        bad = int(np.argmax(np.abs(a - b) != 1))
        raise ctx.error(
            f"edge {bad} joins vertices {int(a[bad])} and {int(b[bad])}; strand edges must join "
            "consecutive vertices",
            "bad_index",
        )
    return a, b


def _ply_counts_from_edges(edges: dict, n: int, ctx: _Context) -> np.ndarray:
    a, b = _ply_edges(edges, n, ctx)
    linked = np.zeros(max(n - 1, 0), dtype=bool)
    linked[np.minimum(a, b)] = True
    starts = np.concatenate([[0], np.flatnonzero(~linked) + 1]) if n else np.zeros(0, np.int64)
    return np.diff(np.append(starts, n)).astype(np.int64)


def _ply_check_edges_agree(edges: dict, counts: np.ndarray, n: int, ctx: _Context) -> None:
    a, b = _ply_edges(edges, n, ctx)
    linked = np.zeros(max(n - 1, 0), dtype=bool)
    linked[np.minimum(a, b)] = True
    expected = np.ones(max(n - 1, 0), dtype=bool)
    ends = np.cumsum(counts)[:-1] - 1  # last point of every strand but the final one
    expected[ends[(ends >= 0) & (ends < n - 1)]] = False
    if len(a) != int(expected.sum()) or not np.array_equal(linked, expected):
        raise ctx.error("the 'edge' element disagrees with the strand element", "bad_index")


def _write_ply(f: BinaryIO, hair: Hair, scale: float, ascii: bool) -> None:
    _check_fits(hair, INT32_MAX, INT32_MAX, "ply")
    columns = _ply_vertex_columns(hair, scale)
    nsegs = hair.counts - 1
    nsegs_type = "ushort" if not len(nsegs) or nsegs.max() <= HAIR_MAX_SEGMENTS else "uint"
    edges = _edge_starts(hair)  # edge k joins vertices edges[k] and edges[k] + 1
    encoding = "ascii" if ascii else "binary_little_endian"
    lines = ["ply", f"format {encoding} 1.0", "comment written by hairport"]
    lines.append(f"element vertex {hair.n_particles}")
    lines += [f"property {ply_type} {name}" for name, ply_type, _ in columns]
    lines += [f"element strand {hair.n_strands}", f"property {nsegs_type} nsegs"]
    lines += [f"element edge {len(edges)}", "property int vertex1", "property int vertex2"]
    lines.append("end_header")
    f.write(("\n".join(lines) + "\n").encode("ascii"))
    if ascii:
        _write_rows(
            f, [values for _, _, values in columns], [_ascii_format(t) for _, t, _ in columns]
        )
        _write_rows(f, [nsegs], ["%d"])
        _write_rows(f, [edges, edges + 1], ["%d", "%d"])
        return
    record = np.dtype([(name, "<" + PLY_TYPES[ply_type]) for name, ply_type, _ in columns])
    table = np.empty(hair.n_particles, dtype=record)
    for name, _, values in columns:
        table[name] = values
    f.write(table.tobytes())
    f.write(nsegs.astype("<u2" if nsegs_type == "ushort" else "<u4").tobytes())
    f.write(np.stack([edges, edges + 1], axis=1).tobytes())


def _edge_starts(hair: Hair) -> np.ndarray:
    """(N-S,) little-endian int32: the first vertex of every segment."""
    starts = np.ones(hair.n_particles, dtype=bool)
    starts[hair.offsets[1:] - 1] = False  # a strand's last vertex starts no segment
    return np.flatnonzero(starts).astype("<i4")


def _ply_vertex_columns(hair: Hair, scale: float) -> list[tuple[str, str, np.ndarray]]:
    points = _to_float32(hair.points / scale, "coordinate")
    columns = [(axis, "float", points[:, i]) for i, axis in enumerate("xyz")]
    if hair.thickness is not None:
        columns.append(("thickness", "float", _to_float32(hair.thickness / scale, "thickness")))
    if hair.color is not None:
        rgb = np.rint(np.clip(hair.color, 0.0, 1.0) * 255).astype(np.uint8)
        columns += [(name, "uchar", rgb[:, i]) for i, name in enumerate(PLY_COLORS)]
    return columns


def _ascii_format(ply_type: str) -> str:
    return PLY_ASCII_FLOAT if PLY_TYPES[ply_type][0] == "f" else "%d"


def _read_npz(buf: bytes | memoryview, ctx: _Context) -> _Strands:
    try:
        archive = zipfile.ZipFile(io.BytesIO(buf))
    except _ZIP_ERRORS:
        if ZIP_MAGIC.startswith(bytes(buf[:4])):  # a zip cut before its directory (at the end)
            raise ctx.error(
                "the npz archive is cut short (no zip directory)", "truncated"
            ) from None
        raise ctx.error("not an npz (zip) archive", "bad_header") from None
    with archive:
        members = {
            name[: -len(".npy")]: name for name in archive.namelist() if name.endswith(".npy")
        }
        missing = [name for name in NPZ_REQUIRED if name not in members]
        if missing:
            raise ctx.error(
                f"not a hairport hair archive: no array(s) {', '.join(missing)}", "bad_header"
            )
        headers = {
            key: _npz_header(archive, members[key], key, ctx)
            for key in (*NPZ_REQUIRED, *NPZ_OPTIONAL)
            if key in members
        }
        _npz_check_marker(archive, members, headers, ctx)
        n_points, n_strands = _npz_check_shapes(headers, ctx)
        ctx.check_limit(n_strands, "strands")
        ctx.check_limit(n_points, "particles")
        arrays = {key: _npz_array(archive, members[key], key, ctx) for key in headers}
    offsets = arrays["offsets"].astype(np.int64)
    if offsets[0] != 0 or offsets[-1] != n_points or (np.diff(offsets) < 0).any():
        raise ctx.error(
            f"offsets must start at 0, end at the point count {n_points:,} and never decrease",
            "bad_offsets",
        )
    extra = sorted(set(members) - set(NPZ_REQUIRED) - set(NPZ_OPTIONAL))
    notes = [f"ignored unknown array(s) {', '.join(extra)}"] if extra else []
    return _Strands(
        arrays["points"],
        np.diff(offsets),
        arrays.get("thickness"),
        arrays.get("color"),
        notes,
        strict=True,
    )


def _npz_header(
    archive: zipfile.ZipFile, member: str, key: str, ctx: _Context
) -> tuple[tuple, np.dtype]:
    """Shape and dtype from the ``.npy`` header, and a check that the data are all there."""
    try:
        with archive.open(member) as f:
            version = np.lib.format.read_magic(f)
            if version not in NPY_HEADER_READERS:
                raise ValueError(f".npy version {version} is not supported")
            read = getattr(np.lib.format, NPY_HEADER_READERS[version])
            shape, _, dtype = read(f, max_header_size=NPZ_MAX_HEADER_BYTES)
            header_end = f.tell()
    except _ZIP_ERRORS as exc:
        raise ctx.error(
            f"array {key!r} has a malformed .npy header ({exc})", "bad_header"
        ) from None
    if dtype.hasobject:
        raise ctx.error(f"array {key!r} holds Python objects, which are not read", "bad_header")
    nbytes = int(np.prod(shape, dtype=object)) * dtype.itemsize
    stored = archive.getinfo(member).file_size
    if header_end + nbytes > stored:
        raise ctx.error(
            f"array {key!r} needs {nbytes:,} bytes of data but has {stored - header_end:,}",
            "truncated",
        )
    return shape, dtype


def _npz_check_marker(
    archive: zipfile.ZipFile, members: dict, headers: dict, ctx: _Context
) -> None:
    for key, kinds in (("format", "US"), ("version", "iu"), ("units", "US")):
        if key in headers and (headers[key][0] != () or headers[key][1].kind not in kinds):
            raise ctx.error(f"array {key!r} must be a scalar of kind {kinds!r}", "bad_header")
    marker = _npz_text(_npz_array(archive, members["format"], "format", ctx))
    if marker != NPZ_FORMAT:
        raise ctx.error(
            f"not a hairport hair archive (format {marker!r}, expected {NPZ_FORMAT!r})",
            "bad_header",
        )
    version = int(_npz_array(archive, members["version"], "version", ctx)[()])
    if not 1 <= version <= NPZ_VERSION:
        raise ctx.error(
            f"archive version {version} is not readable by this hairport (reads 1..{NPZ_VERSION})",
            "bad_header",
        )
    if "units" in headers:
        units = _npz_text(_npz_array(archive, members["units"], "units", ctx))
        if units not in METERS_PER_UNIT:
            raise ctx.error(f"the archive records unknown units {units!r}", "bad_header")
        if units != ctx.units:
            raise ctx.error(
                f"the archive is in {units!r} but was read with units={ctx.units!r}; "
                f"pass units={units!r}",
                "units_mismatch",
            )


def _npz_text(value: np.ndarray) -> str:
    """A scalar ``str_`` or ``bytes_`` array as text."""
    item = value[()]
    return item.decode("utf-8", "replace") if isinstance(item, bytes) else str(item)


def _npz_check_shapes(headers: dict, ctx: _Context) -> tuple[int, int]:
    (points_shape, points_dtype), (offsets_shape, offsets_dtype) = (
        headers["points"],
        headers["offsets"],
    )
    if len(points_shape) != 2 or points_shape[1] != 3 or points_dtype.kind != "f":
        raise ctx.error(
            f"points must be (N, 3) floats, got {points_shape} {points_dtype}", "bad_header"
        )
    if len(offsets_shape) != 1 or offsets_shape[0] < 1 or offsets_dtype.kind not in "iu":
        raise ctx.error(
            f"offsets must be (S+1,) integers, got {offsets_shape} {offsets_dtype}", "bad_header"
        )
    n = points_shape[0]
    for key, shape in (("thickness", (n,)), ("color", (n, 3))):
        if key in headers and (headers[key][0] != shape or headers[key][1].kind != "f"):
            raise ctx.error(
                f"{key} must be {shape} floats, got {headers[key][0]} {headers[key][1]}",
                "bad_header",
            )
    return n, offsets_shape[0] - 1


def _npz_array(archive: zipfile.ZipFile, member: str, key: str, ctx: _Context) -> np.ndarray:
    try:
        with archive.open(member) as f:
            return np.lib.format.read_array(
                f, allow_pickle=False, max_header_size=NPZ_MAX_HEADER_BYTES
            )
    except _ZIP_ERRORS as exc:
        raise ctx.error(f"array {key!r} cannot be read ({exc})", "truncated") from None


def _write_npz(f: BinaryIO, hair: Hair, scale: float, units: str) -> None:
    arrays = {
        "format": np.array(NPZ_FORMAT),
        "version": np.array(NPZ_VERSION, dtype=np.int64),
        "units": np.array(units),
        "points": hair.points / scale,
        "offsets": hair.offsets,
    }
    if hair.thickness is not None:
        arrays["thickness"] = hair.thickness / scale
    if hair.color is not None:
        arrays["color"] = hair.color
    np.savez(f, **arrays)


OBJ_IGNORED_QUIETLY = {b"vn", b"vt", b"vp", b"o", b"g", b"s", b"usemtl", b"mtllib"}


def _read_obj(buf: bytes | memoryview, ctx: _Context) -> _Strands:
    v_rows: list[bytes] = []
    l_rows: list[bytes] = []
    l_base: list[int] = []
    ignored: dict[str, int] = {}
    for line in bytes(buf).splitlines():
        words = line.split(None, 1)
        if not words or words[0].startswith(b"#"):
            continue
        tag = words[0]
        rest = words[1] if len(words) > 1 else b""
        if tag == b"v":
            v_rows.append(rest)
        elif tag == b"l":
            l_rows.append(rest)
            l_base.append(len(v_rows))
        elif tag not in OBJ_IGNORED_QUIETLY:
            key = tag.decode("ascii", "replace")
            ignored[key] = ignored.get(key, 0) + 1
    ctx.check_limit(len(l_rows), "strands")
    ctx.check_limit(len(v_rows), "particles")
    points, color = _obj_vertices(v_rows, ctx)
    index, lengths = _obj_polylines(l_rows, np.array(l_base, dtype=np.int64), len(points), ctx)
    notes = [f"ignored {count:,} '{tag}' record(s)" for tag, count in sorted(ignored.items())]
    return _Strands(points[index], lengths, None, None if color is None else color[index], notes)


def _obj_vertices(rows: list[bytes], ctx: _Context) -> tuple[np.ndarray, np.ndarray | None]:
    widths = np.fromiter((len(r.split()) for r in rows), dtype=np.int64, count=len(rows))
    if len(rows) and (widths != widths[0]).any():
        raise ctx.error("'v' lines have differing numbers of values", "bad_value")
    width = int(widths[0]) if len(rows) else 3
    if width not in (3, 4, 6):
        raise ctx.error(
            f"'v' lines have {width} values; expected x y z [w] or x y z r g b", "bad_value"
        )
    values = _parse_numbers(b"\n".join(rows), np.float64, "the 'v' lines", ctx).reshape(-1, width)
    color = values[:, 3:6] if width == 6 else None
    return values[:, :3], color


def _obj_polylines(
    rows: list[bytes], base: np.ndarray, n_vertices: int, ctx: _Context
) -> tuple[np.ndarray, np.ndarray]:
    block = b"\n".join(rows)
    if b"/" in block:
        block = re.sub(rb"/\S*", b"", block)
    lengths = np.fromiter((len(r.split()) for r in rows), dtype=np.int64, count=len(rows))
    index = _parse_numbers(block, np.int64, "the 'l' lines", ctx)
    if len(index) != int(lengths.sum()):
        raise ctx.error("an 'l' line holds something other than vertex indices", "bad_value")
    if (index == 0).any():
        raise ctx.error("vertex index 0 in an 'l' line (OBJ indices start at 1)", "bad_index")
    index = np.where(index > 0, index - 1, np.repeat(base, lengths) + index)
    if len(index) and (index.min() < 0 or index.max() >= n_vertices):
        raise ctx.error(f"an 'l' line refers to a vertex outside 1..{n_vertices}", "bad_index")
    return index, lengths


def _write_obj(f: BinaryIO, hair: Hair, scale: float) -> None:
    f.write(b"# written by hairport: v lines, then one polyline (l line) per strand, root first\n")
    points = _to_float32(hair.points / scale, "coordinate")
    columns = [points[:, 0], points[:, 1], points[:, 2]]
    formats = [PLY_ASCII_FLOAT] * 3
    if hair.color is not None:
        columns += [hair.color[:, i].astype(np.float32) for i in range(3)]
        formats += [PLY_ASCII_FLOAT] * 3
    _write_rows(f, columns, formats, prefix="v ")
    n = hair.n_particles
    if n == 0:
        return
    last = np.zeros(n, dtype=bool)
    last[hair.offsets[1:] - 1] = True
    first = hair.is_root
    for start in range(0, n, ASCII_CHUNK_ROWS):
        stop = min(start + ASCII_CHUNK_ROWS, n)
        template = np.where(first[start:stop], "l %d", "%d")
        template = np.char.add(template, np.where(last[start:stop], "\n", " "))
        text = "".join(template.tolist()) % tuple(range(start + 1, stop + 1))
        f.write(text.encode("ascii"))


def _writer(
    fmt: str, hair: Hair, units: str, ascii: bool, target: str
) -> Callable[[BinaryIO], None]:
    """A function that writes ``hair`` to a binary file; checks everything it can first."""
    if not isinstance(hair, Hair):
        raise TypeError(f"expected a Hair, got {type(hair).__name__}")
    scale = unit_scale(units)
    if ascii and fmt != "ply":
        raise ValueError(f"ascii=True applies to PLY only, not {fmt!r}")
    dropped = []
    if hair.thickness is not None and fmt in ("data", "obj"):
        dropped.append("thickness")
    if hair.color is not None and fmt == "data":
        dropped.append("color")
    if dropped:
        warnings.warn(
            f"{target}: the {fmt!r} format has no {' or '.join(dropped)}; not written",
            HairIOWarning,
            stacklevel=3,
        )
    writers: dict[str, Callable[[BinaryIO], None]] = {
        "data": lambda f: _write_data(f, hair, scale),
        "hair": lambda f: _write_hair_file(f, hair, scale),
        "ply": lambda f: _write_ply(f, hair, scale, ascii),
        "npz": lambda f: _write_npz(f, hair, scale, units),
        "obj": lambda f: _write_obj(f, hair, scale),
    }
    return writers[fmt]


def _atomic_write(path: Path, write: Callable[[BinaryIO], None]) -> None:
    """Write to a temporary file next to ``path``, then rename it over ``path``."""
    temporary = path.with_name(f".{path.name}.{uuid.uuid4().hex[:12]}.tmp")
    fd = os.open(
        temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666
    )
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(temporary, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temporary)
        raise


def _check_fits(hair: Hair, max_strands: int, max_particles: int, fmt: str) -> None:
    if hair.n_strands > max_strands or hair.n_particles > max_particles:
        raise InputError(
            f"{hair.n_strands:,} strands / {hair.n_particles:,} points do not fit "
            f"the {fmt!r} format",
            code="too_large",
        )


def _to_float32(values: np.ndarray, what: str) -> np.ndarray:
    """Little-endian float32 copy; refuses values float32 cannot hold."""
    with np.errstate(over="ignore"):
        out = np.ascontiguousarray(values, dtype="<f4")
    if not np.isfinite(out).all():
        raise InputError(f"a {what} is not finite or too large for float32", code="non_finite")
    return out


def _write_rows(
    f: BinaryIO, columns: list[np.ndarray], formats: list[str], prefix: str = ""
) -> None:
    """Write a text table, one row per line, formatting a chunk of rows at a time."""
    n = len(columns[0]) if columns else 0
    row = prefix + " ".join(formats) + "\n"
    for start in range(0, n, ASCII_CHUNK_ROWS):
        block = np.stack(
            [np.asarray(c[start : start + ASCII_CHUNK_ROWS], dtype=np.float64) for c in columns],
            axis=1,
        )
        f.write(((row * len(block)) % tuple(block.ravel().tolist())).encode("ascii"))


def _parse_numbers(text: bytes, dtype: type, what: str, ctx: _Context) -> np.ndarray:
    """All whitespace-separated numbers of ``text``; anything else is an error."""
    if not text.strip():
        return np.zeros(0, dtype=dtype)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", DeprecationWarning)
            return np.fromstring(text, dtype=dtype, sep=" ")
    except (ValueError, DeprecationWarning):
        raise ctx.error(f"{what} hold(s) something that is not a number", "bad_value") from None


_READERS: dict[str, Callable[[bytes | memoryview, _Context], _Strands]] = {
    "data": _read_data,
    "hair": _read_hair,
    "ply": _read_ply,
    "npz": _read_npz,
    "obj": _read_obj,
}
