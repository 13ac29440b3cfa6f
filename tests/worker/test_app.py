"""The Celery app: built on first use, configured for late acknowledgement and redelivery."""

import json
import subprocess
import sys

import pytest

from hairport.settings import Settings
from hairport.worker import app as worker_app
from hairport.worker.app import MEMORY_BROKER, QUEUES, ROUTES, make_celery


def test_configuration_follows_the_settings(tmp_path):
    settings = Settings(task_time_limit=100, task_soft_time_limit=90, visibility_timeout=120,
                        redis_url="redis://127.0.0.1:1/3", storage_dir=tmp_path, enqueue_timeout_seconds=2.5)
    app = make_celery(settings)
    conf = app.conf
    assert conf.broker_url == "redis://127.0.0.1:1/3"
    assert conf.task_acks_late and conf.task_reject_on_worker_lost and conf.task_ignore_result
    assert conf.worker_prefetch_multiplier == 1
    assert (conf.task_time_limit, conf.task_soft_time_limit) == (100, 90)
    assert conf.broker_transport_options == {"visibility_timeout": 120, "socket_connect_timeout": 2.5,
                                             "socket_timeout": 2.5}
    assert conf.broker_connection_timeout == 2.5 and conf.task_publish_retry_policy["max_retries"] == 1
    # the queues are the deployment's, named after the id written in its storage
    deployment = json.loads((tmp_path / "deployment.json").read_text())["id"]
    assert app.hairport_deployment == deployment and len(deployment) == 12
    assert conf.task_routes == {name: {"queue": f"hairport.{deployment}.{queue}"} for name, queue in ROUTES.items()}
    assert set(ROUTES.values()) <= set(QUEUES) and conf.accept_content == ["json"]
    memory = make_celery(settings, MEMORY_BROKER)
    assert memory.conf.broker_url == MEMORY_BROKER and memory.conf.broker_transport_options == {}
    assert memory.hairport_deployment == deployment
    other = make_celery(settings.model_copy(update={"storage_dir": tmp_path / "other"}))
    assert other.hairport_deployment != deployment
    assert other.conf.task_default_queue == f"hairport.{other.hairport_deployment}.retarget"


def test_importing_the_app_module_builds_no_app():
    code = ("import hairport.worker.app as a, hairport.worker.queue, hairport.worker.tasks;"
            "print(a.celery_for.cache_info().currsize)")
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout == "0\n"


def test_the_celery_cli_finds_the_configured_app_by_attribute():
    assert worker_app.celery_app is worker_app.configured_celery()
    with pytest.raises(AttributeError):
        worker_app.no_such_thing  # noqa: B018
