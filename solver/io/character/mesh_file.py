"""What every character file reader shares: the limits, the checks, and the type they return.

A reader checks the file (:func:`check_file`), then the element counts against the limits
before it builds arrays (:func:`check_counts`), and :func:`hairport.solver.io.character.load_character`
checks the arrays it got (:func:`check_mesh_arrays`). Every failure is an
:class:`~hairport.solver.model.errors.InputError` naming the file, with a stable ``code``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from hairport.solver.model.character import Skeleton
from hairport.solver.model.errors import InputError

#: largest vertex count accepted by default
DEFAULT_MAX_VERTICES = 2_000_000
#: largest triangle count (after triangulation) accepted by default
DEFAULT_MAX_FACES = 4_000_000
#: largest mesh or skeleton file accepted (bytes)
DEFAULT_MAX_FILE_BYTES = 1 << 30
#: largest bone count accepted in a skeleton
MAX_BONES = 4096
#: what a malformed document can raise inside a reader; turned into InputError
MALFORMED = (KeyError, TypeError, AttributeError, IndexError, ValueError, OverflowError, np.linalg.LinAlgError)


@dataclass(frozen=True)
class Skin:
    """A skeleton and skin weights stored in a mesh file (in file units).

    Attributes
    ----------
    skeleton : Skeleton
    weights : (V, B) scipy.sparse.csr_matrix
        Rows with a positive sum normalised to 1.
    """

    skeleton: Skeleton
    weights: sp.csr_matrix


@dataclass(frozen=True)
class MeshFile:
    """The mesh (and skin) a format reader found in a file.

    Attributes
    ----------
    vertices : (V, 3) float64
        In file units, in file order.
    faces : (F, 3) int64
    skin : Skin or None
        Only formats that can hold a skin (glTF) fill it.
    name : str
        The name of the mesh in the file, where the format has one.
    units : str or None
        The length unit the file states (glTF: meters by specification; USD: the stage's
        ``metersPerUnit``), None where the format states none.
    """

    vertices: np.ndarray
    faces: np.ndarray
    skin: Skin | None = None
    name: str = ""
    units: str | None = None


def check_file(path: Path, max_bytes: int) -> None:
    """Refuse a missing, non-regular, empty or too large file.

    Raises
    ------
    InputError
        ``not_found``, ``empty_mesh`` or ``too_large``.
    """
    source = str(path)
    if not path.exists():
        raise InputError("file not found", source, "not_found")
    if not path.is_file():
        raise InputError("not a regular file", source, "not_found")
    size = path.stat().st_size
    if size > max_bytes:
        raise InputError(f"file has {size} bytes, more than the limit of {max_bytes}", source, "too_large")
    if size == 0:
        raise InputError("file is empty", source, "empty_mesh")


def check_counts(n_vertices: int, n_faces: int, source: str, max_vertices: int, max_faces: int) -> None:
    """Refuse element counts above the limits (``too_large``), before any array is built."""
    if n_vertices > max_vertices:
        raise InputError(
            f"mesh has {n_vertices} vertices, more than the limit of {max_vertices}", source, "too_large"
        )
    if n_faces > max_faces:
        raise InputError(f"mesh has {n_faces} faces, more than the limit of {max_faces}", source, "too_large")


def check_mesh_arrays(
    vertices: np.ndarray, faces: np.ndarray, source: str, max_vertices: int, max_faces: int
) -> None:
    """Refuse an empty mesh (no faces, or no face of any area), counts above the limits,
    non-finite vertices and faces out of range.

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    source : str
        The file, for the error.
    max_vertices, max_faces : int

    Raises
    ------
    InputError
        ``empty_mesh``, ``too_large``, ``non_finite`` or ``bad_faces``.
    """
    if len(vertices) == 0 or len(faces) == 0:
        raise InputError(f"empty mesh: {len(vertices)} vertices, {len(faces)} faces", source, "empty_mesh")
    check_counts(len(vertices), len(faces), source, max_vertices, max_faces)
    finite = np.isfinite(vertices).all(axis=1)
    if not finite.all():
        bad = int(np.argmax(~finite))
        raise InputError(f"vertex {bad} has a non-finite coordinate (NaN or inf)", source, "non_finite")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise InputError("a face index is out of range", source, "bad_faces")
    corners = vertices[faces]
    if not np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]).any():
        raise InputError(f"empty mesh: every face ({len(faces):,}) has zero area (code empty_mesh)", source,
                         "empty_mesh")


def fan_triangles(counts: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """(T, 3) int64: every face of ``counts[f]`` corners (from ``indices``, faces concatenated) as a fan
    ``(v0, vi, vi+1)``, faces in order; faces of fewer than three corners give none."""
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    fans = np.maximum(counts - 2, 0)
    first = np.repeat(starts, fans)
    step = np.arange(int(fans.sum()), dtype=np.int64) - np.repeat(np.cumsum(fans) - fans, fans)
    return np.stack([indices[first], indices[first + step + 1], indices[first + step + 2]], axis=1)
