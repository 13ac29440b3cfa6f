"""Retention: old files go, young and referenced ones stay."""

import os
import time

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


HOUR = 3600.0


def test_the_orphan_sweep_removes_old_blobs_no_record_refers_to(tmp_path):
    storage = LocalStorage(tmp_path)
    now = 1_000 * DAY
    orphan = storage.save_bytes(b"an upload whose API died before its record", ".obj")
    young = storage.save_bytes(b"an upload being validated", ".obj")
    referenced = storage.save_bytes(b"an old character's mesh", ".obj")
    nested = storage.save_bytes(b"a job's result", ".npz")
    artifact = storage.save_bytes(b"a preprocessed hairstyle", ".hpa")
    unrecorded = storage.save_bytes(b"an output of a job running since 3 hours ago", ".png")
    storage.put_record("characters", "c", {"mesh": {"sha256": referenced.sha256, "suffix": ".obj"}})
    storage.put_record("jobs", "j", {"outputs": {"npz": {"sha256": nested.sha256, "suffix": ".npz"}}})
    storage.put_record("artifacts", "a", {"sha256": artifact.sha256, "suffix": ".hpa"})
    storage.put_record("jobs", "running", {"state": "running", "started_at": now - 3 * HOUR})
    for blob, age in ((orphan, 4 * HOUR), (young, 0.5 * HOUR), (referenced, 20 * DAY), (nested, 20 * DAY),
                      (artifact, 20 * DAY), (unrecorded, 2 * HOUR)):
        os.utime(blob.path, (now - age, now - age))

    def running_since(kind, document):
        return document["started_at"] if kind == "jobs" and document.get("state") == "running" else None

    assert storage.sweep_orphans(HOUR, now=now, kept_since=running_since) == 1  # older than the running job
    assert not orphan.path.exists() and unrecorded.path.exists()
    storage.update_record("jobs", "running", lambda job: {**job, "state": "failed"})  # its outputs stay unrecorded
    assert storage.sweep_orphans(HOUR, now=now, kept_since=running_since) == 1
    assert blob_files(tmp_path) == sorted(b.path for b in (young, referenced, nested, artifact))
    assert list((tmp_path / "tmp").iterdir()) == []  # nothing left aside
    storage.delete_record("jobs", "j")
    assert storage.sweep_orphans(HOUR, now=now) == 1 and not nested.path.exists()


def test_a_blob_saved_again_while_the_sweep_removes_it_is_kept(tmp_path, monkeypatch):
    """A save (or read) touches the blob between the sweep's age check and its removal: the blob stays."""
    from hairport.storage import retention

    storage = LocalStorage(tmp_path)
    blob = storage.save_bytes(b"content uploaded again right now", ".obj")
    old = time.time() - 2 * HOUR
    os.utime(blob.path, (old, old))
    moves = []

    def saved_meanwhile(source, target):
        moves.append(source)
        if len(moves) == 1:
            assert storage.save_bytes(b"content uploaded again right now", ".obj") == blob  # touches it
        return os.replace(source, target)

    monkeypatch.setattr(retention.os, "rename", saved_meanwhile)
    assert storage.sweep_orphans(HOUR) == 0
    assert blob.path.read_bytes() == b"content uploaded again right now" and moves == [blob.path]
    assert list((tmp_path / "tmp").iterdir()) == []
    monkeypatch.undo()
    os.utime(blob.path, (old, old))  # not saved again this time: it goes
    assert storage.sweep_orphans(HOUR) == 1 and not blob.path.exists()
