"""Celery tasks: thin wrappers of the job bodies in :mod:`.runner`, registered under the names of :mod:`.queue`.

A task finds its storage and settings, calls one runner function, and turns what Celery must
know into Celery terms: transient errors are retried with exponential backoff, a retarget
waiting for its hairstyle's preprocessing is retried after a pause.
"""

from __future__ import annotations

from celery import shared_task

from hairport.repository import Repository
from hairport.settings import get_settings
from hairport.storage import LocalStorage, retention_seconds

from . import runner
from .app import PREPROCESS_TASK, PURGE_TASK, RETARGET_TASK

#: seconds between checks whether a retarget's hairstyle has been preprocessed
PREPROCESS_POLL_SECONDS = 2.0
#: retries of transient errors (exponential backoff, capped at RETRY_BACKOFF_MAX seconds)
MAX_RETRIES = 5
RETRY_BACKOFF_MAX = 60
#: every job task: retried with exponential backoff on transient errors only
JOB_TASK_OPTIONS = dict(bind=True, autoretry_for=runner.TRANSIENT_ERRORS, retry_backoff=True,
                        retry_backoff_max=RETRY_BACKOFF_MAX, max_retries=MAX_RETRIES)


def repository() -> Repository:
    """The records of the configured storage folder."""
    return Repository(LocalStorage(get_settings().storage_dir))


@shared_task(name=PREPROCESS_TASK, **JOB_TASK_OPTIONS)
def preprocess_task(self, hairstyle_id: str, options: dict | None = None) -> None:
    """Compute (once) the adaptable hairstyle of a hairstyle record (with its options, or ``options``)."""
    runner.run_preprocess(repository(), get_settings(), hairstyle_id, options)


@shared_task(name=RETARGET_TASK, **JOB_TASK_OPTIONS)
def retarget_task(self, job_id: str) -> None:
    """Retarget one hairstyle onto one target character (one job record)."""
    try:
        runner.run_retarget(repository(), get_settings(), job_id, self.request.hostname, polls=self.request.retries)
    except runner.PreprocessingPending:
        raise self.retry(countdown=PREPROCESS_POLL_SECONDS, max_retries=runner.PREPROCESS_POLL_LIMIT) from None


@shared_task(name=PURGE_TASK)
def purge_task() -> int:
    """Delete what is older than the retention period (also run by workers after jobs)."""
    return repository().purge(retention_seconds(get_settings().retention_days))
