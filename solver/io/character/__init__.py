"""Loading characters: a body mesh (OBJ / PLY / glTF / GLB) with a skeleton and skin weights.

Convention: everything returned is in meters, ``vertices (V, 3) float64``, ``faces (F, 3)
int64``. Vertex order and count are exactly those of the file: "same topology" between a
source and a target character is a vertex-for-vertex, face-for-face comparison, so no
reader here merges, splits or reorders vertices.

Readers
-------
- **OBJ**: a reader of our own for ``v`` and ``f`` lines (``trimesh.load(..., process=False)``
  still splits vertices by ``vt``/``vn`` index, which breaks the vertex order). Indices may be
  ``v``, ``v/vt``, ``v//vn``, ``v/vt/vn``, and negative (relative). Polygons are triangulated
  by a fan from their first corner, in file order: polygon ``(a, b, c, d)`` becomes
  ``(a, b, c), (a, c, d)``. The split never depends on positions, so two files of one
  topology always triangulate alike. All groups/objects are kept, in file order.
- **PLY**: trimesh (``process=False, fix_texture=False``: with ``fix_texture=True`` trimesh
  splits vertices that carry per-face texture coordinates). trimesh triangulates polygons
  itself (quads become ``(a, b, c), (c, d, a)``; with mixed polygon sizes it groups the
  triangles by size); this is deterministic per file, but an OBJ and a PLY of the same
  quad mesh do not get identical face lists.
- **glTF / GLB**: a reader of our own (numpy over the JSON + binary buffers) so that it can
  also read the skin. See :func:`read_gltf`.

Skeleton sources, in order of precedence: ``skeleton_path`` given to :func:`load_character`,
the sidecar ``<mesh>.skeleton.json`` beside the mesh (:func:`resolve_skeleton_path`), the
glTF skin of the selected mesh, else none.

Sidecar schema (``*.skeleton.json``)::

    {"units": "m",                               # m | dm | cm | mm; optional, default "m"
     "bones": [{"name": str, "parent": str | null, "head": [x, y, z], "tail": [x, y, z]}, ...],
     "weights": {bone_name: [[vertex_index, weight], ...], ...}}   # optional

Bones may be listed in any order; unknown keys are ignored. Weights are summed over
duplicate ``(vertex, bone)`` entries, and every vertex row with a positive sum is
normalised to sum 1; vertices without any weight keep an all-zero row (they lie in no
bone's valid region). When ``weights`` is absent they are derived from the geometry
(:func:`derive_skin_weights`).
"""

from __future__ import annotations

import base64
import json
import os
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from hairport.solver.mesh.polyline import closest_points_on_segments
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.character import Character, Skeleton
from hairport.solver.model.errors import InputError
from hairport.solver.model.units import unit_scale

#: largest vertex count accepted by default
DEFAULT_MAX_VERTICES = 2_000_000
#: largest triangle count (after triangulation) accepted by default
DEFAULT_MAX_FACES = 4_000_000
#: largest mesh or skeleton file accepted (bytes)
DEFAULT_MAX_FILE_BYTES = 1 << 30
#: largest bone count accepted in a skeleton
MAX_BONES = 4096
#: the mesh formats :func:`load_character` reads
MESH_EXTENSIONS = (".obj", ".ply", ".glb", ".gltf")
#: suffix of the skeleton sidecar that replaces the mesh file's extension
SKELETON_SUFFIX = ".skeleton.json"

#: derived weights: how many nearest bones per vertex are tested for visibility
VISIBILITY_CANDIDATES = 4
#: derived weights: a bone sees a vertex if the ray from the bone hits the mesh no earlier
#: than ``distance - (VISIBILITY_TOLERANCE + VISIBILITY_RELATIVE_TOLERANCE * distance)`` (m, -)
VISIBILITY_TOLERANCE = 1e-5
VISIBILITY_RELATIVE_TOLERANCE = 1e-3
#: derived weights: default number of uniform-Laplacian smoothing steps, and the step size
DEFAULT_WEIGHT_SMOOTHING = 2
WEIGHT_SMOOTHING_STEP = 0.5
#: derived weights below this are dropped after smoothing (then rows are renormalised)
MIN_DERIVED_WEIGHT = 1e-3
#: (vertex, bone) pairs evaluated at once when deriving weights (bounds memory, ~100 MB)
DERIVE_CHUNK_PAIRS = 1 << 22

#: glTF leaf bone: tail = head + LEAF_TAIL_FRACTION * (head - parent head)
LEAF_TAIL_FRACTION = 0.5
#: glTF bone with neither parent nor child joints: length as a fraction of the mesh's
#: bounding-box diagonal, along the joint's local +Y axis (the glTF/Blender bone axis)
ISOLATED_BONE_FRACTION = 0.05
#: a tail closer to its head than this fraction of the bounding-box diagonal counts as none
MIN_BONE_LENGTH_FRACTION = 1e-6

_GLB_MAGIC = 0x46546C67  # b"glTF"
_GLB_JSON = 0x4E4F534A
_GLB_BIN = 0x004E4942
_GLTF_DTYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_GLTF_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_GLTF_TRIANGLES = 4
#: what a malformed document can raise inside a reader; turned into InputError
_MALFORMED = (KeyError, TypeError, AttributeError, IndexError, ValueError, OverflowError, np.linalg.LinAlgError)


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
) -> Character:
    """Read a character: mesh, and skeleton with skin weights where available.

    Parameters
    ----------
    mesh_path : path
        ``.obj``, ``.ply``, ``.glb`` or ``.gltf``.
    skeleton_path : path, optional
        Skeleton JSON sidecar. Default: ``<mesh without extension>.skeleton.json`` if it
        exists, else the glTF skin, else no skeleton.
    units : {"m", "dm", "cm", "mm"}, optional
        Units of the mesh file. Default: the sidecar's ``units`` when a sidecar is used,
        else meters (glTF is meters by specification). The sidecar's own coordinates
        always use its ``units`` key.
    max_vertices, max_faces : int
        Limits checked before the arrays are built; ``max_faces`` counts triangles.
    max_bytes : int
        Largest file accepted.
    mesh_name : str, optional
        glTF only: the node or mesh name to load when the file holds several meshes.
    weight_smoothing : int
        Laplacian smoothing steps for weights derived from the geometry (sidecar without
        ``weights``); 0 keeps hard nearest-visible-bone weights.

    Returns
    -------
    character : Character
        In meters, named after the file.

    Raises
    ------
    InputError
        Missing or unreadable file, unknown extension, empty mesh, non-finite
        coordinates, faces that cannot be triangulated, counts above the limits, bad
        skeleton (see :func:`load_skeleton_json`).
    """
    path = Path(mesh_path)
    source = str(path)
    _check_file(path, max_bytes)
    ext = path.suffix.lower()
    skin = None
    if ext == ".obj":
        vertices, faces = read_obj(path, max_vertices=max_vertices, max_faces=max_faces)
    elif ext == ".ply":
        vertices, faces = read_ply(path, max_vertices=max_vertices, max_faces=max_faces)
    elif ext in (".glb", ".gltf"):
        gltf = read_gltf(path, max_vertices=max_vertices, max_faces=max_faces, mesh_name=mesh_name)
        vertices, faces, skin = gltf.vertices, gltf.faces, gltf.skin
    else:
        raise InputError(
            f"unknown mesh format {path.suffix!r}; expected one of {', '.join(MESH_EXTENSIONS)}",
            source,
            "unknown_format",
        )
    _check_mesh_arrays(vertices, faces, source, max_vertices, max_faces)

    sidecar = Path(skeleton_path) if skeleton_path is not None else resolve_skeleton_path(path)
    skeleton, weights = None, None
    if sidecar is not None:
        skeleton, weights, sidecar_units = _load_skeleton_json(sidecar, len(vertices), max_bytes)
        mesh_units = units if units is not None else sidecar_units
    else:
        mesh_units = units if units is not None else "m"
    scale = unit_scale(mesh_units)
    vertices = vertices * scale
    if sidecar is None and skin is not None:
        skeleton = skin.skeleton.scaled(scale)
        weights = skin.weights
    if skeleton is not None and weights is None:
        weights = derive_skin_weights(vertices, faces, skeleton, smoothing=weight_smoothing)
    return Character(vertices, faces, skeleton, weights, name=path.name)


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
        ``weights`` key (derive them with :func:`derive_skin_weights`).

    Raises
    ------
    InputError
        Unreadable JSON, wrong types, unknown parent, duplicate bone, parent cycle,
        non-finite joint, weights for an unknown bone, vertex index out of range,
        negative or non-finite weight.
    """
    skeleton, weights, _ = _load_skeleton_json(Path(path), n_vertices, max_bytes)
    return skeleton, weights


def _load_skeleton_json(
    path: Path, n_vertices: int, max_bytes: int
) -> tuple[Skeleton, sp.csr_matrix | None, str]:
    try:
        return _parse_skeleton_json(path, n_vertices, max_bytes)
    except InputError:
        raise
    except _MALFORMED as error:
        raise InputError(f"malformed skeleton JSON: {type(error).__name__}: {error}", str(path), "bad_skeleton") from None


def write_skeleton_json(
    path: str | os.PathLike, skeleton: Skeleton, weights: sp.spmatrix | None, units: str = "m"
) -> None:
    """Write a skeleton sidecar atomically (temporary file + ``os.replace``).

    Parameters
    ----------
    path : path
    skeleton : Skeleton
        In meters.
    weights : (V, B) sparse matrix or None
        Only non-zero entries are written; ``None`` omits the ``weights`` key.
    units : {"m", "dm", "cm", "mm"}
        Units of the coordinates in the file.
    """
    path = Path(path)
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
        csc = sp.csc_matrix(weights, dtype=np.float64)
        if csc.shape[1] != skeleton.n_bones:
            raise InputError(
                f"weights have {csc.shape[1]} columns for {skeleton.n_bones} bones", str(path), "bad_weights"
            )
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
    text = json.dumps(document, allow_nan=False, separators=(",", ":"))
    _atomic_write_text(path, text)


def derive_skin_weights(
    vertices: np.ndarray,
    faces: np.ndarray,
    skeleton: Skeleton,
    *,
    smoothing: int = DEFAULT_WEIGHT_SMOOTHING,
    query: MeshQuery | None = None,
) -> sp.csr_matrix:
    """Skin weights from the geometry: nearest visible bone, then Laplacian smoothing.

    Each vertex first gets weight 1 for the nearest bone segment that "sees" it: among its
    :data:`VISIBILITY_CANDIDATES` nearest bones, the nearest one whose ray from the closest
    point on the segment towards the vertex meets the mesh no earlier than the vertex itself
    (up to :data:`VISIBILITY_TOLERANCE`); if none does, the nearest bone. This keeps, e.g.,
    a vertex of the upper arm from going to a spine bone that is nearer through the armpit.
    Then ``smoothing`` steps ``W <- (1 - s) W + s D^-1 A W`` with the uniform graph
    Laplacian of the mesh edges (``A`` adjacency, ``D`` degrees, ``s`` =
    :data:`WEIGHT_SMOOTHING_STEP`) blend the weights across bone borders; weights below
    :data:`MIN_DERIVED_WEIGHT` are then dropped and every row renormalised to sum 1.

    Parameters
    ----------
    vertices : (V, 3) float64
        Meters.
    faces : (F, 3) int64
    skeleton : Skeleton
    smoothing : int
        Number of smoothing steps (0: hard weights).
    query : MeshQuery, optional
        A prebuilt query structure over the same mesh.

    Returns
    -------
    weights : (V, B) scipy.sparse.csr_matrix
        Non-negative, rows sum to 1.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    n_vertices, n_bones = len(vertices), skeleton.n_bones
    if n_bones == 0:
        return sp.csr_matrix((n_vertices, 0))
    query = query or MeshQuery(vertices, faces)
    n_candidates = min(VISIBILITY_CANDIDATES, n_bones)
    chunk = max(1, DERIVE_CHUNK_PAIRS // n_bones)
    bone = np.empty(n_vertices, dtype=np.int64)
    for start in range(0, n_vertices, chunk):
        points = vertices[start : start + chunk]
        _, closest = closest_points_on_segments(points, skeleton.heads, skeleton.tails)
        offset = points[:, None, :] - closest
        distance = np.linalg.norm(offset, axis=2)
        order = np.argsort(distance, axis=1, kind="stable")[:, :n_candidates]
        rows = np.arange(len(points))[:, None]
        cand_distance = distance[rows, order]
        cand_origin = closest[rows, order]
        cand_offset = offset[rows, order]
        visible = cand_distance <= VISIBILITY_TOLERANCE
        cast = ~visible
        if cast.any():
            hits = query.first_hits(cand_origin[cast], cand_offset[cast])
            allowed = cand_distance[cast] * (1.0 - VISIBILITY_RELATIVE_TOLERANCE) - VISIBILITY_TOLERANCE
            visible[cast] = ~hits.hit | (hits.distance >= allowed)
        first_visible = np.argmax(visible, axis=1)
        first_visible[~visible.any(axis=1)] = 0
        bone[start : start + chunk] = order[np.arange(len(points)), first_visible]
    weights = sp.csr_matrix(
        (np.ones(n_vertices), (np.arange(n_vertices), bone)), shape=(n_vertices, n_bones)
    )
    if smoothing > 0:
        weights = _smooth_weights(weights, faces, smoothing)
    return weights


def _smooth_weights(weights: sp.csr_matrix, faces: np.ndarray, steps: int) -> sp.csr_matrix:
    """``steps`` uniform-Laplacian smoothing steps, pruning and row renormalisation."""
    n_vertices = weights.shape[0]
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    edges = np.concatenate([edges, edges[:, ::-1]])
    adjacency = sp.csr_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n_vertices, n_vertices))
    adjacency.data[:] = 1.0  # duplicate edges count once
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    isolated = degree == 0
    inv_degree = np.where(isolated, 0.0, 1.0 / np.where(isolated, 1.0, degree))
    average = sp.diags(inv_degree) @ adjacency + sp.diags(isolated.astype(np.float64))
    step = sp.csr_matrix(
        (1.0 - WEIGHT_SMOOTHING_STEP) * sp.identity(n_vertices) + WEIGHT_SMOOTHING_STEP * average
    )
    for _ in range(steps):
        weights = step @ weights
    weights = sp.csr_matrix(weights)
    weights.data[weights.data < MIN_DERIVED_WEIGHT] = 0.0
    weights.eliminate_zeros()
    return _normalise_rows(weights)


def _normalise_rows(weights: sp.csr_matrix) -> sp.csr_matrix:
    """Divide every row with a positive sum by its sum; all-zero rows stay zero."""
    weights = sp.csr_matrix(weights, dtype=np.float64)
    weights.sum_duplicates()
    weights.eliminate_zeros()
    sums = np.asarray(weights.sum(axis=1)).ravel()
    scale = np.where(sums > 0, 1.0 / np.where(sums > 0, sums, 1.0), 0.0)
    return sp.csr_matrix(sp.diags(scale) @ weights)


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
    n_v = sum(1 for _ in _OBJ_VERTEX_BYTES.finditer(raw))
    n_f = sum(1 for _ in _OBJ_FACE_BYTES.finditer(raw))
    _check_counts(n_v, n_f, source, max_vertices, max_faces)
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
    except ValueError:
        raise InputError("a face has a corner that is not an integer vertex index", source, "bad_faces") from None
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
    import trimesh

    path = Path(path)
    source = str(path)
    n_v, n_f = _ply_header_counts(path)
    _check_counts(n_v, n_f, source, max_vertices, max_faces)
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


@dataclass(frozen=True)
class GltfSkin:
    """A skeleton and skin weights read from a glTF skin (in file units).

    Attributes
    ----------
    skeleton : Skeleton
        Bone ``b`` is joint ``b`` of the skin.
    weights : (V, B) scipy.sparse.csr_matrix
        From ``JOINTS_n`` / ``WEIGHTS_n``; rows with a positive sum normalised to 1.
    """

    skeleton: Skeleton
    weights: sp.csr_matrix


@dataclass(frozen=True)
class GltfMesh:
    """The mesh (and skin) selected from a glTF file.

    Attributes
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    skin : GltfSkin or None
    name : str
        Name of the selected node (or mesh).
    """

    vertices: np.ndarray
    faces: np.ndarray
    skin: GltfSkin | None
    name: str


def read_gltf(
    path: str | os.PathLike,
    *,
    max_vertices: int = DEFAULT_MAX_VERTICES,
    max_faces: int = DEFAULT_MAX_FACES,
    mesh_name: str | None = None,
) -> GltfMesh:
    """Read one mesh, and its skin if any, from a ``.glb`` or ``.gltf`` file.

    Mesh selection: the node or mesh named ``mesh_name`` if given; otherwise the skinned
    mesh nodes if there are any, else all mesh nodes (else the meshes themselves), and of
    those the one with the most vertices. A tie for the most vertices is an error naming
    the candidates. The primitives of the mesh (triangles only) are concatenated in order.
    An unskinned mesh is placed by its node's world transform; a skinned mesh is taken as
    stored (the glTF specification ignores a skinned mesh node's transform).

    Skeleton: bone ``b`` is joint ``b`` of the skin, named after its node (made unique by a
    ``_<b>`` suffix where names repeat). Its head is the joint's bind-pose position in mesh
    space, the translation of the inverse of its inverse bind matrix (the node hierarchy's
    world transform when the skin has no inverse bind matrices). Its parent is the nearest
    ancestor node that is a joint of the skin. Its tail is the mean head of its child
    joints; a leaf (or a bone whose children meet at its head) extends from its head along
    the direction from its parent's head by :data:`LEAF_TAIL_FRACTION` of that distance; a
    joint with neither parent nor children points along its local +Y axis with a length of
    :data:`ISOLATED_BONE_FRACTION` of the mesh's bounding-box diagonal.

    Parameters
    ----------
    path : path
    max_vertices, max_faces : int
    mesh_name : str, optional

    Returns
    -------
    mesh : GltfMesh
        In file units (glTF: meters).
    """
    path = Path(path)
    try:
        return _read_gltf(path, max_vertices, max_faces, mesh_name)
    except InputError:
        raise
    except _MALFORMED as error:
        raise InputError(f"malformed glTF: {type(error).__name__}: {error}", str(path), "bad_mesh") from None


def _read_gltf(path: Path, max_vertices: int, max_faces: int, mesh_name: str | None) -> GltfMesh:
    source = str(path)
    document, binary = _read_gltf_container(path)
    reader = _GltfReader(document, binary, path)
    node_index, mesh_index, skin_index, label = _select_gltf_mesh(document, mesh_name, reader, source)
    mesh = document["meshes"][mesh_index]
    primitives = mesh.get("primitives", [])
    counts = [reader.count(p.get("attributes", {}).get("POSITION"), "POSITION") for p in primitives]
    face_counts = [
        reader.count(p["indices"], "indices") // 3 if "indices" in p else counts[i] // 3
        for i, p in enumerate(primitives)
    ]
    _check_counts(sum(counts), sum(face_counts), source, max_vertices, max_faces)
    vertices_parts, faces_parts = [], []
    offset = 0
    for i, primitive in enumerate(primitives):
        mode = primitive.get("mode", _GLTF_TRIANGLES)
        if mode != _GLTF_TRIANGLES:
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
        skin = _read_gltf_skin(reader, skin_index, primitives, counts, vertices, world, source)
    return GltfMesh(vertices, faces, skin, label)


def _read_gltf_container(path: Path) -> tuple[dict, bytes | None]:
    """The JSON document and the GLB binary chunk (``None`` for ``.gltf``)."""
    source = str(path)
    data = path.read_bytes()
    binary = None
    if data[:4] == b"glTF":
        if len(data) < 20:
            raise InputError("GLB file is truncated (no chunk header)", source, "truncated")
        magic, version, length = np.frombuffer(data, "<u4", 3)
        if version != 2:
            raise InputError(f"GLB version {version} is not supported (expected 2)", source, "bad_mesh")
        if length > len(data):
            raise InputError(f"GLB header declares {length} bytes, file has {len(data)}", source, "truncated")
        chunks = []
        position = 12
        while position + 8 <= length:
            chunk_length, chunk_type = (int(x) for x in np.frombuffer(data, "<u4", 2, position))
            start, end = position + 8, position + 8 + chunk_length
            if end > length:
                raise InputError("GLB chunk runs past the end of the file", source, "truncated")
            chunks.append((chunk_type, data[start:end]))
            position = end + (-end % 4)
        if not chunks or chunks[0][0] != _GLB_JSON:
            raise InputError("GLB file does not start with a JSON chunk", source, "bad_mesh")
        json_bytes = chunks[0][1]
        binary = next((chunk for kind, chunk in chunks[1:] if kind == _GLB_BIN), None)
    else:
        json_bytes = data
    try:
        document = json.loads(json_bytes.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise InputError(f"glTF JSON is not readable: {error}", source, "bad_mesh") from None
    if not isinstance(document, dict):
        raise InputError("glTF JSON is not an object", source, "bad_mesh")
    return document, binary


class _GltfReader:
    """Accessors, buffers and node transforms of a glTF document, with range checks."""

    def __init__(self, document: dict, binary: bytes | None, path: Path):
        self.document = document
        self.binary = binary
        self.path = path
        self.source = str(path)
        self._buffers: dict[int, bytes] = {}

    def _error(self, problem: str, code: str = "bad_mesh") -> InputError:
        return InputError(problem, self.source, code)

    def _item(self, kind: str, index) -> dict:
        items = self.document.get(kind, [])
        if not isinstance(index, int) or not 0 <= index < len(items) or not isinstance(items[index], dict):
            raise self._error(f"glTF refers to {kind}[{index}], which does not exist")
        return items[index]

    def buffer(self, index: int) -> bytes:
        if index in self._buffers:
            return self._buffers[index]
        buffer = self._item("buffers", index)
        uri = buffer.get("uri")
        if uri is None:
            if self.binary is None:
                raise self._error(f"buffer {index} has no uri and the file has no binary chunk")
            data = self.binary
        elif uri.startswith("data:"):
            try:
                data = base64.b64decode(uri.split(",", 1)[1], validate=False)
            except (IndexError, ValueError):
                raise self._error(f"buffer {index} has a malformed data uri") from None
        else:
            from urllib.parse import unquote

            relative = Path(unquote(uri))
            if relative.is_absolute() or ".." in relative.parts or ":" in uri.split("/", 1)[0]:
                raise self._error(f"buffer {index} uri {uri!r} must be a relative path beside the file")
            target = self.path.parent / relative
            if not target.is_file():
                raise self._error(f"buffer {index} file {uri!r} not found", "not_found")
            data = target.read_bytes()
        declared = buffer.get("byteLength", len(data))
        if not isinstance(declared, int) or declared > len(data):
            raise self._error(f"buffer {index} declares {declared} bytes but holds {len(data)}", "truncated")
        self._buffers[index] = data
        return data

    def count(self, index, what: str) -> int:
        if index is None:
            raise self._error(f"a primitive has no {what} accessor")
        count = self._item("accessors", index).get("count", 0)
        if not isinstance(count, int) or count < 0:
            raise self._error(f"accessor {index} has a bad count {count!r}")
        return count

    def accessor(self, index: int) -> np.ndarray:
        """Accessor ``index`` as a ``(count, width)`` array (normalised integers as float64)."""
        accessor = self._item("accessors", index)
        if "sparse" in accessor:
            raise self._error(f"accessor {index} is sparse; sparse accessors are not supported")
        dtype = _GLTF_DTYPES.get(accessor.get("componentType"))
        width = _GLTF_WIDTHS.get(accessor.get("type"))
        count = self.count(index, "")
        if dtype is None or width is None:
            raise self._error(f"accessor {index} has an unknown component type or type")
        dtype = np.dtype(dtype).newbyteorder("<")
        if "bufferView" not in accessor:
            values = np.zeros((count, width), dtype=dtype)
        else:
            view = self._item("bufferViews", accessor["bufferView"])
            data = self.buffer(view.get("buffer", -1))
            view_offset = view.get("byteOffset", 0)
            view_length = view.get("byteLength", 0)
            offset = view_offset + accessor.get("byteOffset", 0)
            element = dtype.itemsize * width
            stride = view.get("byteStride", element)
            if stride < element or view_offset + view_length > len(data):
                raise self._error(f"accessor {index}: bufferView stride or length is invalid", "truncated")
            end = offset + (count - 1) * stride + element if count else offset
            if offset < view_offset or end > view_offset + view_length:
                raise self._error(f"accessor {index} runs past the end of its bufferView", "truncated")
            if offset % dtype.itemsize or stride % dtype.itemsize:
                raw = np.frombuffer(data, np.uint8, end - offset, offset)
                values = np.lib.stride_tricks.as_strided(raw, (count, element), (stride, 1)).copy()
                values = values.view(dtype).reshape(count, width)
            else:
                values = np.ndarray((count, width), dtype, data, offset, (stride, dtype.itemsize)).copy()
        if accessor.get("normalized") and dtype.kind in "iu":
            values = np.maximum(values / float(np.iinfo(dtype).max), -1.0)
        return values

    def local_matrix(self, node: dict) -> np.ndarray:
        if "matrix" in node:
            matrix = np.asarray(node["matrix"], dtype=np.float64)
            if matrix.shape != (16,):
                raise self._error("a node matrix does not have 16 numbers")
            return matrix.reshape(4, 4).T  # column-major
        translation = np.asarray(node.get("translation", [0, 0, 0]), dtype=np.float64)
        x, y, z, w = np.asarray(node.get("rotation", [0, 0, 0, 1]), dtype=np.float64)
        scale = np.asarray(node.get("scale", [1, 1, 1]), dtype=np.float64)
        norm = np.sqrt(x * x + y * y + z * z + w * w) or 1.0
        x, y, z, w = x / norm, y / norm, z / norm, w / norm
        rotation = np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ]
        )
        matrix = np.eye(4)
        matrix[:3, :3] = rotation * scale[None, :]
        matrix[:3, 3] = translation
        return matrix

    def parents(self) -> np.ndarray:
        nodes = self.document.get("nodes", [])
        parents = np.full(len(nodes), -1, dtype=np.int64)
        for i, node in enumerate(nodes):
            for child in node.get("children", []):
                if not isinstance(child, int) or not 0 <= child < len(nodes) or parents[child] >= 0:
                    raise self._error(f"node {i} has an invalid or shared child {child!r}")
                parents[child] = i
        return parents

    def world_matrices(self) -> np.ndarray:
        """(N, 4, 4) world transform of every node."""
        nodes = self.document.get("nodes", [])
        parents = self.parents()
        local = np.stack([self.local_matrix(n) for n in nodes]) if nodes else np.zeros((0, 4, 4))
        world = local.copy()
        done = parents < 0
        for _ in range(len(nodes)):
            if done.all():
                break
            ready = ~done & done[np.maximum(parents, 0)]
            index = np.flatnonzero(ready)
            world[index] = world[parents[index]] @ local[index]
            done[index] = True
        if not done.all():
            raise self._error("glTF node hierarchy has a cycle")
        return world


def _select_gltf_mesh(document: dict, mesh_name: str | None, reader: _GltfReader, source: str):
    """(node index or None, mesh index, skin index or None, label) of the mesh to load."""
    nodes = document.get("nodes", [])
    meshes = document.get("meshes", [])
    if not isinstance(meshes, list) or not meshes:
        raise InputError("glTF file has no mesh", source, "empty_mesh")
    candidates = []  # (node, mesh, skin, label)
    for i, node in enumerate(nodes):
        if isinstance(node, dict) and "mesh" in node:
            reader._item("meshes", node["mesh"])
            skin = node.get("skin")
            if skin is not None:
                reader._item("skins", skin)
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


def _read_gltf_skin(
    reader: _GltfReader,
    skin_index: int,
    primitives: list,
    counts: list[int],
    vertices: np.ndarray,
    world: np.ndarray,
    source: str,
) -> GltfSkin:
    skin = reader._item("skins", skin_index)
    joints = np.asarray(skin.get("joints", []), dtype=np.int64)
    nodes = reader.document.get("nodes", [])
    n_bones = len(joints)
    if n_bones == 0:
        raise InputError(f"skin {skin_index} has no joints", source, "bad_skeleton")
    if n_bones > MAX_BONES:
        raise InputError(f"skin has {n_bones} joints, more than {MAX_BONES}", source, "too_large")
    if joints.min() < 0 or joints.max() >= len(nodes) or len(np.unique(joints)) != n_bones:
        raise InputError(f"skin {skin_index} has an invalid or repeated joint node", source, "bad_skeleton")
    if "inverseBindMatrices" in skin:
        inverse_bind = reader.accessor(skin["inverseBindMatrices"]).astype(np.float64)
        if inverse_bind.shape != (n_bones, 16):
            raise InputError("inverse bind matrices do not match the joint count", source, "bad_skeleton")
        inverse_bind = inverse_bind.reshape(n_bones, 4, 4).transpose(0, 2, 1)  # column-major
        if not np.isfinite(inverse_bind).all():
            raise InputError("inverse bind matrices are not finite", source, "non_finite")
        try:
            bind = np.linalg.inv(inverse_bind)
        except np.linalg.LinAlgError:
            raise InputError("an inverse bind matrix is singular", source, "bad_skeleton") from None
    else:
        bind = world[joints]
    heads = bind[:, :3, 3]

    # parent bone: nearest ancestor node that is a joint
    node_parents = reader.parents()
    bone_of_node = np.full(len(nodes) + 1, -1, dtype=np.int64)
    bone_of_node[joints] = np.arange(n_bones)
    parents = np.full(n_bones, -1, dtype=np.int64)
    ancestor = node_parents[joints]
    open_ = ancestor >= 0
    for _ in range(len(nodes)):
        if not open_.any():
            break
        found = open_ & (bone_of_node[ancestor] >= 0)
        parents[found] = bone_of_node[ancestor[found]]
        open_ &= ~found
        ancestor = np.where(open_, node_parents[np.maximum(ancestor, 0)], -1)
        open_ &= ancestor >= 0

    diagonal = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0))) or 1.0
    has_parent = parents >= 0
    child_sum = np.zeros((n_bones, 3))
    np.add.at(child_sum, parents[has_parent], heads[has_parent])
    child_count = np.bincount(parents[has_parent], minlength=n_bones)
    tails = child_sum / np.maximum(child_count, 1)[:, None]
    leaf = (child_count == 0) | (np.linalg.norm(tails - heads, axis=1) < MIN_BONE_LENGTH_FRACTION * diagonal)
    from_parent = heads - heads[np.maximum(parents, 0)]
    extend = leaf & has_parent & (np.linalg.norm(from_parent, axis=1) >= MIN_BONE_LENGTH_FRACTION * diagonal)
    tails[extend] = heads[extend] + LEAF_TAIL_FRACTION * from_parent[extend]
    isolated = leaf & ~extend
    if isolated.any():
        axis_y = bind[isolated, :3, 1]
        axis_y = axis_y / np.maximum(np.linalg.norm(axis_y, axis=1, keepdims=True), np.finfo(float).tiny)
        axis_y[np.linalg.norm(axis_y, axis=1) == 0] = [0.0, 1.0, 0.0]
        tails[isolated] = heads[isolated] + ISOLATED_BONE_FRACTION * diagonal * axis_y

    raw_names = [str(nodes[j].get("name") or f"joint_{b}") for b, j in enumerate(joints.tolist())]
    seen: dict[str, int] = {}
    for name in raw_names:
        seen[name] = seen.get(name, 0) + 1
    names = [f"{name}_{b}" if seen[name] > 1 else name for b, name in enumerate(raw_names)]
    skeleton = Skeleton(names, parents, heads, tails)

    rows, cols, vals = [], [], []
    offset = 0
    for primitive, count in zip(primitives, counts):
        attributes = primitive.get("attributes", {})
        set_index = 0
        while f"JOINTS_{set_index}" in attributes and f"WEIGHTS_{set_index}" in attributes:
            joint_ids = reader.accessor(attributes[f"JOINTS_{set_index}"]).astype(np.int64)
            weight = reader.accessor(attributes[f"WEIGHTS_{set_index}"]).astype(np.float64)
            if joint_ids.shape != weight.shape or len(joint_ids) != count:
                raise InputError(
                    f"JOINTS_{set_index}/WEIGHTS_{set_index} do not match the vertex count", source, "bad_weights"
                )
            if not np.isfinite(weight).all() or (weight < 0).any():
                raise InputError(f"WEIGHTS_{set_index} has a negative or non-finite weight", source, "bad_weights")
            used = weight > 0
            if used.any() and (joint_ids[used].min() < 0 or joint_ids[used].max() >= n_bones):
                raise InputError(f"JOINTS_{set_index} refers to a joint outside the skin", source, "bad_weights")
            rows.append((np.arange(count)[:, None] + offset + np.zeros_like(joint_ids))[used])
            cols.append(joint_ids[used])
            vals.append(weight[used])
            set_index += 1
        offset += count
    n_vertices = len(vertices)
    if rows:
        weights = sp.csr_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n_vertices, n_bones)
        )
    else:
        weights = sp.csr_matrix((n_vertices, n_bones))
    return GltfSkin(skeleton, _normalise_rows(weights))


def _parse_skeleton_json(
    path: Path, n_vertices: int, max_bytes: int
) -> tuple[Skeleton, sp.csr_matrix | None, str]:
    source = str(path)
    _check_file(path, max_bytes)
    try:
        document = json.loads(path.read_bytes().decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise InputError(f"skeleton file is not valid JSON: {error}", source, "bad_skeleton") from None
    if not isinstance(document, dict):
        raise InputError("skeleton JSON must be an object with 'bones'", source, "bad_skeleton")
    units = document.get("units", "m")
    if not isinstance(units, str):
        raise InputError(f"'units' must be a string, got {units!r}", source, "unknown_units")
    try:
        scale = unit_scale(units)
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
    return _normalise_rows(matrix)


def _check_file(path: Path, max_bytes: int) -> None:
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


def _check_counts(n_vertices: int, n_faces: int, source: str, max_vertices: int, max_faces: int) -> None:
    if n_vertices > max_vertices:
        raise InputError(
            f"mesh has {n_vertices} vertices, more than the limit of {max_vertices}", source, "too_large"
        )
    if n_faces > max_faces:
        raise InputError(f"mesh has {n_faces} faces, more than the limit of {max_faces}", source, "too_large")


def _check_mesh_arrays(
    vertices: np.ndarray, faces: np.ndarray, source: str, max_vertices: int, max_faces: int
) -> None:
    if len(vertices) == 0 or len(faces) == 0:
        raise InputError(f"empty mesh: {len(vertices)} vertices, {len(faces)} faces", source, "empty_mesh")
    _check_counts(len(vertices), len(faces), source, max_vertices, max_faces)
    finite = np.isfinite(vertices).all(axis=1)
    if not finite.all():
        bad = int(np.argmax(~finite))
        raise InputError(f"vertex {bad} has a non-finite coordinate (NaN or inf)", source, "non_finite")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise InputError("a face index is out of range", source, "bad_faces")


def _atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file in the same folder and ``os.replace``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    handle = tempfile.NamedTemporaryFile(
        "w", encoding="utf-8", dir=path.parent, prefix=f".{path.name}.", suffix=".tmp", delete=False
    )
    try:
        with handle:
            handle.write(text)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(handle.name, path)
    except BaseException:
        try:
            os.unlink(handle.name)
        except OSError:
            pass
        raise
