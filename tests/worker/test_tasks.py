"""The tasks: registered under the queue's names, retried on transient errors only."""

import os

from hairport.settings import Settings, get_settings
from hairport.worker import runner, tasks
from hairport.worker.app import MEMORY_BROKER, PREPROCESS_TASK, PURGE_TASK, RETARGET_TASK, make_celery


def test_tasks_are_registered_under_their_names_with_retries():
    celery = make_celery(Settings(), MEMORY_BROKER, deployment="d1")
    celery.loader.import_default_modules()
    registered = celery.tasks
    for name in (PREPROCESS_TASK, RETARGET_TASK, PURGE_TASK):
        assert name in registered
    for name in (PREPROCESS_TASK, RETARGET_TASK):
        task = registered[name]
        assert task.autoretry_for == runner.TRANSIENT_ERRORS and task.max_retries == tasks.MAX_RETRIES
        assert task.retry_backoff and task.retry_backoff_max == tasks.RETRY_BACKOFF_MAX


def test_purge_task_runs_the_retention_on_the_configured_storage(tmp_path, monkeypatch):
    monkeypatch.setenv("HAIRPORT_STORAGE_DIR", str(tmp_path))
    get_settings.cache_clear()
    try:
        (tmp_path / "tmp").mkdir()
        stale = tmp_path / "tmp" / "left-over.tmp"
        stale.write_bytes(b"x")
        os.utime(stale, (0, 0))
        assert tasks.purge_task.run() == 1 and not stale.exists()
    finally:
        get_settings.cache_clear()
