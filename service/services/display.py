"""What the dashboard draws: a job's strands (result or source) decimated, its bodies, its hairlines, and a
character's mesh, in the display wire format (:mod:`hairport.solver.display`)."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from hairport import solver
from hairport.records import FRAMES_OUTPUT, BlobRef, CharacterRecord, JobRecord
from hairport.repository import Repository
from hairport.settings import Settings
from hairport.solver import display, documents
from hairport.solver import options as solver_options
from hairport.solver import sequence as solver_sequence

from ..errors import Problem
from ..uploads import input_problem
from .jobs import outputs_of, require_sequence, stored_path

#: scenes kept loaded per API process (a 10^6-particle scene is ~13 MB): the viewer asks several times
SCENES_KEPT = 4


@lru_cache(maxsize=SCENES_KEPT)
def _scene(path: str, names: tuple[str, ...] | None) -> dict[str, np.ndarray]:
    return display.load_scene(path, names)


@lru_cache(maxsize=SCENES_KEPT)
def _source_scene(path: str) -> dict[str, np.ndarray]:
    return documents.source_scene(path)


def scene_path(repository: Repository, job: JobRecord) -> Path:
    """The job's saved scene (409 before it succeeded, or for a job run before scenes were saved)."""
    outputs = outputs_of(job)
    if "scene" not in outputs:
        raise Problem(409, "no_scene", f"job {job.id} ran before hairport saved what the dashboard draws; "
                                       "run the retarget again")
    return stored_path(repository, outputs["scene"])


def artifact_path(repository: Repository, job: JobRecord) -> Path:
    artifact = repository.artifact(job.artifact_key)
    if artifact is None:
        raise Problem(410, "gone", "the preprocessed hairstyle of this job was removed by the retention policy")
    return stored_path(repository, BlobRef(sha256=artifact.sha256, suffix=artifact.suffix))


@lru_cache(maxsize=SCENES_KEPT)
def _solved_frames(path: str) -> solver_sequence.SolvedFrames:
    return solver_sequence.SolvedFrames.load(path)


def _layer_arrays(repository: Repository, job: JobRecord, layer: str, names: tuple[str, ...],
                  frame: int | None = None) -> dict:
    """The arrays of a job's ``layer`` scene; of the result, at ``frame`` of a sequence (422 ``bad_frames`` for a
    frame of a job onto one body, of the source layer, or past the sequence's)."""
    if frame is not None:
        outputs = outputs_of(job)  # 409 before the job has outputs, as without a frame
        require_sequence(job)
        if layer != "result":
            raise Problem(422, "bad_frames", f"frame: the {layer} layer does not move; only the result has frames")
    try:
        if layer != "result":
            return _source_scene(str(artifact_path(repository, job)))
        scene = _scene(str(scene_path(repository, job)), names)
        if frame is None:
            return scene
        kept = _solved_frames(str(stored_path(repository, outputs[FRAMES_OUTPUT])))
        return kept.scene_at(scene, kept.check_frame(frame))
    except solver.InputError as error:
        raise input_problem(error, "frame" if error.code == "bad_frames" else "layer") from None


def strands(repository: Repository, job: JobRecord, layer: str, strand_count: int | None, stride: int | None,
            max_vertices: int, frame: int | None = None) -> bytes:
    """The job's ``layer`` strands (a sequence's result at ``frame``), decimated (422 for a plan over the display
    limits)."""
    arrays = _layer_arrays(repository, job, layer, ("points", "offsets", "inside", "crossing", "color"), frame)
    try:
        strand_ids, stride = display.plan_display(arrays["offsets"], max_vertices, strand_count, stride)
    except solver.InputError as error:
        raise input_problem(error, "strands") from None
    return display.strands_payload(arrays, strand_ids, stride, layer)


def body(repository: Repository, job: JobRecord, layer: str, frame: int | None = None) -> bytes:
    """The job's target body (as solved, hairport's frame; a sequence's at ``frame``), its source body, or the source
    body wrapped onto a target of another topology (409 ``no_wrap`` for a job whose target was not wrapped)."""
    if frame is not None and layer != "target":
        raise Problem(422, "bad_frames", f"frame: the {layer} body does not move; only the target has frames")
    if layer == "target":
        arrays = _layer_arrays(repository, job, "result", ("body_vertices", "body_faces"), frame)
    elif layer == "wrapped":
        arrays = _wrapped_arrays(repository, job)
    else:
        arrays = _layer_arrays(repository, job, "source", ())
    return display.body_payload(arrays["body_vertices"], arrays["body_faces"], layer, up=[0.0, 1.0, 0.0])


def _wrapped_arrays(repository: Repository, job: JobRecord) -> dict[str, np.ndarray]:
    """The scene's wrapped body, named as the other bodies are."""
    scene = _layer_arrays(repository, job, "result", display.WRAPPED_ARRAYS)
    if not display.scene_has_wrap(scene):
        raise Problem(409, "no_wrap", f"the target of job {job.id} was not wrapped: it has the source's mesh "
                                      "topology (or options.wrap was off), so the target body is the one drawn")
    vertices, faces = (scene[name] for name in display.WRAPPED_ARRAYS)
    return {"body_vertices": vertices, "body_faces": faces}


def hairline(repository: Repository, job: JobRecord) -> dict:
    """The target's current front hairline, each preset's edit of it, and the rotation to the groom's axes."""
    names = ("hairline_points", "hairline_turning", "groom_rotation", "meta",
             *(display.scene_preset_array(name) for name in solver_options.HAIRLINE_PRESETS))
    scene = _scene(str(scene_path(repository, job)), names)
    meta = display.scene_meta(scene)
    if meta.get("hairline_error"):
        raise Problem(409, "no_hairline", f"the groom of job {job.id} has no front hairline to edit: "
                                          f"{meta['hairline_error']}")
    return {**display.hairline_json(scene), "groom_units": meta.get("groom_units", "m")}


def character_mesh(repository: Repository, settings: Settings, character: CharacterRecord) -> bytes:
    """A character's mesh as uploaded (its own units and axes), with the up vector to draw it with."""
    path = stored_path(repository, character.mesh)
    try:
        loaded, units = solver.read_character(path, units=None if character.units in (None, solver.AUTO)
                                              else character.units, max_vertices=settings.max_vertices,
                                              max_faces=settings.max_faces, max_bytes=settings.max_file_bytes)
    except solver.InputError as error:
        raise input_problem(error, "mesh") from None
    up, how = display.display_up(loaded.vertices, character.up_axis)
    return display.body_payload(loaded.vertices, loaded.faces, "character", up=up, up_found=how, units=units)

