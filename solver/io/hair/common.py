"""What every hair format module shares: read limits and reports, the records a reader and a
writer work on, the format record the registry holds, and the checks and number handling
that more than one format needs.

A format module turns bytes into :class:`Strands` (in file units, short strands included)
and a :class:`~hairport.solver.model.hair.Hair` into bytes; :func:`finish_read` does the
rest of every read the same way (finite values, short strands dropped and counted, units
converted to meters).
"""

from __future__ import annotations

import os
import tempfile
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import BinaryIO

import numpy as np

from hairport.solver.budget import check_memory
from hairport.solver.io.external import ALLOW_EXTERNAL_FILES, EXTERNAL_REFERENCE
from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import (
    ATTRIBUTE_NAME,
    MAX_ATTRIBUTE_NAME,
    MIN_PARTICLES_PER_STRAND,
    VERTEX,
    Hair,
    HairAttribute,
    attribute_problem,
    require_hair,
)
from hairport.solver.model.units import unit_scale

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
    "empty_hair": "no strand of two or more points, or every strand of zero length: nothing to retarget",
    "not_text": "a text format (obj) holds bytes that are not text: a binary or damaged file",
    "over_memory_budget": "the declared particle count needs more memory than ReadLimits.memory_budget_bytes",
    "bad_file": "a count or index past what the reader's arithmetic holds (past int64)",
    "bad_attribute": "an attribute (primvar, property, array) of the wrong length, type or name for its domain",
    "unknown_prim": "no curves prim (USD) or object (Alembic) of the name or path asked for (none in other formats)",
    "format_unavailable": "the format needs an optional library this installation lacks (Alembic: hairport[alembic])",
    EXTERNAL_REFERENCE: "the file names another file (a USD sublayer, reference, payload, clip or asset path) and "
                        "ReadLimits.allow_external_files is False",
}

#: most points one strand may have: real strands have 10^2-10^3; one strand of millions of
#: points (a few KB of a compressed .npz) would keep a worker busy for minutes on one QP
MAX_PARTICLES_PER_STRAND = 10_000

# Largest counts the binary formats' integer fields hold.
UINT16_MAX = int(np.iinfo(np.uint16).max)
INT32_MAX = int(np.iinfo(np.int32).max)
UINT32_MAX = int(np.iinfo(np.uint32).max)

ASCII_FLOAT = "%.9g"  # enough significant digits to give back every float32 exactly
ASCII_DOUBLE = "%.17g"  # ... and every float64
ASCII_CHUNK_ROWS = 1 << 16  # rows formatted per string operation when writing text


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
        File size, and the decompressed size of a compressed file's content (``.npz``
        members); ``None`` for no limit.
    max_strand_particles : int
        Points one strand may have (``too_large``).
    memory_budget_bytes : int or None
        The declared particle count is refused (``over_memory_budget``) when a retarget of
        it is estimated to need more (:func:`hairport.solver.budget.estimate_bytes`).
    allow_external_files : bool
        Whether a USD stage may compose the files it names (sublayers, references, payloads,
        clips) from the disk, as the command line does with the user's own files. False (the
        default, for uploads): a file naming any other file is refused (``external_reference``)
        before anything is opened (:mod:`hairport.solver.io.external`).
    """

    max_strands: int = 5_000_000
    max_particles: int = 50_000_000
    max_bytes: int | None = None
    max_strand_particles: int = MAX_PARTICLES_PER_STRAND
    memory_budget_bytes: int | None = None
    allow_external_files: bool = ALLOW_EXTERNAL_FILES


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
    up_axis : str or None
        The up axis (``+y``, ``+z``) the file records (an ``.npz`` archive, a USD stage's
        ``upAxis``), else None.
    """

    hair: Hair
    format: str
    source: str
    strands_in_file: int
    skipped_strands: int
    skipped_particles: int
    kept_strands: np.ndarray
    warnings: tuple[str, ...] = ()
    up_axis: str | None = None


class HairIOWarning(UserWarning):
    """Something a reader or writer dropped (short strands, transparency, attributes)."""


@dataclass
class Strands:
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
    attributes : dict of str to HairAttribute
        Every other per-point or per-strand array, short strands' rows included.
    up_axis : str or None
        The up axis the file records, if it records one.
    """

    points: np.ndarray
    counts: np.ndarray
    thickness: np.ndarray | None = None
    color: np.ndarray | None = None
    warnings: list[str] = field(default_factory=list)
    strict: bool = False
    attributes: dict[str, HairAttribute] = field(default_factory=dict)
    up_axis: str | None = None

    def add_attribute(self, name: str, values: np.ndarray, domain: str, role: str = "", where: str = "") -> None:
        """Keep a file's array as attribute ``name``; a name hairport cannot carry (not an identifier,
        or one already taken) is named in a warning and the array dropped."""
        prefix = f"{where}: " if where else ""
        if len(name) > MAX_ATTRIBUTE_NAME or not ATTRIBUTE_NAME.fullmatch(name):
            self.warnings.append(f"{prefix}attribute {name[:MAX_ATTRIBUTE_NAME]!r} dropped: not a name hairport "
                                 "carries (letters, digits, underscores, ':' between namespaces)")
        elif name in self.attributes:
            self.warnings.append(f"{prefix}attribute {name!r} appears twice: the second one dropped")
        else:
            self.attributes[name] = HairAttribute(values, domain, role)


@dataclass(frozen=True)
class ReadContext:
    """Where the bytes come from (for messages), the limits to enforce, the file's units, the
    one prim or object to read (USD, Alembic; None: every curves prim or object), and the file on
    disk the bytes were read from (None for bytes: an upload), which a USD stage is composed from
    when ``limits.allow_external_files`` (its relative sublayers are beside it, not beside a copy)."""

    source: str
    limits: ReadLimits
    units: str
    prim: str | None = None
    path: str | None = None

    def error(self, problem: str, code: str) -> InputError:
        """An :class:`InputError` naming the source, with one of ``ERROR_CODES``."""
        return InputError(problem, self.source, code)

    def check_limit(self, count: int, what: str) -> None:
        """Refuse ``count`` ``"strands"`` or ``"particles"`` above the limits (``too_large``)."""
        limit = self.limits.max_strands if what == "strands" else self.limits.max_particles
        if count > limit:
            raise self.error(
                f"the file declares {count:,} {what}, above the limit of {limit:,} "
                f"(ReadLimits.max_{what})",
                "too_large",
            )
        if what == "particles":
            check_memory(count, self.limits.memory_budget_bytes, source=self.source)


@dataclass(frozen=True)
class WriteOptions:
    """How a writer writes: the file's length unit, meters per that unit, text or binary, and the
    input axis that points up (``"+y"``, ``"+z"``...; formats that record an up axis write it)."""

    units: str
    scale: float
    ascii: bool = False
    up_axis: str = "+y"


#: frames per second of an animated file's time codes when nothing else says (USD's own default)
FRAMES_PER_SECOND = 24.0


@dataclass(frozen=True, eq=False)
class Animation:
    """Time-sampled points of one hairstyle layout.

    Attributes
    ----------
    times : (F,) float64
        Each frame's time code (frame number), increasing.
    points : sequence of (N, 3) float64
        Each frame's points, in meters, in the order of ``times``.
    frames_per_second : float
        Time codes per second.
    """

    times: np.ndarray
    points: Sequence[np.ndarray]
    frames_per_second: float = FRAMES_PER_SECOND

    def __post_init__(self) -> None:
        times = np.asarray(self.times, dtype=np.float64)
        object.__setattr__(self, "times", times)
        if len(times) != len(self.points) or len(times) == 0:
            raise ValueError(f"an animation needs one points array per time: {len(times)} times, "
                             f"{len(self.points)} arrays")
        if len(times) > 1 and not (np.diff(times) > 0).all():
            raise ValueError("an animation's times must increase")


Reader = Callable[[bytes | memoryview, ReadContext], Strands]
Writer = Callable[[BinaryIO, Hair, WriteOptions], None]


@dataclass(frozen=True)
class HairFormat:
    """One hair file format, as the registry holds it.

    Attributes
    ----------
    name : str
        The format's name, which is also its file extension (without the dot).
    read : Reader
        ``read(buffer, context) -> Strands``.
    write : Writer
        ``write(binary_file, hair, options)``; the hairstyle is in meters.
    keeps_thickness, keeps_color : bool
        Whether the file holds per-point thickness / color (else the writer warns and
        drops them).
    keeps_attribute : callable
        ``keeps_attribute(name, attribute) -> bool``: whether the writer writes that attribute
        (the others are named in one warning and dropped); by default none.
    has_prims : bool
        Whether a file holds named curves prims or objects one of which may be read alone.
    has_ascii : bool
        Whether the writer has a text variant (``ascii=True``).
    recorded_units : callable or None
        ``recorded_units(path) -> str | None``: the length unit a file of this format records
        (None: unreadable, or none recorded); None for formats that record none.
    """

    name: str
    read: Reader
    write: Writer
    keeps_thickness: bool
    keeps_color: bool
    has_ascii: bool = False
    recorded_units: Callable[[str], str | None] | None = None
    keeps_attribute: Callable[[str, HairAttribute], bool] = lambda name, attribute: False
    has_prims: bool = False
    #: ``write_frames(binary_file, hair, animation, options)``: the hairstyle's layout with time-sampled points
    #: (formats that hold animation; None for the others)
    write_frames: Callable[[BinaryIO, Hair, Animation, WriteOptions], None] | None = None

    @property
    def extension(self) -> str:
        """``"." + name``."""
        return f".{self.name}"


def finish_read(raw: Strands, fmt: str, ctx: ReadContext) -> ReadReport:
    """Check values, drop short strands, convert to meters, build the ``Hair``.

    Parameters
    ----------
    raw : Strands
        What the format reader found, in file units.
    fmt : str
        The format's name, for the report.
    ctx : ReadContext

    Returns
    -------
    report : ReadReport

    Raises
    ------
    InputError
        ``non_finite``; ``short_strand`` when ``raw.strict``; ``empty_hair`` when no strand of
        two points is left, or every strand has zero length.
    """
    counts = np.asarray(raw.counts, dtype=np.int64)
    check_memory(int(counts.sum()), ctx.limits.memory_budget_bytes, source=ctx.source)
    if len(counts) and counts.max() > ctx.limits.max_strand_particles:
        bad = int(np.argmax(counts))
        raise ctx.error(
            f"strand {bad} has {int(counts[bad]):,} points, above the limit of "
            f"{ctx.limits.max_strand_particles:,} per strand (ReadLimits.max_strand_particles)",
            "too_large",
        )
    check_finite(raw.points, counts, "coordinate", ctx)
    if raw.thickness is not None:
        check_finite(raw.thickness, counts, "thickness", ctx)
    if raw.color is not None:
        check_finite(raw.color, counts, "color", ctx)
    n_file_points = int(counts.sum())
    for name, attribute in raw.attributes.items():
        problem = attribute_problem(name, attribute, n_file_points, len(counts))
        if problem is not None:
            raise ctx.error(problem, "non_finite" if "non-finite" in problem else "bad_attribute")
    attributes = raw.attributes
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
        attributes = {name: attribute.take(particle_keep if attribute.domain == VERTEX else keep)
                      for name, attribute in attributes.items()}
        notes.append(
            f"skipped {n_skipped:,} strand(s) with fewer than {MIN_PARTICLES_PER_STRAND} points "
            f"({skipped_particles:,} point(s)); USC-HairSalon files mark scalp positions "
            "without hair this way"
        )
    kept = counts[keep]
    offsets = np.zeros(len(kept) + 1, dtype=np.int64)
    np.cumsum(kept, out=offsets[1:])
    require_hair(np.asarray(points).reshape(-1, 3), offsets, ctx.source)
    scale = unit_scale(ctx.units)
    points = np.asarray(points, dtype=np.float64)
    if scale != 1.0:
        points = points * scale
    if thickness is not None:
        thickness = np.asarray(thickness, dtype=np.float64) * scale
    hair = Hair(points.reshape(-1, 3), offsets, thickness, color, attributes)
    return ReadReport(
        hair=hair,
        format=fmt,
        source=ctx.source,
        strands_in_file=len(counts),
        skipped_strands=n_skipped,
        skipped_particles=skipped_particles,
        kept_strands=np.flatnonzero(keep).astype(np.int64),
        warnings=tuple(notes),
        up_axis=raw.up_axis,
    )


def check_finite(values: np.ndarray, counts: np.ndarray, what: str, ctx: ReadContext) -> None:
    """Refuse NaN or infinite values, naming the first bad point and its strand.

    Parameters
    ----------
    values : (N,) or (N, k) float
        One row per point.
    counts : (S,) int64
        Points per strand.
    what : str
        What the values are, for the message.
    ctx : ReadContext

    Raises
    ------
    InputError
        ``non_finite``.
    """
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


def require_bytes(ctx: ReadContext, needed: int, size: int, what: str) -> None:
    """Refuse a file of ``size`` bytes when ``what`` needs ``needed`` (``truncated``)."""
    if needed > size:
        raise ctx.error(f"{what} needs {needed:,} bytes but the file has {size:,}", "truncated")


def no_trailing(ctx: ReadContext, end: int, size: int) -> None:
    """Refuse bytes after ``end``, where the data end (``trailing_data``)."""
    if end < size:
        raise ctx.error(
            f"{size - end:,} unexpected byte(s) after the data, which ends at byte {end:,}",
            "trailing_data",
        )


def parse_numbers(text: bytes, dtype: type, what: str, ctx: ReadContext) -> np.ndarray:
    """All whitespace-separated numbers of ``text``; anything else is an error.

    Returns
    -------
    numbers : (K,) dtype

    Raises
    ------
    InputError
        ``bad_value``.
    """
    if not text.strip():
        return np.zeros(0, dtype=dtype)
    try:
        with warnings.catch_warnings():
            # numpy only warns (and stops) at the first word that is not a number
            warnings.simplefilter("error", DeprecationWarning)
            return np.fromstring(text, dtype=dtype, sep=" ")
    except (ValueError, DeprecationWarning):
        raise ctx.error(f"{what} hold(s) something that is not a number", "bad_value") from None


def write_through_file(out: BinaryIO, suffix: str, write_file: Callable[[str], None]) -> None:
    """Copy into ``out`` what ``write_file(path)`` writes to a scratch file of extension ``suffix``: for
    libraries (USD, Alembic) that write to paths only."""
    with tempfile.TemporaryDirectory(prefix="hairport-write-") as folder:
        path = os.path.join(folder, f"groom{suffix}")
        write_file(path)
        with open(path, "rb") as handle:
            out.write(handle.read())


def check_fits(hair: Hair, max_strands: int, max_particles: int, fmt: str) -> None:
    """Refuse a hairstyle whose counts the format's integer fields cannot hold (``too_large``)."""
    if hair.n_strands > max_strands or hair.n_particles > max_particles:
        raise InputError(
            f"{hair.n_strands:,} strands / {hair.n_particles:,} points do not fit "
            f"the {fmt!r} format",
            code="too_large",
        )


def to_float32(values: np.ndarray, what: str) -> np.ndarray:
    """Little-endian float32 copy; refuses values float32 cannot hold (``non_finite``)."""
    with np.errstate(over="ignore"):
        out = np.ascontiguousarray(values, dtype="<f4")
    if not np.isfinite(out).all():
        raise InputError(f"a {what} is not finite or too large for float32", code="non_finite")
    return out


def write_rows(
    f: BinaryIO, columns: list[np.ndarray], formats: list[str], prefix: str = ""
) -> None:
    """Write a text table, one row per line, formatting a chunk of rows at a time.

    Parameters
    ----------
    f : binary file
    columns : list of (R,) arrays
        One per column, converted to float64 before formatting.
    formats : list of str
        A ``%`` format per column.
    prefix : str
        Written at the start of every row (e.g. ``"v "``).
    """
    n = len(columns[0]) if columns else 0
    row = prefix + " ".join(formats) + "\n"
    for start in range(0, n, ASCII_CHUNK_ROWS):
        block = np.stack(
            [np.asarray(c[start : start + ASCII_CHUNK_ROWS], dtype=np.float64) for c in columns],
            axis=1,
        )
        f.write(((row * len(block)) % tuple(block.ravel().tolist())).encode("ascii"))
