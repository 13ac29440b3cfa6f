"""Content-addressed blobs: streamed uploads, limits, memory, produced files, scratch folders."""

import asyncio
import hashlib
import os
import tracemalloc

import pytest

from hairport.storage import UPLOAD_CHUNK_BYTES, Blob, LocalStorage, UploadTooLarge, iter_upload
from tests.hairport.storage.helpers import blob_files

MB = 1 << 20


async def _chunks(parts):
    for part in parts:
        yield part


def _tmp_files(root):
    return sorted(p for p in (root / "tmp").rglob("*") if p.is_file())


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
    assert blob_files(tmp_path) == [blob.path]
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
    assert len(blob_files(tmp_path / "store")) == 2


def test_upload_over_the_limit_is_refused_and_leaves_nothing(tmp_path):
    storage = LocalStorage(tmp_path)
    parts = [b"a" * 400, b"b" * 400, b"c" * 400, b"d" * 400]
    with pytest.raises(UploadTooLarge) as caught:
        asyncio.run(storage.save_stream(_chunks(parts), max_bytes=1000))
    assert (caught.value.limit, caught.value.received) == (1000, 1200)
    assert blob_files(tmp_path) == [] and _tmp_files(tmp_path) == []
    exact = asyncio.run(storage.save_stream(_chunks([b"x" * 600, b"y" * 400]), max_bytes=1000))
    assert exact.size == 1000 and blob_files(tmp_path) == [exact.path]
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
