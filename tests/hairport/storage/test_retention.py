"""Retention: old files go, young and referenced ones stay."""

import os

from hairport.storage import LocalStorage, retention_seconds
from tests.hairport.storage.helpers import blob_files

DAY = 86_400.0


def test_purge_removes_old_files_and_keeps_young_and_referenced_ones(tmp_path):
    storage = LocalStorage(tmp_path)
    now = 1_000 * DAY
    old, young = now - 31 * DAY, now - 1 * DAY
    old_blob = storage.save_bytes(b"old upload", ".obj")
    young_blob = storage.save_bytes(b"young result", ".npz")
    mesh = storage.save_bytes(b"old mesh of a young character", ".obj")
    orphan = storage.save_bytes(b"old mesh of an old character", ".obj")
    storage.put_record("jobs", "old", {"outputs": {"npz": {"sha256": young_blob.sha256}}})
    storage.put_record("jobs", "young", {"state": "queued"})
    storage.put_record("characters", "young", {"mesh": {"sha256": mesh.sha256, "suffix": ".obj"}})
    storage.put_record("characters", "old", {"mesh": {"sha256": orphan.sha256, "suffix": ".obj"}})
    records = tmp_path / "records"
    stale_upload = tmp_path / "tmp" / "blob-dead.tmp"
    stale_upload.write_bytes(b"half an upload")
    with storage.work_dir() as live_work:
        (live_work / "out.npz").write_bytes(b"being written")
        dead_work = tmp_path / "work" / "work-crashed"
        (dead_work / "sub").mkdir(parents=True)
        (dead_work / "a.bin").write_bytes(b"a")
        (dead_work / "sub" / "b.bin").write_bytes(b"b")
        for path in (old_blob.path, mesh.path, orphan.path, stale_upload, dead_work / "a.bin",
                     dead_work / "sub" / "b.bin", dead_work / "sub", dead_work,
                     records / "jobs" / "old.json", records / "characters" / "old.json"):
            os.utime(path, (old, old))
        for path in (young_blob.path, records / "jobs" / "young.json", records / "characters" / "young.json",
                     live_work, live_work / "out.npz"):
            os.utime(path, (young, young))

        removed = storage.purge(retention_seconds(30.0), now=now)
        # 2 old unreferenced blobs, 2 old records, 1 stale upload, 2 files of the crashed work dir
        assert removed == 7
        assert not old_blob.path.exists() and not orphan.path.exists()
        assert not stale_upload.exists() and not dead_work.exists()
        assert storage.get_record("jobs", "old") is None and storage.get_record("characters", "old") is None
        assert not (records / "jobs" / "old.lock").exists()
        assert young_blob.path.exists()  # young (its old record is gone: no matter)
        assert mesh.path.exists()  # old, but a young record refers to it
        assert storage.get_record("jobs", "young") == {"state": "queued"}
        assert (live_work / "out.npz").exists()
        assert storage.purge(retention_seconds(30.0), now=now) == 0

    # reading through blob() and saving the same content again restart a blob's retention
    os.utime(young_blob.path, (old, old))
    assert storage.blob(young_blob.sha256, ".npz") == young_blob
    assert os.path.getmtime(young_blob.path) > now  # touched: the real clock is far past `now`
    os.utime(young_blob.path, (old, old))
    assert storage.save_bytes(b"young result", ".npz") == young_blob
    assert os.path.getmtime(young_blob.path) > now
    # once its record is gone, the old mesh goes at the next purge
    storage.delete_record("characters", "young")
    assert storage.purge(retention_seconds(30.0), now=now) == 1
    assert blob_files(tmp_path) == [young_blob.path]
