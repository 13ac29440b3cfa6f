"""What a job's run reads: stored characters, grooms and artifacts, by record, and the error a job reports.

Shared by the job bodies of :mod:`.runner` and the fine-level chunks of :mod:`.fine`.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

from celery.exceptions import SoftTimeLimitExceeded

from hairport import solver
from hairport.messages import safe_detail
from hairport.records import ArtifactRecord, BlobRef, CharacterRecord, ErrorInfo, HairstyleRecord, JobRecord
from hairport.repository import Repository
from hairport.settings import Settings
from hairport.solver import options as solver_options
from hairport.storage import Blob

#: error code of a job or preprocessing that needed more memory than ``Settings.memory_budget_bytes``
OVER_MEMORY_BUDGET = "over_memory_budget"


def stored(blob: Blob, suffix: str) -> BlobRef:
    """The reference a record keeps of a stored output."""
    return BlobRef(sha256=blob.sha256, suffix=suffix, size=blob.size)


def limits(settings: Settings) -> dict:
    return dict(max_vertices=settings.max_vertices, max_faces=settings.max_faces, max_bytes=settings.max_file_bytes)


def blob_path(repository: Repository, ref: BlobRef | None) -> Path | None:
    """The local path of a stored input, or an ``InputError`` (code ``gone``) if retention removed it."""
    if ref is None:
        return None
    blob = repository.storage.blob(ref.sha256, ref.suffix)
    if blob is None:
        raise solver.InputError("a stored input is gone (purged by retention?)", ref.sha256[:12], "gone")
    return blob.path


def load_character(repository: Repository, settings: Settings,
                   character_id: str) -> tuple[solver.Character, str | None, CharacterRecord]:
    """The character of a record, loaded from its stored files: in meters when its units are
    given or stated by its files (the units are returned), else in the file's own (None)."""
    record = repository.get(CharacterRecord, character_id)
    if record is None:
        raise solver.InputError(f"character {character_id} does not exist", code="not_found")
    character, units = solver.read_character(
        blob_path(repository, record.mesh), skeleton_path=blob_path(repository, record.skeleton),
        units=None if record.units == solver.AUTO else record.units, **limits(settings),
    )
    return character, units, record


def read_source(repository: Repository, settings: Settings, hairstyle: HairstyleRecord) -> solver.SourceInputs:
    """A hairstyle's source character and hair, in hairport's frame (see :func:`hairport.solver.canonical_source`)."""
    source, source_units, character = load_character(repository, settings, hairstyle.source_character_id)
    path = blob_path(repository, hairstyle.hair)
    units = hairstyle.units if hairstyle.units not in (None, solver.AUTO) else (
        solver.recorded_hair_units(path, hairstyle.format))
    hair = solver.read_hair(path, units=units or "m", format=hairstyle.format, prim=hairstyle.prim,
                            limits=solver.ReadLimits(settings.max_strands, settings.max_particles,
                                                     settings.max_file_bytes,
                                                     memory_budget_bytes=settings.memory_budget_bytes))
    return solver.canonical_source(source, hair, source_units=source_units, hair_units=units,
                                   up=character.up_axis, front=character.front_axis)


@lru_cache(maxsize=2)
def adaptable_at(path: str) -> solver.AdaptableHairstyle:
    # one worker process retargets one groom onto many bodies: keep the last artifacts loaded
    return solver.load_adaptable(path)


def artifact_adaptable(repository: Repository, artifact: ArtifactRecord) -> solver.AdaptableHairstyle:
    """The adaptable hairstyle an artifact record stores (kept loaded: :func:`adaptable_at`)."""
    return adaptable_at(str(blob_path(repository, BlobRef(sha256=artifact.sha256, suffix=artifact.suffix))))


def job_options(settings: Settings, job: JobRecord, frame, landmarks=None) -> solver.RetargetOptions:
    """A job's retarget options: its request's, the worker's thread count, its hairline edit with canonical axes
    (a drawn curve is read in the groom's ``frame``, as the result is written), and ``landmarks``."""
    edit = None if job.hairline is None else solver.hairline_edit_from_request(job.hairline)
    return solver.RetargetOptions(**job.options, workers=settings.solver_workers,
                                  hairline=solver.edit_in_canonical(frame, edit), landmarks=landmarks)


def error_info(error: BaseException, soft_time_limit: float) -> ErrorInfo:
    """What a failed job or preprocessing reports: the problem of bad input, else the exception."""
    if isinstance(error, solver.InputError):
        # the problem only: the source of a stored input is a storage path, meaningless to the caller
        return ErrorInfo(code=error.code or "bad_input", message=safe_detail(error.problem))
    if isinstance(error, SoftTimeLimitExceeded):
        return ErrorInfo(code="time_limit", message=f"the job ran over its time limit ({soft_time_limit:g} s)")
    if isinstance(error, MemoryError):
        return ErrorInfo(code=OVER_MEMORY_BUDGET, message="the job needed more memory than a job may use "
                                                          "(HAIRPORT_MEMORY_BUDGET_BYTES)")
    return ErrorInfo(code="internal", message=safe_detail(f"{type(error).__name__}: {error}"))


def job_inputs(repository: Repository, settings: Settings, job: JobRecord, artifact: ArtifactRecord
               ) -> tuple[solver.AdaptableHairstyle, solver.Character, dict]:
    """A job's adaptable hairstyle and target character (in hairport's frame), and what reading the target found."""
    adaptable = artifact_adaptable(repository, artifact)
    target, units, character = load_character(repository, settings, job.target_character_id)
    target, target_input = solver.canonical_target(adaptable.source, target, units=units, up=character.up_axis,
                                                   front=character.front_axis)
    return adaptable, target, target_input


def explained(error: solver.InputError, mode: str, found: dict) -> solver.InputError:
    """A job's refusal of its target in the API's terms: a ``topology_mismatch`` under ``options.wrap`` off says
    that the default would have wrapped it; a ``wrap_failed`` names the axes the target was read in when they
    were fitted (``found``: ``canonical_target``'s report), the likeliest cause. Other errors as they are."""
    off, auto = solver_options.WRAP_MODES[2], solver_options.WRAP_MODES[0]
    if error.code == "topology_mismatch" and mode == off:
        return solver.InputError(f"{error.problem}; options.wrap {off} keeps to the source's topology (wrap {auto} "
                                 "wraps the source body onto this target)", error.source, error.code)
    if error.code == "wrap_failed" and found.get("axes_how") not in (None, "given"):
        # first: a job's message is cut at MAX_DETAIL_CHARS
        return solver.InputError(f"the target was read with up {found['up']} and front {found['front']} (fitted; "
                                 f"give the character's up_axis and front_axis if those are wrong): {error.problem}",
                                 error.source, error.code)
    return error
