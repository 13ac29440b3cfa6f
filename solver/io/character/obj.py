"""Wavefront OBJ: a reader of our own that keeps vertex order and count, and the writer.

``trimesh.load(..., process=False)`` still splits vertices by ``vt``/``vn`` index, which
breaks the vertex order, so :func:`read_obj` reads the ``v`` and ``f`` lines itself. Indices
may be ``v``, ``v/vt``, ``v//vn``, ``v/vt/vn``, and negative (relative). Polygons are
triangulated by a fan from their first corner, in file order: polygon ``(a, b, c, d)``
becomes ``(a, b, c), (a, c, d)``. The split never depends on positions, so two files of one
topology always triangulate alike. All groups/objects are kept, in file order.
:func:`write_obj` writes ``v`` and ``f`` lines only, which :func:`read_obj` reads back
vertex for vertex.
"""

from __future__ import annotations

import io
import os
import re
from pathlib import Path

import numpy as np

from hairport.solver.io.character.mesh_file import DEFAULT_MAX_FACES, DEFAULT_MAX_VERTICES, MeshFile, check_counts
from hairport.solver.io.external import ALLOW_EXTERNAL_FILES
from hairport.solver.model.errors import InputError
from hairport.solver.model.files import atomic_write_bytes

_OBJ_VERTEX = re.compile(r"^[ \t]*v[ \t]+([^\n#]*)", re.MULTILINE)
_OBJ_FACE = re.compile(r"^[ \t]*f[ \t]+([^\n#]*)", re.MULTILINE)
_OBJ_FACE_ATTRIBUTES = re.compile(r"/\S*")
_OBJ_VERTEX_BYTES = re.compile(rb"^[ \t]*v[ \t]", re.MULTILINE)
_OBJ_FACE_BYTES = re.compile(rb"^[ \t]*f[ \t]", re.MULTILINE)


def read_obj(
    path: str | os.PathLike, *, max_vertices: int = DEFAULT_MAX_VERTICES, max_faces: int = DEFAULT_MAX_FACES
) -> tuple[np.ndarray, np.ndarray]:
    """Read the ``v`` and ``f`` lines of a Wavefront OBJ file, keeping vertex order and count.

    Parameters
    ----------
    path : path
    max_vertices : int
    max_faces : int
        Limit on polygons in the file and on triangles after triangulation.

    Returns
    -------
    vertices : (V, 3) float64
        In file units; extra components (``w``, vertex colours) are ignored.
    faces : (F, 3) int64
        Polygons fan-triangulated from their first corner, in file order.
    """
    path = Path(path)
    source = str(path)
    raw = path.read_bytes()
    nul = raw.find(b"\0")
    if nul >= 0:
        raise InputError(f"byte {nul:,} is a NUL byte: a binary file, not OBJ text (code not_text)", source,
                         "not_text")
    n_v = sum(1 for _ in _OBJ_VERTEX_BYTES.finditer(raw))
    n_f = sum(1 for _ in _OBJ_FACE_BYTES.finditer(raw))
    check_counts(n_v, n_f, source, max_vertices, max_faces)
    text = raw.decode("utf-8", errors="replace")
    del raw
    if "\\" in text:  # line continuations
        text = re.sub(r"\\[ \t]*\r?\n", " ", text)
    vertex_lines = _OBJ_VERTEX.findall(text)
    face_lines = _OBJ_FACE.findall(text)
    if not vertex_lines or not face_lines:
        raise InputError(
            f"empty mesh: {len(vertex_lines)} vertices, {len(face_lines)} faces", source, "empty_mesh"
        )
    vertices = _parse_obj_vertices(vertex_lines, source)
    del vertex_lines
    # drop the /vt/vn parts of every corner; one line per face
    face_lines = _OBJ_FACE_ATTRIBUTES.sub("", "\n".join(face_lines)).split("\n")
    corner_counts = np.array([len(line.split()) for line in face_lines], dtype=np.int64)
    short = corner_counts < 3
    if short.any():
        bad = int(np.argmax(short))
        raise InputError(
            f"face {bad} has {int(corner_counts[bad])} corner(s); it cannot be triangulated",
            source,
            "bad_faces",
        )
    n_triangles = int((corner_counts - 2).sum())
    if n_triangles > max_faces:
        raise InputError(
            f"mesh has {n_triangles} triangles, more than the limit of {max_faces}", source, "too_large"
        )
    try:
        corners = np.array(" ".join(face_lines).split(), dtype=np.int64)
    except (ValueError, OverflowError):  # OverflowError: an index beyond int64 (2^63)
        raise InputError("a face has a corner that is not an integer vertex index in range", source,
                         "bad_faces") from None
    if (corners == 0).any():
        raise InputError("a face refers to vertex 0 (OBJ indices start at 1)", source, "bad_faces")
    negative = corners < 0
    if negative.any():
        # relative index: -1 is the last vertex defined before the face line
        vertex_positions = np.array([m.start() for m in _OBJ_VERTEX.finditer(text)], dtype=np.int64)
        face_positions = np.array([m.start() for m in _OBJ_FACE.finditer(text)], dtype=np.int64)
        defined_before = np.searchsorted(vertex_positions, face_positions)
        corners = np.where(negative, np.repeat(defined_before, corner_counts) + corners, corners - 1)
    else:
        corners = corners - 1
    if corners.min() < 0 or corners.max() >= len(vertices):
        raise InputError(
            f"a face refers to a vertex outside 1..{len(vertices)}", source, "bad_faces"
        )
    return vertices, fan_triangulate(corners, corner_counts)


def _parse_obj_vertices(lines: list[str], source: str) -> np.ndarray:
    try:
        values = np.array(" ".join(lines).split(), dtype=np.float64)
    except ValueError:
        raise InputError("a vertex line has a coordinate that is not a number", source, "bad_mesh") from None
    if len(values) == 3 * len(lines):
        return values.reshape(-1, 3)
    counts = np.array([len(line.split()) for line in lines], dtype=np.int64)
    if counts.min() < 3:
        bad = int(np.argmax(counts < 3))
        raise InputError(f"vertex {bad + 1} has {int(counts[bad])} coordinate(s), expected 3", source, "bad_mesh")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    return values[starts[:, None] + np.arange(3)]


def fan_triangulate(corners: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Triangulate polygons by a fan from each polygon's first corner.

    Parameters
    ----------
    corners : (sum(counts),) int64
        Vertex indices of all polygons, concatenated.
    counts : (P,) int64
        Corners per polygon, each >= 3.

    Returns
    -------
    faces : (sum(counts - 2), 3) int64
        Polygon ``(c0, c1, ..., cn)`` gives ``(c0, c1, c2), (c0, c2, c3), ...``, in order.
    """
    counts = np.asarray(counts, dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    n_tri = counts - 2
    first = np.repeat(starts, n_tri)
    within = np.arange(int(n_tri.sum()), dtype=np.int64) - np.repeat(np.cumsum(n_tri) - n_tri, n_tri)
    return np.stack([corners[first], corners[first + within + 1], corners[first + within + 2]], axis=1)


def write_obj(path: str | os.PathLike, vertices: np.ndarray, faces: np.ndarray, comment: str) -> None:
    """Write a triangle mesh as OBJ ``v`` and ``f`` lines, atomically; the folder is created.

    Parameters
    ----------
    path : path
    vertices : (V, 3) float64
        Written with 9 significant digits (``%.9g``), in vertex order.
    faces : (F, 3) int64
        0-based; written 1-based.
    comment : str
        One line written first, as ``# comment``.
    """
    path = Path(path)
    text = io.StringIO()
    text.write(f"# {comment}\n")
    np.savetxt(text, vertices, fmt="v %.9g %.9g %.9g")
    np.savetxt(text, np.asarray(faces) + 1, fmt="f %d %d %d")
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, text.getvalue().encode("utf-8"))


def _read(path: Path, *, max_vertices: int, max_faces: int, mesh_name: str | None,
          allow_external_files: bool = ALLOW_EXTERNAL_FILES) -> MeshFile:
    """:func:`read_obj` behind the reader interface of the format registry (an OBJ has no skin; its
    ``mtllib`` is never opened, whatever ``allow_external_files``)."""
    vertices, faces = read_obj(path, max_vertices=max_vertices, max_faces=max_faces)
    return MeshFile(vertices, faces)


#: the readers of this module, by file extension
READERS = {".obj": _read}
