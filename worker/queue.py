"""How the API reaches the workers: tasks sent by name over the broker (this module imports no task).

The service uses this module and nothing else of the worker. A :class:`TaskQueue` wraps the
Celery app of one broker (:func:`connect`).
"""

from __future__ import annotations

from celery import Celery

from .app import PREPROCESS_TASK, QUEUES, RETARGET_TASK, ROUTES, celery_for

__all__ = ["QUEUES", "TaskQueue", "connect"]


def connect(broker_url: str) -> TaskQueue:
    """The task queue of a broker (``redis://...``, or ``memory://`` for the embedded mode)."""
    return TaskQueue(celery_for(broker_url))


class TaskQueue:
    """Send, revoke and ping over one Celery app (and its broker)."""

    def __init__(self, celery: Celery):
        self.celery = celery

    def send_preprocess(self, hairstyle_id: str, options: dict | None = None) -> str:
        """Preprocess a hairstyle (with its own options, or those of a variant); the task id."""
        return self._send(PREPROCESS_TASK, hairstyle_id, options)

    def send_retarget(self, job_id: str) -> str:
        """Run a retarget job; the task id."""
        return self._send(RETARGET_TASK, job_id)

    def revoke(self, task_id: str) -> None:
        """Ask workers not to start a queued task."""
        self.celery.control.revoke(task_id)

    def ping_workers(self, timeout: float) -> list:
        """The replies of the workers that answer within ``timeout`` seconds."""
        return self.celery.control.ping(timeout=timeout)

    def _send(self, name: str, *args) -> str:
        return self.celery.send_task(name, args=list(args), queue=ROUTES[name]).id
