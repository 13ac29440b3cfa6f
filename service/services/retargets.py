"""Retargets: one job per target character; an ``Idempotency-Key`` makes a repeated request safe."""

from __future__ import annotations

from hairport import solver
from hairport.records import (
    CharacterRecord,
    HairstyleRecord,
    IdempotencyRecord,
    JobRecord,
    PreprocessSettings,
    digest,
    new_job_id,
    now,
    owned_id,
)
from hairport.repository import Repository
from hairport.settings import Settings
from hairport.worker.queue import QueueUnavailable, TaskQueue, new_task_id

from ..deps import owned
from ..errors import Problem
from ..schemas import RetargetIn
from ..uploads import input_problem
from .hairstyles import queue_unavailable, start_preprocessing

#: longest Idempotency-Key accepted (characters)
MAX_IDEMPOTENCY_KEY = 200


def create_retargets(repository: Repository, queue: TaskQueue, settings: Settings, owner: str, request: RetargetIn,
                     idempotency_key: str | None) -> list[JobRecord]:
    """Create and send one job per target (or replay the jobs of an earlier request with the same key)."""
    body = request.model_dump(mode="json")
    replay_id = None
    if idempotency_key is not None:
        if not 0 < len(idempotency_key) <= MAX_IDEMPOTENCY_KEY:
            raise Problem(422, "bad_idempotency_key", f"Idempotency-Key must have 1-{MAX_IDEMPOTENCY_KEY} characters")
        replay_id = owned_id(owner, digest("idempotency", idempotency_key))
        previous = repository.get(IdempotencyRecord, replay_id)
        if previous is not None:
            if previous.request != digest(body):
                raise Problem(422, "idempotency_conflict", "this Idempotency-Key was used with a different request")
            return [job for job in map(repository.job, previous.jobs) if job is not None]
    if len(request.target_character_ids) > settings.max_targets_per_request:
        raise Problem(422, "too_many_targets", f"at most {settings.max_targets_per_request} targets per request, "
                                               f"got {len(request.target_character_ids)}")
    hairstyle: HairstyleRecord = owned(repository, HairstyleRecord, owner, request.hairstyle_id, "hairstyle")
    targets = [owned(repository, CharacterRecord, owner, target_id, "character")
               for target_id in request.target_character_ids]
    options = request.options.model_dump()
    guides = options.pop("guides")  # a guide count asks for k-means guides, even of a hairstyle with flagged ones
    variant = PreprocessSettings(k=options.pop("k") or hairstyle.options.k,
                                 guides=guides or hairstyle.options.guides, anchoring=hairstyle.options.anchoring,
                                 guides_from=None if guides else hairstyle.options.guides_from)
    check_options(options, variant, body["hairline"])
    try:
        solver.check_memory(hairstyle.particles, settings.memory_budget_bytes, k=variant.k)
    except solver.InputError as error:
        raise input_problem(error, "options") from None
    key = (hairstyle.artifact_key if variant == hairstyle.options
           else repository.variant_key(hairstyle, variant, solver.ARTIFACT_FORMAT_VERSION))
    jobs = []
    for target in targets:
        job = JobRecord(
            id=new_job_id(), owner=owner, hairstyle_id=hairstyle.id, target_character_id=target.id, options=options,
            hairline=body["hairline"], preprocess_options=variant, artifact_key=key,
            output_format=request.output_format, flag_guides=request.flag_guides, created_at=now(), updated_at=now(),
            task_id=new_task_id(),
            enqueued_at=now(),
        )
        repository.create_job(job)
        jobs.append(job)
    if replay_id is not None:
        repository.put(IdempotencyRecord(request=digest(body), jobs=[job.id for job in jobs], created_at=now()),
                       replay_id)
    try:
        start_preprocessing(repository, queue, settings, hairstyle, None if key == hairstyle.artifact_key else variant,
                            key)
        for job in jobs:
            queue.send_retarget(job.id, job.task_id)
    except QueueUnavailable as error:
        # nothing of this request stays: a retry (with the same Idempotency-Key) starts afresh; a message
        # already sent finds no record and does nothing
        if replay_id is not None:
            repository.storage.delete_record(IdempotencyRecord.KIND, replay_id)
        for job in jobs:
            repository.delete_job(job)
        raise queue_unavailable(error) from None
    return jobs


def check_options(options: dict, variant: PreprocessSettings, hairline: dict | None) -> None:
    """422 for options the solver would refuse (named after the request field)."""
    try:
        solver.RetargetOptions(**options).validate()
        solver.PreprocessOptions(**variant.model_dump()).validate()
    except solver.InputError as error:
        raise input_problem(error, "options") from None
    if hairline is not None:
        try:
            solver.RetargetOptions(**options, hairline=solver.hairline_edit_from_request(hairline)).validate()
        except solver.InputError as error:
            raise input_problem(error, "hairline") from None
