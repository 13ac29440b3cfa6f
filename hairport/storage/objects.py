"""Object stores: where blobs live for every host, behind one small interface.

A deployment names its store with ``HAIRPORT_STORAGE_URL``: a folder (``file:///srv/hairport``
or a plain path: one host, or hosts that mount one volume) or an S3 bucket and prefix
(``s3://bucket/prefix``: any number of hosts, each with its own local folder as a cache,
:mod:`.s3`). Keys are relative, ``/``-separated names (``blobs/ab/<sha256>.obj``); an object is
written whole or not at all, and is never changed once written (blobs are content-addressed).

Every implementation raises :class:`StorageUnavailable` when the store cannot be reached (a
network error, a server answering 5xx, a missing bucket): callers answer 503 with
``Retry-After`` or retry the task, and nothing half-written is left under a key.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from .layout import _create_temp, _unlink

#: URL schemes of a ``HAIRPORT_STORAGE_URL`` (:func:`hairport.storage.object_store_for_url`)
FOLDER_SCHEME, S3_SCHEME = "file", "s3"


class StorageUnavailable(ConnectionError):
    """The object store could not be reached or did not answer; ``reason`` says how. A ``ConnectionError``:
    a worker's task retries it like any other transient error."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


@dataclass(frozen=True)
class ObjectInfo:
    """A stored object: its key, size (bytes) and last write (seconds since the epoch)."""

    key: str
    size: int
    modified: float


class ObjectStore(Protocol):
    """What hairport needs of an object store (keys as in the module docstring)."""

    url: str

    def put_file(self, key: str, path: Path) -> None:
        """Store the file's bytes under ``key`` (whole or not at all)."""

    def get_file(self, key: str, path: Path) -> bool:
        """Write the object to ``path`` (whole, by rename); False when there is no such object."""

    def stat(self, key: str) -> ObjectInfo | None:
        """The object's size and last write, or None."""

    def delete(self, key: str) -> None:
        """Remove the object (no error when it is not there)."""

    def list(self, prefix: str) -> Iterator[ObjectInfo]:
        """Every object whose key starts with ``prefix``."""

    def check(self) -> None:
        """Raise :class:`StorageUnavailable` unless the store answers (readiness)."""


class FolderObjects:
    """An object store in a local folder: each key a file under ``root`` (written by rename).

    Parameters
    ----------
    root : Path
    durable : bool
        ``fsync`` each file before it is renamed into place.
    """

    def __init__(self, root: Path, *, durable: bool = True):
        self.root = Path(root)
        self.durable = durable
        self.url = self.root.as_uri()
        self.root.mkdir(parents=True, exist_ok=True)

    def put_file(self, key: str, path: Path) -> None:
        target = self._path(key)
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, temporary = _create_temp(target.parent, ".put-")
        try:
            with os.fdopen(fd, "wb") as sink, open(path, "rb") as source:
                shutil.copyfileobj(source, sink, 1 << 20)
                if self.durable:
                    sink.flush()
                    os.fsync(sink.fileno())
            os.replace(temporary, target)
        except BaseException:
            _unlink(temporary)
            raise

    def get_file(self, key: str, path: Path) -> bool:
        source = self._path(key)
        path = Path(path)
        fd, temporary = _create_temp(path.parent, ".get-")
        try:
            with os.fdopen(fd, "wb") as sink, open(source, "rb") as stored:
                shutil.copyfileobj(stored, sink, 1 << 20)
            os.replace(temporary, path)
            return True
        except FileNotFoundError:
            _unlink(temporary)
            return False
        except BaseException:
            _unlink(temporary)
            raise

    def stat(self, key: str) -> ObjectInfo | None:
        try:
            status = self._path(key).stat()
        except FileNotFoundError:
            return None
        return ObjectInfo(key, status.st_size, status.st_mtime)

    def delete(self, key: str) -> None:
        _unlink(self._path(key))

    def list(self, prefix: str) -> Iterator[ObjectInfo]:
        for path in sorted(self.root.rglob("*")):
            key = path.relative_to(self.root).as_posix()
            if path.is_file() and key.startswith(prefix) and not path.name.startswith("."):
                info = self.stat(key)
                if info is not None:
                    yield info

    def check(self) -> None:
        if not self.root.is_dir():
            raise StorageUnavailable(f"the storage folder {self.root} does not exist")

    def _path(self, key: str) -> Path:
        check_key(key)
        return self.root / key


def check_key(key: str) -> None:
    """Refuse keys that could leave the store's root (absolute, ``..``, empty parts)."""
    parts = key.split("/")
    if not key or key.startswith("/") or any(part in ("", ".", "..") for part in parts):
        raise ValueError(f"not an object key: {key!r}")
