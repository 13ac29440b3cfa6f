"""PLY meshes, read through trimesh with the file's vertex order and count.

trimesh is called with ``process=False, fix_texture=False`` (with ``fix_texture=True`` it
splits vertices that carry per-face texture coordinates). It triangulates polygons itself
(quads become ``(a, b, c), (c, d, a)``; with mixed polygon sizes it groups the triangles by
size); this is deterministic per file, but an OBJ and a PLY of the same quad mesh do not
get identical face lists. The header's element counts are checked against the limits
before the body is read.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from hairport.solver.io.character.mesh_file import DEFAULT_MAX_FACES, DEFAULT_MAX_VERTICES, MeshFile, check_counts
from hairport.solver.io.external import ALLOW_EXTERNAL_FILES
from hairport.solver.model.errors import InputError

#: bytes of a PLY header read at most when looking for ``end_header``
MAX_PLY_HEADER_BYTES = 1 << 16


def read_ply(
    path: str | os.PathLike, *, max_vertices: int = DEFAULT_MAX_VERTICES, max_faces: int = DEFAULT_MAX_FACES
) -> tuple[np.ndarray, np.ndarray]:
    """Read a PLY mesh through trimesh, keeping the file's vertex order and count.

    The header's element counts are checked against the limits before the body is read.

    Parameters
    ----------
    path : path
    max_vertices, max_faces : int

    Returns
    -------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    """
    import trimesh  # on first use: importing it costs more than the other readers need

    path = Path(path)
    source = str(path)
    n_v, n_f = _ply_header_counts(path)
    check_counts(n_v, n_f, source, max_vertices, max_faces)
    try:
        mesh = trimesh.load(path, force="mesh", process=False, fix_texture=False, skip_materials=True)
    except Exception as error:  # trimesh raises many types on malformed files
        raise InputError(f"cannot read PLY: {error}", source, "bad_mesh") from None
    vertices = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), dtype=np.float64)
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.int64).reshape(-1, 3)
    if len(vertices) == 0 or len(faces) == 0:
        raise InputError(f"empty mesh: {len(vertices)} vertices, {len(faces)} faces", source, "empty_mesh")
    if len(vertices) != n_v:
        raise InputError(
            f"the PLY reader returned {len(vertices)} vertices for the {n_v} in the header", source, "bad_mesh"
        )
    return vertices, faces


def _ply_header_counts(path: Path) -> tuple[int, int]:
    """Vertex and face element counts of a PLY header."""
    source = str(path)
    with open(path, "rb") as handle:
        head = handle.read(MAX_PLY_HEADER_BYTES)
    if not head.startswith(b"ply"):
        raise InputError("not a PLY file (no 'ply' magic)", source, "bad_mesh")
    end = head.find(b"end_header")
    if end < 0:
        raise InputError("PLY header has no end_header", source, "bad_mesh")
    counts = {"vertex": 0, "face": 0}
    for line in head[:end].decode("ascii", errors="replace").splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[0] == "element" and parts[1] in counts:
            try:
                counts[parts[1]] = int(parts[2])
            except ValueError:
                raise InputError(f"PLY header line {line!r} has a bad count", source, "bad_mesh") from None
    if counts["vertex"] < 0 or counts["face"] < 0:
        raise InputError("PLY header has a negative element count", source, "bad_mesh")
    return counts["vertex"], counts["face"]


def _read(path: Path, *, max_vertices: int, max_faces: int, mesh_name: str | None,
          allow_external_files: bool = ALLOW_EXTERNAL_FILES) -> MeshFile:
    """:func:`read_ply` behind the reader interface of the format registry (a PLY has no skin; the
    texture its header may name is never opened, whatever ``allow_external_files``)."""
    vertices, faces = read_ply(path, max_vertices=max_vertices, max_faces=max_faces)
    return MeshFile(vertices, faces)


#: the readers of this module, by file extension
READERS = {".ply": _read}
