"""The orphan sweep in a real ``hairport worker`` process: its sweeper thread removes, on the deployment's
first sweep, the stored files no record refers to that are past the grace period, and keeps the young
ones, the referenced ones and what a running job saved."""

from __future__ import annotations

import os
import time

from hairport.records import BlobRef, CharacterRecord, JobRecord, PreprocessSettings, now
from hairport.repository import Repository
from hairport.storage import LocalStorage

from .deployment import service_env, spawn_worker, stop

#: seconds the worker has to start and sweep
SWEPT_WITHIN_SECONDS = 90
HOUR = 3600.0


def test_a_worker_removes_orphan_blobs_and_keeps_the_live_ones(tmp_path, redis_url):
    storage_dir = tmp_path / "storage"
    storage = LocalStorage(storage_dir)
    repository = Repository(storage)
    orphan = storage.save_bytes(b"the body of an upload whose API was killed before its record", ".obj")
    young = storage.save_bytes(b"an upload being validated", ".obj")
    mesh = storage.save_bytes(b"a character's mesh", ".obj")
    output = storage.save_bytes(b"a result of a job running for an hour and a half", ".npz")
    repository.put(CharacterRecord(id="c" * 32, owner="kowner", created_at=now(), vertices=3, faces=1, bones=[],
                                   mesh=BlobRef(sha256=mesh.sha256, suffix=".obj")), "c" * 32)
    repository.create_job(JobRecord(id="a" * 32, owner="kowner", hairstyle_id="h" * 32, target_character_id="c" * 32,
                                    options={}, preprocess_options=PreprocessSettings(k=5, guides=9),
                                    artifact_key="e" * 64, output_format="npz", created_at=now() - 1.5 * HOUR,
                                    updated_at=now(), state="running", started_at=now() - 1.5 * HOUR,
                                    heartbeat_at=now(), run_token="r", attempts=1))
    # past the grace period of an hour; the orphan is also older than the running job
    for blob, age in ((orphan, 2 * HOUR), (mesh, 2 * HOUR), (output, 1.25 * HOUR)):
        os.utime(blob.path, (now() - age, now() - age))
    # a sweep every second; the job's run stays alive for the test (its heartbeat is not checked again)
    env = service_env(storage_dir, redis_url, HAIRPORT_SWEEP_SECONDS="1", HAIRPORT_STALE_AFTER_SECONDS="86400")
    worker = spawn_worker("orphans", env, tmp_path, warmup=False)
    try:
        deadline = time.monotonic() + SWEPT_WITHIN_SECONDS
        while orphan.path.exists():
            assert worker.poll() is None and time.monotonic() < deadline, (tmp_path / "orphans.log").read_text()
            time.sleep(0.2)
    finally:
        stop(worker)
    assert young.path.exists() and mesh.path.exists() and output.path.exists()
    assert "removed 1 stored files no record refers to" in (tmp_path / "orphans.log").read_text()
    assert repository.job("a" * 32).state == "running"
