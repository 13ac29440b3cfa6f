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

from hairport.solver.model.lazy import lazy_exports

#: the package's names, by the module that defines each, imported on first use: the child process that reads a USD
#: or Alembic character (:mod:`hairport.solver.io.sandbox`) imports its reader, not the loader and the skinning
PUBLIC_NAMES = {
    "export": ("write_character",),
    "load": ("MESH_EXTENSIONS", "load_character"),
    "skeleton_json": ("load_skeleton_json", "resolve_skeleton_path", "write_skeleton_json"),
}

__all__, __getattr__, __dir__ = lazy_exports(__name__, PUBLIC_NAMES)
