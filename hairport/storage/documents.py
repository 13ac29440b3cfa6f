"""JSON records: small documents rewritten atomically under a per-record ``flock``."""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
from collections.abc import Callable, Iterator
from pathlib import Path

from hairport.solver import atomic_write_bytes

from .layout import FILE_MODE, LOCK_SUFFIX, RECORD_SUFFIX, _files, _read_text, _unlink, check_name

#: ``written(old, new)``: called under a record's lock after it was written
Written = Callable[[dict | None, dict], None]


class DocumentStore:
    """Records under ``root/records/<kind>/<id>.json`` (see :mod:`hairport.storage`)."""

    records_dir: Path
    durable: bool

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


def _write_json(path: Path, document: dict, durable: bool = True) -> None:
    """Atomically replace ``path`` by the JSON of ``document``."""
    data = json.dumps(document, separators=(",", ":")).encode()
    atomic_write_bytes(path, data, durable=durable)


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
