"""The job bodies: plain functions the Celery tasks wrap (and unit tests call).

Each loads its inputs by record id, calls the solver's public face, stores the outputs and
the record's new state. Bad input (:class:`hairport.solver.InputError`) fails the job at once
with its message; transient errors (I/O, the broker) propagate for the task to retry. Outputs
are written to a private work directory and stored only when everything succeeded, so a job
that fails, is cancelled or loses its worker leaves no partial result.
"""

from __future__ import annotations

import json
import logging
import time
import traceback

from celery.exceptions import SoftTimeLimitExceeded

from hairport import solver
from hairport.outputs import OutputSet, add_result, json_default
from hairport.records import (
    CANCELLED,
    FAILED,
    LOSSLESS_OUTPUT,
    QUEUED,
    READY,
    RUNNING,
    SUCCEEDED,
    TERMINAL_STATES,
    WAITING_STATES,
    ArtifactRecord,
    BlobRef,
    ErrorInfo,
    HairstyleRecord,
    JobRecord,
    PreprocessingRecord,
    PreprocessSettings,
    now,
)
from hairport.repository import Repository
from hairport.settings import Settings
from hairport.solver import display, distributed, documents
from hairport.storage import retention_seconds

from . import bodies, sequences, wraps
from .fine import FineDispatch, SpreadFineLevel
from .loading import artifact_adaptable, error_info, explained, job_inputs, job_options, read_source, stored
from .runs import TRANSIENT_ERRORS, Heartbeat, OwnRun, run_gone, start_run

#: a running job writes its progress at most this often (s)
PROGRESS_INTERVAL_SECONDS = 0.5
#: a worker purges expired files at most this often (s), after a job
PURGE_INTERVAL_SECONDS = 3600.0
#: a retarget waits for its hairstyle's preprocessing this many checks at most (then fails)
PREPROCESS_POLL_LIMIT = 1800

log = logging.getLogger(__name__)


class PreprocessingPending(Exception):
    """The job's hairstyle is still being preprocessed: run the job again later."""


def run_preprocess(repository: Repository, settings: Settings, hairstyle_id: str, options: dict | None = None,
                   task_id: str | None = None, worker: str = "") -> None:
    """Compute (once) the adaptable hairstyle of a hairstyle record (with its options, or ``options``)."""
    hairstyle = repository.get(HairstyleRecord, hairstyle_id)
    if hairstyle is None:
        return
    if options is None:
        variant, key = hairstyle.options, hairstyle.artifact_key
    else:
        variant = PreprocessSettings.model_validate(options)
        key = repository.variant_key(hairstyle, variant, solver.ARTIFACT_FORMAT_VERSION)
    if repository.exists(ArtifactRecord, key):
        repository.set_preprocessing(key, READY)
        return
    if not repository.exists(PreprocessingRecord, key):  # a message sent without a claim (an older API)
        repository.put(PreprocessingRecord(key=key, state=QUEUED, task_id=task_id, hairstyle_id=hairstyle_id,
                                           options=options, updated_at=now()), key)
    run = start_run(lambda change: repository.change_preprocessing(key, change), settings, task_id, worker,
                    "its preprocessing", (QUEUED,))
    if run is None:
        return
    began = time.perf_counter()
    try:
        with Heartbeat(run.beat, settings.heartbeat_seconds):
            inputs = read_source(repository, settings, hairstyle)
            adaptable = solver.preprocess(inputs.source, inputs.hair, solver.PreprocessOptions(**variant.model_dump()),
                                          frame=inputs.frame, input_report=inputs.report)
            blob = repository.storage.save_written(lambda path: solver.save_adaptable(adaptable, path),
                                                   solver.ARTIFACT_EXTENSION)
        repository.put(ArtifactRecord(
            key=key, sha256=blob.sha256, suffix=solver.ARTIFACT_EXTENSION, size=blob.size,
            format_version=solver.ARTIFACT_FORMAT_VERSION, seconds=time.perf_counter() - began,
            guides=int(len(adaptable.multiscale.guides)), created_at=now(),
        ), key)
        run.write(state=READY, error=None, seconds=time.perf_counter() - began)
    except TRANSIENT_ERRORS:
        run.release()
        raise
    except Exception as error:  # noqa: BLE001 - every other failure is this hairstyle's, reported on it
        run.write(state=FAILED, error=error_info(error, settings.task_soft_time_limit))
        if not isinstance(error, solver.InputError):
            traceback.print_exc()


class JobProgress:
    """Writes a job's stage and progress to its record, at most every PROGRESS_INTERVAL_SECONDS,
    and reads its cancellation flag as often (a :data:`hairport.solver.ProgressFn`)."""

    def __init__(self, repository: Repository, job_id: str, run: OwnRun | None = None):
        self.repository, self.job_id, self.run = repository, job_id, run
        self.last_write = 0.0
        self.last_check = 0.0
        self.stage = None
        self.cancelled = False

    def __call__(self, stage: str, fraction: float, message: str) -> None:
        moment = time.monotonic()
        if stage != self.stage or moment - self.last_write >= PROGRESS_INTERVAL_SECONDS:
            self.stage, self.last_write = stage, moment
            fields = dict(stage=stage, progress=round(float(fraction), 4), message=message)
            if self.run is None:
                self.repository.set_job(self.job_id, **fields)
            elif not self.run.write(**fields, heartbeat_at=now()):
                self.cancelled = True  # another run took the job over: stop

    def should_stop(self) -> bool:
        moment = time.monotonic()
        if moment - self.last_check >= PROGRESS_INTERVAL_SECONDS:
            self.last_check = moment
            job = self.repository.job(self.job_id)
            taken_over = self.run is not None and (job is None or job.run_token != self.run.token)
            self.cancelled = self.cancelled or job is None or job.cancel_requested or taken_over
        return self.cancelled


def run_retarget(repository: Repository, settings: Settings, job_id: str, worker: str, polls: int = 0,
                 task_id: str | None = None, chunks: FineDispatch | None = None) -> None:
    """Retarget one hairstyle onto one target character (one job record), if the message ``task_id`` is
    the job's current one and no live run has it (see :mod:`.runs`). With ``chunks`` (how to send and
    revoke ``fine`` tasks), a large multi-scale fine level is spread over the workers (:mod:`.fine`).

    Raises :class:`PreprocessingPending` while the hairstyle is being preprocessed (after
    ``polls`` earlier checks; the job fails with ``preprocess_timeout`` after
    :data:`PREPROCESS_POLL_LIMIT`)."""
    job = repository.job(job_id)
    if job is None or job.state in TERMINAL_STATES:
        return
    if task_id is not None and job.task_id not in (None, task_id):
        log.info("job %s: message %s is not the job's current one (%s): nothing to do", job_id, task_id, job.task_id)
        return
    if job.cancel_requested and job.state in WAITING_STATES:
        repository.set_job(job_id, state=CANCELLED, finished_at=now())
        return
    if job.state == RUNNING and not run_gone(job, settings.stale_after_seconds, job.started_at):
        log.info("job %s is running on %s: a duplicate delivery, nothing to do", job_id, job.worker)
        return
    hairstyle = repository.get(HairstyleRecord, job.hairstyle_id)
    key = job.artifact_key
    artifact = repository.artifact(key) if hairstyle is not None else None
    if artifact is None:
        status = repository.preprocessing_status(hairstyle, key) if hairstyle is not None else None
        if status is None or status.state == FAILED:
            reason = status.error.message if status is not None and status.error is not None else "it is gone"
            repository.set_job(job_id, state=FAILED, finished_at=now(), error=ErrorInfo(
                code="preprocess_failed", message=f"the hairstyle could not be preprocessed: {reason}"))
            return
        if polls >= PREPROCESS_POLL_LIMIT:
            repository.set_job(job_id, state=FAILED, finished_at=now(), error=ErrorInfo(
                code="preprocess_timeout", message="the hairstyle's preprocessing did not finish"))
            return
        repository.set_job(job_id, stage="waiting_for_preprocessing", progress=0.0)
        raise PreprocessingPending(key)

    try:  # pre-flight: refuse what cannot fit before the artifact is loaded (the budget may have shrunk)
        solver.check_memory(hairstyle.particles, settings.memory_budget_bytes, k=job.preprocess_options.k)
    except solver.InputError as error:
        repository.set_job(job_id, state=FAILED, finished_at=now(), error=error_info(error, 0))
        return
    run = start_run(lambda change: repository.change_job(job_id, change), settings, task_id, worker, "it",
                    WAITING_STATES, dict(stage="loading", progress=0.0, started_at=now()))
    if run is None:
        return
    progress = JobProgress(repository, job_id, run)
    began = time.perf_counter()
    try:
        with Heartbeat(run.beat, settings.heartbeat_seconds):
            if job.sequence is None:
                spread = SpreadFineLevel(repository, settings, job_id, run, worker, chunks)
                outputs, metrics, timings = _retarget_and_store(repository, settings, job, artifact, progress, spread)
            else:
                outputs, metrics, timings = _sequence_and_store(repository, settings, job, artifact, progress, run)
        timings = {**timings, "job": time.perf_counter() - began}
        run.write(state=SUCCEEDED, stage="done", progress=1.0, message="done", finished_at=now(),
                  metrics=_jsonable(metrics), timings=timings, outputs=outputs)
        repository.purge_if_due(retention_seconds(settings.retention_days), PURGE_INTERVAL_SECONDS)
    except solver.Cancelled:
        run.write(state=CANCELLED, stage="cancelled", finished_at=now())
    except TRANSIENT_ERRORS:
        run.release()
        raise
    except Exception as error:  # noqa: BLE001 - the job fails with a reason; the worker lives on
        run.write(state=FAILED, finished_at=now(), error=error_info(error, settings.task_soft_time_limit))
        if not isinstance(error, (solver.InputError, SoftTimeLimitExceeded, MemoryError)):
            traceback.print_exc()


def _sequence_and_store(repository: Repository, settings: Settings, job: JobRecord, artifact: ArtifactRecord,
                        progress: JobProgress, run: OwnRun) -> tuple[dict[str, BlobRef], dict, dict]:
    """A sequence job's frames solved and its outputs stored (:mod:`.sequences`): outputs, metrics, timings."""
    return sequences.solve_and_store(repository, settings, job, artifact_adaptable(repository, artifact), progress,
                                     run.write)


def _retarget_and_store(repository: Repository, settings: Settings, job: JobRecord, artifact: ArtifactRecord,
                        progress: JobProgress, fine_runner) -> tuple[dict[str, BlobRef], dict, dict]:
    adaptable, target, target_input = job_inputs(repository, settings, job, artifact)
    landmarks = None if job.landmarks is None else solver.landmarks_in_canonical(
        solver.LandmarkPairs.from_document(job.landmarks), adaptable, target_input)
    options = job_options(settings, job, adaptable.frame, landmarks)
    surface, cache_timings = bodies.collision_surface(repository, settings, target)
    wrapped, wrap_timings = wraps.cached_wrap(repository, settings, adaptable, target, options.wrap, progress,
                                              landmarks)
    if solver.needs_wrap(adaptable.source, target, options.wrap):
        # the fine level's chunks, on other workers, read the target as one of the source's topology
        # (distributed.solve_fine_chunk): a wrapped target's fine level is solved in this run
        fine_runner = distributed.solve_here
    try:
        result = solver.retarget(adaptable, target, options, progress=progress, should_stop=progress.should_stop,
                                 target_input=target_input, fine_runner=fine_runner, collision_surface=surface,
                                 wrapped=wrapped)
    except solver.InputError as error:
        raise explained(error, options.wrap, target_input) from None
    if wrapped is None:
        wrap_timings.update(wraps.keep(repository, settings, result.wrapped))
    result.timings.update(cache_timings, **wrap_timings)
    progress("storing", 0.99, "writing outputs")
    outputs = {}
    report = {**result.report(), "job": {"id": job.id, "hairstyle_id": job.hairstyle_id,
                                          "target_character_id": job.target_character_id}}
    storage = repository.storage
    with storage.work_dir() as work:
        hair = {fmt: work / f"result.{fmt}" for fmt in sorted({LOSSLESS_OUTPUT, job.output_format})}
        files = {**hair, "report": work / "report.json", "preview": work / "preview.png"}
        with OutputSet() as written:
            add_result(written, adaptable, result, target, hair, report=(files["report"], report),
                       preview=files["preview"], flag_guides=job.flag_guides)
            written.commit()
        for name, path in files.items():
            outputs[name] = stored(storage.save_file(path, path.suffix), path.suffix)
        path = display.save_scene(work / "scene.npz", documents.display_scene(adaptable, result, target))
        outputs["scene"] = stored(storage.save_file(path, ".npz"), ".npz")
    return outputs, result.metrics, result.timings


def _jsonable(document: dict) -> dict:
    return json.loads(json.dumps(document, default=json_default))
