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
