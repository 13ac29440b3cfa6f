"""hairport's numerical core: retarget a strand hairstyle to another body, of the same topology or wrapped.

This module is the solver's public face. The command line, the worker and the service import the
names below from here, and otherwise only the solver's named public modules, each by its name:

- :mod:`~hairport.solver.options`: the options, their ranges and every choice they take;
- :mod:`~hairport.solver.display`: the dashboard's wire format;
- :mod:`~hairport.solver.documents`: hairline curve documents and the scenes a dashboard draws;
- :mod:`~hairport.solver.distributed`: a retarget's fine level solved in pieces elsewhere;
- :mod:`~hairport.solver.sequence`: one hairstyle onto a sequence of bodies, and animated files;
- :mod:`~hairport.solver.kernels`: the compiled kernels and their warm-up;
- :mod:`~hairport.solver.synthetic` and :mod:`~hairport.solver.render`: demo characters and grooms, pictures.

An import-linter contract (``pyproject.toml``) refuses any other import of a solver module from
outside the solver. The folder ``solver/`` is installed as ``hairport.solver``.

The stages (paper sections): :func:`preprocess` (source only: anchors Eq. 2, guides and
neighbours Eq. 8-9/14) gives an :class:`AdaptableHairstyle`; :func:`retarget` adapts it to a
target (initial transfer Eq. 3-6, optional hairline edit Sec. 6, shape adaptation Eq. 1 by
the multi-scale solve Sec. 5, or a baseline) and measures the result.
"""

from __future__ import annotations

from hairport.solver.model.lazy import lazy_exports

#: the public names, by the module (below ``hairport.solver``) that defines them, each imported on its first use
#: (:mod:`~hairport.solver.model.lazy`): a child process that reads one file loads its parser, not the solver
PUBLIC_NAMES: dict[str, tuple[str, ...]] = {
    "adaptable": ("AdaptableHairstyle",),
    "adaptation.loop.options": ("Cancelled",),
    "adaptation.source.guide_flags": ("flagged_guides", "with_guide_flags"),
    "artifact": ("ARTIFACT_EXTENSION:EXTENSION", "ARTIFACT_FORMAT_VERSION:FORMAT_VERSION", "load_adaptable",
                 "save_adaptable"),
    "budget": ("OVER_MEMORY_BUDGET", "check_memory"),
    "hairline.edit": ("HairlineEdit", "hairline_edit", "hairline_edit_from_request"),
    "inputs": ("SourceInputs", "canonical_source", "canonical_target", "edit_in_canonical", "hair_in_frame"),
    "io.character": ("MESH_EXTENSIONS", "resolve_skeleton_path"),
    "io.character.load": ("read_character",),
    "io.hair": ("HAIR_FORMATS:SUPPORTED_FORMATS", "ReadLimits", "format_for_path", "read_hair", "read_hair_report",
                "write_hair", "recorded_hair_units:recorded_units"),
    "mesh.collision": ("body_key", "collision_faces"),
    "model.character": ("Character",),
    "model.errors": ("InputError",),
    "model.files": ("FILE_MODE", "TEMP_SUFFIX", "atomic_write_bytes", "fsync_folder"),
    "model.frame": ("AUTO", "AXIS_CHOICES", "parse_axis"),
    "model.hair": ("Hair",),
    "model.landmarks": ("LandmarkPairs", "read_landmarks"),
    "model.progress": ("ProgressFn", "no_progress"),
    "model.units": ("UNITS",),
    "options": ("PreprocessOptions", "RetargetOptions"),
    "pipeline": ("RetargetResult", "penetrating_mask", "preprocess", "retarget"),
    "wrapping": ("WrappedTarget", "landmarks_in_canonical", "needs_wrap", "require_a_wrap_for", "wrap_key",
                 "wrap_target"),
}

__all__, __getattr__, __dir__ = lazy_exports(__name__, PUBLIC_NAMES)
