"""The storage shared by API and workers: blobs, limits, memory, records, locking, retention."""

import asyncio
import hashlib
import multiprocessing
import os
import tracemalloc

import pytest

from hairport.storage import (
    UPLOAD_CHUNK_BYTES,
    Blob,
    LocalStorage,
    UploadTooLarge,
    iter_upload,
    retention_seconds,
)

MB = 1 << 20
DAY = 86_400.0


async def _chunks(parts):
    for part in parts:
        yield part


def _blob_files(root):
    return sorted(p for p in (root / "blobs").rglob("*") if p.is_file())


def _tmp_files(root):
    return sorted(p for p in (root / "tmp").rglob("*") if p.is_file())


def test_layout_is_created(tmp_path):
    LocalStorage(tmp_path / "store")
    assert sorted(p.name for p in (tmp_path / "store").iterdir()) == ["blobs", "records", "tmp", "work"]


def test_save_stream_hashes_and_stores_multi_chunk_content(tmp_path):
    storage = LocalStorage(tmp_path)
    parts = [b"v 0 0 0\n" * 1000, b"", b"v 1 0 0\n" * 7, bytes(range(256)) * 3]
    content = b"".join(parts)
    blob = asyncio.run(storage.save_stream(_chunks(parts), max_bytes=10 * MB, suffix=".obj"))
    sha = hashlib.sha256(content).hexdigest()
    assert blob == Blob(sha, len(content), tmp_path / "blobs" / sha[:2] / f"{sha}.obj")
    assert blob.size == 8000 + 56 + 768
    assert blob.path.read_bytes() == content
    again = asyncio.run(storage.save_stream(_chunks([content]), max_bytes=10 * MB, suffix=".obj"))
    assert again == blob
    assert _blob_files(tmp_path) == [blob.path]
    assert _tmp_files(tmp_path) == []
    # another suffix is another file; absent digests and suffixes give None
    assert storage.save_bytes(content).path.name == sha
    assert storage.blob(sha, ".obj") == blob
    assert storage.blob(sha, ".abc") is None
    assert storage.blob(hashlib.sha256(b"other").hexdigest()) is None
    with pytest.raises(ValueError):
        storage.blob("../../etc/passwd")
    with pytest.raises(ValueError):
        storage.save_bytes(b"x", suffix="/evil")


def test_save_file_and_save_bytes_give_the_same_blob(tmp_path):
    storage = LocalStorage(tmp_path / "store")
    data = os.urandom(3 * UPLOAD_CHUNK_BYTES + 17)
    source = tmp_path / "result.npz"
    source.write_bytes(data)
    blob = storage.save_file(source, ".npz")
    assert blob.sha256 == hashlib.sha256(data).hexdigest() and blob.size == len(data)
    assert blob.path.read_bytes() == data and source.exists()
    assert storage.save_bytes(data, ".npz") == blob
    moved = storage.save_file(source, ".npz", move=True)
    assert moved == blob and not source.exists()
    fresh = tmp_path / "fresh.bin"
    fresh.write_bytes(b"moved in")
    moved = storage.save_file(fresh, move=True)
    assert moved.path.read_bytes() == b"moved in" and not fresh.exists()
    assert len(_blob_files(tmp_path / "store")) == 2


def test_upload_over_the_limit_is_refused_and_leaves_nothing(tmp_path):
    storage = LocalStorage(tmp_path)
    parts = [b"a" * 400, b"b" * 400, b"c" * 400, b"d" * 400]
    with pytest.raises(UploadTooLarge) as caught:
        asyncio.run(storage.save_stream(_chunks(parts), max_bytes=1000))
    assert (caught.value.limit, caught.value.received) == (1000, 1200)
    assert _blob_files(tmp_path) == [] and _tmp_files(tmp_path) == []
    exact = asyncio.run(storage.save_stream(_chunks([b"x" * 600, b"y" * 400]), max_bytes=1000))
    assert exact.size == 1000 and _blob_files(tmp_path) == [exact.path]
    empty = asyncio.run(storage.save_stream(_chunks([]), max_bytes=0))
    assert empty.sha256 == hashlib.sha256(b"").hexdigest() and empty.size == 0


class _FakeUpload:
    """What Starlette's ``UploadFile`` offers the storage: ``async read(n)``."""

    def __init__(self, data: bytes):
        self.data, self.offset, self.sizes = data, 0, []

    async def read(self, n: int) -> bytes:
        self.sizes.append(n)
        chunk = self.data[self.offset:self.offset + n]
        self.offset += len(chunk)
        return chunk


def test_iter_upload_reads_in_chunks(tmp_path):
    storage = LocalStorage(tmp_path)
    upload = _FakeUpload(b"0123456789" * 25)
    blob = asyncio.run(storage.save_stream(iter_upload(upload, chunk_size=100), max_bytes=250))
    assert blob.size == 250 and upload.sizes == [100, 100, 100, 100]  # 100 + 100 + 50 + empty
    with pytest.raises(UploadTooLarge) as caught:
        asyncio.run(storage.save_stream(iter_upload(_FakeUpload(b"z" * 250), chunk_size=100), max_bytes=150))
    assert caught.value.received == 200


def test_saving_a_large_stream_holds_about_one_chunk(tmp_path):
    storage = LocalStorage(tmp_path)
    chunk_count = 64

    async def stream():
        for i in range(chunk_count):
            yield bytes([i]) * MB  # a new 1 MB object each time: holding them would show

    tracemalloc.start()
    try:
        blob = asyncio.run(storage.save_stream(stream(), max_bytes=chunk_count * MB, suffix=".bin"))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    expected = hashlib.sha256()
    for i in range(chunk_count):
        expected.update(bytes([i]) * MB)
    assert blob.size == chunk_count * MB and blob.sha256 == expected.hexdigest()
    assert peak < 8 * MB, f"peak {peak / MB:.1f} MB"


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
    storage.delete_record("jobs", "j1")
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


@pytest.mark.parametrize("bad", ["../x", "a/b", "", "x" * 65, "A", "a.json", "..", "a b"])
def test_invalid_kinds_and_ids_are_refused(tmp_path, bad):
    storage = LocalStorage(tmp_path)
    with pytest.raises(ValueError):
        storage.put_record("jobs", bad, {})
    with pytest.raises(ValueError):
        storage.put_record(bad, "ok", {})
    with pytest.raises(ValueError):
        storage.get_record("jobs", bad)
    with pytest.raises(ValueError):
        storage.update_record("jobs", bad, lambda doc: doc)
    with pytest.raises(ValueError):
        storage.delete_record("jobs", bad)
    with pytest.raises(ValueError):
        storage.list_records(bad)
    storage.put_record("jobs", "x" * 64, {"ok": True})  # 64 is the longest allowed
    assert storage.get_record("jobs", "x" * 64) == {"ok": True}


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
    assert _blob_files(tmp_path) == [young_blob.path]


def test_work_dir_is_removed_on_exit_and_on_error(tmp_path):
    storage = LocalStorage(tmp_path)
    with storage.work_dir() as work:
        assert work.is_dir() and work.parent == tmp_path / "work"
        (work / "result.npz").write_bytes(b"x" * 1000)
        (work / "nested").mkdir()
        (work / "nested" / "preview.png").write_bytes(b"png")
    assert not work.exists()
    with pytest.raises(RuntimeError):
        with storage.work_dir() as failing:
            (failing / "partial.bin").write_bytes(b"partial")
            raise RuntimeError("job failed")
    assert not failing.exists() and work != failing
    assert list((tmp_path / "work").iterdir()) == []
