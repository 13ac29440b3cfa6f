"""A Celery worker inside the API process, on Celery's in-memory transport (no Redis).

For a laptop: ``hairport serve --embedded``. Jobs run one at a time in a background thread
of the server process; nothing survives a restart of that process.
"""

from __future__ import annotations

import threading

from celery import Celery

from .app import MEMORY_BROKER, celery_for, queue_names

_started = threading.Event()


def embedded_worker_running() -> bool:
    """Whether this process runs the embedded worker (its tasks then run one at a time, in its thread)."""
    return _started.is_set()


def start_embedded_worker() -> tuple[Celery, threading.Thread]:
    """Consume every queue of the in-memory transport in a thread; the app to send tasks with, and the thread."""
    _started.set()
    app = celery_for(MEMORY_BROKER)
    queues = list(queue_names(app.hairport_deployment).values())
    controller = app.WorkController(
        pool_cls="solo", concurrency=1, queues=queues, without_heartbeat=True, without_mingle=True,
        without_gossip=True, hostname="hairport-embedded@localhost",
    )
    thread = threading.Thread(target=controller.start, name="hairport-embedded-worker", daemon=True)
    thread.start()
    return app, thread
