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

from hairport.solver.adaptable import AdaptableHairstyle
from hairport.solver.adaptation.loop.options import Cancelled
from hairport.solver.adaptation.source.guide_flags import flagged_guides, with_guide_flags
from hairport.solver.artifact import EXTENSION as ARTIFACT_EXTENSION
from hairport.solver.artifact import FORMAT_VERSION as ARTIFACT_FORMAT_VERSION
from hairport.solver.artifact import load_adaptable, save_adaptable
from hairport.solver.budget import OVER_MEMORY_BUDGET, check_memory
from hairport.solver.hairline.edit import HairlineEdit, hairline_edit, hairline_edit_from_request
from hairport.solver.inputs import SourceInputs, canonical_source, canonical_target, edit_in_canonical, hair_in_frame
from hairport.solver.io.character import MESH_EXTENSIONS, resolve_skeleton_path
from hairport.solver.io.character.load import read_character
from hairport.solver.io.hair import SUPPORTED_FORMATS as HAIR_FORMATS
from hairport.solver.io.hair import ReadLimits, format_for_path, read_hair, read_hair_report, write_hair
from hairport.solver.io.hair import recorded_units as recorded_hair_units
from hairport.solver.mesh.collision import body_key, collision_faces
from hairport.solver.model.character import Character
from hairport.solver.model.errors import InputError
from hairport.solver.model.files import FILE_MODE, TEMP_SUFFIX, atomic_write_bytes, fsync_folder
from hairport.solver.model.frame import AUTO, AXIS_CHOICES, parse_axis
from hairport.solver.model.hair import Hair
from hairport.solver.model.landmarks import LandmarkPairs, read_landmarks
from hairport.solver.model.progress import ProgressFn, no_progress
from hairport.solver.model.units import UNITS
from hairport.solver.options import PreprocessOptions, RetargetOptions
from hairport.solver.pipeline import RetargetResult, penetrating_mask, preprocess, retarget
from hairport.solver.wrapping import (
    WrappedTarget,
    landmarks_in_canonical,
    needs_wrap,
    require_a_wrap_for,
    wrap_key,
    wrap_target,
)

__all__ = [
    "ARTIFACT_EXTENSION", "ARTIFACT_FORMAT_VERSION", "AUTO", "AXIS_CHOICES", "AdaptableHairstyle", "Cancelled",
    "Character", "FILE_MODE", "HAIR_FORMATS", "Hair", "HairlineEdit", "InputError", "MESH_EXTENSIONS",
    "OVER_MEMORY_BUDGET", "PreprocessOptions", "ProgressFn", "ReadLimits", "RetargetOptions", "RetargetResult",
    "SourceInputs", "TEMP_SUFFIX", "UNITS", "atomic_write_bytes", "body_key", "canonical_source", "canonical_target",
    "check_memory", "collision_faces", "edit_in_canonical", "flagged_guides", "format_for_path", "fsync_folder",
    "hair_in_frame", "hairline_edit", "hairline_edit_from_request", "load_adaptable", "no_progress", "parse_axis",
    "penetrating_mask", "preprocess", "read_character", "read_hair", "read_hair_report", "recorded_hair_units",
    "resolve_skeleton_path", "retarget", "save_adaptable", "with_guide_flags", "write_hair", "WrappedTarget",
    "needs_wrap", "wrap_key", "wrap_target", "LandmarkPairs", "read_landmarks", "landmarks_in_canonical",
    "require_a_wrap_for",
]
