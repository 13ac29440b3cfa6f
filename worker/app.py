"""The Celery application: Redis broker, two queues, late acknowledgement.

Jobs are acknowledged after they finish (``acks_late``), and a job whose worker process
dies is handed back to the queue (``reject_on_worker_lost`` for a lost pool child; the
broker's visibility timeout for a lost worker host), so another worker runs it again from
the start. Job state does not travel through Celery results: tasks write it to the job's
record in the shared storage (:mod:`.storage`), which the API reads.
"""

from __future__ import annotations

from celery import Celery

from hairport.settings import Settings, get_settings

PREPROCESS_QUEUE = "preprocess"
RETARGET_QUEUE = "retarget"
QUEUES = (PREPROCESS_QUEUE, RETARGET_QUEUE)
#: broker URL of the embedded (single-process, no Redis) mode
MEMORY_BROKER = "memory://"


def make_celery(settings: Settings, broker_url: str | None = None) -> Celery:
    """A Celery app configured from ``settings`` (``broker_url`` overrides the Redis URL)."""
    app = Celery("hairport", broker=broker_url or settings.redis_url, include=["hairport.worker.tasks"])
    app.conf.update(
        task_acks_late=True,
        task_reject_on_worker_lost=True,
        task_ignore_result=True,
        worker_prefetch_multiplier=1,
        task_time_limit=settings.task_time_limit,
        task_soft_time_limit=settings.task_soft_time_limit,
        broker_transport_options={"visibility_timeout": settings.visibility_timeout},
        broker_connection_retry_on_startup=True,
        task_default_queue=RETARGET_QUEUE,
        task_routes={
            "hairport.preprocess": {"queue": PREPROCESS_QUEUE},
            "hairport.retarget": {"queue": RETARGET_QUEUE},
        },
        worker_hijack_root_logger=False,
        task_serializer="json",
        accept_content=["json"],
    )
    return app


celery_app = make_celery(get_settings())
