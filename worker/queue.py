"""How the API reaches the workers: tasks sent by name over the broker (this module imports no task).

The service uses this module and nothing else of the worker. A :class:`TaskQueue` wraps the
Celery app of one broker and one deployment (:func:`connect`): it sends tasks to the
deployment's queues with the deployment id, finds the deployment's workers, and lists the
task ids the broker holds (for the sweeper, :class:`Sweeper`, re-exported here for the API).
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import redis
from celery import Celery
from kombu.exceptions import KombuError

from .app import (
    FINE_TASK,
    PREPROCESS_TASK,
    PUBLISH_RETRIES,
    PUBLISH_RETRY_PAUSE_SECONDS,
    QUEUES,
    RETARGET_TASK,
    ROUTES,
    celery_for,
    queue_names,
)
from .runs import new_task_id
from .sweeper import Sweeper

__all__ = ["QUEUES", "QueueUnavailable", "Sweeper", "TaskQueue", "connect", "new_task_id"]

log = logging.getLogger(__name__)

#: the Redis transport keeps a queue's messages of priority p > 0 in ``<queue><SEP><p>`` (kombu's layout)
PRIORITY_SEPARATOR = "\x06\x16"
PRIORITY_STEPS = (3, 6, 9)
#: the Redis transport's hash of delivered, unacknowledged messages (kombu's default name)
UNACKED_KEY = "unacked"


class QueueUnavailable(Exception):
    """The broker did not take a task (down, unreachable, or too slow): try again later."""


def connect(broker_url: str, storage_dir: Path | None = None) -> TaskQueue:
    """The task queue of a broker (``redis://...``, or ``memory://`` for the embedded mode) for the
    deployment of ``storage_dir`` (default: the configured storage)."""
    return TaskQueue(celery_for(broker_url, storage_dir))


class TaskQueue:
    """Send, revoke, ping and list over one Celery app (its broker and deployment)."""

    def __init__(self, celery: Celery):
        self.celery = celery
        self.deployment: str = celery.hairport_deployment
        self.names = queue_names(self.deployment)

    @property
    def broker(self) -> str:
        """The broker's kind: ``redis`` or ``memory``."""
        return self.celery.conf.broker_url.split(":", 1)[0]

    def send_preprocess(self, hairstyle_id: str, options: dict | None = None, task_id: str | None = None) -> str:
        """Preprocess a hairstyle (with its own options, or those of a variant); the task id."""
        return self._send(PREPROCESS_TASK, task_id, hairstyle_id, options)

    def send_retarget(self, job_id: str, task_id: str | None = None) -> str:
        """Run a retarget job; the task id."""
        return self._send(RETARGET_TASK, task_id, job_id)

    def send_fine_chunk(self, job_id: str, run_token: str, index: int, task_id: str) -> str:
        """Solve chunk ``index`` of the fine level of the job's run ``run_token``; the task id."""
        return self._send(FINE_TASK, task_id, job_id, run_token, index)

    def revoke(self, *task_ids: str) -> bool:
        """Ask the workers not to start these queued tasks (one broadcast); whether the broker took it.

        Revoking is only a saving, never what stops a task: every task reads its record before it runs and
        does nothing for a job that is over or cancelled (a cancel is written to the record first), and a worker
        that starts after the broadcast never hears of it. So a broker that is down or slow is logged, not
        raised: the tasks' messages, when delivered, find their records cancelled."""
        if not task_ids:
            return True
        try:
            with self.celery.connection_for_write() as connection:
                # as many tries as a send gets (Celery's broadcast alone would wait twice the connection timeout)
                connection.ensure_connection(max_retries=PUBLISH_RETRIES, interval_start=PUBLISH_RETRY_PAUSE_SECONDS,
                                             interval_step=PUBLISH_RETRY_PAUSE_SECONDS,
                                             interval_max=PUBLISH_RETRY_PAUSE_SECONDS)
                self.celery.control.revoke(list(task_ids), connection=connection)
        except (KombuError, redis.RedisError, OSError) as error:
            log.warning("tasks %s not revoked, the broker did not answer (%s: %s); their records say what to do",
                        ", ".join(task_ids), type(error).__name__, error)
            return False
        return True

    def ping_workers(self, timeout: float) -> list:
        """The replies of the workers (of any deployment on this broker) that answer within ``timeout`` s."""
        return self._fresh(lambda connection=None: self.celery.control.ping(timeout=timeout, connection=connection))

    def workers(self, timeout: float) -> list[str]:
        """The names of the workers that consume this deployment's queues and answer within ``timeout`` s."""
        replies = self._fresh(lambda connection=None: self.celery.control.inspect(
            timeout=timeout, connection=connection).active_queues()) or {}
        ours = set(self.names.values())
        return sorted(name for name, queues in replies.items() if ours & {queue.get("name") for queue in queues or []})

    def depths(self) -> dict[str, int]:
        """Messages waiting per queue (short names), or {} when the broker cannot say."""
        if self.broker != "redis":
            return {}
        return self._with_redis(lambda client: {
            short: sum(int(client.llen(name)) for name in _priority_lists(full)) for short, full in self.names.items()})

    def task_ids_in_broker(self) -> set[str] | None:
        """The ids of every task of this deployment the broker holds (waiting in its queues, or delivered
        and not acknowledged, e.g. held by a worker until its countdown); None when the broker cannot be
        listed (the in-memory one)."""
        if self.broker != "redis":
            return None
        return self._with_redis(_held_task_ids, self.names.values())

    def _fresh(self, call):
        # pooled connections may have died with a Redis restart: try once more on a new connection
        try:
            return call()
        except (KombuError, redis.RedisError, OSError):
            with self.celery.connection() as connection:
                return call(connection)

    def _with_redis(self, read, *args):
        # a pooled connection may have died with a Redis restart: one more try on a fresh one
        with self.celery.connection_for_read() as connection:
            client = connection.default_channel.client
            try:
                return read(client, *args)
            except redis.ConnectionError:
                client.connection_pool.disconnect()
                return read(client, *args)

    def _send(self, name: str, task_id: str | None, *args) -> str:
        try:
            return self.celery.send_task(name, args=list(args), kwargs={"deployment": self.deployment},
                                         queue=self.names[ROUTES[name]], task_id=task_id or new_task_id()).id
        except (KombuError, redis.RedisError, OSError) as error:
            raise QueueUnavailable(f"the task queue did not take the task: {type(error).__name__}") from error


def _held_task_ids(client, queues) -> set[str]:
    found = set()
    for full in queues:
        for name in _priority_lists(full):
            found.update(_task_id(raw) for raw in client.lrange(name, 0, -1))
    for raw in client.hvals(UNACKED_KEY):
        try:
            found.add(_task_id(json.loads(raw)[0]))
        except (ValueError, IndexError, TypeError):
            continue
    found.discard(None)
    return found


def _priority_lists(queue: str) -> list[str]:
    return [queue] + [f"{queue}{PRIORITY_SEPARATOR}{step}" for step in PRIORITY_STEPS]


def _task_id(message) -> str | None:
    try:
        message = json.loads(message) if isinstance(message, (str, bytes)) else message
        return message["headers"]["id"]
    except (ValueError, KeyError, TypeError):
        return None
