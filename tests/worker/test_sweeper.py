"""The sweeper over a real storage and Celery's in-memory broker: stale runs, lost messages, limits."""

import os

import pytest

from hairport.records import JobRecord, PreprocessingRecord, PreprocessSettings, now
from hairport.repository import Repository
from hairport.settings import Settings
from hairport.storage import LocalStorage
from hairport.worker.app import MEMORY_BROKER, make_celery
from hairport.worker.queue import Sweeper, TaskQueue


class Held(TaskQueue):
    """The in-memory queue, with the task ids the broker holds given by the test (that broker cannot be listed)."""

    held: set[str] = set()

    def task_ids_in_broker(self):
        return self.held


@pytest.fixture
def sweep(tmp_path):
    settings = Settings(storage_dir=tmp_path, stale_after_seconds=5, lost_after_seconds=5, max_attempts=2)
    celery = make_celery(settings, MEMORY_BROKER, deployment="sweeptest")
    with celery.connection_for_write() as connection:
        for name in ("hairport.sweeptest.retarget", "hairport.sweeptest.preprocess"):
            connection.SimpleQueue(name).clear()
    repository = Repository(LocalStorage(tmp_path, durable=False))
    return repository, Sweeper(repository, Held(celery), settings), celery


def job(repository, number: int, **fields) -> JobRecord:
    record = JobRecord(id=f"{number:032x}", owner="o", hairstyle_id="h" * 32, target_character_id="t" * 32, options={},
                       preprocess_options=PreprocessSettings(k=5, guides=4), artifact_key="a" * 64,
                       output_format="ply", created_at=now() - 100, updated_at=now(), **fields)
    repository.create_job(record)
    return record


def sent(celery, queue: str) -> list[str]:
    ids = []
    with celery.connection_for_read() as connection:
        simple = connection.SimpleQueue(f"hairport.sweeptest.{queue}")
        while simple.qsize():
            message = simple.get(timeout=1)
            ids.append(message.headers["id"])
            message.ack()
    return ids


def test_a_silent_run_becomes_stale_and_is_sent_again_until_the_attempts_limit(sweep):
    repository, sweeper, celery = sweep
    old = now() - 60
    job(repository, 1, state="running", attempts=1, run_token="r", heartbeat_at=old, task_id="first")
    job(repository, 2, state="running", attempts=2, run_token="r", heartbeat_at=old, task_id="x", worker="w@h")
    job(repository, 3, state="running", attempts=1, run_token="r", heartbeat_at=now(), task_id="alive")
    assert sweeper.sweep() == {"stale": 1, "resent": 0, "failed": 1}
    stale = repository.job(f"{1:032x}")
    assert stale.state == "stale" and stale.stale_at is not None and stale.run_token is None
    assert stale.task_id != "first" and sent(celery, "retarget") == [stale.task_id]
    lost = repository.job(f"{2:032x}")
    assert lost.state == "failed" and lost.error.code == "worker_lost" and "died 2 times" in lost.error.message
    assert repository.job(f"{3:032x}").state == "running"
    assert sweeper.sweep() == {"stale": 0, "resent": 0, "failed": 0}


def test_a_waiting_job_whose_message_is_gone_is_sent_again_then_failed(sweep):
    repository, sweeper, celery = sweep
    job(repository, 4, task_id="gone", enqueued_at=now() - 60)
    job(repository, 5, task_id="held", enqueued_at=now() - 60)
    job(repository, 6, task_id="young", enqueued_at=now())
    sweeper.queue.held = {"held"}
    assert sweeper.sweep() == {"stale": 0, "resent": 1, "failed": 0}
    again = repository.job(f"{4:032x}")
    assert again.state == "queued" and again.requeues == 1 and sent(celery, "retarget") == [again.task_id]
    repository.set_job(again.id, enqueued_at=now() - 60)
    sweeper.sweep()
    repository.set_job(again.id, enqueued_at=now() - 60)
    assert sweeper.sweep()["failed"] == 1
    failed = repository.job(again.id)
    assert failed.state == "failed" and failed.error.code == "message_lost" and failed.requeues == 2
    assert repository.job(f"{5:032x}").requeues == repository.job(f"{6:032x}").requeues == 0


def test_a_lost_preprocessing_claim_is_sent_again(sweep):
    repository, sweeper, celery = sweep
    repository.put(PreprocessingRecord(key="k1", state="queued", hairstyle_id="h" * 32, options={"k": 5, "guides": 4},
                                       task_id="gone", enqueued_at=now() - 60, updated_at=now() - 60), "k1")
    repository.put(PreprocessingRecord(key="k2", state="running", hairstyle_id="h" * 32, task_id="t2", run_token="r",
                                       attempts=1, heartbeat_at=now() - 60, updated_at=now() - 60), "k2")
    assert sweeper.sweep() == {"stale": 1, "resent": 1, "failed": 0}
    first, second = repository.get(PreprocessingRecord, "k1"), repository.get(PreprocessingRecord, "k2")
    assert first.task_id != "gone" and first.requeues == 1
    assert second.state == "queued" and second.stale_at is not None and second.task_id != "t2"
    assert sorted(sent(celery, "preprocess")) == sorted([first.task_id, second.task_id])


def test_one_sweep_per_period_for_the_deployment(sweep):
    repository = sweep[0]
    assert repository.sweep_due(60) and not repository.sweep_due(60) and repository.sweep_due(0)


def test_the_orphan_sweep_takes_its_grace_from_the_settings_and_runs_once_per_interval(sweep):
    repository, sweeper, _ = sweep
    storage = repository.storage
    sweeper.settings = sweeper.settings.model_copy(update={"orphan_grace_seconds": 600.0})
    orphan, young = storage.save_bytes(b"never recorded", ".obj"), storage.save_bytes(b"being validated", ".obj")
    for blob, age in ((orphan, 700), (young, 500)):
        os.utime(blob.path, (now() - age, now() - age))
    assert sweeper.sweep_orphans() == 1 and not orphan.path.exists() and young.path.exists()
    os.utime(young.path, (now() - 700, now() - 700))
    assert sweeper.sweep_orphans() is None and young.path.exists()  # not due again within the hour
