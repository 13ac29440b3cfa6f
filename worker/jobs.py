"""Records of characters, hairstyles and jobs in the shared storage, and how jobs start.

The API creates records and enqueues tasks; tasks update the records (state, stage,
progress, outputs). Both sides go through these functions, so the record layout lives in
one place. Record kinds: ``characters``, ``hairstyles``, ``artifacts`` (preprocessing
cache, keyed by a content hash of its inputs), ``jobs`` and ``idempotency``.

Job states: ``queued`` -> ``running`` -> ``succeeded`` | ``failed`` | ``cancelled``; a job
whose worker died goes back to ``running`` on its next delivery (``attempts`` counts them).
"""

from __future__ import annotations

import hashlib
import json
import time
import uuid
from functools import lru_cache
from pathlib import Path

from hairport.settings import Settings, get_settings

from .storage import LocalStorage

QUEUED, RUNNING, SUCCEEDED, FAILED, CANCELLED = "queued", "running", "succeeded", "failed", "cancelled"
JOB_STATES = (QUEUED, RUNNING, SUCCEEDED, FAILED, CANCELLED)
TERMINAL_STATES = (SUCCEEDED, FAILED, CANCELLED)
#: hairstyle preprocessing states
PREPROCESS_STATES = (QUEUED, RUNNING, "ready", FAILED)


@lru_cache(maxsize=4)
def _storage_at(root: str) -> LocalStorage:
    return LocalStorage(Path(root))


def get_storage(settings: Settings | None = None) -> LocalStorage:
    """The storage of the configured ``storage_dir`` (one object per directory and process)."""
    settings = settings or get_settings()
    return _storage_at(str(settings.storage_dir.resolve()))


def now() -> float:
    return time.time()


def digest(*parts: object) -> str:
    """SHA-256 hex of the JSON of ``parts`` (stable key order)."""
    return hashlib.sha256(json.dumps(parts, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def owned_id(owner: str, content_key: str) -> str:
    """A content-addressed id scoped to its owner: the same upload by one key gives one id."""
    return digest("id", owner, content_key)[:32]


def new_job_id() -> str:
    return uuid.uuid4().hex


def artifact_key(character: dict, hair_sha256: str, units: str, options: dict, format_version: int) -> str:
    """Content hash of everything preprocessing depends on."""
    return digest(
        "artifact", character["mesh"]["sha256"], (character.get("skeleton") or {}).get("sha256"),
        character["units"], hair_sha256, units, options, format_version,
    )


def variant_key(storage: LocalStorage, hairstyle: dict, options: dict, format_version: int) -> str:
    """The artifact key of a hairstyle preprocessed with other options (e.g. another guide count)."""
    character = storage.get_record("characters", hairstyle["source_character_id"])
    return artifact_key(character, hairstyle["hair"]["sha256"], hairstyle["units"], options, format_version)


def preprocessing_status(storage: LocalStorage, hairstyle: dict, key: str | None = None) -> dict:
    """``{"state", "error"}`` of a hairstyle's preprocessing (its own, or the variant ``key``),
    shared by every hairstyle of the same inputs."""
    key = key or hairstyle["artifact_key"]
    if storage.get_record("artifacts", key) is not None:
        return {"state": "ready", "error": None}
    status = storage.get_record("preprocessing", key)
    if status is None:
        return {"state": QUEUED, "error": None}
    return {"state": status["state"], "error": status.get("error")}


def start_preprocessing(storage: LocalStorage, hairstyle: dict, options: dict | None = None,
                        key: str | None = None) -> bool:
    """Enqueue preprocessing (with the hairstyle's options, or ``options`` of the variant ``key``)
    unless its artifact exists or a run for the same inputs is under way (a failed one is tried
    again). Returns whether a task was sent."""
    key = key or hairstyle["artifact_key"]
    started = {"sent": False}

    def claim(status: dict) -> dict | None:
        if status.get("state") in (QUEUED, RUNNING) and now() - status.get("updated_at", 0) < _stale_after():
            return None
        started["sent"] = True
        return {"key": key, "state": QUEUED, "error": None, "updated_at": now()}

    if storage.get_record("artifacts", key) is not None:
        return False
    if storage.get_record("preprocessing", key) is None:
        storage.put_record("preprocessing", key, {"key": key, "state": FAILED, "error": None, "updated_at": 0.0})
    storage.update_record("preprocessing", key, lambda status: claim(status) or status)
    if started["sent"]:
        enqueue_preprocess(hairstyle["id"], options)
    return started["sent"]


def _stale_after() -> float:
    """A queued or running preprocessing older than a job's time limit (plus redelivery) is stale."""
    settings = get_settings()
    return settings.task_time_limit + settings.visibility_timeout


def set_job(storage: LocalStorage, job_id: str, **fields) -> dict | None:
    """Update fields of a job record under its lock (returns the new record)."""

    def change(job: dict) -> dict:
        job.update(fields)
        job["updated_at"] = now()
        return job

    return storage.update_record("jobs", job_id, change)


def enqueue_preprocess(hairstyle_id: str, options: dict | None = None) -> None:
    from .tasks import preprocess_task

    preprocess_task.delay(hairstyle_id, options)


def enqueue_retarget(job_id: str) -> str:
    """Send a retarget job to the queue; returns the Celery task id."""
    from .tasks import retarget_task

    return retarget_task.delay(job_id).id


def revoke(task_id: str) -> None:
    """Ask workers not to start a queued task."""
    from .app import celery_app

    celery_app.control.revoke(task_id)
