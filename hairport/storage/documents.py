"""JSON records in a folder: small documents rewritten atomically under a per-record ``flock``.

:class:`FolderRecords` is one of the two record stores (the other, in a PostgreSQL database, is
:class:`~.postgres.PostgresRecords`); both answer the same methods, which
:class:`~hairport.storage.LocalStorage` hands on.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import math
import os
from collections.abc import Callable, Iterator
from pathlib import Path

from hairport.solver import atomic_write_bytes

from .layout import (
    FILE_MODE,
    LOCK_SUFFIX,
    RECORD_SUFFIX,
    TEMP_SUFFIX,
    _files,
    _is_old,
    _mtime,
    _read_text,
    _subdirs,
    _unlink,
    blob_references,
    check_name,
)

#: ``written(old, new)``: called under a record's lock after it was written
Written = Callable[[dict | None, dict], None]


class FolderRecords:
    """Records under ``records_dir/<kind>/<id>.json`` (see :mod:`hairport.storage`).

    Parameters
    ----------
    records_dir : Path
    durable : bool
        ``fsync`` every written record.
    """

    def __init__(self, records_dir: Path, durable: bool = True):
        self.records_dir = Path(records_dir)
        self.durable = durable
        self.records_dir.mkdir(parents=True, exist_ok=True)

    def put_record(self, kind: str, record_id: str, document: dict, written: Written | None = None) -> None:
        """Write (create or replace) a record atomically; ``written(old, new)`` runs under its lock after the
        write (``old`` is None for a new record)."""
        path = self._record_path(kind, record_id)
        if not isinstance(document, dict):
            raise TypeError(f"a record is a dict, got {type(document).__name__}")
        path.parent.mkdir(exist_ok=True)
        with self._locked(path):
            old = _read_json(path) if written is not None else None
            _write_json(path, document, self.durable)
            if written is not None:
                written(old, document)

    def get_record(self, kind: str, record_id: str) -> dict | None:
        """The record, or None if it does not exist."""
        return _read_json(self._record_path(kind, record_id))

    def get_record_text(self, kind: str, record_id: str) -> str | None:
        """The record's JSON text, or None if it does not exist (for parsers faster than ``json``)."""
        return _read_text(self._record_path(kind, record_id))

    def update_record(self, kind: str, record_id: str, change: Callable[[dict], dict | None],
                      written: Written | None = None) -> dict | None:
        """Read-modify-write of a record under its exclusive lock (between threads, processes and hosts).

        ``change`` gets the current document and returns the new one; returning None leaves
        the record unchanged (nothing is written). ``written(old, new)``, when given, runs
        after the write with the lock still held (to keep derived files such as an index in
        step). Returns the record as stored afterwards, or None (``change`` not called) if the
        record does not exist.
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
            if written is not None:
                written(json.loads(text), new)
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

    def has_record(self, kind: str, record_id: str) -> bool:
        return self._record_path(kind, record_id).exists()

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


    # ------------------------------------------------------------------ retention

    def purge_old(self, cutoff: float, removed: Callable[[str, str], None] | None = None) -> tuple[int, set[str]]:
        """Remove the records not written since ``cutoff`` (each under its lock, its mtime checked again), old
        temporary files and orphaned lock files; the count removed and the digests the remaining records refer
        to (:func:`~.layout.blob_references`). ``removed(kind, id)`` runs under a purged record's lock."""
        count, referenced = 0, set()
        for kind_dir in _subdirs(self.records_dir):
            for entry in _files(kind_dir):
                name = entry.name
                if name.endswith(RECORD_SUFFIX) and not name.startswith("."):
                    if _is_old(entry, cutoff) and self._purge_record(entry, cutoff, removed):
                        count += 1
                    else:
                        referenced |= blob_references(_read_json(entry))
                elif name.endswith(TEMP_SUFFIX) and _is_old(entry, cutoff):
                    count += _unlink(entry)
            for entry in _files(kind_dir):  # lock files of records gone by other means
                if entry.name.endswith(LOCK_SUFFIX) and _is_old(entry, cutoff):
                    record = entry.with_suffix(RECORD_SUFFIX)
                    if not record.exists():
                        with self._locked(record) as lock:
                            if not record.exists():
                                _unlink(lock)
        return count, referenced

    def references(self, kept_since: Callable[[str, dict], float | None] | None = None) -> tuple[set[str], float]:
        """The digests every record refers to, and the earliest time since which ``kept_since(kind, document)``
        keeps every blob (infinity when no record says so)."""
        referenced: set[str] = set()
        earliest = math.inf
        for kind_dir in _subdirs(self.records_dir):
            for entry in _files(kind_dir):
                if entry.name.endswith(RECORD_SUFFIX) and not entry.name.startswith("."):
                    document = _read_json(entry)
                    if document is None:
                        continue
                    referenced |= blob_references(document)
                    since = None if kept_since is None else kept_since(kind_dir.name, document)
                    if since is not None:
                        earliest = min(earliest, since)
        return referenced, earliest

    def _purge_record(self, path: Path, cutoff: float, removed: Callable[[str, str], None] | None) -> bool:
        """Remove an old record unless it was written meanwhile; whether it was removed."""
        with self._locked(path) as lock:
            mtime = _mtime(path)
            if mtime is None or mtime >= cutoff:
                return False
            _unlink(path)
            if removed is not None:
                removed(path.parent.name, path.name[:-len(RECORD_SUFFIX)])
            _unlink(lock)
            return True


def record_text(document: dict) -> str:
    """A record's stored JSON text (compact), in a file or a database row alike."""
    return json.dumps(document, separators=(",", ":"))


def _write_json(path: Path, document: dict, durable: bool = True) -> None:
    """Atomically replace ``path`` by the JSON of ``document``."""
    atomic_write_bytes(path, record_text(document).encode(), durable=durable)


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
