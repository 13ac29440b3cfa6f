"""The skeleton sidecar ``<mesh>.skeleton.json``: a skeleton and optional skin weights beside a mesh file.

Schema::

    {"units": "m",                               # m | dm | cm | mm; optional (see below)
     "bones": [{"name": str, "parent": str | null, "head": [x, y, z], "tail": [x, y, z]}, ...],
     "weights": {bone_name: [[vertex_index, weight], ...], ...}}   # optional

Bones may be listed in any order; unknown keys are ignored. Weights are summed over
duplicate ``(vertex, bone)`` entries, and every vertex row with a positive sum is
normalised to sum 1; vertices without any weight keep an all-zero row (they lie in no
bone's valid region). When ``weights`` is absent the reader returns none, and
:func:`~hairport.solver.io.character.load_character` derives them from the geometry
(:func:`hairport.solver.body.skinning.derive_skin_weights`). Vertex indices are 0-based.
:func:`write_skeleton_json` writes this schema (:func:`skeleton_document`), and is the one
writer of it.

``units`` states the units of the joints and of the mesh beside the file. Without it the
joints are read as they are (meters, unless the mesh turns out to be in other units) and the
mesh's units are unknown: :func:`hairport.solver.inputs.canonical_source` infers them and
scales the joints with the mesh.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from hairport.solver.io.character.mesh_file import DEFAULT_MAX_FILE_BYTES, MALFORMED, MAX_BONES, check_file
from hairport.solver.model.character import Skeleton, normalise_weight_rows
from hairport.solver.model.errors import InputError
from hairport.solver.model.files import atomic_write_bytes
from hairport.solver.model.json_input import parse_json
from hairport.solver.model.units import unit_scale

#: suffix of the skeleton sidecar that replaces the mesh file's extension
SKELETON_SUFFIX = ".skeleton.json"


def resolve_skeleton_path(mesh_path: str | os.PathLike) -> Path | None:
    """The sidecar ``<mesh path without extension>.skeleton.json`` if it exists.

    Parameters
    ----------
    mesh_path : path

    Returns
    -------
    path : Path or None
    """
    mesh_path = Path(mesh_path)
    candidate = mesh_path.with_name(mesh_path.stem + SKELETON_SUFFIX)
    return candidate if candidate.is_file() else None


def load_skeleton_json(
    path: str | os.PathLike, n_vertices: int, *, max_bytes: int = DEFAULT_MAX_FILE_BYTES
) -> tuple[Skeleton, sp.csr_matrix | None]:
    """Read and validate a skeleton sidecar (schema in the module docstring).

    Parameters
    ----------
    path : path
    n_vertices : int
        Vertex count of the mesh the weights refer to.
    max_bytes : int

    Returns
    -------
    skeleton : Skeleton
        In meters (converted from the file's ``units``).
    weights : (V, B) scipy.sparse.csr_matrix or None
        Rows with a positive sum normalised to 1; ``None`` when the file has no
        ``weights`` key (derive them with
        :func:`~hairport.solver.body.skinning.derive_skin_weights`).

    Raises
    ------
    InputError
        Unreadable JSON, wrong types, unknown parent, duplicate bone, parent cycle,
        non-finite joint, weights for an unknown bone, vertex index out of range,
        negative or non-finite weight.
    """
    skeleton, weights, _ = read_skeleton_json(Path(path), n_vertices, max_bytes)
    return skeleton, weights


def read_skeleton_json(
    path: Path, n_vertices: int, max_bytes: int
) -> tuple[Skeleton, sp.csr_matrix | None, str]:
    """:func:`load_skeleton_json`, also returning the file's ``units`` (for the mesh beside it; None when
    the file has no ``units`` key: its joints are then read as meters, and the mesh's units are unknown)."""
    try:
        return _parse_skeleton_json(path, n_vertices, max_bytes)
    except InputError:
        raise
    except MALFORMED as error:
        raise InputError(f"malformed skeleton JSON: {type(error).__name__}: {error}", str(path), "bad_skeleton") from None


def skeleton_document(
    skeleton: Skeleton, weights: sp.spmatrix | None, units: str = "m", *, source: str = ""
) -> dict:
    """The sidecar of a skeleton and its weights as a JSON-ready dict (schema in the module docstring).

    Parameters
    ----------
    skeleton : Skeleton
        In meters.
    weights : (V, B) sparse matrix or None
        Only non-zero entries are written, by bone and then by vertex; every bone gets a
        ``weights`` entry (possibly empty); ``None`` omits the ``weights`` key.
    units : {"m", "dm", "cm", "mm"}
        Units of the coordinates in the document.
    source : str
        Where the document goes, for errors.

    Returns
    -------
    document : dict

    Raises
    ------
    InputError
        ``bad_weights`` when ``weights`` does not have one column per bone.
    """
    per_meter = 1.0 / unit_scale(units)
    names = skeleton.names
    bones = [
        {
            "name": name,
            "parent": names[p] if p >= 0 else None,
            "head": (skeleton.heads[b] * per_meter).tolist(),
            "tail": (skeleton.tails[b] * per_meter).tolist(),
        }
        for b, (name, p) in enumerate(zip(names, skeleton.parents.tolist()))
    ]
    document: dict = {"units": units, "bones": bones}
    if weights is not None:
        # a copy: dropping stored zeros must not change the caller's matrix
        csc = sp.csc_matrix(weights, dtype=np.float64, copy=True)
        if csc.shape[1] != skeleton.n_bones:
            raise InputError(f"weights have {csc.shape[1]} columns for {skeleton.n_bones} bones", source, "bad_weights")
        csc.eliminate_zeros()
        document["weights"] = {
            name: [
                [i, w]
                for i, w in zip(
                    csc.indices[csc.indptr[b] : csc.indptr[b + 1]].tolist(),
                    csc.data[csc.indptr[b] : csc.indptr[b + 1]].tolist(),
                )
            ]
            for b, name in enumerate(names)
        }
    return document


def write_skeleton_json(
    path: str | os.PathLike, skeleton: Skeleton, weights: sp.spmatrix | None, units: str = "m"
) -> None:
    """Write a skeleton sidecar atomically (:func:`hairport.solver.model.files.atomic_write`).

    The folder is created if needed. Parameters as :func:`skeleton_document`; the JSON is
    compact and refuses NaN and infinity.
    """
    path = Path(path)
    document = skeleton_document(skeleton, weights, units, source=str(path))
    text = json.dumps(document, allow_nan=False, separators=(",", ":"))
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, text.encode("utf-8"))


def _parse_skeleton_json(
    path: Path, n_vertices: int, max_bytes: int
) -> tuple[Skeleton, sp.csr_matrix | None, str]:
    source = str(path)
    check_file(path, max_bytes)
    document = parse_json(path.read_bytes(), source, "bad_skeleton", "skeleton file")
    if not isinstance(document, dict):
        raise InputError("skeleton JSON must be an object with 'bones'", source, "bad_skeleton")
    units = document.get("units")  # absent: meters for the joints, unknown for the mesh beside it
    if "units" in document and not isinstance(units, str):
        raise InputError(f"'units' must be a string, got {units!r}", source, "unknown_units")
    try:
        scale = unit_scale(units or "m")
    except InputError as error:
        raise InputError(error.problem, source, error.code) from None
    bones = document.get("bones")
    if not isinstance(bones, list) or not bones:
        raise InputError("skeleton JSON needs a non-empty 'bones' list", source, "bad_skeleton")
    if len(bones) > MAX_BONES:
        raise InputError(f"skeleton has {len(bones)} bones, more than {MAX_BONES}", source, "too_large")
    names: list[str] = []
    parent_names: list[str | None] = []
    joints = np.empty((len(bones), 2, 3))
    for b, bone in enumerate(bones):
        if not isinstance(bone, dict):
            raise InputError(f"bone {b} is not an object", source, "bad_skeleton")
        name = bone.get("name")
        if not isinstance(name, str) or not name:
            raise InputError(f"bone {b} has no name (a non-empty string)", source, "bad_skeleton")
        parent = bone.get("parent")
        if parent is not None and not isinstance(parent, str):
            raise InputError(f"bone {name!r}: parent must be a bone name or null", source, "bad_skeleton")
        for k, key in enumerate(("head", "tail")):
            value = bone.get(key)
            if (
                not isinstance(value, list)
                or len(value) != 3
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in value)
            ):
                raise InputError(f"bone {name!r}: {key} must be a list of 3 numbers", source, "bad_skeleton")
            joints[b, k] = value
        names.append(name)
        parent_names.append(parent)
    if not np.isfinite(joints).all():
        bad = int(np.argmax(~np.isfinite(joints).all(axis=(1, 2))))
        raise InputError(f"bone {names[bad]!r} has a non-finite joint", source, "non_finite")
    index: dict[str, int] = {}
    for b, name in enumerate(names):
        if name in index:
            raise InputError(f"duplicate bone {name!r}", source, "bad_skeleton")
        index[name] = b
    parents = np.empty(len(names), dtype=np.int64)
    for b, parent in enumerate(parent_names):
        if parent is None:
            parents[b] = -1
        elif parent not in index:
            raise InputError(f"bone {names[b]!r} has unknown parent {parent!r}", source, "bad_skeleton")
        else:
            parents[b] = index[parent]
    cycle = _bones_in_cycles(parents)
    if cycle.any():
        members = ", ".join(repr(names[b]) for b in np.flatnonzero(cycle)[:5])
        raise InputError(f"bone parents form a cycle (through {members})", source, "bad_skeleton")
    skeleton = Skeleton(names, parents, joints[:, 0] * scale, joints[:, 1] * scale)

    weights = None
    if document.get("weights") is not None:
        weights = _parse_json_weights(document["weights"], index, n_vertices, source)
    return skeleton, weights, units


def _bones_in_cycles(parents: np.ndarray) -> np.ndarray:
    """(B,) bool: bones whose chain of parents never reaches a root."""
    n = len(parents)
    current = parents.copy()
    for _ in range(n):
        current = np.where(current >= 0, parents[np.maximum(current, 0)], -1)
    # after n steps every chain that ends has reached -1; the rest loop forever
    return current >= 0


def _parse_json_weights(weights, index: dict[str, int], n_vertices: int, source: str) -> sp.csr_matrix:
    if not isinstance(weights, dict):
        raise InputError("'weights' must be an object {bone name: [[vertex, weight], ...]}", source, "bad_weights")
    rows, cols, vals = [], [], []
    for name, entries in weights.items():
        if name not in index:
            raise InputError(f"weights given for unknown bone {name!r}", source, "bad_weights")
        if not isinstance(entries, list):
            raise InputError(f"weights of bone {name!r} must be a list of [vertex, weight]", source, "bad_weights")
        if not entries:
            continue
        try:
            pairs = np.array(entries, dtype=np.float64)
        except (ValueError, TypeError):
            raise InputError(
                f"weights of bone {name!r} must be [vertex, weight] pairs of numbers", source, "bad_weights"
            ) from None
        if pairs.ndim != 2 or pairs.shape[1] != 2:
            raise InputError(f"weights of bone {name!r} must be [vertex, weight] pairs", source, "bad_weights")
        vertex, weight = pairs[:, 0], pairs[:, 1]
        if not (np.isfinite(vertex).all() and (vertex == np.round(vertex)).all()):
            raise InputError(f"weights of bone {name!r} have a non-integer vertex index", source, "bad_weights")
        out = (vertex < 0) | (vertex >= n_vertices)
        if out.any():
            raise InputError(
                f"weights of bone {name!r} refer to vertex {int(vertex[out][0])}, outside 0..{n_vertices - 1}",
                source,
                "bad_weights",
            )
        if not np.isfinite(weight).all():
            raise InputError(f"weights of bone {name!r} have a non-finite weight", source, "non_finite")
        if (weight < 0).any():
            raise InputError(f"weights of bone {name!r} have a negative weight", source, "bad_weights")
        rows.append(vertex.astype(np.int64))
        cols.append(np.full(len(vertex), index[name], dtype=np.int64))
        vals.append(weight)
    shape = (n_vertices, len(index))
    if not rows:
        return sp.csr_matrix(shape)
    matrix = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=shape)
    return normalise_weight_rows(matrix)
