"""An API app over a temporary storage and the in-memory broker (no worker: these tests send no task)."""

import pytest
from fastapi.testclient import TestClient

from hairport.service.app import create_app
from hairport.settings import Settings
from hairport.worker.app import MEMORY_BROKER, make_celery
from hairport.worker.queue import TaskQueue

KEY = "unit-key"
AUTH = {"Authorization": f"Bearer {KEY}"}


@pytest.fixture
def settings(tmp_path) -> Settings:
    return Settings(storage_dir=tmp_path / "storage", api_keys=KEY)


@pytest.fixture
def client(settings) -> TestClient:
    app = create_app(settings, readiness=lambda: {"redis": True, "worker": False}, queue_depths=lambda: {"retarget": 3},
                     queue=TaskQueue(make_celery(settings, MEMORY_BROKER)))
    return TestClient(app)
