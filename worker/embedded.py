"""A Celery worker inside the API process, on Celery's in-memory transport (no Redis).

For a laptop: ``hairport serve --embedded``. Jobs run one at a time in a background thread
of the server process; nothing survives a restart of that process.
"""

from __future__ import annotations

import threading

from .app import MEMORY_BROKER, QUEUES, celery_app


def start_embedded_worker() -> threading.Thread:
    """Point the Celery app at the in-memory transport and consume every queue in a thread."""
    celery_app.conf.broker_url = MEMORY_BROKER
    celery_app.conf.broker_transport_options = {}
    controller = celery_app.WorkController(
        pool_cls="solo", concurrency=1, queues=list(QUEUES), without_heartbeat=True, without_mingle=True,
        without_gossip=True, hostname="hairport-embedded@localhost",
    )
    thread = threading.Thread(target=controller.start, name="hairport-embedded-worker", daemon=True)
    thread.start()
    return thread
