"""JSON records: put, get, list, delete, read-modify-write under a lock shared by processes."""

import json
import multiprocessing

from hairport.storage import LocalStorage


def test_records_put_get_list_delete(tmp_path):
    storage = LocalStorage(tmp_path)
    assert storage.get_record("jobs", "j1") is None
    assert list(storage.list_records("jobs")) == []
    storage.put_record("jobs", "j2", {"id": "j2", "state": "queued"})
    storage.put_record("jobs", "j1", {"id": "j1", "state": "running", "progress": 0.5})
    storage.put_record("characters", "c1", {"id": "c1"})
    assert storage.get_record("jobs", "j1") == {"id": "j1", "state": "running", "progress": 0.5}
    assert [r["id"] for r in storage.list_records("jobs")] == ["j1", "j2"]
    storage.put_record("jobs", "j1", {"id": "j1", "state": "succeeded"})
    assert storage.get_record("jobs", "j1") == {"id": "j1", "state": "succeeded"}
    assert json.loads(storage.get_record_text("jobs", "j1")) == {"id": "j1", "state": "succeeded"}
    storage.delete_record("jobs", "j1")
    assert storage.get_record_text("jobs", "j1") is None
    storage.delete_record("jobs", "never-existed")
    assert storage.get_record("jobs", "j1") is None
    assert [r["id"] for r in storage.list_records("jobs")] == ["j2"]
    # lock files and temporary files never show up as records
    assert sorted(p.name for p in (tmp_path / "records" / "jobs").iterdir()) == ["j2.json", "j2.lock"]


def test_update_record(tmp_path):
    storage = LocalStorage(tmp_path)
    assert storage.update_record("jobs", "missing", lambda job: job) is None
    assert not (tmp_path / "records" / "jobs").exists() or list((tmp_path / "records" / "jobs").iterdir()) == []
    storage.put_record("jobs", "j", {"state": "queued", "task_id": "t"})
    new = storage.update_record("jobs", "j", lambda job: {**job, "state": "running"})
    assert new == {"state": "running", "task_id": "t"} == storage.get_record("jobs", "j")
    assert storage.update_record("jobs", "j", lambda job: None) == new  # None: unchanged


def _increment(root: str, field: str, times: int) -> None:
    # without fsync (durable=False): the locking is the same, and 400 contended fsyncs take ~4 s
    storage = LocalStorage(root, durable=False)
    for _ in range(times):
        storage.update_record("jobs", "shared", lambda job: {**job, "counter": job["counter"] + 1, field: True})


def test_update_record_from_two_processes_loses_nothing(tmp_path):
    storage = LocalStorage(tmp_path)
    storage.put_record("jobs", "shared", {"counter": 0})
    context = multiprocessing.get_context("spawn")
    workers = [context.Process(target=_increment, args=(str(tmp_path), f"seen_by_{i}", 200)) for i in range(2)]
    for worker in workers:
        worker.start()
    for worker in workers:
        worker.join(timeout=60)
    assert [worker.exitcode for worker in workers] == [0, 0]
    assert storage.get_record("jobs", "shared") == {"counter": 400, "seen_by_0": True, "seen_by_1": True}
