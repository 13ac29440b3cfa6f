"""Content-addressed blobs: uploads streamed in chunks, produced files, scratch folders of jobs.

Without an object store every blob lives in the local folder (``root/blobs``), which all
processes share. With one (``remote``: ``HAIRPORT_STORAGE_URL``, :mod:`.objects`) the store is
where blobs live and the local folder is this host's cache of them: a save publishes the content
to the store before it enters the cache (so the cache never holds what the store lacks), and a
read that misses the cache fetches it from the store by its digest.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import hashlib
import os
import shutil
import tempfile
import threading
import time
from collections.abc import AsyncIterator, Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from hairport.solver import fsync_folder

from .layout import _create_temp, _unlink, blob_relpath, check_sha256, check_suffix
from .objects import ObjectStore

#: a save of content the object store already holds writes it again when the stored copy is older
#: than this (s): the store's objects keep their first write time, by which the orphan sweep judges
#: them, and content saved again for a new record must not look older than its grace period
REPUBLISH_AFTER_SECONDS = 600.0

#: bytes read from an upload (or a produced file) at a time: bounds the memory of one save
UPLOAD_CHUNK_BYTES = 1 << 20


class UploadTooLarge(Exception):
    """An upload went past its limit: ``limit`` and ``received`` (bytes read when it stopped)."""

    def __init__(self, limit: int, received: int):
        super().__init__(f"upload larger than {limit} bytes ({received} bytes received when stopped)")
        self.limit = limit
        self.received = received


@dataclass(frozen=True)
class Blob:
    """A stored file: its SHA-256 (hex), its size (bytes) and its local path (with the suffix)."""

    sha256: str
    size: int
    path: Path
    #: this save put the content in the store (it was not there before): only then may a caller
    #: that refuses the content take it out again (:meth:`BlobStore.discard_new`)
    created: bool = field(default=False, compare=False)


async def iter_upload(upload, chunk_size: int = UPLOAD_CHUNK_BYTES) -> AsyncIterator[bytes]:
    """The chunks of anything with ``async read(n)`` (a Starlette ``UploadFile``), until it is empty."""
    while True:
        chunk = await upload.read(chunk_size)
        if not chunk:
            return
        yield chunk


class _Sink:
    """A temporary file being written and hashed; thread-safe ``write`` / ``discard``."""

    def __init__(self, folder: Path, durable: bool):
        fd, self.path = _create_temp(folder, "blob-")
        self.durable = durable
        self.file = os.fdopen(fd, "wb")
        self.hash = hashlib.sha256()
        self.size = 0
        self._lock = threading.Lock()

    def write(self, chunk: bytes) -> None:
        with self._lock:
            self.file.write(chunk)
            self.hash.update(chunk)
            self.size += memoryview(chunk).nbytes

    def finish(self) -> None:
        with self._lock:
            self.file.flush()
            if self.durable:
                os.fsync(self.file.fileno())
            self.file.close()

    def discard(self) -> None:
        with self._lock:
            self.file.close()
            _unlink(self.path)


class BlobStore:
    """Blobs under ``root/blobs`` (see :mod:`hairport.storage` for the layout and the assumptions)."""

    root: Path
    durable: bool
    blobs_dir: Path
    tmp_dir: Path
    work_root: Path
    #: where blobs live for every host, when not only in ``root`` (module docstring)
    remote: ObjectStore | None = None

    async def save_stream(self, chunks: AsyncIterator[bytes], max_bytes: int, suffix: str = "") -> Blob:
        """Store an upload chunk by chunk, hashing while writing; memory stays at one chunk.

        Raises
        ------
        UploadTooLarge
            As soon as more than ``max_bytes`` arrived; nothing is left on disk and the
            iterator is closed (``aclose``) when it has one.
        """
        check_suffix(suffix)
        if max_bytes < 0:
            raise ValueError(f"max_bytes must be >= 0, got {max_bytes}")
        sink = _Sink(self.tmp_dir, self.durable)
        try:
            async for chunk in chunks:
                received = sink.size + memoryview(chunk).nbytes
                if received > max_bytes:
                    raise UploadTooLarge(max_bytes, received)
                await asyncio.to_thread(sink.write, chunk)
            return await asyncio.to_thread(self._commit, sink, suffix)
        except BaseException:
            sink.discard()
            aclose = getattr(chunks, "aclose", None)
            if aclose is not None:
                with contextlib.suppress(Exception):
                    await aclose()
            raise

    def save_bytes(self, data: bytes, suffix: str = "") -> Blob:
        """Store ``data`` (small contents; large ones go through :meth:`save_stream` or :meth:`save_file`)."""
        return self._save_chunks([data], suffix)

    def save_file(self, source: Path, suffix: str = "", *, move: bool = False) -> Blob:
        """Store a produced file (a result, an artifact), read in chunks of :data:`UPLOAD_CHUNK_BYTES`.

        ``source`` is copied unless ``move``: then it is renamed into the store when it is
        on the same file system (a job's :meth:`work_dir` is), and is gone afterwards; it
        keeps its mode, so create it readable by the other processes (not with ``mkstemp``).
        """
        check_suffix(suffix)
        source = Path(source)
        if move:
            digest, size = _hash_file(source)
            target = self.root / blob_relpath(digest, suffix)
            target.parent.mkdir(exist_ok=True)
            self._publish(source, blob_relpath(digest, suffix))
            if self._touch(target):
                source.unlink()
                return Blob(digest, size, target)
            if self.durable:
                with open(source, "rb") as handle:
                    os.fsync(handle.fileno())
            try:
                os.replace(source, target)
            except OSError as error:
                if error.errno != errno.EXDEV:
                    raise
            else:
                os.utime(target)
                self._fsync_dir(target.parent)
                return Blob(digest, size, target)
            blob = self.save_file(source, suffix)
            source.unlink()
            return blob
        with open(source, "rb") as handle:
            return self._save_chunks(iter(lambda: handle.read(UPLOAD_CHUNK_BYTES), b""), suffix)

    def blob(self, sha256: str, suffix: str = "") -> Blob | None:
        """The stored blob of that digest and suffix (touched: retention restarts), or None."""
        check_sha256(sha256)
        check_suffix(suffix)
        path = self.root / blob_relpath(sha256, suffix)
        if not self._touch(path) and not self._fetch(blob_relpath(sha256, suffix), path):
            return None
        try:
            return Blob(sha256, path.stat().st_size, path)
        except FileNotFoundError:
            return None

    def save_written(self, write: Callable[[Path], None], suffix: str = "") -> Blob:
        """Store the file ``write(path)`` makes (at a path of a fresh :meth:`work_dir`, moved into the store)."""
        with self.work_dir() as work:
            path = work / f"written{suffix}"
            write(path)
            return self.save_file(path, suffix, move=True)

    @contextlib.contextmanager
    def work_dir(self) -> Iterator[Path]:
        """A fresh directory under ``root/work`` for a job's outputs, removed on exit (also on error)."""
        path = Path(tempfile.mkdtemp(prefix="work-", dir=self.work_root))
        try:
            yield path
        finally:
            shutil.rmtree(path, ignore_errors=True)

    def _save_chunks(self, chunks: Iterable[bytes], suffix: str) -> Blob:
        check_suffix(suffix)
        sink = _Sink(self.tmp_dir, self.durable)
        try:
            for chunk in chunks:
                sink.write(chunk)
            return self._commit(sink, suffix)
        except BaseException:
            sink.discard()
            raise

    def _commit(self, sink: _Sink, suffix: str) -> Blob:
        """Durably move a finished temporary file to its content address (one file per content)."""
        sink.finish()
        digest = sink.hash.hexdigest()
        target = self.root / blob_relpath(digest, suffix)
        target.parent.mkdir(exist_ok=True)
        published = self._publish(sink.path, blob_relpath(digest, suffix))
        created = False
        if self._touch(target):
            _unlink(sink.path)
        else:
            os.replace(sink.path, target)
            self._fsync_dir(target.parent)
            created = True
        return Blob(digest, sink.size, target, created if self.remote is None else published)

    def _publish(self, path: Path, key: str) -> bool:
        """Put a blob's content into the object store unless it holds a recent copy; whether it was not
        there before (nothing without a store)."""
        if self.remote is None:
            return False
        stored = self.remote.stat(key)
        if stored is not None and stored.modified >= time.time() - REPUBLISH_AFTER_SECONDS:
            return False
        self.remote.put_file(key, path)
        return stored is None

    def _fetch(self, key: str, path: Path) -> bool:
        """Bring a blob from the object store into the cache at ``path``; whether the store has it."""
        if self.remote is None:
            return False
        path.parent.mkdir(parents=True, exist_ok=True)
        return self.remote.get_file(key, path)

    def discard_new(self, *blobs: Blob | None) -> int:
        """Remove the blobs this process's saves created (a refused upload keeps no file); a blob
        that was already stored may be another record's and stays. How many were removed.

        Blobs are shared by content: an identical upload accepted between this save and the
        discard would lose its file; the window is the validation of one upload."""
        removed = 0
        for blob in blobs:
            if blob is not None and blob.created:
                if self.remote is not None:
                    self.remote.delete(blob_relpath(blob.sha256, blob.path.name[len(blob.sha256):]))
                removed += _unlink(blob.path) or self.remote is not None
        return removed

    def _fsync_dir(self, path: Path) -> None:
        if self.durable:
            fsync_folder(path)

    @staticmethod
    def _touch(path: Path) -> bool:
        """Set the mtime of an existing file to now; whether it exists (if not allowed to touch: only checks)."""
        try:
            os.utime(path)
            return True
        except FileNotFoundError:
            return False
        except OSError:  # not the owner without write permission, or a read-only mount
            return path.exists()


def _hash_file(path: Path) -> tuple[str, int]:
    """SHA-256 (hex) and size (bytes) of a file, read in chunks."""
    digest = hashlib.sha256()
    size = 0
    with open(path, "rb") as handle:
        for chunk in iter(lambda: handle.read(UPLOAD_CHUNK_BYTES), b""):
            digest.update(chunk)
            size += len(chunk)
    return digest.hexdigest(), size
