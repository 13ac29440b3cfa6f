"""Character files: a body mesh (OBJ / PLY / glTF / GLB) with a skeleton and skin weights.

Convention: everything returned is in meters, ``vertices (V, 3) float64``, ``faces (F, 3)
int64``. Vertex order and count are exactly those of the file: "same topology" between a
source and a target character is a vertex-for-vertex, face-for-face comparison, so no
reader here merges, splits or reorders vertices.

Modules
-------
- :mod:`.load`: :func:`load_character` and the registry of mesh formats;
- one module per format, each exporting ``READERS = {extension: reader}``: :mod:`.obj`
  (our own reader, and the writer), :mod:`.ply` (through trimesh), :mod:`.usd` (through
  usd-core, in the sandbox's child; the stage opened by :mod:`hairport.solver.io.usd`), and the
  package :mod:`.gltf` (our own reader, skin included: :mod:`.gltf.buffers`, :mod:`.gltf.skin`);
  a format needing several modules is a package whose ``__init__`` exports ``READERS``;
- :mod:`.bones`: the bones of a skin's joints (tails, unique names), as the glTF and USD
  readers make them;
- :mod:`.skeleton_json`: the skeleton sidecar ``<mesh>.skeleton.json`` (read, write, find);
- :mod:`.mesh_file`: the limits and checks every reader shares;
- :mod:`.export`: :func:`write_character` (OBJ + sidecar).

Skin weights derived from the geometry (a sidecar without ``weights``) are body knowledge:
:mod:`hairport.solver.body.skinning`.
"""

from hairport.solver.io.character.export import write_character
from hairport.solver.io.character.load import MESH_EXTENSIONS, load_character
from hairport.solver.io.character.skeleton_json import load_skeleton_json, resolve_skeleton_path, write_skeleton_json

__all__ = [
    "MESH_EXTENSIONS",
    "load_character",
    "load_skeleton_json",
    "resolve_skeleton_path",
    "write_character",
    "write_skeleton_json",
]
