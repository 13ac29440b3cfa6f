"""Celery tasks: thin wrappers of the job bodies in :mod:`.runner`, registered under the names of :mod:`.queue`.

A task finds its storage and settings, checks that it belongs to this worker's deployment,
calls one runner function, and turns what Celery must know into Celery terms: transient
errors are retried with exponential backoff, a retarget waiting for its hairstyle's
preprocessing is retried after a pause. The worker's signals limit each pool child's memory
(:mod:`.memory`) and run the sweeper (:mod:`.sweeper`) in the worker's main process.
"""

from __future__ import annotations

import logging
import os
from functools import lru_cache

from celery import shared_task
from celery.signals import worker_process_init, worker_ready, worker_shutdown

from hairport.repository import Repository
from hairport.settings import get_settings
from hairport.storage import deployment_for, open_storage, queue_name, retention_seconds

from . import runner
from .app import FINE_TASK, PREPROCESS_TASK, PURGE_TASK, RETARGET_TASK, ROUTES, configured_celery
from .embedded import embedded_worker_running
from .fine import FineDispatch, run_fine_chunk
from .memory import data_bytes, limit_memory
from .queue import Sweeper, TaskQueue

log = logging.getLogger(__name__)

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
    return Repository(open_storage(get_settings()))


@lru_cache(maxsize=1)
def own_deployment() -> str:
    """The deployment of this worker (:func:`hairport.storage.deployment_for`)."""
    return deployment_for(get_settings())


def foreign(task, deployment: str | None) -> bool:
    """Whether a task belongs to another deployment than this worker's (then it is not run, loudly: sent on
    to its own deployment's queue, or dropped when it names none)."""
    own = own_deployment()
    if deployment == own:
        return False
    where = f"this worker serves deployment {own} (storage {get_settings().storage_dir})"
    if deployment is None:
        log.error("task %s %s names no deployment; %s: refused, not run", task.name, task.request.id, where)
        return True
    target = queue_name(deployment, ROUTES[task.name])
    task.app.send_task(task.name, args=list(task.request.args or ()), kwargs=dict(task.request.kwargs or {}),
                       queue=target, task_id=task.request.id)
    log.error("task %s %s belongs to deployment %s; %s: refused, not run, sent on to %s", task.name,
              task.request.id, deployment, where, target)
    return True


@shared_task(name=PREPROCESS_TASK, **JOB_TASK_OPTIONS)
def preprocess_task(self, hairstyle_id: str, options: dict | None = None, deployment: str | None = None) -> None:
    """Compute (once) the adaptable hairstyle of a hairstyle record (with its options, or ``options``)."""
    if foreign(self, deployment):
        return
    runner.run_preprocess(repository(), get_settings(), hairstyle_id, options, task_id=self.request.id,
                          worker=self.request.hostname)


@shared_task(name=RETARGET_TASK, **JOB_TASK_OPTIONS)
def retarget_task(self, job_id: str, deployment: str | None = None) -> None:
    """Retarget one hairstyle onto one target character (one job record)."""
    if foreign(self, deployment):
        return
    try:
        runner.run_retarget(repository(), get_settings(), job_id, self.request.hostname, polls=self.request.retries,
                            task_id=self.request.id, chunks=fine_dispatch())
    except runner.PreprocessingPending:
        raise self.retry(countdown=PREPROCESS_POLL_SECONDS, max_retries=runner.PREPROCESS_POLL_LIMIT) from None


@shared_task(name=FINE_TASK, **JOB_TASK_OPTIONS)
def fine_chunk_task(self, job_id: str, run_token: str, index: int, deployment: str | None = None) -> None:
    """Solve one chunk of a job's multi-scale fine level (:mod:`.fine`)."""
    if foreign(self, deployment):
        return
    run_fine_chunk(repository(), get_settings(), job_id, run_token, index, self.request.hostname,
                   task_id=self.request.id)


def fine_dispatch() -> FineDispatch | None:
    """How a job's run sends its fine-level chunks: through the configured broker (none in the embedded mode,
    whose single thread could not run them before the job ends)."""
    if embedded_worker_running():
        return None
    queue = TaskQueue(configured_celery())
    return FineDispatch(send=queue.send_fine_chunk, revoke=queue.revoke)


@shared_task(name=PURGE_TASK)
def purge_task() -> int:
    """Delete what is older than the retention period (also run by workers after jobs)."""
    return repository().purge(retention_seconds(get_settings().retention_days))


@worker_process_init.connect
def _limit_child(**_) -> None:
    # in each pool child (not in the embedded worker, which shares the API's process)
    settings = get_settings()
    used = data_bytes()
    limit_memory(settings.memory_budget_bytes)
    os.nice(settings.worker_niceness)
    log.info("worker child: memory budget %s bytes (%s in use at start), niceness +%d",
             f"{settings.memory_budget_bytes:,}", f"{used:,}", settings.worker_niceness)


_sweepers: dict[int, Sweeper] = {}


@worker_ready.connect
def _start_sweeper(sender=None, **_) -> None:
    app = sender.app
    sweeper = Sweeper(repository(), TaskQueue(app), get_settings())
    _sweepers[id(app)] = sweeper
    sweeper.start()
    storage = sweeper.repository.storage
    where = storage.root if storage.remote is None else f"{storage.remote.url} (cache {storage.root})"
    log.warning("hairport worker of deployment %s, storage %s: consuming %s", app.hairport_deployment,
                where, ", ".join(sorted(queue.name for queue in sender.task_consumer.queues)))
    for name, answers in storage.reachability().items():
        if not answers():  # the worker still starts: its tasks retry until the store or database answers again
            log.error("hairport worker: the %s cannot be reached (see the warning above); its tasks wait for it", name)


@worker_shutdown.connect
def _stop_sweepers(**_) -> None:
    for sweeper in _sweepers.values():
        sweeper.stop()
