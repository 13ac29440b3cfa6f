"""hairport's own hair archive (``.npz``).

Layout: a numpy ``.npz`` (zip) archive of ``format = "hairport-hair"``, ``version`` (int),
``units`` (str), ``points (N, 3)``, ``offsets (S+1,)``, optional ``thickness (N,)`` and
``color (N, 3)``, all kept exactly (float64). Version 2 adds the hairstyle's other attributes:
``attributes``, a JSON list of ``{"name", "domain", "role"}``, and array ``attribute_<i>`` for
the i-th, in its own dtype (``(N, ...)`` per point, ``(S, ...)`` per strand). Read with
``allow_pickle=False``; every array's shape and dtype is checked from its ``.npy`` header
before its data are read. Version 2 also records the up axis of its coordinates (``up_axis``),
so that a conversion to a format with an up axis (USD) writes the right one.

The archive records its units and refuses to be read with other units (code
``"units_mismatch"``). The reader is strict about short strands (its writer never makes
them): code ``"short_strand"``.
"""

from __future__ import annotations

import io
import json
import lzma
import re
import zipfile
import zlib
from typing import BinaryIO

import numpy as np

from hairport.solver.io.hair.common import HairFormat, ReadContext, Strands, WriteOptions
from hairport.solver.model.frame import AXIS_VECTORS
from hairport.solver.model.hair import ATTRIBUTE_KINDS, DOMAINS, MAX_ATTRIBUTES, ROLES, VERTEX, Hair
from hairport.solver.model.units import METERS_PER_UNIT

NPZ_FORMAT = "hairport-hair"
NPZ_VERSION = 2
NPZ_REQUIRED = ("format", "version", "points", "offsets")
NPZ_OPTIONAL = ("units", "thickness", "color", "attributes", "up_axis")
NPZ_ATTRIBUTE = "attribute_{}"
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

_Header = tuple[tuple, np.dtype]  # shape and dtype of one member, from its .npy header


def read_npz(buf: bytes | memoryview, ctx: ReadContext) -> Strands:
    """Read a hairport archive, checking every member's header before its data.

    Returns
    -------
    strands : Strands
        ``points (N, 3)``, ``counts (S,) int64`` and the optional arrays as stored; strict
        about short strands.
    """
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
        attribute_keys = [key for key in members if re.fullmatch(NPZ_ATTRIBUTE.format(r"\d+"), key)]
        known = (*NPZ_REQUIRED, *NPZ_OPTIONAL, *attribute_keys)
        _check_unpacked_size(archive, [members[key] for key in known if key in members], ctx)
        headers = {key: _member_header(archive, members[key], key, ctx) for key in known if key in members}
        _check_marker(archive, members, headers, ctx)
        n_points, n_strands = _check_shapes(headers, ctx)
        ctx.check_limit(n_strands, "strands")
        ctx.check_limit(n_points, "particles")
        described = _attribute_descriptions(archive, members, headers, n_points, n_strands, ctx)
        arrays = {key: _member_array(archive, members[key], key, ctx) for key in headers if key != "attributes"}
    offsets = arrays["offsets"].astype(np.int64)
    if offsets[0] != 0 or offsets[-1] != n_points or (np.diff(offsets) < 0).any():
        raise ctx.error(
            f"offsets must start at 0, end at the point count {n_points:,} and never decrease",
            "bad_offsets",
        )
    used = {*NPZ_REQUIRED, *NPZ_OPTIONAL, *(NPZ_ATTRIBUTE.format(i) for i in range(len(described)))}
    extra = sorted(set(members) - used)
    notes = [f"ignored unknown array(s) {', '.join(extra)}"] if extra else []
    strands = Strands(arrays["points"], np.diff(offsets), arrays.get("thickness"), arrays.get("color"), notes,
                      strict=True)
    for index, (name, domain, role) in enumerate(described):
        strands.add_attribute(name, arrays[NPZ_ATTRIBUTE.format(index)], domain, role)
    if "up_axis" in arrays:
        up_axis = _member_text(arrays["up_axis"])
        if up_axis not in AXIS_VECTORS:
            raise ctx.error(f"the archive records an unknown up axis {up_axis!r}", "bad_header")
        strands.up_axis = up_axis
    return strands


def _attribute_descriptions(archive: zipfile.ZipFile, members: dict[str, str], headers: dict[str, _Header],
                            n_points: int, n_strands: int, ctx: ReadContext) -> list[tuple[str, str, str]]:
    """``(name, domain, role)`` of every attribute the archive describes, each array's header checked
    against its domain's row count before any data is read."""
    if "attributes" not in headers:
        return []
    shape, dtype = headers["attributes"]
    if shape != () or dtype.kind not in "US":
        raise ctx.error("array 'attributes' must be a JSON text scalar", "bad_header")
    try:
        described = json.loads(_member_text(_member_array(archive, members["attributes"], "attributes", ctx)))
        described = [(str(item["name"]), str(item["domain"]), str(item.get("role", ""))) for item in described]
    except (ValueError, TypeError, KeyError):
        raise ctx.error("array 'attributes' is not a JSON list of {name, domain, role}", "bad_header") from None
    if any(domain not in DOMAINS or role not in ROLES for _, domain, role in described):
        raise ctx.error(f"array 'attributes' is not a JSON list of {{name, domain, role}} with a domain of "
                        f"{', '.join(DOMAINS)} and a role of {', '.join(map(repr, ROLES))}", "bad_header")
    if len(described) > MAX_ATTRIBUTES:
        raise ctx.error(f"{len(described):,} attributes, at most {MAX_ATTRIBUTES}", "bad_attribute")
    for index, (name, domain, _) in enumerate(described):
        key = NPZ_ATTRIBUTE.format(index)
        if key not in headers:
            raise ctx.error(f"attribute {name!r} is described but its array {key!r} is missing", "bad_header")
        shape, dtype = headers[key]
        rows = n_points if domain == VERTEX else n_strands
        if dtype.kind not in ATTRIBUTE_KINDS or len(shape) not in (1, 2) or shape[0] != rows:
            raise ctx.error(f"attribute {name!r} ({domain}) must be ({rows:,},) or ({rows:,}, k) numbers, got "
                            f"{shape} {dtype}", "bad_attribute")
    return described


def _check_unpacked_size(archive: zipfile.ZipFile, names: list[str], ctx: ReadContext) -> None:
    """Refuse (``too_large``) members whose declared uncompressed sizes add up to more than
    ``max_bytes``: a few MB of deflated zeros can unpack to GBs. The reads that follow stay
    within the declared sizes (``zipfile`` stops a member at its ``file_size`` and checks its
    CRC, and every array is checked to fit in it), so a header that lies is caught there."""
    limit = ctx.limits.max_bytes
    unpacked = sum(archive.getinfo(name).file_size for name in names)
    if limit is not None and unpacked > limit:
        raise ctx.error(
            f"the archive unpacks to {unpacked:,} bytes, above the limit of {limit:,} (ReadLimits.max_bytes)",
            "too_large",
        )


def _member_header(archive: zipfile.ZipFile, member: str, key: str, ctx: ReadContext) -> _Header:
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


def _check_marker(
    archive: zipfile.ZipFile, members: dict[str, str], headers: dict[str, _Header], ctx: ReadContext
) -> None:
    """The ``format`` marker, a readable ``version`` and the recorded ``units``."""
    for key, kinds in (("format", "US"), ("version", "iu"), ("units", "US"), ("up_axis", "US")):
        if key in headers and (headers[key][0] != () or headers[key][1].kind not in kinds):
            raise ctx.error(f"array {key!r} must be a scalar of kind {kinds!r}", "bad_header")
    marker = _member_text(_member_array(archive, members["format"], "format", ctx))
    if marker != NPZ_FORMAT:
        raise ctx.error(
            f"not a hairport hair archive (format {marker!r}, expected {NPZ_FORMAT!r})",
            "bad_header",
        )
    version = int(_member_array(archive, members["version"], "version", ctx)[()])
    if not 1 <= version <= NPZ_VERSION:
        raise ctx.error(
            f"archive version {version} is not readable by this hairport (reads 1..{NPZ_VERSION})",
            "bad_header",
        )
    if "units" in headers:
        units = _member_text(_member_array(archive, members["units"], "units", ctx))
        if units not in METERS_PER_UNIT:
            raise ctx.error(f"the archive records unknown units {units!r}", "bad_header")
        if units != ctx.units:
            raise ctx.error(
                f"the archive is in {units!r} but was read with units={ctx.units!r}; "
                f"pass units={units!r}",
                "units_mismatch",
            )


def _member_text(value: np.ndarray) -> str:
    """A scalar ``str_`` or ``bytes_`` array as text."""
    item = value[()]
    return item.decode("utf-8", "replace") if isinstance(item, bytes) else str(item)


def _check_shapes(headers: dict[str, _Header], ctx: ReadContext) -> tuple[int, int]:
    """(N, S) from the shapes of ``points`` and ``offsets``; the optional arrays must match."""
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


def _member_array(
    archive: zipfile.ZipFile, member: str, key: str, ctx: ReadContext
) -> np.ndarray:
    try:
        with archive.open(member) as f:
            return np.lib.format.read_array(
                f, allow_pickle=False, max_header_size=NPZ_MAX_HEADER_BYTES
            )
    except _ZIP_ERRORS as exc:
        raise ctx.error(f"array {key!r} cannot be read ({exc})", "truncated") from None


def recorded_units(path) -> str | None:
    """The units a hairport archive records, without reading its arrays.

    Returns None for a file that is not a readable archive or records none (the reader then
    says what is wrong, or reads it in the units asked for).
    """
    units = _recorded_text(path, "units")
    return units if units in METERS_PER_UNIT else None


def _recorded_text(path, key: str) -> str | None:
    try:
        with zipfile.ZipFile(path) as archive, archive.open(f"{key}.npy") as f:
            value = np.lib.format.read_array(f, allow_pickle=False, max_header_size=NPZ_MAX_HEADER_BYTES)
    except (*_ZIP_ERRORS, KeyError):
        return None
    if value.shape != () or value.dtype.kind not in "US":
        return None
    return _member_text(value)


def write_npz(f: BinaryIO, hair: Hair, options: WriteOptions) -> None:
    """Write the archive: marker, version, units and the hairstyle's arrays in file units."""
    scale = options.scale
    arrays = {
        "format": np.array(NPZ_FORMAT),
        "version": np.array(NPZ_VERSION, dtype=np.int64),
        "units": np.array(options.units),
        "points": hair.points / scale,
        "offsets": hair.offsets,
        "up_axis": np.array(options.up_axis),
    }
    if hair.thickness is not None:
        arrays["thickness"] = hair.thickness / scale
    if hair.color is not None:
        arrays["color"] = hair.color
    if hair.attributes:
        arrays["attributes"] = np.array(json.dumps(
            [{"name": name, "domain": attribute.domain, "role": attribute.role}
             for name, attribute in hair.attributes.items()]))
        for index, attribute in enumerate(hair.attributes.values()):
            arrays[NPZ_ATTRIBUTE.format(index)] = attribute.values
    np.savez(f, **arrays)


FORMAT = HairFormat("npz", read_npz, write_npz, keeps_thickness=True, keeps_color=True, recorded_units=recorded_units,
                    keeps_attribute=lambda name, attribute: True)
