"""hairport's numerical core: retarget a strand hairstyle to another body of the same topology.

This module is the public face of the solver: the command line, the worker, the service and
the benchmarks import from here and from nowhere else in ``hairport.solver`` (the fixtures of
:mod:`hairport.solver.synthetic` and the pictures of :mod:`hairport.solver.render` are their
own sub-packages). The folder ``solver/`` is installed as ``hairport.solver``.

The stages (paper sections): :func:`preprocess` (source only: anchors Eq. 2, guides and
neighbours Eq. 8-9/14) gives an :class:`AdaptableHairstyle`; :func:`retarget` adapts it to a
target (initial transfer Eq. 3-6, optional hairline edit Sec. 6, shape adaptation Eq. 1 by
the multi-scale solve Sec. 5, or a baseline) and measures the result.

Names are loaded on first use (PEP 562 module ``__getattr__``): importing a single solver
module, or starting the command line, does not pull in the whole numerical stack.
"""

from __future__ import annotations

import importlib

#: public name -> (module, name in that module)
_EXPORTS = {
    "ARTIFACT_EXTENSION": ("hairport.solver.artifact", "EXTENSION"),
    "ARTIFACT_FORMAT_VERSION": ("hairport.solver.artifact", "FORMAT_VERSION"),
    "ANCHOR_BY_BONES": ("hairport.solver.transfer.anchors", "ANCHOR_BY_BONES"),
    "ANCHORINGS": ("hairport.solver.transfer.anchors", "ANCHORINGS"),
    "AUTO": ("hairport.solver.model.frame", "AUTO"),
    "AXIS_CHOICES": ("hairport.solver.model.frame", "AXIS_CHOICES"),
    "AdaptableHairstyle": ("hairport.solver.adaptable", "AdaptableHairstyle"),
    "BASELINE_METHODS": ("hairport.solver.baselines", "BASELINE_METHODS"),
    "Cancelled": ("hairport.solver.adaptation.loop.options", "Cancelled"),
    "Character": ("hairport.solver.model.character", "Character"),
    "DEFAULT_DISPLAY_VERTICES": ("hairport.solver.display", "DEFAULT_DISPLAY_VERTICES"),
    "DISPLAY_MEDIA_TYPE": ("hairport.solver.display", "MEDIA_TYPE"),
    "MAX_DISPLAY_STRIDE": ("hairport.solver.display", "MAX_STRIDE"),
    "MAX_DISPLAY_VERTICES": ("hairport.solver.display", "MAX_DISPLAY_VERTICES"),
    "body_payload": ("hairport.solver.display", "body_payload"),
    "display_up": ("hairport.solver.display", "display_up"),
    "display_scene": ("hairport.solver.pipeline", "display_scene"),
    "hairline_json": ("hairport.solver.display", "hairline_json"),
    "load_scene": ("hairport.solver.display", "load_scene"),
    "plan_display": ("hairport.solver.display", "plan_display"),
    "scene_preset_array": ("hairport.solver.display", "scene_preset_array"),
    "scene_arrays": ("hairport.solver.display", "scene_arrays"),
    "scene_meta": ("hairport.solver.display", "scene_meta"),
    "save_scene": ("hairport.solver.display", "save_scene"),
    "source_scene": ("hairport.solver.artifact", "source_scene"),
    "strands_payload": ("hairport.solver.display", "strands_payload"),
    "DEFAULT_GUIDES": ("hairport.solver.adaptation.source.guides", "DEFAULT_GUIDES"),
    "GUIDE_FLAG": ("hairport.solver.adaptation.source.guide_flags", "GUIDE_FLAG"),
    "FILE_MODE": ("hairport.solver.model.files", "FILE_MODE"),
    "HAIRLINE_PRESETS": ("hairport.solver.hairline.presets", "PRESETS"),
    "HAIR_FORMATS": ("hairport.solver.io.hair", "SUPPORTED_FORMATS"),
    "FineInputs": ("hairport.solver.adaptation.fine.fine_chunks", "FineInputs"),
    "FineLevel": ("hairport.solver.adaptation.multiscale", "FineLevel"),
    "Hair": ("hairport.solver.model.hair", "Hair"),
    "HairlineEdit": ("hairport.solver.hairline.edit", "HairlineEdit"),
    "InputError": ("hairport.solver.model.errors", "InputError"),
    "InputFrame": ("hairport.solver.model.frame", "InputFrame"),
    "MESH_EXTENSIONS": ("hairport.solver.io.character", "MESH_EXTENSIONS"),
    "METERS_PER_UNIT": ("hairport.solver.model.units", "METERS_PER_UNIT"),
    "METHODS": ("hairport.solver.options", "METHODS"),
    "OVER_MEMORY_BUDGET": ("hairport.solver.budget", "OVER_MEMORY_BUDGET"),
    "check_memory": ("hairport.solver.budget", "check_memory"),
    "warm_up": ("hairport.solver.jit", "warm_up"),
    "uncached_kernels": ("hairport.solver.jit", "uncached_kernels"),
    "COLD_COMPILE_SECONDS": ("hairport.solver.jit", "COLD_COMPILE_SECONDS"),
    "OPTION_RANGES": ("hairport.solver.options", "OPTION_RANGES"),
    "EVEN_SPACING_WEIGHT": ("hairport.solver.adaptation.problem.spacing", "EVEN_SPACING_WEIGHT"),
    "PARAMETERIZATIONS": ("hairport.solver.mesh.parameterization", "PARAMETERIZATIONS"),
    "PenetrationRemaining": ("hairport.solver.model.errors", "PenetrationRemaining"),
    "PreprocessOptions": ("hairport.solver.options", "PreprocessOptions"),
    "ProgressFn": ("hairport.solver.model.progress", "ProgressFn"),
    "QP_BACKENDS": ("hairport.solver.adaptation.solve", "QP_BACKENDS"),
    "RELOCATION_METHODS": ("hairport.solver.hairline.edit", "RELOCATION_METHODS"),
    "ReadLimits": ("hairport.solver.io.hair", "ReadLimits"),
    "RetargetOptions": ("hairport.solver.options", "RetargetOptions"),
    "RetargetResult": ("hairport.solver.pipeline", "RetargetResult"),
    "SOLVER_METHODS": ("hairport.solver.options", "SOLVER_METHODS"),
    "Skeleton": ("hairport.solver.model.character", "Skeleton"),
    "SourceInputs": ("hairport.solver.inputs", "SourceInputs"),
    "TEMP_SUFFIX": ("hairport.solver.model.files", "TEMP_SUFFIX"),
    "UNITS": ("hairport.solver.model.units", "UNITS"),
    "TopologyMismatch": ("hairport.solver.model.errors", "TopologyMismatch"),
    "atomic_write": ("hairport.solver.model.files", "atomic_write"),
    "atomic_write_bytes": ("hairport.solver.model.files", "atomic_write_bytes"),
    "body_key": ("hairport.solver.mesh.collision", "body_key"),
    "collision_faces": ("hairport.solver.mesh.collision", "collision_faces"),
    "canonical_source": ("hairport.solver.inputs", "canonical_source"),
    "canonical_target": ("hairport.solver.inputs", "canonical_target"),
    "curve_document_in_frame": ("hairport.solver.inputs", "curve_document_in_frame"),
    "edit_in_canonical": ("hairport.solver.inputs", "edit_in_canonical"),
    "format_for_path": ("hairport.solver.io.hair", "format_for_path"),
    "fsync_folder": ("hairport.solver.model.files", "fsync_folder"),
    "hair_in_frame": ("hairport.solver.inputs", "hair_in_frame"),
    "with_guide_flags": ("hairport.solver.adaptation.source.guide_flags", "with_guide_flags"),
    "flagged_guides": ("hairport.solver.adaptation.source.guide_flags", "flagged_guides"),
    "hairline_document": ("hairport.solver.pipeline", "hairline_document"),
    "hairline_edit": ("hairport.solver.hairline.edit", "hairline_edit"),
    "hairline_edit_from_request": ("hairport.solver.hairline.edit", "hairline_edit_from_request"),
    "load_adaptable": ("hairport.solver.artifact", "load_adaptable"),
    "load_character": ("hairport.solver.io.character", "load_character"),
    "no_progress": ("hairport.solver.model.progress", "no_progress"),
    "chunk_strands": ("hairport.solver.adaptation.multiscale", "chunk_strands"),
    "solve_fine_chunk": ("hairport.solver.pipeline", "solve_fine_chunk"),
    "solve_here": ("hairport.solver.adaptation.multiscale", "solve_here"),
    "solve_level_run": ("hairport.solver.adaptation.multiscale", "solve_level_run"),
    "SolveReport": ("hairport.solver.adaptation.loop.options", "SolveReport"),
    "SOLVE_STAGE": ("hairport.solver.adaptation.loop.options", "SOLVE_STAGE"),
    "parse_axis": ("hairport.solver.model.frame", "parse_axis"),
    "penetrating_mask": ("hairport.solver.pipeline", "penetrating_mask"),
    "preprocess": ("hairport.solver.pipeline", "preprocess"),
    "read_character": ("hairport.solver.io.character.load", "read_character"),
    "read_hair": ("hairport.solver.io.hair", "read_hair"),
    "read_hair_report": ("hairport.solver.io.hair", "read_hair_report"),
    "recorded_hair_units": ("hairport.solver.io.hair", "recorded_units"),
    "rescaled": ("hairport.solver.model.progress", "rescaled"),
    "resolve_skeleton_path": ("hairport.solver.io.character", "resolve_skeleton_path"),
    "retarget": ("hairport.solver.pipeline", "retarget"),
    "save_adaptable": ("hairport.solver.artifact", "save_adaptable"),
    "unit_scale": ("hairport.solver.model.units", "unit_scale"),
    "write_hair": ("hairport.solver.io.hair", "write_hair"),
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    try:
        module, attribute = _EXPORTS[name]
    except KeyError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    value = getattr(importlib.import_module(module), attribute)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return __all__
