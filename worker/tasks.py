"""Celery tasks: load by id, call ``solver.pipeline``, store, report progress.

Bad input (:class:`InputError`) fails the job at once, with its message; transient errors
(I/O, the broker) are retried with exponential backoff. Outputs are written to a private
work directory and stored only when everything succeeded, so a job that fails, is
cancelled or loses its worker leaves no partial result.
"""

from __future__ import annotations

import json
import os
import time
import traceback
from functools import lru_cache
from pathlib import Path

from celery.exceptions import SoftTimeLimitExceeded

from hairport.outputs import json_default
from hairport.settings import get_settings
from hairport.solver import pipeline

from . import jobs
from .app import celery_app

#: seconds between checks whether a retarget's hairstyle has been preprocessed ...
PREPROCESS_POLL_SECONDS = 2.0
#: ... for at most this many checks (then the job fails)
PREPROCESS_POLL_LIMIT = 1800
#: a running job writes its progress at most this often (s)
PROGRESS_INTERVAL_SECONDS = 0.5
#: a worker purges expired files at most this often (s), after a job
PURGE_INTERVAL_SECONDS = 3600.0
#: retries of transient errors (exponential backoff, capped at RETRY_BACKOFF_MAX seconds)
MAX_RETRIES = 5
RETRY_BACKOFF_MAX = 60
TRANSIENT_ERRORS = (ConnectionError, TimeoutError, InterruptedError, BlockingIOError)


class PreprocessFailed(RuntimeError):
    """The hairstyle a job needs could not be preprocessed."""


def _limits() -> dict:
    settings = get_settings()
    return dict(max_vertices=settings.max_vertices, max_faces=settings.max_faces, max_bytes=settings.max_file_bytes)


def _blob_path(storage, ref: dict | None) -> Path | None:
    if ref is None:
        return None
    blob = storage.blob(ref["sha256"], ref.get("suffix", ""))
    if blob is None:
        raise pipeline.InputError("a stored input is gone (purged by retention?)", ref["sha256"][:12], "gone")
    return blob.path


def load_character(storage, character_id: str):
    """The character of a record, loaded from its stored files."""
    record = storage.get_record("characters", character_id)
    if record is None:
        raise pipeline.InputError(f"character {character_id} does not exist", code="not_found")
    return pipeline.load_character_file(
        _blob_path(storage, record["mesh"]), _blob_path(storage, record.get("skeleton")), record["units"], **_limits()
    )


@lru_cache(maxsize=2)
def _adaptable(path: str):
    # one worker process retargets one groom onto many bodies: keep the last artifacts loaded
    return pipeline.load_adaptable_file(path)


def _error(error: BaseException) -> dict:
    if isinstance(error, pipeline.InputError):
        # the problem only: the source of a stored input is a storage path, meaningless to the caller
        return {"code": error.code or "bad_input", "message": error.problem}
    if isinstance(error, SoftTimeLimitExceeded):
        return {"code": "time_limit", "message": f"the job ran over its time limit ({get_settings().task_soft_time_limit} s)"}
    return {"code": "internal", "message": f"{type(error).__name__}: {error}"}


#: every job task: retried with exponential backoff on transient errors only
JOB_TASK_OPTIONS = dict(bind=True, autoretry_for=TRANSIENT_ERRORS, retry_backoff=True,
                        retry_backoff_max=RETRY_BACKOFF_MAX, max_retries=MAX_RETRIES)


@celery_app.task(name="hairport.preprocess", **JOB_TASK_OPTIONS)
def preprocess_task(self, hairstyle_id: str, options: dict | None = None) -> None:
    """Compute (once) the adaptable hairstyle of a hairstyle record (with its options, or ``options``)."""
    storage = jobs.get_storage()
    hairstyle = storage.get_record("hairstyles", hairstyle_id)
    if hairstyle is None:
        return
    if options is None:
        options, key = hairstyle["options"], hairstyle["artifact_key"]
    else:
        key = jobs.variant_key(storage, hairstyle, options, pipeline.ARTIFACT_FORMAT_VERSION)
    if storage.get_record("artifacts", key) is not None:
        _set_preprocessing(storage, key, "ready")
        return
    _set_preprocessing(storage, key, jobs.RUNNING)
    began = time.perf_counter()
    try:
        source = load_character(storage, hairstyle["source_character_id"])
        settings = get_settings()
        hair = pipeline.read_hair_file(
            _blob_path(storage, hairstyle["hair"]), hairstyle["units"], max_strands=settings.max_strands,
            max_particles=settings.max_particles, max_bytes=settings.max_file_bytes,
        )
        adaptable = pipeline.preprocess(source, hair, pipeline.PreprocessOptions(**options))
        with storage.work_dir() as work:
            path = work / "adaptable.hpa"
            pipeline.save_adaptable_file(adaptable, path)
            blob = storage.save_file(path, ".hpa")
        storage.put_record("artifacts", key, {
            "key": key, "sha256": blob.sha256, "suffix": ".hpa", "size": blob.size,
            "format_version": pipeline.ARTIFACT_FORMAT_VERSION, "seconds": time.perf_counter() - began,
            "guides": int(len(adaptable.multiscale.guides)), "created_at": jobs.now(),
        })
        _set_preprocessing(storage, key, "ready", seconds=time.perf_counter() - began)
    except TRANSIENT_ERRORS:
        raise
    except Exception as error:  # noqa: BLE001 - every other failure is this hairstyle's, reported on it
        _set_preprocessing(storage, key, jobs.FAILED, error=_error(error))
        if not isinstance(error, pipeline.InputError):
            traceback.print_exc()


def _set_preprocessing(storage, key: str, state: str, error: dict | None = None, seconds: float | None = None):
    """Preprocessing state is kept per artifact key: every hairstyle with the same inputs shares it."""
    storage.put_record("preprocessing", key, {"key": key, "state": state, "error": error, "seconds": seconds,
                                              "updated_at": jobs.now()})


class _Progress:
    """Writes a job's stage and progress to its record, at most every PROGRESS_INTERVAL_SECONDS,
    and reads its cancellation flag as often."""

    def __init__(self, storage, job_id: str):
        self.storage, self.job_id = storage, job_id
        self.last_write = 0.0
        self.last_check = 0.0
        self.stage = None
        self.cancelled = False

    def __call__(self, stage: str, fraction: float, message: str) -> None:
        moment = time.monotonic()
        if stage != self.stage or moment - self.last_write >= PROGRESS_INTERVAL_SECONDS:
            self.stage, self.last_write = stage, moment
            jobs.set_job(self.storage, self.job_id, stage=stage, progress=round(float(fraction), 4), message=message)

    def should_stop(self) -> bool:
        moment = time.monotonic()
        if moment - self.last_check >= PROGRESS_INTERVAL_SECONDS:
            self.last_check = moment
            job = self.storage.get_record("jobs", self.job_id)
            self.cancelled = job is None or bool(job.get("cancel_requested"))
        return self.cancelled


@celery_app.task(name="hairport.retarget", **JOB_TASK_OPTIONS)
def retarget_task(self, job_id: str) -> None:
    """Retarget one hairstyle onto one target character (one job record)."""
    storage = jobs.get_storage()
    job = storage.get_record("jobs", job_id)
    if job is None or job["state"] in jobs.TERMINAL_STATES:
        return
    if job.get("cancel_requested"):
        jobs.set_job(storage, job_id, state=jobs.CANCELLED, finished_at=jobs.now())
        return
    hairstyle = storage.get_record("hairstyles", job["hairstyle_id"])
    key = job.get("artifact_key") or (hairstyle or {}).get("artifact_key")
    artifact = storage.get_record("artifacts", key) if hairstyle else None
    if artifact is None:
        status = jobs.preprocessing_status(storage, hairstyle, key) if hairstyle else {"state": jobs.FAILED, "error": None}
        if status["state"] == jobs.FAILED:
            error = status.get("error") or {}
            jobs.set_job(storage, job_id, state=jobs.FAILED, finished_at=jobs.now(), error={
                "code": "preprocess_failed",
                "message": f"the hairstyle could not be preprocessed: {error.get('message', 'it is gone')}",
            })
            return
        if self.request.retries >= PREPROCESS_POLL_LIMIT:
            jobs.set_job(storage, job_id, state=jobs.FAILED, finished_at=jobs.now(),
                         error={"code": "preprocess_timeout", "message": "the hairstyle's preprocessing did not finish"})
            return
        jobs.set_job(storage, job_id, stage="waiting_for_preprocessing", progress=0.0)
        raise self.retry(countdown=PREPROCESS_POLL_SECONDS, max_retries=PREPROCESS_POLL_LIMIT)

    attempts = int(job.get("attempts", 0)) + 1
    jobs.set_job(storage, job_id, state=jobs.RUNNING, stage="loading", progress=0.0, attempts=attempts,
                 started_at=jobs.now(), error=None, worker=self.request.hostname, worker_pid=os.getpid())
    progress = _Progress(storage, job_id)
    began = time.perf_counter()
    try:
        adaptable = _adaptable(str(_blob_path(storage, artifact)))
        target = load_character(storage, job["target_character_id"])
        hairline = job.get("hairline")
        edit = None if hairline is None else pipeline.hairline_edit_from_request(hairline)
        options = pipeline.RetargetOptions(**job["options"], workers=get_settings().solver_workers, hairline=edit)
        result = pipeline.retarget(adaptable, target, options, progress=progress, should_stop=progress.should_stop)
        progress("storing", 0.99, "writing outputs")
        outputs = {}
        report = {**result.report(), "job": {"id": job_id, "hairstyle_id": job["hairstyle_id"],
                                              "target_character_id": job["target_character_id"]}}
        with storage.work_dir() as work:
            for fmt in sorted({"npz", job["output_format"]}):
                path = work / f"result.{fmt}"
                pipeline.write_hair_file(path, result.hair, fmt)
                outputs[fmt] = _stored(storage.save_file(path, f".{fmt}"), f".{fmt}")
            path = work / "report.json"
            path.write_text(json.dumps(report, indent=2, default=json_default) + "\n")
            outputs["report"] = _stored(storage.save_file(path, ".json"), ".json")
            path = work / "preview.png"
            pipeline.write_preview(path, adaptable, result, target)
            outputs["preview"] = _stored(storage.save_file(path, ".png"), ".png")
        timings = {**result.timings, "job": time.perf_counter() - began}
        jobs.set_job(storage, job_id, state=jobs.SUCCEEDED, stage="done", progress=1.0, message="done",
                     finished_at=jobs.now(), metrics=_jsonable(result.metrics), timings=timings, outputs=outputs)
        purge_if_due(storage)
    except pipeline.Cancelled:
        jobs.set_job(storage, job_id, state=jobs.CANCELLED, stage="cancelled", finished_at=jobs.now())
    except TRANSIENT_ERRORS:
        raise
    except Exception as error:  # noqa: BLE001 - the job fails with a reason; the worker lives on
        jobs.set_job(storage, job_id, state=jobs.FAILED, finished_at=jobs.now(), error=_error(error))
        if not isinstance(error, (pipeline.InputError, SoftTimeLimitExceeded)):
            traceback.print_exc()


def purge_if_due(storage) -> int:
    """Apply the retention setting at most every PURGE_INTERVAL_SECONDS (shared by all workers)."""
    settings = get_settings()
    due = {"run": False}

    def claim(record: dict) -> dict | None:
        if jobs.now() - record.get("last_purge", 0.0) < PURGE_INTERVAL_SECONDS:
            return None
        due["run"] = True
        return {**record, "last_purge": jobs.now()}

    if storage.get_record("maintenance", "purge") is None:
        storage.put_record("maintenance", "purge", {"last_purge": 0.0})
    storage.update_record("maintenance", "purge", claim)
    if not due["run"]:
        return 0
    return storage.purge(settings.retention_days * 86400.0)


@celery_app.task(name="hairport.purge")
def purge_task() -> int:
    """Delete what is older than the retention period (also run by workers after jobs)."""
    return jobs.get_storage().purge(get_settings().retention_days * 86400.0)


def _stored(blob, suffix: str) -> dict:
    return {"sha256": blob.sha256, "suffix": suffix, "size": blob.size}


def _jsonable(document: dict) -> dict:
    return json.loads(json.dumps(document, default=json_default))
