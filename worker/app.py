"""The Celery application: Redis broker, three queues per deployment, late acknowledgement, built on first use.

Jobs are acknowledged after they finish (``acks_late``), and a job whose worker process
dies is handed back to the queue (``reject_on_worker_lost`` for a lost pool child); a job
whose worker host dies stops writing its heartbeat and is queued again by the sweeper
(:mod:`.sweeper`) well before the broker's visibility timeout. Job state does not travel
through Celery results: tasks write it to the job's record in the shared storage
(:mod:`hairport.repository`), which the API reads.

Queues are named after the deployment (``hairport.<deployment>.retarget``, see
:func:`hairport.storage.queue_name`), so two deployments on one Redis database never share a
message; every task also carries its deployment id (keyword ``deployment``).
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

from celery import Celery

from hairport.settings import Settings, get_settings
from hairport.storage import deployment_for, queue_name

PREPROCESS_QUEUE = "preprocess"
RETARGET_QUEUE = "retarget"
#: chunks of one job's multi-scale fine level (:mod:`.fine`)
FINE_QUEUE = "fine"
QUEUES = (PREPROCESS_QUEUE, RETARGET_QUEUE, FINE_QUEUE)

PREPROCESS_TASK = "hairport.preprocess"
RETARGET_TASK = "hairport.retarget"
FINE_TASK = "hairport.fine_chunk"
PURGE_TASK = "hairport.purge"
#: the queue of each task (short names: the broker's names are the deployment's, see :func:`queue_names`)
ROUTES = {PREPROCESS_TASK: PREPROCESS_QUEUE, RETARGET_TASK: RETARGET_QUEUE, FINE_TASK: FINE_QUEUE,
          PURGE_TASK: RETARGET_QUEUE}

#: broker URL of the embedded (single-process, no Redis) mode
MEMORY_BROKER = "memory://"
#: the module whose import registers the task functions (a worker imports it when it starts)
TASKS_MODULE = "hairport.worker.tasks"
#: attempts to publish a task when the broker does not answer, and the pauses between them (s): with the
#: connection timeout (``Settings.enqueue_timeout_seconds``) a request fails in seconds, not minutes
PUBLISH_RETRIES = 1
PUBLISH_RETRY_PAUSE_SECONDS = 0.5


def queue_names(deployment: str) -> dict[str, str]:
    """The broker name of each queue of a deployment (short name -> ``hairport.<deployment>.<queue>``)."""
    return {queue: queue_name(deployment, queue) for queue in QUEUES}


def make_celery(settings: Settings, broker_url: str | None = None, deployment: str | None = None) -> Celery:
    """A Celery app configured from ``settings`` (``broker_url`` overrides the Redis URL) for ``deployment``
    (default: the settings' own, :func:`hairport.storage.deployment_for`)."""
    deployment = deployment or deployment_for(settings)
    names = queue_names(deployment)
    app = Celery("hairport", broker=broker_url or settings.redis_url, include=[TASKS_MODULE], set_as_current=False)
    timeout = settings.enqueue_timeout_seconds
    app.conf.update(
        task_acks_late=True,
        task_reject_on_worker_lost=True,
        task_ignore_result=True,
        worker_prefetch_multiplier=1,
        task_time_limit=settings.task_time_limit,
        task_soft_time_limit=settings.task_soft_time_limit,
        broker_transport_options={} if broker_url == MEMORY_BROKER else {
            "visibility_timeout": settings.visibility_timeout, "socket_connect_timeout": timeout,
            "socket_timeout": timeout},
        broker_connection_retry_on_startup=True,
        broker_connection_timeout=timeout,
        task_publish_retry_policy={"max_retries": PUBLISH_RETRIES, "interval_start": PUBLISH_RETRY_PAUSE_SECONDS,
                                   "interval_step": PUBLISH_RETRY_PAUSE_SECONDS,
                                   "interval_max": PUBLISH_RETRY_PAUSE_SECONDS},
        task_default_queue=names[RETARGET_QUEUE],
        task_routes={name: {"queue": names[queue]} for name, queue in ROUTES.items()},
        worker_hijack_root_logger=False,
        task_serializer="json",
        accept_content=["json"],
    )
    app.hairport_deployment = deployment
    return app


@lru_cache(maxsize=4)
def celery_for(broker_url: str, storage_dir: Path | None = None) -> Celery:
    """One Celery app per broker and storage in a process, made on first use (never at import)."""
    settings = get_settings()
    if storage_dir is not None and Path(storage_dir) != settings.storage_dir:
        settings = settings.model_copy(update={"storage_dir": Path(storage_dir)})
    return make_celery(settings, broker_url)


def configured_celery() -> Celery:
    """The Celery app of the configured Redis and storage."""
    settings = get_settings()
    return celery_for(settings.redis_url, settings.storage_dir)


def __getattr__(name: str) -> Celery:
    # ``celery -A hairport.worker.app:celery_app ...`` (the compose health check) finds the app by
    # attribute: build it on that first access rather than when the module is imported
    if name == "celery_app":
        return configured_celery()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
