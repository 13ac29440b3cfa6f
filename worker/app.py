"""The Celery application: Redis broker, two queues, late acknowledgement, built on first use.

Jobs are acknowledged after they finish (``acks_late``), and a job whose worker process
dies is handed back to the queue (``reject_on_worker_lost`` for a lost pool child; the
broker's visibility timeout for a lost worker host), so another worker runs it again from
the start. Job state does not travel through Celery results: tasks write it to the job's
record in the shared storage (:mod:`hairport.repository`), which the API reads.
"""

from __future__ import annotations

from functools import lru_cache

from celery import Celery

from hairport.settings import Settings, get_settings

PREPROCESS_QUEUE = "preprocess"
RETARGET_QUEUE = "retarget"
QUEUES = (PREPROCESS_QUEUE, RETARGET_QUEUE)

PREPROCESS_TASK = "hairport.preprocess"
RETARGET_TASK = "hairport.retarget"
PURGE_TASK = "hairport.purge"
#: the queue of each task
ROUTES = {PREPROCESS_TASK: PREPROCESS_QUEUE, RETARGET_TASK: RETARGET_QUEUE, PURGE_TASK: RETARGET_QUEUE}

#: broker URL of the embedded (single-process, no Redis) mode
MEMORY_BROKER = "memory://"
#: the module whose import registers the task functions (a worker imports it when it starts)
TASKS_MODULE = "hairport.worker.tasks"


def make_celery(settings: Settings, broker_url: str | None = None) -> Celery:
    """A Celery app configured from ``settings`` (``broker_url`` overrides the Redis URL)."""
    app = Celery("hairport", broker=broker_url or settings.redis_url, include=[TASKS_MODULE], set_as_current=False)
    app.conf.update(
        task_acks_late=True,
        task_reject_on_worker_lost=True,
        task_ignore_result=True,
        worker_prefetch_multiplier=1,
        task_time_limit=settings.task_time_limit,
        task_soft_time_limit=settings.task_soft_time_limit,
        broker_transport_options={} if broker_url == MEMORY_BROKER else {
            "visibility_timeout": settings.visibility_timeout},
        broker_connection_retry_on_startup=True,
        task_default_queue=RETARGET_QUEUE,
        task_routes={name: {"queue": queue} for name, queue in ROUTES.items()},
        worker_hijack_root_logger=False,
        task_serializer="json",
        accept_content=["json"],
    )
    return app


@lru_cache(maxsize=4)
def celery_for(broker_url: str) -> Celery:
    """One Celery app per broker in a process, made on first use (never at import)."""
    return make_celery(get_settings(), broker_url)


def configured_celery() -> Celery:
    """The Celery app of the configured Redis."""
    return celery_for(get_settings().redis_url)


def __getattr__(name: str) -> Celery:
    # ``celery -A hairport.worker.app:celery_app ...`` (the compose health check) finds the app by
    # attribute: build it on that first access rather than when the module is imported
    if name == "celery_app":
        return configured_celery()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
