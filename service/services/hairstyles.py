"""Hairstyles: a hair file made for a source character; preprocessing runs once per content."""

from __future__ import annotations

from fastapi import UploadFile

from hairport import solver
from hairport.records import (
    FAILED,
    QUEUED,
    BlobRef,
    CharacterRecord,
    HairstyleRecord,
    PreprocessSettings,
    artifact_key,
    now,
    owned_id,
)
from hairport.repository import Repository
from hairport.settings import Settings
from hairport.solver import options as solver_options
from hairport.worker.queue import QueueUnavailable, TaskQueue, new_task_id

from ..deps import owned
from ..errors import Problem
from ..schemas import HairstyleOut, PreprocessingOut
from ..uploads import check_units, extension_of, input_problem, store_upload, validated

#: seconds a client should wait before trying again when the task queue is away (Retry-After)
RETRY_AFTER_SECONDS = 10


def queue_unavailable(error: QueueUnavailable) -> Problem:
    """503 ``queue_unavailable``: the broker did not take the request's task; nothing was kept."""
    return Problem(503, "queue_unavailable", f"the task queue is unavailable ({error}); nothing was started, "
                                             f"try again in {RETRY_AFTER_SECONDS} s",
                   headers={"Retry-After": str(RETRY_AFTER_SECONDS)})


def preprocessing_settings(k: int, guides: int | None, anchoring: str,
                           guides_from: str | None = None) -> PreprocessSettings:
    """Validated preprocessing options (``guides=None``: the solver's default)."""
    if guides is not None and guides_from is not None:
        raise Problem(422, "bad_option", "options: give guides or guides_from, not both")
    options = solver.PreprocessOptions(k=k, guides=solver_options.DEFAULT_GUIDES if guides is None else guides,
                                       anchoring=anchoring, guides_from=guides_from)
    try:
        options.validate()
    except solver.InputError as error:
        raise input_problem(error, "options") from None
    return PreprocessSettings(k=options.k, guides=options.guides, anchoring=options.anchoring,
                              guides_from=options.guides_from)


async def create_hairstyle(repository: Repository, queue: TaskQueue, settings: Settings, owner: str,
                           source_character_id: str, hair: UploadFile, units: str, k: int,
                           guides: int | None, anchoring: str, prim: str | None = None,
                           guides_from: str | None = None) -> HairstyleRecord:
    """Store and validate an uploaded hair file for the owner's character, and start its
    preprocessing unless an identical hairstyle was preprocessed already."""
    check_units(units)
    character: CharacterRecord = owned(repository, CharacterRecord, owner, source_character_id, "character")
    options = preprocessing_settings(k, guides, anchoring, guides_from)
    if options.anchoring == solver_options.ANCHOR_BY_BONES and not character.bones:
        raise Problem(422, "no_skeleton", "anchoring by bones needs a source character with a skeleton "
                                          "(skeleton JSON or glTF skin); anchor by the surface (anchoring surface or auto)")
    suffix = extension_of(hair, tuple(f".{name}" for name in solver.HAIR_FORMATS), "hair")
    blob = await store_upload(repository.storage, hair, settings, suffix, "hair")
    key = artifact_key(character, blob.sha256, units, options, solver.ARTIFACT_FORMAT_VERSION, prim)
    hairstyle_id = owned_id(character.owner, key)
    record = repository.get(HairstyleRecord, hairstyle_id)
    if record is None:
        try:
            # read as the solver will, fitted to its source character, its guide flags checked (module
            # notes of service/validation_child.py); in a process of the validation pool
            loaded = await validated(
                settings, "hair", "hair", hair=str(blob.path), units=units, prim=prim,
                limits={"max_strands": settings.max_strands, "max_particles": settings.max_particles,
                        "max_bytes": settings.max_upload_bytes, "memory_budget_bytes": settings.memory_budget_bytes},
                source=source_files(repository, settings, character), guides_from=guides_from,
                max_guides=solver_options.OPTION_RANGES["guides"].maximum,
            )
        except Problem:
            repository.storage.discard_new(blob)  # a refused upload keeps no file
            raise
        record = HairstyleRecord(
            id=hairstyle_id, owner=character.owner, created_at=now(), source_character_id=character.id,
            hair=BlobRef(sha256=blob.sha256, suffix=suffix, size=blob.size), format=suffix[1:],
            units=loaded["units"] or solver.AUTO,
            options=options, artifact_key=key, strands=loaded["strands"], particles=loaded["particles"], prim=prim,
        )
        repository.put(record, hairstyle_id)
    start_preprocessing(repository, queue, settings, record)
    return record


def source_files(repository: Repository, settings: Settings, character: CharacterRecord) -> dict | None:
    """What a validation needs to refuse a hair that does not sit on its source character (``units_mismatch``,
    ``hair_off_body``): the character's stored files, units, axes and read limits; None when its files were
    purged (the preprocessing reports it)."""
    storage = repository.storage
    mesh = storage.blob(character.mesh.sha256, character.mesh.suffix)
    skeleton = storage.blob(character.skeleton.sha256, character.skeleton.suffix) if character.skeleton else None
    if mesh is None or (character.skeleton is not None and skeleton is None):
        return None
    return {"mesh": str(mesh.path), "skeleton": str(skeleton.path) if skeleton else None, "units": character.units,
            "up": character.up_axis, "front": character.front_axis, "max_vertices": settings.max_vertices,
            "max_faces": settings.max_faces, "max_bytes": settings.max_file_bytes}


def start_preprocessing(repository: Repository, queue: TaskQueue, settings: Settings, hairstyle: HairstyleRecord,
                        variant: PreprocessSettings | None = None, key: str | None = None) -> bool:
    """Send the preprocessing of a hairstyle (or of its ``variant`` under ``key``) unless it is done or
    under way (a failed one is tried again); whether a task was sent. 503 ``queue_unavailable`` (the
    claim released) when the broker does not take it."""
    key = key or hairstyle.artifact_key
    if repository.preprocessing_status(hairstyle, key).state not in (QUEUED, FAILED):
        return False
    # a queued or running claim older than a job's time limit plus redelivery is stale (the sweeper
    # normally finds it first: a silent run or a lost message)
    options = None if variant is None else variant.model_dump()
    task_id = new_task_id()
    if not repository.claim_preprocessing(key, settings.task_time_limit + settings.visibility_timeout, hairstyle.id,
                                          options, task_id):
        return False
    try:
        queue.send_preprocess(hairstyle.id, options, task_id)
    except QueueUnavailable as error:
        repository.release_preprocessing(key, task_id)
        raise queue_unavailable(error) from None
    return True


def hairstyle_out(repository: Repository, record: HairstyleRecord) -> HairstyleOut:
    status = repository.preprocessing_status(record)
    return HairstyleOut.of(record, PreprocessingOut(state=status.state, error=status.error))
