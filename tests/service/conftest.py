"""An API app over a temporary storage and Celery's in-memory broker, with no worker: the tests see
what the API sends, nothing runs it."""

import pytest
from fastapi.testclient import TestClient

from hairport.service.app import create_app
from hairport.settings import Settings
from hairport.worker.app import MEMORY_BROKER, make_celery, queue_names
from hairport.worker.queue import TaskQueue

KEY = "unit-key"
AUTH = {"Authorization": f"Bearer {KEY}"}


@pytest.fixture
def settings(tmp_path) -> Settings:
    return Settings(storage_dir=tmp_path / "storage", api_keys=KEY)


@pytest.fixture
def client(settings) -> TestClient:
    celery = make_celery(settings, MEMORY_BROKER)
    # the in-memory transport is one per process: start every test with empty queues
    with celery.connection_for_write() as connection:
        for name in queue_names(celery.hairport_deployment).values():
            connection.SimpleQueue(name).clear()
    app = create_app(settings, readiness=lambda: {"redis": True, "worker": False}, queue_depths=lambda: {"retarget": 3},
                     queue=TaskQueue(celery))
    return TestClient(app)


@pytest.fixture
def client_without_broker(settings) -> TestClient:
    """The API over the same storage as ``client``, its task queue on a Redis that is down (nothing listens on
    its port, a connection is refused): every send and revoke meets an outage."""
    from ..conftest import free_port

    hasty = settings.model_copy(update={"enqueue_timeout_seconds": 0.5})
    queue = TaskQueue(make_celery(hasty, f"redis://127.0.0.1:{free_port()}/0"))
    return TestClient(create_app(hasty, readiness=lambda: {"redis": False, "worker": False}, queue_depths=lambda: {},
                                 queue=queue))
