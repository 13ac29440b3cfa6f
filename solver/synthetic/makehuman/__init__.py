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

Modules
-------
- :mod:`.macros`: the parameters (:class:`MakeHumanParams`) and the macro target weights;
- :mod:`.targets`: the shape target files, parsed per folder;
- :mod:`.base_model`: the base mesh, rig and skin weights, parsed;
- :mod:`.cache`: the ``.npz`` caches under ``<assets>/parsed/`` (built on first use: ~7 s
  once for all macro folders; then a build takes 0.02-0.1 s in a new process);
- :mod:`.store`: the parsed assets kept per process (a few ms per build in a warm one);
- :mod:`.builder`: :func:`build_character`, :data:`PRESETS`, :func:`build_preset`.

:func:`write_character` (OBJ + skeleton sidecar) is the character writer of
:mod:`hairport.solver.io.character`, importable here too.
"""

from hairport.solver.io.character.export import write_character
from hairport.solver.synthetic.makehuman.builder import PRESETS, build_character, build_preset, full_mesh_positions
from hairport.solver.synthetic.makehuman.macros import (
    MakeHumanParams,
    age_from_years,
    macro_target_weights,
    macro_variable_weights,
    years_from_age,
)
from hairport.solver.synthetic.makehuman.store import available_targets

__all__ = [
    "PRESETS",
    "MakeHumanParams",
    "age_from_years",
    "available_targets",
    "build_character",
    "build_preset",
    "full_mesh_positions",
    "macro_target_weights",
    "macro_variable_weights",
    "write_character",
    "years_from_age",
]
