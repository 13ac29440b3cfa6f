"""Loading a character: the registry of mesh formats, :func:`read_character` (with the units
the files state) and :func:`load_character` (in meters).

Each format module exports ``READERS = {extension: reader}``, a reader being
``reader(path, *, max_vertices, max_faces, mesh_name, allow_external_files) -> MeshFile`` (in the style of
trimesh's ``exchange/``); :data:`MESH_READERS` merges them and :data:`MESH_EXTENSIONS` is
its keys. A character's skeleton comes, in order of precedence, from the ``skeleton_path``
given to :func:`load_character`, the sidecar ``<mesh>.skeleton.json`` beside the mesh
(:func:`~hairport.solver.io.character.skeleton_json.resolve_skeleton_path`), the glTF skin or
UsdSkel binding of the selected mesh, else nowhere.

Other files: unless ``allow_external_files`` (the command line's own files), a mesh file that names
another file (a glTF buffer or image that is not a ``data:`` URI, a USD sublayer, reference or asset
path) is refused with code ``external_reference`` before anything it names is opened
(:mod:`hairport.solver.io.external`). The skeleton sidecar beside the mesh is found by the mesh's
own name, never by a name inside a file.
"""

from __future__ import annotations

import os
from pathlib import Path

from hairport.solver.body.skinning import DEFAULT_WEIGHT_SMOOTHING, derive_skin_weights
from hairport.solver.io.character.alembic import READERS as ALEMBIC_READERS
from hairport.solver.io.character.gltf import READERS as GLTF_READERS
from hairport.solver.io.character.mesh_file import (
    DEFAULT_MAX_FACES,
    DEFAULT_MAX_FILE_BYTES,
    DEFAULT_MAX_VERTICES,
    check_file,
    check_mesh_arrays,
)
from hairport.solver.io.character.obj import READERS as OBJ_READERS
from hairport.solver.io.character.ply import READERS as PLY_READERS
from hairport.solver.io.character.skeleton_json import read_skeleton_json, resolve_skeleton_path
from hairport.solver.io.character.usd import READERS as USD_READERS
from hairport.solver.io.external import ALLOW_EXTERNAL_FILES
from hairport.solver.model.character import Character
from hairport.solver.model.errors import PARSER_FAILURES, InputError, parser_failure
from hairport.solver.model.units import unit_scale

#: the reader of every mesh format :func:`load_character` reads, by lower-case file extension
MESH_READERS = {**OBJ_READERS, **PLY_READERS, **GLTF_READERS, **USD_READERS, **ALEMBIC_READERS}
#: the mesh formats :func:`load_character` reads
MESH_EXTENSIONS = tuple(MESH_READERS)


def load_character(
    mesh_path: str | os.PathLike,
    *,
    skeleton_path: str | os.PathLike | None = None,
    units: str | None = None,
    max_vertices: int = DEFAULT_MAX_VERTICES,
    max_faces: int = DEFAULT_MAX_FACES,
    max_bytes: int = DEFAULT_MAX_FILE_BYTES,
    mesh_name: str | None = None,
    weight_smoothing: int = DEFAULT_WEIGHT_SMOOTHING,
    allow_external_files: bool = ALLOW_EXTERNAL_FILES,
) -> Character:
    """Read a character in meters: :func:`read_character` with a mesh of unstated units read as meters.

    Parameters are those of :func:`read_character`.

    Returns
    -------
    character : Character
    """
    character, stated = read_character(mesh_path, skeleton_path=skeleton_path, units=units, max_vertices=max_vertices,
                                       max_faces=max_faces, max_bytes=max_bytes, mesh_name=mesh_name,
                                       weight_smoothing=weight_smoothing, allow_external_files=allow_external_files)
    if stated is None and character.skeleton is not None and character.weights is None:
        weights = derive_skin_weights(character.vertices, character.faces, character.skeleton,
                                      smoothing=weight_smoothing)
        character = Character(character.vertices, character.faces, character.skeleton, weights, character.name)
    return character


def read_character(
    mesh_path: str | os.PathLike,
    *,
    skeleton_path: str | os.PathLike | None = None,
    units: str | None = None,
    max_vertices: int = DEFAULT_MAX_VERTICES,
    max_faces: int = DEFAULT_MAX_FACES,
    max_bytes: int = DEFAULT_MAX_FILE_BYTES,
    mesh_name: str | None = None,
    weight_smoothing: int = DEFAULT_WEIGHT_SMOOTHING,
    allow_external_files: bool = ALLOW_EXTERNAL_FILES,
) -> tuple[Character, str | None]:
    """Read a character: mesh, and skeleton with skin weights where available, and its units.

    Parameters
    ----------
    mesh_path : path
        ``.obj``, ``.ply``, ``.glb``, ``.gltf``, ``.usd``, ``.usda`` or ``.usdc``.
    skeleton_path : path, optional
        Skeleton JSON sidecar. Default: ``<mesh without extension>.skeleton.json`` if it
        exists, else the glTF skin, else no skeleton.
    units : {"m", "dm", "cm", "mm"}, optional
        Units of the mesh file. Default: the sidecar's ``units`` when a sidecar is used,
        else the unit the file states (meters for glTF by specification, a USD stage's
        ``metersPerUnit``), else unknown. The sidecar's own
        coordinates always use its ``units`` key.
    max_vertices, max_faces : int
        Limits checked before the arrays are built; ``max_faces`` counts triangles.
    max_bytes : int
        Largest file accepted.
    mesh_name : str, optional
        glTF only: the node or mesh name to load when the file holds several meshes.
    weight_smoothing : int
        Laplacian smoothing steps for weights derived from the geometry (sidecar without
        ``weights``); 0 keeps hard nearest-visible-bone weights.
    allow_external_files : bool
        Read what the mesh file names (glTF buffer files beside it, USD sublayers and
        references), as the command line does with the user's own files. False (the default,
        for uploads): such a file is refused (``external_reference``).

    Returns
    -------
    character : Character
        In meters when ``units`` is known, else in the file's own coordinates; named after
        the file.
    units : str or None
        The mesh's units: ``units`` when given, else the sidecar's ``units``, else the unit the
        file states (glTF, USD), else None (nothing states them: the character is in
        the file's coordinates, for :func:`hairport.solver.inputs.canonical_source` to infer,
        and skin weights a sidecar lacks are derived there, in meters).

    Raises
    ------
    InputError
        Missing or unreadable file, unknown extension, empty mesh, non-finite
        coordinates, faces that cannot be triangulated, counts above the limits, a file
        naming another one (``external_reference``), bad skeleton (see
        :func:`~hairport.solver.io.character.skeleton_json.load_skeleton_json`).
    """
    units = None if units == "auto" else units
    path = Path(mesh_path)
    source = str(path)
    check_file(path, max_bytes)
    reader = MESH_READERS.get(path.suffix.lower())
    if reader is None:
        raise InputError(
            f"unknown mesh format {path.suffix!r}; expected one of {', '.join(MESH_EXTENSIONS)}",
            source,
            "unknown_format",
        )
    try:
        mesh = reader(path, max_vertices=max_vertices, max_faces=max_faces, mesh_name=mesh_name,
                      allow_external_files=allow_external_files)
    except PARSER_FAILURES as error:
        raise parser_failure(error, source) from None
    vertices, faces, skin = mesh.vertices, mesh.faces, mesh.skin
    check_mesh_arrays(vertices, faces, source, max_vertices, max_faces)

    sidecar = Path(skeleton_path) if skeleton_path is not None else resolve_skeleton_path(path)
    skeleton, weights = None, None
    if sidecar is not None:
        skeleton, weights, sidecar_units = read_skeleton_json(sidecar, len(vertices), max_bytes)
        mesh_units = units if units is not None else sidecar_units
    else:
        mesh_units = units if units is not None else mesh.units
    scale = unit_scale(mesh_units or "m")
    vertices = vertices * scale
    if sidecar is None and skin is not None:
        skeleton = skin.skeleton.scaled(scale)
        weights = skin.weights
    if skeleton is not None and weights is None and mesh_units is not None:
        # derived in meters: with unknown units the weights wait for the units (canonical_source)
        weights = derive_skin_weights(vertices, faces, skeleton, smoothing=weight_smoothing)
    return Character(vertices, faces, skeleton, weights, name=path.name), mesh_units

