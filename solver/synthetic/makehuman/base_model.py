"""The MakeHuman base mesh ``hm08`` with the game-engine rig and its skin weights, parsed.

The full base mesh (19,158 vertices: body, helper geometry, joint cubes) is read from
``3dobjs/base.obj``; its ``body`` group (13,380 vertices) is the character's mesh, its quads
split along their shorter diagonal *on the base mesh*, so the split never depends on the
shape. Every joint of the rig is a mean of full-mesh vertices (a joint cube, a vertex list,
or one vertex per axis), kept as a sparse joint regressor, so a shaped mesh places the
skeleton with three sparse products. Bones are ordered parents first. The parsed arrays are
cached as ``<assets>/parsed/base-model.npz`` (:mod:`.cache`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from hairport.solver.model.character import normalise_weight_rows
from hairport.solver.model.errors import InputError
from hairport.solver.synthetic.assets import BASE_OBJ, RIG_FILE, VERTEX_GROUPS_FILE, WEIGHTS_FILE

METERS_PER_MAKEHUMAN_UNIT = 0.1
"""The MakeHuman base mesh and its targets are in decimeters."""

N_FULL_VERTICES = 19158
"""Vertices of the full base mesh ``hm08`` (body + helper geometry + joint cubes)."""

BODY_GROUP = "body"
"""The vertex group (and OBJ group) of the character's mesh."""


@dataclass(frozen=True, eq=False)
class BaseModel:
    """The parsed base mesh, rig and weights (all on the full mesh, decimeters).

    Attributes
    ----------
    vertices : (N, 3) float64
        Full base mesh, dm, N = 19158.
    body_vertices : (V,) int64
        Full-mesh index of each body vertex (V = 13380).
    triangles : (F, 3) int64
        Body triangles on body indices.
    bone_names : tuple of str, length B
    parents : (B,) int64
    joint_regressor : tuple of three (2B, N) csr_matrix
        Per axis; rows ``2b`` and ``2b+1`` give the head and tail of bone ``b``.
    weights : (V, B) csr_matrix
        Skin weights on body vertices, rows normalised where they sum > 0.
    """

    vertices: np.ndarray
    body_vertices: np.ndarray
    triangles: np.ndarray
    bone_names: tuple[str, ...]
    parents: np.ndarray
    joint_regressor: tuple[sp.csr_matrix, sp.csr_matrix, sp.csr_matrix]
    weights: sp.csr_matrix


def _parse_obj(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (N, 3) float64 and the quads (Q, 4) int64 of the ``body`` group of ``base.obj``."""
    vertices: list[list[float]] = []
    body_faces: list[list[int]] = []
    group = None
    with open(path, encoding="utf-8") as handle:
        for line in handle:
            if line.startswith("v "):
                vertices.append([float(t) for t in line.split()[1:4]])
            elif line.startswith("g "):
                group = line[2:].strip()
            elif line.startswith("f ") and group == BODY_GROUP:
                body_faces.append([int(t.split("/")[0]) - 1 for t in line.split()[1:]])
    verts = np.asarray(vertices, dtype=np.float64)
    if verts.shape != (N_FULL_VERTICES, 3):
        raise InputError(f"expected {N_FULL_VERTICES} vertices, found {len(verts)}", str(path), "bad_mesh")
    if not body_faces or any(len(f) != 4 for f in body_faces):
        raise InputError("the body group must consist of quads", str(path), "bad_mesh")
    return verts, np.asarray(body_faces, dtype=np.int64)


def split_quads(quads: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Split quads ``(a, b, c, d)`` along the shorter diagonal of the given (base) positions.

    Returns (2Q, 3) triangles; triangles ``2q`` and ``2q+1`` come from quad ``q`` and keep
    its orientation.
    """
    a, b, c, d = quads.T
    diag_ac = np.linalg.norm(vertices[a] - vertices[c], axis=1)
    diag_bd = np.linalg.norm(vertices[b] - vertices[d], axis=1)
    use_ac = diag_ac <= diag_bd
    first = np.where(use_ac[:, None], np.stack([a, b, c], 1), np.stack([a, b, d], 1))
    second = np.where(use_ac[:, None], np.stack([a, c, d], 1), np.stack([b, c, d], 1))
    return np.stack([first, second], axis=1).reshape(-1, 3)


def _vertex_groups(path: Path) -> dict[str, np.ndarray]:
    """Vertex groups of the full mesh: name -> (k,) int64 indices (from inclusive ranges)."""
    raw = json.loads(path.read_text())
    return {
        name: np.concatenate([np.arange(lo, hi + 1, dtype=np.int64) for lo, hi in ranges])
        for name, ranges in raw.items()
    }


def parents_first(names: list[str], parent_of: dict[str, str]) -> list[str]:
    """The bone names ordered parents first (depth first, children in file order).

    Parameters
    ----------
    names : list of str
    parent_of : dict of str to str
        Every bone's parent, ``""`` for a root.

    Raises
    ------
    InputError
        ``bad_skeleton``: an unknown parent, or parent links that form a cycle.
    """
    children: dict[str, list[str]] = {}
    roots = []
    for name in names:
        parent = parent_of[name]
        if parent:
            if parent not in parent_of:
                raise InputError(f"bone {name!r} has unknown parent {parent!r}", RIG_FILE, "bad_skeleton")
            children.setdefault(parent, []).append(name)
        else:
            roots.append(name)
    order: list[str] = []
    stack = list(reversed(roots))
    while stack:
        name = stack.pop()
        order.append(name)
        stack.extend(reversed(children.get(name, [])))
    if len(order) != len(names):
        raise InputError("the rig's parent links contain a cycle", RIG_FILE, "bad_skeleton")
    return order


def joint_vertex_rows(end: dict, groups: dict[str, np.ndarray], where: str) -> list[np.ndarray]:
    """For one bone end, the vertices whose mean gives x, y and z (three index arrays).

    Strategies (MPFB2 ``Rig.get_best_location_from_strategy``): CUBE = mean of the
    vertex group ``cube_name``; MEAN = mean of ``vertex_indices``; VERTEX = ``vertex_index``;
    XYZ = one vertex per axis, in Blender's axes (x, y=-z_obj, z=y_obj).
    """
    strategy = end.get("strategy")
    if "offset" in end:
        raise InputError(f"{where}: joint offsets are not supported", RIG_FILE, "bad_skeleton")
    if strategy == "CUBE":
        cube = end.get("cube_name")
        if cube not in groups:
            raise InputError(f"{where}: unknown joint cube {cube!r}", RIG_FILE, "bad_skeleton")
        rows = [groups[cube]] * 3
    elif strategy == "MEAN":
        rows = [np.asarray(end["vertex_indices"], dtype=np.int64)] * 3
    elif strategy == "VERTEX":
        rows = [np.asarray([end["vertex_index"]], dtype=np.int64)] * 3
    elif strategy == "XYZ":
        vx, vy_blender, vz_blender = (int(i) for i in end["vertex_indices"][:3])
        rows = [np.array([vx]), np.array([vz_blender]), np.array([vy_blender])]
    else:
        raise InputError(f"{where}: unsupported joint strategy {strategy!r}", RIG_FILE, "bad_skeleton")
    for r in rows:
        if r.size == 0 or r.min() < 0 or r.max() >= N_FULL_VERTICES:
            raise InputError(f"{where}: joint vertices out of range", RIG_FILE, "bad_skeleton")
    return rows


def parse_base_model(assets: Path) -> dict[str, np.ndarray]:
    """Parse the base mesh, rig and weights into the flat arrays of the cache.

    Parameters
    ----------
    assets : Path
        The MakeHuman assets directory.

    Returns
    -------
    arrays : dict of str to ndarray
        ``vertices``, ``body_vertices``, ``triangles``, ``bone_names``, ``parents``, the
        skin weights as ``w_rows``/``w_cols``/``w_vals`` on body vertices and the joint
        regressor as ``reg<axis>_indptr``/``_indices``/``_data``; see
        :func:`base_model_from_arrays`.
    """
    vertices, quads = _parse_obj(assets / BASE_OBJ)
    groups = _vertex_groups(assets / VERTEX_GROUPS_FILE)
    body = groups[BODY_GROUP]
    used = np.unique(quads)
    if not np.array_equal(used, body):
        raise InputError("body faces and the body vertex group disagree", str(assets / BASE_OBJ), "bad_mesh")
    full_to_body = np.full(N_FULL_VERTICES, -1, dtype=np.int64)
    full_to_body[body] = np.arange(len(body))
    triangles = full_to_body[split_quads(quads, vertices)]

    rig = json.loads((assets / RIG_FILE).read_text())
    if isinstance(rig.get("bones"), dict):  # newer MPFB rig files wrap the bones
        rig = rig["bones"]
    names = parents_first(list(rig), {n: b.get("parent") or "" for n, b in rig.items()})
    index = {n: i for i, n in enumerate(names)}
    parents = np.array([index[rig[n]["parent"]] if rig[n].get("parent") else -1 for n in names], dtype=np.int64)
    regressor = _regressor_arrays(rig, names, groups)
    weights = _weight_arrays(assets, index, full_to_body)
    return {
        "vertices": vertices,
        "body_vertices": body,
        "triangles": triangles,
        "bone_names": np.array(names, dtype=str),
        "parents": parents,
        **weights,
        **regressor,
    }


def _regressor_arrays(rig: dict, names: list[str], groups: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per axis, the CSR arrays of the (2B, N) joint regressor: rows ``2b``, ``2b+1`` = head, tail of bone ``b``."""
    reg_rows: list[list[np.ndarray]] = [[], [], []]
    for n in names:
        for end in ("head", "tail"):
            for axis, r in enumerate(joint_vertex_rows(rig[n][end], groups, f"bone {n} {end}")):
                reg_rows[axis].append(r)
    regressor = {}
    for axis in range(3):
        rows = reg_rows[axis]
        lengths = np.array([len(r) for r in rows])
        regressor[f"reg{axis}_indptr"] = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
        regressor[f"reg{axis}_indices"] = np.concatenate(rows).astype(np.int64)
        regressor[f"reg{axis}_data"] = np.repeat(1.0 / lengths, lengths)
    return regressor


def _weight_arrays(assets: Path, index: dict[str, int], full_to_body: np.ndarray) -> dict[str, np.ndarray]:
    """The rig's skin weights as COO arrays on body vertices (entries of other vertices dropped)."""
    raw_weights = json.loads((assets / WEIGHTS_FILE).read_text())["weights"]
    unknown = set(raw_weights) - set(index)
    if unknown:
        raise InputError(f"weights for unknown bones {sorted(unknown)}", WEIGHTS_FILE, "bad_skeleton")
    w_rows, w_cols, w_vals = [], [], []
    for bone, pairs in raw_weights.items():
        if not pairs:
            continue
        table = np.asarray(pairs, dtype=np.float64).reshape(-1, 2)
        vert = table[:, 0].astype(np.int64)
        keep = (vert >= 0) & (vert < N_FULL_VERTICES)
        keep[keep] &= full_to_body[vert[keep]] >= 0
        w_rows.append(full_to_body[vert[keep]])
        w_cols.append(np.full(int(keep.sum()), index[bone], dtype=np.int64))
        w_vals.append(table[keep, 1])
    return {"w_rows": np.concatenate(w_rows), "w_cols": np.concatenate(w_cols), "w_vals": np.concatenate(w_vals)}


def base_model_from_arrays(a: dict[str, np.ndarray]) -> BaseModel:
    """The base model from the arrays of :func:`parse_base_model` (weights: negative entries
    dropped, rows normalised)."""
    n_bones = len(a["bone_names"])
    n_body = len(a["body_vertices"])
    regressor = tuple(
        sp.csr_matrix(
            (a[f"reg{k}_data"], a[f"reg{k}_indices"], a[f"reg{k}_indptr"]), shape=(2 * n_bones, N_FULL_VERTICES)
        )
        for k in range(3)
    )
    weights = sp.csr_matrix((a["w_vals"], (a["w_rows"], a["w_cols"])), shape=(n_body, n_bones))
    weights.sum_duplicates()
    weights.data[weights.data < 0] = 0.0
    weights = normalise_weight_rows(weights)
    return BaseModel(
        vertices=a["vertices"],
        body_vertices=a["body_vertices"],
        triangles=a["triangles"],
        bone_names=tuple(a["bone_names"].tolist()),
        parents=a["parents"],
        joint_regressor=regressor,  # type: ignore[arg-type]
        weights=weights,
    )
