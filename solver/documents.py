"""What hairport hands out besides hair files: hairline curve documents and the scenes a dashboard draws.

A *hairline document* is a target's front hairline as an editable curve,
``{"units": "m", "points": [[x, y, z], ...], "turning_points": [...]}``: ``hairport hairline`` writes
one (in the groom's axes and units, :func:`curve_document_in_frame`), a user redraws it, and a
retarget takes it back as its hairline edit. A *scene* is what a job's run saves for the dashboard
(:func:`display_scene`, and the source groom's :func:`source_scene`), in the display wire format of
:mod:`hairport.solver.display`.
"""

from __future__ import annotations

import json

import numpy as np

from hairport.solver.adaptable import AdaptableHairstyle
from hairport.solver.artifact import source_scene
from hairport.solver.body.target import prepare_target
from hairport.solver.display import scene_arrays
from hairport.solver.hairline.curve import HairlineCurve
from hairport.solver.hairline.edit import HairlineEdit
from hairport.solver.hairline.presets import PRESETS as HAIRLINE_PRESETS
from hairport.solver.hairline.presets import parse_preset
from hairport.solver.hairline.relocation import edit_curve, scalp_chart
from hairport.solver.mesh.collision import collision_query
from hairport.solver.model.character import Character
from hairport.solver.model.errors import InputError
from hairport.solver.model.frame import InputFrame
from hairport.solver.pipeline import RetargetResult, crossing_mask, penetrating_mask

__all__ = ["curve_document_in_frame", "display_scene", "hairline_document", "hairline_documents", "source_scene"]

#: decimals of a canonical document's coordinates (meters): 0.1 micrometre
DOCUMENT_DECIMALS = 7


def hairline_document(adaptable: AdaptableHairstyle, target: Character, preset: str | None = None,
                      parameterization: str = "harmonic") -> dict:
    """The target's current front hairline (or a preset's edit of it) as a curve document,
    ``{"units": "m", "points": [[x, y, z], ...], "turning_points": [...]}``, ready to be
    edited and passed back as a hairline curve (same ends, same turning points)."""
    return hairline_documents(adaptable, target, (preset,), parameterization)[preset]


def hairline_documents(adaptable: AdaptableHairstyle, target: Character, presets: tuple[str | None, ...],
                       parameterization: str = "harmonic") -> dict[str | None, dict]:
    """:func:`hairline_document` for several presets (None: the current hairline), the scalp chart built once."""
    target = prepare_target(adaptable, target)
    roots = adaptable.hair.roots
    setup = scalp_chart(target, adaptable.anchors.face[roots], parameterization)
    documents = {}
    for preset in presets:
        if preset is None:
            curve = HairlineCurve(setup.rest[setup.front], setup.turning)
        else:
            name, amount = parse_preset(preset)
            curve = edit_curve(setup, HairlineEdit(preset=name, amount=amount))
        documents[preset] = {"units": "m", "points": np.round(curve.points, DOCUMENT_DECIMALS).tolist(),
                             "turning_points": np.asarray(curve.turning_points).tolist()}
    return documents


def curve_document_in_frame(frame: InputFrame, document: dict) -> dict:
    """A hairline curve document (canonical, meters) in the groom's axes and units."""
    points = frame.axes_out(np.asarray(document["points"], dtype=np.float64)) / frame.scale
    decimals = DOCUMENT_DECIMALS + int(round(np.log10(frame.scale)))  # the canonical document's precision
    return {**document, "units": frame.units, "points": np.round(points, decimals).tolist()}


def display_scene(adaptable: AdaptableHairstyle, result: RetargetResult, target: Character) -> dict[str, np.ndarray]:
    """What the dashboard draws of a retarget (:func:`~hairport.solver.display.scene_arrays`): the result, its
    particles inside the body and its segments through it, the target, and the target's current front hairline
    with every preset's edit of it (left out, with the reason in ``meta``, when the groom has no front hairline
    to find). The hairline of a target of another topology is found on its wrap (:attr:`RetargetResult.wrapped`),
    the body drawn is the target; the wrapped body is kept beside it (``wrapped_vertices``, ``wrapped_faces``) to
    be drawn over it."""
    inside, crossing = result.inside, result.crossing
    if inside is None or crossing is None:  # a result the pipeline did not measure: one collision surface for both
        body = collision_query(target.vertices, target.faces, target.name)
        inside = penetrating_mask(result.hair, target, body) if inside is None else inside
        crossing = crossing_mask(result.hair, target, body) if crossing is None else crossing
    try:
        shape = target if result.wrapped is None else result.wrapped.shape
        documents = hairline_documents(adaptable, shape, (None, *HAIRLINE_PRESETS))
        hairline, hairline_error = documents.pop(None), None
    except InputError as error:
        documents, hairline, hairline_error = {}, {"points": [], "turning_points": []}, error.problem
    wrapped = None if result.wrapped is None else (result.wrapped.shape.vertices, result.wrapped.shape.faces)
    arrays = scene_arrays(result.hair.points, result.hair.offsets, inside, result.hair.color, target.vertices,
                          target.faces, adaptable.frame.rotation, hairline, documents, wrapped, crossing)
    meta = {"groom_units": adaptable.frame.units, "hairline_error": hairline_error}
    arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    return arrays
