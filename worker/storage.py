"""Storage shared by the web service and the Celery workers: content-addressed blobs and JSON records.

Layout of a :class:`LocalStorage` under its ``root`` (``Settings.storage_dir``)::

    root/blobs/<aa>/<sha256><suffix>    immutable file contents; aa = first two hex characters
    root/records/<kind>/<id>.json       small JSON documents (characters, hairstyles, jobs, ...)
    root/records/<kind>/<id>.lock       empty file, ``flock``-ed around every write of that record
    root/tmp/                           uploads and copies being written (same file system as blobs/)
    root/work/<dir>/                    scratch directories of jobs (:meth:`LocalStorage.work_dir`)

Conventions: sizes in bytes, times in seconds since the epoch (file ``st_mtime``), digests
as 64 lower-case hex characters of SHA-256. Every write is atomic: the data goes to a new
file on the same file system, is ``fsync``-ed (unless ``durable=False``), then is
``os.replace``-d onto its name, so a reader in another process sees the old file or the
new one, never a partial one. A blob suffix (``".obj"``) is part of its file name only, so
that readers inferring a format from the extension work; the same bytes under two
suffixes are two files.

Deployment assumption: the API and every worker host mount the same volume at the same
path (``storage_dir``), on a file system with POSIX semantics for ``rename`` (atomic
replace) and ``flock`` (advisory lock shared between processes and hosts). A local disk or
a Docker volume shared by containers of one host qualifies. NFS caveat: NFSv4 (or v3 with a
running lock manager) emulates ``flock`` with byte-range locks and the ``local_lock`` mount
option must not cover ``flock``; attribute caching can delay by a few seconds when one host
sees another's new records and mtimes; and an existing blob is never overwritten (only
touched) so that a host reading it does not get ``ESTALE``. Files are created with mode
``0o666`` minus the umask: API and workers running as different users need a common group
and a umask such as ``002``.

Retention (:meth:`LocalStorage.purge`) works on mtimes: a record lives until ``retention``
after its last write; a blob lives until ``retention`` after it was last saved (saving the
same content again touches it) or read through :meth:`LocalStorage.blob` (which touches
it), and in any case as long as a surviving record refers to it by a ``"sha256"`` field.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import fcntl
import hashlib
import json
import os
import re
import secrets
import shutil
import tempfile
import threading
import time
from collections.abc import AsyncIterator, Callable, Iterable, Iterator
from contextlib import AbstractContextManager
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

#: bytes read from an upload (or a produced file) at a time: bounds the memory of one save
UPLOAD_CHUNK_BYTES = 1 << 20
#: hex characters of the fan-out directory of a blob (256 directories)
BLOB_FANOUT_CHARS = 2
#: hex characters of a SHA-256 digest
SHA256_HEX_CHARS = 64
#: seconds in a day (``Settings.retention_days`` -> :meth:`LocalStorage.purge`)
SECONDS_PER_DAY = 86_400.0
#: mode of created files before the umask (readable by the other users of a shared volume)
FILE_MODE = 0o666
#: random bytes in a temporary file name (hex-encoded: twice as many characters)
TEMP_NAME_BYTES = 8

RECORD_SUFFIX = ".json"
LOCK_SUFFIX = ".lock"
TEMP_SUFFIX = ".tmp"

#: record kinds and ids: file names never come from user input unchecked
NAME_PATTERN = re.compile(r"[a-z0-9_-]{1,64}")
SHA256_PATTERN = re.compile(r"[0-9a-f]{64}")
#: blob suffixes: ``""`` or one or more ``.ext`` parts, at most 32 characters
SUFFIX_PATTERN = re.compile(r"(\.[A-Za-z0-9_-]+)*")
SUFFIX_MAX_CHARS = 32


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


def retention_seconds(days: float) -> float:
    """``Settings.retention_days`` in seconds, the argument of :meth:`LocalStorage.purge`."""
    return days * SECONDS_PER_DAY


def check_name(value: str, what: str = "name") -> str:
    """``value`` if it matches :data:`NAME_PATTERN`, else ``ValueError``."""
    if not isinstance(value, str) or not NAME_PATTERN.fullmatch(value):
        raise ValueError(f"invalid {what} {value!r}: expected 1 to 64 of a-z, 0-9, '_', '-'")
    return value


def check_sha256(value: str) -> str:
    """``value`` if it is 64 lower-case hex characters, else ``ValueError``."""
    if not isinstance(value, str) or not SHA256_PATTERN.fullmatch(value):
        raise ValueError(f"invalid sha256 {value!r}: expected 64 lower-case hex characters")
    return value


def check_suffix(value: str) -> str:
    """``value`` if it is ``""`` or like ``".obj"`` / ``".tar.gz"`` (no path separators), else ``ValueError``."""
    if not isinstance(value, str) or len(value) > SUFFIX_MAX_CHARS or not SUFFIX_PATTERN.fullmatch(value):
        raise ValueError(f"invalid blob suffix {value!r}: expected '' or '.ext' parts of a-z, A-Z, 0-9, '_', '-'")
    return value


def blob_relpath(sha256: str, suffix: str = "") -> str:
    """``blobs/<aa>/<sha256><suffix>`` relative to the storage root."""
    return f"blobs/{sha256[:BLOB_FANOUT_CHARS]}/{sha256}{suffix}"


def blob_references(document) -> set[str]:
    """Every ``"sha256"`` string value found at any depth of a JSON document."""
    found: set[str] = set()
    stack = [document]
    while stack:
        item = stack.pop()
        if isinstance(item, dict):
            value = item.get("sha256")
            if isinstance(value, str):
                found.add(value)
            stack.extend(item.values())
        elif isinstance(item, list):
            stack.extend(item)
    return found


async def iter_upload(upload, chunk_size: int = UPLOAD_CHUNK_BYTES) -> AsyncIterator[bytes]:
    """The chunks of anything with ``async read(n)`` (a Starlette ``UploadFile``), until it is empty."""
    while True:
        chunk = await upload.read(chunk_size)
        if not chunk:
            return
        yield chunk


class Storage(Protocol):
    """What the API and the workers use; :class:`LocalStorage` is the one implementation.

    Blobs are handed out as local paths (:attr:`Blob.path`): a remote backend would keep a
    local cache.
    """

    async def save_stream(self, chunks: AsyncIterator[bytes], max_bytes: int, suffix: str = "") -> Blob: ...
    def save_file(self, source: Path, suffix: str = "") -> Blob: ...
    def save_bytes(self, data: bytes, suffix: str = "") -> Blob: ...
    def blob(self, sha256: str, suffix: str = "") -> Blob | None: ...
    def work_dir(self) -> AbstractContextManager[Path]: ...
    def put_record(self, kind: str, record_id: str, document: dict) -> None: ...
    def get_record(self, kind: str, record_id: str) -> dict | None: ...
    def update_record(self, kind: str, record_id: str, change: Callable[[dict], dict | None]) -> dict | None: ...
    def list_records(self, kind: str) -> Iterator[dict]: ...
    def delete_record(self, kind: str, record_id: str) -> None: ...
    def purge(self, older_than_seconds: float, now: float | None = None) -> int: ...


def _fsync_dir(path: Path) -> None:
    """Make a rename in ``path`` durable (best effort: not every file system allows it)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _create_temp(folder: Path, prefix: str) -> tuple[int, Path]:
    """A new empty file in ``folder`` (mode :data:`FILE_MODE` minus the umask), opened for writing."""
    while True:
        path = folder / f"{prefix}{secrets.token_hex(TEMP_NAME_BYTES)}{TEMP_SUFFIX}"
        try:
            return os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, FILE_MODE), path
        except FileExistsError:
            continue


def _unlink(path: Path) -> bool:
    """Remove a file; whether it was there."""
    try:
        path.unlink()
        return True
    except FileNotFoundError:
        return False


def _mtime(path: Path) -> float | None:
    try:
        return path.stat().st_mtime
    except FileNotFoundError:
        return None


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


class LocalStorage:
    """Blobs and records in a local directory (see the module docstring for layout and assumptions).

    Parameters
    ----------
    root : Path
        The storage directory; ``blobs/``, ``records/``, ``tmp/`` and ``work/`` are created.
    durable : bool
        ``fsync`` every written file and the directory of every rename (the default). Off
        only for tests and throwaway stores: a crash could then leave an old or empty file,
        but atomicity between processes and the locking are the same.
    """

    def __init__(self, root: Path, *, durable: bool = True):
        self.root = Path(root)
        self.durable = durable
        self.blobs_dir = self.root / "blobs"
        self.records_dir = self.root / "records"
        self.tmp_dir = self.root / "tmp"
        self.work_root = self.root / "work"
        for folder in (self.blobs_dir, self.records_dir, self.tmp_dir, self.work_root):
            folder.mkdir(parents=True, exist_ok=True)

    def __repr__(self) -> str:
        return f"LocalStorage({str(self.root)!r}, durable={self.durable})"

    # ---------------------------------------------------------------- blobs

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
        if not self._touch(path):
            return None
        try:
            return Blob(sha256, path.stat().st_size, path)
        except FileNotFoundError:
            return None

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
        if self._touch(target):
            _unlink(sink.path)
        else:
            os.replace(sink.path, target)
            self._fsync_dir(target.parent)
        return Blob(digest, sink.size, target)

    def _fsync_dir(self, path: Path) -> None:
        if self.durable:
            _fsync_dir(path)

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

    # ---------------------------------------------------------------- records

    def put_record(self, kind: str, record_id: str, document: dict) -> None:
        """Write (create or replace) a record atomically."""
        path = self._record_path(kind, record_id)
        if not isinstance(document, dict):
            raise TypeError(f"a record is a dict, got {type(document).__name__}")
        path.parent.mkdir(exist_ok=True)
        with self._locked(path):
            _write_json(path, document, self.durable)

    def get_record(self, kind: str, record_id: str) -> dict | None:
        """The record, or None if it does not exist."""
        return _read_json(self._record_path(kind, record_id))

    def update_record(self, kind: str, record_id: str, change: Callable[[dict], dict | None]) -> dict | None:
        """Read-modify-write of a record under its exclusive lock (between threads, processes and hosts).

        ``change`` gets the current document and returns the new one; returning None leaves
        the record unchanged (nothing is written). Returns the record as stored afterwards,
        or None (``change`` not called) if the record does not exist.
        """
        path = self._record_path(kind, record_id)
        if not path.exists():
            return None
        with self._locked(path) as lock:
            text = _read_text(path)
            if text is None:  # deleted while we waited for the lock
                _unlink(lock)
                return None
            new = change(json.loads(text))
            if new is None:
                return json.loads(text)
            if not isinstance(new, dict):
                raise TypeError(f"change must return a dict or None, got {type(new).__name__}")
            _write_json(path, new, self.durable)
            return new

    def list_records(self, kind: str) -> Iterator[dict]:
        """Every record of a kind, in id order (records deleted meanwhile are skipped)."""
        folder = self.records_dir / check_name(kind, "record kind")
        return _iter_records(folder)

    def delete_record(self, kind: str, record_id: str) -> None:
        """Remove a record (and its lock file); nothing happens if it does not exist."""
        path = self._record_path(kind, record_id)
        if not path.parent.is_dir():
            return
        with self._locked(path) as lock:
            _unlink(path)
            _unlink(lock)

    def _record_path(self, kind: str, record_id: str) -> Path:
        check_name(kind, "record kind")
        check_name(record_id, "record id")
        return self.records_dir / kind / f"{record_id}{RECORD_SUFFIX}"

    @contextlib.contextmanager
    def _locked(self, path: Path) -> Iterator[Path]:
        """Hold ``flock(LOCK_EX)`` on the record's lock file; yields the lock file's path.

        The lock file may be unlinked by its holder (delete, purge): after locking, the path
        must still name the locked inode, else the lock is taken again on the new file.
        """
        lock = path.with_suffix(LOCK_SUFFIX)
        while True:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, FILE_MODE)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX)
                held = os.fstat(fd)
                try:
                    named = os.stat(lock)
                    same = (named.st_ino, named.st_dev) == (held.st_ino, held.st_dev)
                except FileNotFoundError:
                    same = False
            except BaseException:
                os.close(fd)
                raise
            if same:
                break
            os.close(fd)
        try:
            yield lock
        finally:
            os.close(fd)  # releases the lock

    # ---------------------------------------------------------------- retention

    def purge(self, older_than_seconds: float, now: float | None = None) -> int:
        """Delete what was not written (or, for blobs, saved or read) for ``older_than_seconds``.

        Removes, in this order: records whose mtime is older than the cutoff (under their
        lock, the mtime checked again), then blobs older than the cutoff that no remaining
        record refers to (:func:`blob_references`), then temporary files and work
        directories (all of whose files are) older than the cutoff. Lock files of removed
        records go too but are not counted.

        Deployment assumption: a record refers to a blob it got from a ``save_*`` call or
        :meth:`blob` (both touch the blob), so a blob is at least as young as the record that
        was just written with it; records are kept no longer than the retention after their
        last write, and blobs no longer than the retention after their last save or read
        unless a kept record refers to them.

        Parameters
        ----------
        older_than_seconds : float
            Retention (s), e.g. ``retention_seconds(settings.retention_days)``.
        now : float, optional
            The current time (s since the epoch); ``time.time()`` by default.

        Returns
        -------
        removed : int
            Files removed (blobs, records, temporary files and files in work directories).
        """
        cutoff = (time.time() if now is None else now) - older_than_seconds
        removed = 0
        referenced: set[str] = set()
        for kind_dir in _subdirs(self.records_dir):
            for entry in _files(kind_dir):
                name = entry.name
                if name.endswith(RECORD_SUFFIX) and not name.startswith("."):
                    if _is_old(entry, cutoff) and self._purge_record(entry, cutoff):
                        removed += 1
                    else:
                        referenced |= blob_references(_read_json(entry))
                elif name.endswith(TEMP_SUFFIX) and _is_old(entry, cutoff):
                    removed += _unlink(entry)
            for entry in _files(kind_dir):  # lock files of records gone by other means
                if entry.name.endswith(LOCK_SUFFIX) and _is_old(entry, cutoff):
                    record = entry.with_suffix(RECORD_SUFFIX)
                    if not record.exists():
                        with self._locked(record) as lock:
                            if not record.exists():
                                _unlink(lock)
        for fan_dir in _subdirs(self.blobs_dir):
            for entry in _files(fan_dir):
                if entry.name[:SHA256_HEX_CHARS] not in referenced and _is_old(entry, cutoff):
                    removed += _unlink(entry)
        for entry in _files(self.tmp_dir):
            if _is_old(entry, cutoff):
                removed += _unlink(entry)
        for folder in _subdirs(self.work_root):
            files, newest = _tree_stats(folder)
            if newest < cutoff:
                shutil.rmtree(folder, ignore_errors=True)
                removed += files
        return removed

    def _purge_record(self, path: Path, cutoff: float) -> bool:
        """Remove an old record unless it was written meanwhile; whether it was removed."""
        with self._locked(path) as lock:
            mtime = _mtime(path)
            if mtime is None or mtime >= cutoff:
                return False
            _unlink(path)
            _unlink(lock)
            return True


def _hash_file(path: Path) -> tuple[str, int]:
    """SHA-256 (hex) and size (bytes) of a file, read in chunks."""
    digest = hashlib.sha256()
    size = 0
    with open(path, "rb") as handle:
        for chunk in iter(lambda: handle.read(UPLOAD_CHUNK_BYTES), b""):
            digest.update(chunk)
            size += len(chunk)
    return digest.hexdigest(), size


def _write_json(path: Path, document: dict, durable: bool = True) -> None:
    """Atomically replace ``path`` by the JSON of ``document`` (temporary file in the same directory)."""
    data = json.dumps(document, separators=(",", ":")).encode()
    fd, temp = _create_temp(path.parent, f".{path.stem}.")
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            if durable:
                os.fsync(handle.fileno())
        os.replace(temp, path)
    except BaseException:
        _unlink(temp)
        raise
    if durable:
        _fsync_dir(path.parent)


def _read_text(path: Path) -> str | None:
    try:
        return path.read_text()
    except FileNotFoundError:
        return None


def _read_json(path: Path) -> dict | None:
    text = _read_text(path)
    return None if text is None else json.loads(text)


def _iter_records(folder: Path) -> Iterator[dict]:
    names = sorted(entry.name for entry in _files(folder)
                   if entry.name.endswith(RECORD_SUFFIX) and not entry.name.startswith("."))
    for name in names:
        document = _read_json(folder / name)
        if document is not None:
            yield document


def _files(folder: Path) -> list[Path]:
    """Regular files directly in ``folder`` (none if it does not exist)."""
    try:
        with os.scandir(folder) as entries:
            return [Path(entry.path) for entry in entries if entry.is_file(follow_symlinks=False)]
    except FileNotFoundError:
        return []


def _subdirs(folder: Path) -> list[Path]:
    try:
        with os.scandir(folder) as entries:
            return [Path(entry.path) for entry in entries if entry.is_dir(follow_symlinks=False)]
    except FileNotFoundError:
        return []


def _is_old(path: Path, cutoff: float) -> bool:
    """Whether ``path`` exists with an mtime before ``cutoff`` (checked right before a removal)."""
    mtime = _mtime(path)
    return mtime is not None and mtime < cutoff


def _tree_stats(folder: Path) -> tuple[int, float]:
    """Number of files under ``folder`` and the newest mtime of it and everything in it."""
    files = 0
    newest = _mtime(folder) or 0.0
    for parent, dirs, names in os.walk(folder):
        for name in dirs + names:
            newest = max(newest, _mtime(Path(parent) / name) or 0.0)
        files += len(names)
    return files, newest
