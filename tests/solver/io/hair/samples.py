"""Hair files made for the tests: small helical grooms, and hand-built bytes from small
independent encoders (``data_bytes``, ``hair_file_bytes``, ``ply_bytes``, ``npz_bytes``) so
that the readers are not only checked against their own writers."""

from __future__ import annotations

import io
import struct
import warnings

import numpy as np
import pytest

from hairport.solver.io.hair import HairIOWarning, read_hair
from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import Hair

# every (format, ascii) pair the writer can produce
WRITE_VARIANTS = [
    ("data", False),
    ("hair", False),
    ("ply", False),
    ("ply", True),
    ("npz", False),
    ("obj", False),
    ("usd", False),
    ("usda", False),
    ("usdc", False),
    ("abc", False),
]
PLY_ENCODINGS = ["ascii", "binary_little_endian", "binary_big_endian"]


def helix_hair(
    n_strands: int = 40,
    *,
    seed: int = 0,
    min_points: int = 2,
    max_points: int = 25,
    thickness: bool = False,
    color: bool = False,
) -> Hair:
    """Helical strands hanging from random roots on a 10 cm sphere, in meters."""
    rng = np.random.default_rng(seed)
    counts = rng.integers(min_points, max_points + 1, n_strands)
    offsets = np.concatenate([[0], np.cumsum(counts)])
    n = int(offsets[-1])
    t = np.arange(n) - np.repeat(offsets[:-1], counts)
    roots = rng.normal(size=(n_strands, 3))
    roots = 0.1 * roots / np.linalg.norm(roots, axis=1, keepdims=True)
    phase = np.repeat(rng.uniform(0, 2 * np.pi, n_strands), counts)
    points = np.repeat(roots, counts, axis=0) + np.stack(
        [0.01 * np.cos(0.4 * t + phase), 0.01 * np.sin(0.4 * t + phase), -0.004 * t], axis=1
    )
    thick = 8e-5 * (1.0 - 0.5 * t / max_points) if thickness else None
    rgb = rng.uniform(0, 1, (n, 3)) if color else None
    return Hair(points, offsets, thick, rgb)


def f32(values: np.ndarray) -> np.ndarray:
    """The float64 values a float32 file gives back."""
    return np.asarray(values, dtype=np.float32).astype(np.float64)


def data_bytes(strands: list[np.ndarray], n_strands: int | None = None) -> bytes:
    """USC-HairSalon bytes, encoded strand by strand with struct."""
    out = [struct.pack("<i", len(strands) if n_strands is None else n_strands)]
    for strand in strands:
        strand = np.asarray(strand, dtype=np.float64).reshape(-1, 3)
        out.append(struct.pack("<i", len(strand)))
        out.append(struct.pack(f"<{3 * len(strand)}f", *strand.ravel()))
    return b"".join(out)


def hair_file_bytes(
    counts,
    points,
    *,
    segments_array: bool = True,
    d_segments: int = 0,
    thickness=None,
    transparency=None,
    color=None,
    magic: bytes = b"HAIR",
    hair_count: int | None = None,
    point_count: int | None = None,
    flags: int | None = None,
) -> bytes:
    """Cem Yuksel HAIR bytes from the format description (header packed with struct)."""
    counts = np.asarray(counts)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if flags is None:
        flags = 2 | (1 if segments_array else 0)
        flags |= 4 if thickness is not None else 0
        flags |= 8 if transparency is not None else 0
        flags |= 16 if color is not None else 0
    header = struct.pack(
        "<4s4I5f88s",
        magic,
        len(counts) if hair_count is None else hair_count,
        len(points) if point_count is None else point_count,
        flags,
        d_segments,
        1.0,
        0.0,
        0.5,
        0.4,
        0.3,
        b"test",
    )
    assert len(header) == 128
    body = b""
    if segments_array:
        body += (counts - 1).astype("<u2").tobytes()
    body += points.astype("<f4").tobytes()
    for extra in (thickness, transparency, color):
        if extra is not None:
            body += np.asarray(extra, dtype="<f4").tobytes()
    return header + body


PLY_STRUCT = {
    "uchar": "B",
    "char": "b",
    "ushort": "H",
    "short": "h",
    "int": "i",
    "uint": "I",
    "float": "f",
    "double": "d",
}


def ply_bytes(encoding: str, elements: list[tuple[str, int, list[tuple]]]) -> bytes:
    """A PLY file, record by record.

    ``elements`` holds ``(name, count, properties)``; a property is ``(name, type, values)``
    or ``(name, ("list", count_type, item_type), list_of_lists)``.
    """
    lines = ["ply", f"format {encoding} 1.0", "comment made by the hairport tests"]
    for name, count, props in elements:
        lines.append(f"element {name} {count}")
        for prop_name, kind, _ in props:
            if isinstance(kind, tuple):
                lines.append(f"property list {kind[1]} {kind[2]} {prop_name}")
            else:
                lines.append(f"property {kind} {prop_name}")
    lines.append("end_header")
    head = ("\n".join(lines) + "\n").encode("ascii")
    order = ">" if encoding == "binary_big_endian" else "<"
    body = []
    for _, count, props in elements:
        for r in range(count):
            if encoding == "ascii":
                tokens = []
                for _, kind, values in props:
                    if isinstance(kind, tuple):
                        tokens += [str(len(values[r]))] + [repr(v) for v in values[r]]
                    else:
                        tokens.append(
                            repr(values[r].item() if hasattr(values[r], "item") else values[r])
                        )
                body.append((" ".join(tokens) + "\n").encode("ascii"))
            else:
                for _, kind, values in props:
                    if isinstance(kind, tuple):
                        items = list(values[r])
                        body.append(struct.pack(order + PLY_STRUCT[kind[1]], len(items)))
                        body.append(struct.pack(order + PLY_STRUCT[kind[2]] * len(items), *items))
                    else:
                        body.append(struct.pack(order + PLY_STRUCT[kind], values[r]))
    return head + b"".join(body)


def xyz_props(points: np.ndarray) -> list[tuple]:
    return [(axis, "float", [float(v) for v in points[:, i]]) for i, axis in enumerate("xyz")]


def write_bytes(tmp_path, name: str, data: bytes):
    path = tmp_path / name
    path.write_bytes(data)
    return path


def read_quietly(path, **kwargs) -> Hair:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HairIOWarning)
        return read_hair(path, **kwargs)


def expect_error(code: str, func, *args, **kwargs) -> InputError:
    with pytest.raises(InputError) as info, warnings.catch_warnings():
        warnings.simplefilter("ignore", HairIOWarning)
        func(*args, **kwargs)
    assert info.value.code == code, f"expected {code!r}, got {info.value.code!r}: {info.value}"
    return info.value


def variant_path(tmp_path, fmt: str, ascii: bool, stem: str = "groom"):
    return tmp_path / f"{stem}{'_ascii' if ascii else ''}.{fmt}"


def strands_of(counts, seed=0) -> tuple[np.ndarray, np.ndarray]:
    counts = np.asarray(counts)
    points = f32(np.random.default_rng(seed).normal(size=(int(counts.sum()), 3)))
    return points, np.concatenate([[0], np.cumsum(counts)])


def npz_bytes(**arrays) -> bytes:
    base = {
        "format": np.array("hairport-hair"),
        "version": np.array(1),
        "points": np.arange(12.0).reshape(4, 3),  # strands of some length: zero-length ones are empty hair
        "offsets": np.array([0, 2, 4]),
    }
    base.update(arrays)
    buffer = io.BytesIO()
    np.savez(buffer, **{k: v for k, v in base.items() if v is not None})
    return buffer.getvalue()


def mutate(data: bytes, rng: np.random.Generator) -> bytes:
    """Overwrite, delete, insert or bit-flip bytes at a few random places."""
    out = bytearray(data)
    for _ in range(int(rng.integers(1, 6))):
        at = int(rng.integers(0, len(out)))
        op = int(rng.integers(0, 4))
        if op == 0:
            out[at] = int(rng.integers(0, 256))
        elif op == 1:
            del out[at : at + int(rng.integers(1, 20))]
        elif op == 2:
            out[at:at] = rng.integers(0, 256, int(rng.integers(1, 10))).astype(np.uint8).tobytes()
        else:
            out[at] ^= 1 << int(rng.integers(0, 8))
    return bytes(out)


# the start of hand-written ASCII PLY files
ASCII_PLY = b"ply\nformat ascii 1.0\n"
XYZ = b"property float x\nproperty float y\nproperty float z\n"


def long_strand_hair(n_points: int) -> Hair:
    """One straight strand of ``n_points`` points, 1 m apart along x, y and z."""
    return Hair(np.zeros((n_points, 3)) + np.arange(n_points)[:, None], np.array([0, n_points]))
