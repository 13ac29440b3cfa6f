"""Writing a character: the mesh as OBJ and the skeleton with its skin weights as a sidecar.

:func:`write_character` writes what :func:`~hairport.solver.io.character.load_character`
reads back vertex for vertex, through the format modules' writers
(:func:`~hairport.solver.io.character.obj.write_obj`,
:func:`~hairport.solver.io.character.skeleton_json.write_skeleton_json`).
"""

from __future__ import annotations

import os

import scipy.sparse as sp

from hairport.solver.io.character.obj import write_obj
from hairport.solver.io.character.skeleton_json import write_skeleton_json
from hairport.solver.model.character import Character
from hairport.solver.model.errors import InputError


def write_character(character: Character, mesh_path: str | os.PathLike, skeleton_path: str | os.PathLike) -> None:
    """Write the mesh as OBJ (meters) and the skeleton + skin weights as a JSON sidecar.

    The OBJ has a comment line, ``v x y z`` lines in vertex order and 1-based ``f i j k``
    triangles, nothing else. The sidecar is in meters with 0-based vertex indices
    (:mod:`~hairport.solver.io.character.skeleton_json`); every bone has a ``weights``
    entry, an empty one for every bone when the character has no skin weights. Both files
    are written atomically, the mesh first.

    Parameters
    ----------
    character : Character
        Must have a skeleton.
    mesh_path, skeleton_path : path

    Raises
    ------
    InputError
        ``bad_skeleton`` when the character has no skeleton (nothing is written).
    """
    skeleton = character.skeleton
    if skeleton is None:
        raise InputError("character has no skeleton", character.name, "bad_skeleton")
    weights = character.weights
    if weights is None:
        weights = sp.csr_matrix((character.n_vertices, skeleton.n_bones))
    comment = f"{character.name}: {character.n_vertices} vertices, {character.n_faces} triangles, meters, Y up"
    write_obj(mesh_path, character.vertices, character.faces, comment)
    write_skeleton_json(skeleton_path, skeleton, weights, units="m")
