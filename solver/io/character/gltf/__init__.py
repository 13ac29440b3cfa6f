"""glTF 2.0 (``.gltf``, ``.glb``): one mesh, and its skin if it has one.

A reader of our own (numpy over the JSON and binary buffers, :mod:`.buffers`) so that
it can also read the skin (:mod:`.skin`). This module picks the mesh to load and
assembles its triangles; see :func:`read_gltf`.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from hairport.solver.io.character.gltf.buffers import GltfReader, read_gltf_container, refuse_external_uris
from hairport.solver.io.character.gltf.skin import read_gltf_skin
from hairport.solver.io.character.mesh_file import (
    DEFAULT_MAX_FACES,
    DEFAULT_MAX_VERTICES,
    MALFORMED,
    MeshFile,
    check_counts,
)
from hairport.solver.io.external import ALLOW_EXTERNAL_FILES
from hairport.solver.model.errors import InputError

#: primitive mode of a triangle list (the only one read)
TRIANGLES_MODE = 4

#: glTF's length unit, by its specification
GLTF_UNITS = "m"


def read_gltf(
    path: str | os.PathLike,
    *,
    max_vertices: int = DEFAULT_MAX_VERTICES,
    max_faces: int = DEFAULT_MAX_FACES,
    mesh_name: str | None = None,
    allow_external_files: bool = ALLOW_EXTERNAL_FILES,
) -> MeshFile:
    """Read one mesh, and its skin if any, from a ``.glb`` or ``.gltf`` file.

    Mesh selection: the node or mesh named ``mesh_name`` if given; otherwise the skinned
    mesh nodes if there are any, else all mesh nodes (else the meshes themselves), and of
    those the one with the most vertices. A tie for the most vertices is an error naming
    the candidates. The primitives of the mesh (triangles only) are concatenated in order.
    An unskinned mesh is placed by its node's world transform; a skinned mesh is taken as
    stored (the glTF specification ignores a skinned mesh node's transform).

    Skeleton and weights: see :mod:`.skin`.

    Parameters
    ----------
    path : path
    max_vertices, max_faces : int
    mesh_name : str, optional
    allow_external_files : bool
        Read buffers from files beside the document; else any ``uri`` that is not a ``data:``
        URI (a buffer's, an image's) refuses the file, ``external_reference``, before anything
        else is read (:func:`~.buffers.refuse_external_uris`).

    Returns
    -------
    mesh : MeshFile
        In file units (glTF: meters).
    """
    path = Path(path)
    try:
        return _read_gltf(path, max_vertices, max_faces, mesh_name, allow_external_files)
    except InputError:
        raise
    except MALFORMED as error:
        raise InputError(f"malformed glTF: {type(error).__name__}: {error}", str(path), "bad_mesh") from None


def _read_gltf(path: Path, max_vertices: int, max_faces: int, mesh_name: str | None,
               allow_external_files: bool) -> MeshFile:
    source = str(path)
    document, reader, (node_index, mesh_index, skin_index, label) = open_gltf(path, mesh_name, allow_external_files)
    mesh = document["meshes"][mesh_index]
    primitives = mesh.get("primitives", [])
    counts = [reader.count(p.get("attributes", {}).get("POSITION"), "POSITION") for p in primitives]
    face_counts = [
        reader.count(p["indices"], "indices") // 3 if "indices" in p else counts[i] // 3
        for i, p in enumerate(primitives)
    ]
    check_counts(sum(counts), sum(face_counts), source, max_vertices, max_faces)
    vertices_parts, faces_parts = [], []
    offset = 0
    for i, primitive in enumerate(primitives):
        mode = primitive.get("mode", TRIANGLES_MODE)
        if mode != TRIANGLES_MODE:
            raise InputError(
                f"mesh {label!r} primitive {i} has mode {mode}; only triangles (4) can be read",
                source,
                "bad_faces",
            )
        positions = reader.accessor(primitive["attributes"]["POSITION"]).astype(np.float64).reshape(-1, 3)
        if "indices" in primitive:
            index = reader.accessor(primitive["indices"]).astype(np.int64).ravel()
        else:
            index = np.arange(len(positions), dtype=np.int64)
        if len(index) % 3:
            raise InputError(
                f"mesh {label!r} primitive {i} has {len(index)} indices, not a multiple of 3", source, "bad_faces"
            )
        if len(index) and (index.min() < 0 or index.max() >= len(positions)):
            raise InputError(f"mesh {label!r} primitive {i} has an index out of range", source, "bad_faces")
        vertices_parts.append(positions)
        faces_parts.append(index.reshape(-1, 3) + offset)
        offset += len(positions)
    if not vertices_parts:
        raise InputError(f"mesh {label!r} has no primitives", source, "empty_mesh")
    vertices = np.concatenate(vertices_parts)
    faces = np.concatenate(faces_parts)
    world = reader.world_matrices()
    skin = None
    if skin_index is None:
        if node_index is not None:
            matrix = world[node_index]
            vertices = vertices @ matrix[:3, :3].T + matrix[:3, 3]
            if np.linalg.det(matrix[:3, :3]) < 0:
                faces = faces[:, [0, 2, 1]]
    else:
        skin = read_gltf_skin(reader, skin_index, primitives, counts, vertices, world, source)
    return MeshFile(vertices, faces, skin, label, GLTF_UNITS)


def open_gltf(path: Path, mesh_name: str | None, allow_external_files: bool) -> tuple[dict, GltfReader, tuple]:
    """The document, its reader and the mesh to load (:func:`select_gltf_mesh`); a document naming files beside it is
    refused unless ``allow_external_files``."""
    document, binary = read_gltf_container(path)
    if not allow_external_files:
        refuse_external_uris(document, str(path))
    reader = GltfReader(document, binary, path, allow_external_files)
    return document, reader, select_gltf_mesh(document, mesh_name, reader, str(path))


def select_gltf_mesh(document: dict, mesh_name: str | None, reader: GltfReader, source: str):
    """(node index or None, mesh index, skin index or None, label) of the mesh to load."""
    nodes = document.get("nodes", [])
    meshes = document.get("meshes", [])
    if not isinstance(meshes, list) or not meshes:
        raise InputError("glTF file has no mesh", source, "empty_mesh")
    candidates = []  # (node, mesh, skin, label)
    for i, node in enumerate(nodes):
        if isinstance(node, dict) and "mesh" in node:
            reader.item("meshes", node["mesh"])
            skin = node.get("skin")
            if skin is not None:
                reader.item("skins", skin)
            mesh_label = meshes[node["mesh"]].get("name")
            candidates.append((i, node["mesh"], skin, node.get("name") or mesh_label or f"node {i}", mesh_label))
    if not candidates:
        candidates = [(None, m, None, mesh.get("name") or f"mesh {m}", mesh.get("name")) for m, mesh in enumerate(meshes)]
    if mesh_name is not None:
        chosen = [c for c in candidates if mesh_name in (c[3], c[4])]
        if not chosen:
            names = ", ".join(repr(c[3]) for c in candidates)
            raise InputError(f"no mesh named {mesh_name!r}; the file has {names}", source, "bad_mesh")
        candidates = chosen[:1]
    skinned = [c for c in candidates if c[2] is not None]
    pool = skinned or candidates

    def vertex_count(candidate) -> int:
        return sum(
            reader.count(p.get("attributes", {}).get("POSITION"), "POSITION")
            for p in meshes[candidate[1]].get("primitives", [])
        )

    sizes = [vertex_count(c) for c in pool]
    largest = max(sizes)
    best = [c for c, n in zip(pool, sizes) if n == largest]
    # nodes that instance one skinned mesh with one skin load the same data; unskinned
    # nodes differ by their transforms
    if len({(c[1], c[2]) if c[2] is not None else (c[0],) for c in best}) > 1:
        kind = "skinned meshes" if skinned else "meshes"
        names = ", ".join(repr(c[3]) for c in best)
        raise InputError(
            f"ambiguous: {kind} {names} have {largest} vertices each; choose one with mesh_name",
            source,
            "ambiguous_mesh",
        )
    node, mesh, skin, label, _ = best[0]
    return node, mesh, skin, label


def _read(path: Path, *, max_vertices: int, max_faces: int, mesh_name: str | None,
          allow_external_files: bool = ALLOW_EXTERNAL_FILES) -> MeshFile:
    """:func:`read_gltf` behind the reader interface of the format registry."""
    return read_gltf(path, max_vertices=max_vertices, max_faces=max_faces, mesh_name=mesh_name,
                     allow_external_files=allow_external_files)


#: the readers of this module, by file extension
READERS = {".glb": _read, ".gltf": _read}
