"""Retargets: one job per target character; an ``Idempotency-Key`` makes a repeated request safe.

:func:`plan_job` checks one hairstyle x target pair and its options and makes its job record;
:func:`submit_jobs` stores planned jobs and sends them (or keeps nothing when the broker does
not answer). Batches (:mod:`.batches`) plan a grid of pairs with the same two steps.
"""

from __future__ import annotations

from dataclasses import dataclass

from hairport import solver
from hairport.records import (
    FROM_CHARACTERS,
    CharacterRecord,
    HairstyleRecord,
    IdempotencyRecord,
    JobRecord,
    PreprocessSettings,
    SequencePlan,
    digest,
    new_job_id,
    now,
    owned_id,
)
from hairport.repository import Repository
from hairport.settings import Settings
from hairport.solver import options as solver_options
from hairport.solver import sequence as solver_sequence
from hairport.worker.queue import QueueUnavailable, TaskQueue, new_task_id

from ..deps import MAX_IDEMPOTENCY_KEY, owned
from ..errors import Problem
from ..schemas import RetargetIn, RetargetOptionsIn
from ..uploads import input_problem
from . import sequences
from .hairstyles import queue_unavailable, start_preprocessing


@dataclass
class PlannedJob:
    """A job ready to be stored and sent, with the hairstyle and the artifact it needs."""

    job: JobRecord
    hairstyle: HairstyleRecord
    variant: PreprocessSettings
    key: str


def idempotent_replay(repository: Repository, owner: str, idempotency_key: str | None,
                      body: dict) -> tuple[str | None, IdempotencyRecord | None]:
    """The id under which a request with ``idempotency_key`` is remembered, and the earlier request's record
    when there is one (422 when that earlier request differs from ``body``)."""
    if idempotency_key is None:
        return None, None
    if not 0 < len(idempotency_key) <= MAX_IDEMPOTENCY_KEY:
        raise Problem(422, "bad_idempotency_key", f"Idempotency-Key must have 1-{MAX_IDEMPOTENCY_KEY} characters")
    replay_id = owned_id(owner, digest("idempotency", idempotency_key))
    previous = repository.get(IdempotencyRecord, replay_id)
    if previous is not None and previous.request != digest(body):
        raise Problem(422, "idempotency_conflict", "this Idempotency-Key was used with a different request")
    return replay_id, previous


def create_retargets(repository: Repository, queue: TaskQueue, settings: Settings, owner: str, request: RetargetIn,
                     idempotency_key: str | None) -> list[JobRecord]:
    """Create and send one job per target (or replay the jobs of an earlier request with the same key)."""
    body = request.model_dump(mode="json")
    replay_id, previous = idempotent_replay(repository, owner, idempotency_key, body)
    if previous is not None:
        return [job for job in map(repository.job, previous.jobs) if job is not None]
    frames_of_characters = request.sequence is not None and request.sequence.frames_from == FROM_CHARACTERS
    most = solver_sequence.MAX_FRAMES if frames_of_characters else settings.max_targets_per_request
    if len(request.target_character_ids) > most:
        raise Problem(422, "too_many_targets", f"at most {most} targets per request, "
                                               f"got {len(request.target_character_ids)}")
    hairstyle: HairstyleRecord = owned(repository, HairstyleRecord, owner, request.hairstyle_id, "hairstyle")
    targets = [owned(repository, CharacterRecord, owner, target_id, "character")
               for target_id in request.target_character_ids]
    if request.landmarks is not None and len(targets) > 1:
        raise Problem(422, "bad_landmarks", f"landmarks name points on one target; this request has {len(targets)}: "
                                            "send one request per target")
    output_format = sequences.output_format(request.output_format, request.sequence)
    if request.sequence is None:
        jobs = [(target, None) for target in targets]
    else:
        jobs = sequences.sequence_plans(request.sequence, targets, hairstyle, request.options, settings,
                                        body["landmarks"])
    planned = [plan_job(repository, settings, owner, hairstyle, target, request.options, body["hairline"],
                        output_format, request.flag_guides, landmarks=body["landmarks"], sequence=plan)
               for target, plan in jobs]
    remember = None if replay_id is None else (replay_id, IdempotencyRecord(
        request=digest(body), jobs=[plan.job.id for plan in planned], created_at=now()))
    submit_jobs(repository, queue, settings, planned, remember)
    return [plan.job for plan in planned]


def plan_job(repository: Repository, settings: Settings, owner: str, hairstyle: HairstyleRecord,
             target: CharacterRecord, options_in: RetargetOptionsIn, hairline: dict | None, output_format: str,
             flag_guides: bool, batch_id: str | None = None, landmarks: dict | None = None,
             sequence: SequencePlan | None = None) -> PlannedJob:
    """The job of one pair, its options checked (422 for what the solver would refuse, named after the field)."""
    options = options_in.model_dump()
    if sequence is not None and "spacing" not in options_in.model_fields_set:
        options["spacing"] = solver_options.SEQUENCE_SPACING  # a sequence's own default, shown in the job's options
    guides = options.pop("guides")  # a guide count asks for k-means guides, even of a hairstyle with flagged ones
    variant = PreprocessSettings(k=options.pop("k") or hairstyle.options.k,
                                 guides=guides or hairstyle.options.guides, anchoring=hairstyle.options.anchoring,
                                 guides_from=None if guides else hairstyle.options.guides_from)
    check_options(options, variant, hairline)
    check_landmarks(options, landmarks)
    try:
        solver.check_memory(hairstyle.particles, settings.memory_budget_bytes, k=variant.k)
    except solver.InputError as error:
        raise input_problem(error, "options") from None
    key = (hairstyle.artifact_key if variant == hairstyle.options
           else repository.variant_key(hairstyle, variant, solver.ARTIFACT_FORMAT_VERSION))
    job = JobRecord(
        id=new_job_id(), owner=owner, hairstyle_id=hairstyle.id, target_character_id=target.id, options=options,
        hairline=hairline, landmarks=landmarks, preprocess_options=variant, artifact_key=key,
        output_format=output_format,
        flag_guides=flag_guides, created_at=now(), updated_at=now(), task_id=new_task_id(), enqueued_at=now(),
        batch_id=batch_id, sequence=sequence,
    )
    return PlannedJob(job, hairstyle, variant, key)


def submit_jobs(repository: Repository, queue: TaskQueue, settings: Settings, planned: list[PlannedJob],
                remember: tuple[str, IdempotencyRecord] | None = None, undo=None) -> None:
    """Store the planned jobs (and the idempotency record), start each artifact's preprocessing once, send the
    jobs. When the broker does not take a task nothing of the request stays (``undo()`` removes the caller's
    own records) and the answer is 503: a retry starts afresh; a message already sent finds no record."""
    for plan in planned:
        repository.create_job(plan.job)
    if remember is not None:
        repository.put(remember[1], remember[0])
    try:
        started = set()
        for plan in planned:
            if plan.key not in started:
                started.add(plan.key)
                start_preprocessing(repository, queue, settings, plan.hairstyle,
                                    None if plan.key == plan.hairstyle.artifact_key else plan.variant, plan.key)
        for plan in planned:
            queue.send_retarget(plan.job.id, plan.job.task_id)
    except QueueUnavailable as error:
        if remember is not None:
            repository.storage.delete_record(IdempotencyRecord.KIND, remember[0])
        for plan in planned:
            repository.delete_job(plan.job)
        if undo is not None:
            undo()
        raise queue_unavailable(error) from None


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


def check_landmarks(options: dict, landmarks: dict | None) -> None:
    """422 for landmarks the solver would refuse: names on one side only, or with the wrap off."""
    if landmarks is None:
        return
    try:
        solver.RetargetOptions(**options, landmarks=solver.LandmarkPairs.from_document(landmarks)).validate()
    except solver.InputError as error:
        raise input_problem(error, "landmarks") from None
