"""MakeHuman busts shaped like game and scan characters: extra shells, an open cut, non-manifold edges.

Real character meshes rarely are one closed skin. :func:`build_bust` makes MakeHuman bodies
that carry what they usually carry, on one topology for every shape (so a source and a
target still match vertex for vertex):

* **Extra shells** from MakeHuman's own helper geometry, shaped with the body: the eyeballs
  (closed), the upper and lower teeth (open disks in the base mesh, closed here with a fan
  around each border loop's centroid), the tongue (closed) and the eyelashes (open strips).
  Their quads are split along the shorter diagonal of the base mesh, as the body's are; their
  vertices are skinned to the ``head`` bone alone, so they move with the head.
* **An open cut**: the body's faces with a vertex below a horizontal plane (the chest, by
  default halfway up the ``spine_03`` bone) are removed, with the vertices no face uses.
* **Open eye sockets** (optional): the skin faces over each eyeball (all three vertices
  within :data:`EYE_OPENING_RADIUS_SHARE` of the eyeball's radius from its centre) are removed,
  as game meshes leave the eyelid opening to the eyeball, and with them the socket's inner
  pocket they held to the skin.
* **Non-manifold edges** (optional): ``fins`` thin triangles, each on an edge of a torso face
  (a third face on an edge the skin already closes) with its tip inside the body.

Vertex order: the kept body vertices in their body order, then the shells' vertices in the
order of ``shells``, then the fins' tips. Weights: the body's rows, one ``head`` weight per
shell vertex, each fin tip the mean of its edge's rows.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from hairport.solver.mesh.shells import border_vertices, shell_labels
from hairport.solver.mesh.topology import boundary_loops, submesh
from hairport.solver.model.character import Character
from hairport.solver.model.errors import InputError
from hairport.solver.synthetic.assets import BASE_OBJ, VERTEX_GROUPS_FILE
from hairport.solver.synthetic.makehuman.base_model import METERS_PER_MAKEHUMAN_UNIT, split_quads
from hairport.solver.synthetic.makehuman.builder import PRESETS, build_character, full_mesh_positions
from hairport.solver.synthetic.makehuman.macros import MakeHumanParams
from hairport.solver.synthetic.makehuman.store import asset_store

#: helper groups of the MakeHuman base mesh that make the extra shells
HELPER_SHELLS = ("helper-l-eye", "helper-r-eye", "helper-upper-teeth", "helper-lower-teeth", "helper-tongue",
                 "helper-l-eyelashes-1", "helper-l-eyelashes-2", "helper-r-eyelashes-1", "helper-r-eyelashes-2")
#: the default extra shells: both eyeballs and both rows of teeth, all closed
DEFAULT_SHELLS = ("helper-l-eye", "helper-r-eye", "helper-upper-teeth", "helper-lower-teeth")
#: shells whose border loops are closed with a fan (the teeth are open disks in the base mesh)
CLOSED_SHELLS = ("helper-upper-teeth", "helper-lower-teeth")
#: the bone the extra shells are skinned to
SHELL_BONE = "head"
#: the default cut: the plane through this point of the ``spine_03`` bone (0 = head, 1 = tail)
CUT_BONE = "spine_03"
CUT_BONE_PARAMETER = 0.5
#: skin vertices within this share of an eyeball's radius from its centre are the eye opening
EYE_OPENING_RADIUS_SHARE = 1.0
#: bone whose dominant faces carry the fins, and how deep (m) inside the body their tips lie
FIN_BONE = "spine_03"
FIN_DEPTH_M = 0.01


@functools.lru_cache(maxsize=4)
def helper_quads(assets: Path) -> dict[str, np.ndarray]:
    """The quads (Q, 4) int64 of every helper group of ``base.obj``, on full-mesh vertex ids."""
    groups: dict[str, list[list[int]]] = {}
    group = None
    with open(Path(assets) / BASE_OBJ, encoding="utf-8") as handle:
        for line in handle:
            if line.startswith("g "):
                group = line[2:].strip()
            elif line.startswith("f ") and group is not None and group.startswith("helper-"):
                groups.setdefault(group, []).append([int(t.split("/")[0]) - 1 for t in line.split()[1:]])
    return {name: np.asarray(quads, dtype=np.int64) for name, quads in groups.items()}


def shell_geometry(quads: np.ndarray, base: np.ndarray, close: bool) -> tuple[sp.csr_matrix, np.ndarray]:
    """One helper shell as an averaging map from the full mesh and triangles.

    Parameters
    ----------
    quads : (Q, 4) int64
        Full-mesh vertex ids.
    base : (N, 3) float64
        The base mesh (its shorter diagonals split the quads; its signed volume orients a
        closed shell outward).
    close : bool
        Fill every border loop with a fan around a new vertex at the loop's centroid.

    Returns
    -------
    average : (n, N) csr_matrix
        Row ``i`` averages the full-mesh vertices that make shell vertex ``i``.
    triangles : (t, 3) int64
        Into the shell's ``n`` vertices.
    """
    vertices, triangles = submesh(split_quads(quads, base), np.arange(2 * len(quads)))
    rows = [np.array([v]) for v in vertices]
    if close:
        fans = []
        for loop in boundary_loops(triangles):
            centre = len(rows)
            rows.append(vertices[loop])
            # the loop runs along the shell's border half-edges a -> b; the fan holds b -> a
            fans.append(np.stack([np.roll(loop, -1), loop, np.full(len(loop), centre)], axis=1))
        triangles = np.vstack([triangles, *fans]) if fans else triangles
    lengths = np.array([len(r) for r in rows])
    average = sp.csr_matrix((np.repeat(1.0 / lengths, lengths), np.concatenate(rows),
                             np.concatenate([[0], np.cumsum(lengths)])), shape=(len(rows), len(base)))
    if close:
        points = average @ base
        corners = points[triangles]
        volume = np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])).sum() / 6.0
        if volume < 0:
            triangles = triangles[:, ::-1]
    return average, np.ascontiguousarray(triangles, dtype=np.int64)


def add_shells(character: Character, full: np.ndarray, shells: tuple[str, ...], assets: Path) -> Character:
    """``character`` with the helper ``shells`` of the shaped full mesh ``full (N, 3)`` (m) appended."""
    quads = helper_quads(assets)
    base = asset_store(assets).model.vertices
    bone = character.skeleton.index(SHELL_BONE)
    vertices, faces, weights = [character.vertices], [character.faces], [character.weights]
    offset = character.n_vertices
    for name in shells:
        if name not in HELPER_SHELLS:
            raise InputError(f"unknown helper shell {name!r}; expected one of {', '.join(HELPER_SHELLS)}",
                             "shells", "bad_option")
        average, triangles = shell_geometry(quads[name], base, name in CLOSED_SHELLS)
        vertices.append(average @ full)
        faces.append(triangles + offset)
        n = average.shape[0]
        weights.append(sp.csr_matrix((np.ones(n), (np.arange(n), np.full(n, bone))),
                                     shape=(n, character.skeleton.n_bones)))
        offset += n
    return Character(np.vstack(vertices), np.vstack(faces), character.skeleton, sp.vstack(weights).tocsr(),
                     character.name)


def keep_faces(character: Character, keep: np.ndarray) -> Character:
    """``character`` with the faces ``keep (F,) bool`` only, and only the vertices they use (in order)."""
    used = np.zeros(character.n_vertices, dtype=bool)
    used[character.faces[keep].ravel()] = True
    new_id = np.cumsum(used) - 1
    weights = None if character.weights is None else character.weights[used]
    return Character(character.vertices[used], new_id[character.faces[keep]], character.skeleton, weights,
                     character.name)


def cut_height(character: Character) -> float:
    """The default cut's height (m along +Y): :data:`CUT_BONE_PARAMETER` of the way up :data:`CUT_BONE`."""
    bone = character.skeleton.index(CUT_BONE)
    head, tail = character.skeleton.heads[bone], character.skeleton.tails[bone]
    return float(head[1] + CUT_BONE_PARAMETER * (tail[1] - head[1]))


def eye_opening_faces(character: Character, full: np.ndarray, assets: Path) -> np.ndarray:
    """(F,) bool: skin faces over the eyeballs (all corners within the eyeball's radius of its centre)."""
    groups = json.loads((Path(assets) / VERTEX_GROUPS_FILE).read_text())
    over = np.zeros(character.n_faces, dtype=bool)
    for name in ("helper-l-eye", "helper-r-eye"):
        ids = np.concatenate([np.arange(lo, hi + 1) for lo, hi in groups[name]])
        centre = full[ids].mean(axis=0)
        radius = np.linalg.norm(full[ids] - centre, axis=1).mean()
        inside = np.linalg.norm(character.vertices - centre, axis=1) <= EYE_OPENING_RADIUS_SHARE * radius
        over |= inside[character.faces].all(axis=1)
    return over


def add_fins(character: Character, count: int) -> Character:
    """``character`` with ``count`` non-manifold edges: a thin triangle on one edge of each of
    ``count`` faces dominated by :data:`FIN_BONE` off the border (spread over them), its tip :data:`FIN_DEPTH_M`
    inside the body below the edge's midpoint."""
    if count <= 0:
        return character
    faces = character.faces
    bone = character.skeleton.index(FIN_BONE)
    dominant = np.asarray(character.weights.argmax(axis=1)).ravel() == bone
    inner = ~border_vertices(faces, character.n_vertices)  # a fin on a border edge would only extend it
    candidates = np.flatnonzero((dominant & inner)[faces].all(axis=1))
    if len(candidates) < count:
        raise InputError(f"only {len(candidates)} faces to carry {count} fins", character.name, "bad_option")
    chosen = candidates[np.linspace(0, len(candidates) - 1, count).astype(np.int64)]
    a, b, c = (faces[chosen, k] for k in range(3))
    p = character.vertices
    normal = np.cross(p[b] - p[a], p[c] - p[a])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    tips = 0.5 * (p[a] + p[b]) - FIN_DEPTH_M * normal
    tip_ids = character.n_vertices + np.arange(count)
    tip_weights = 0.5 * (character.weights[a] + character.weights[b])
    return Character(np.vstack([p, tips]), np.vstack([faces, np.stack([b, a, tip_ids], axis=1)]),
                     character.skeleton, sp.vstack([character.weights, tip_weights]).tocsr(), character.name)


def build_bust(
    params: MakeHumanParams | str | None = None,
    assets_dir: Path | None = None,
    *,
    shells: tuple[str, ...] = DEFAULT_SHELLS,
    cut: bool = True,
    open_eyes: bool = False,
    fins: int = 0,
    name: str | None = None,
) -> Character:
    """A MakeHuman body with extra shells, cut open at the chest (see the module docstring).

    Parameters
    ----------
    params : MakeHumanParams or str, optional
        Body parameters or a preset name (:data:`.builder.PRESETS`); default MakeHuman's default human.
    assets_dir : Path, optional
    shells : tuple of str
        Names from :data:`HELPER_SHELLS`, appended in this order.
    cut : bool
        Remove the body below the chest (:func:`cut_height`).
    open_eyes : bool
        Remove the skin over the eyeballs (:func:`eye_opening_faces`).
    fins : int
        Non-manifold edges to add on the torso (:func:`add_fins`).
    name : str, optional

    Returns
    -------
    character : Character
        Meters, Y up, face toward +Z; the same faces for every shape with the same options.
    """
    label = params if isinstance(params, str) else "makehuman"
    if isinstance(params, str):
        if params not in PRESETS:
            raise InputError(f"unknown preset {params!r}; expected one of {', '.join(PRESETS)}", "preset",
                             "unknown_preset")
        params = PRESETS[params]
    params = params if params is not None else MakeHumanParams()
    store = asset_store(assets_dir)
    body = build_character(params, store.assets, name=name or f"bust:{label}")
    full = full_mesh_positions(params, store.assets) * METERS_PER_MAKEHUMAN_UNIT
    keep = np.ones(body.n_faces, dtype=bool)
    if cut:
        # decided on the base mesh, so every shape keeps the same faces
        base = build_character(MakeHumanParams(), store.assets)
        keep &= ~(base.vertices[body.faces, 1] < cut_height(base)).any(axis=1)
    if open_eyes:
        base_full = full_mesh_positions(MakeHumanParams(), store.assets) * METERS_PER_MAKEHUMAN_UNIT
        base = build_character(MakeHumanParams(), store.assets)
        keep &= ~eye_opening_faces(base, base_full, store.assets)
        # the eye sockets' inner pockets, cut off from the skin, go too
        labels = shell_labels(body.faces[keep])
        keep[np.flatnonzero(keep)[labels != np.argmax(np.bincount(labels))]] = False
    body = keep_faces(body, keep)
    return add_fins(add_shells(body, full, tuple(shells), store.assets), fins)
