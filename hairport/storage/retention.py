"""Retention: what was not written, saved or read for a while is removed (see :meth:`purge`)."""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable
from pathlib import Path

from .documents import _read_json
from .layout import (
    LOCK_SUFFIX,
    RECORD_SUFFIX,
    SHA256_HEX_CHARS,
    TEMP_SUFFIX,
    _files,
    _is_old,
    _mtime,
    _subdirs,
    _tree_stats,
    _unlink,
    blob_references,
)


class Retention:
    """The purge of a :class:`hairport.storage.LocalStorage`."""

    def purge(self, older_than_seconds: float, now: float | None = None,
              removed: Callable[[str, str], None] | None = None) -> int:
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
        removed : callable, optional
            ``removed(kind, record_id)`` runs under a purged record's lock right after its
            removal (to drop what is derived from it, e.g. an index row).

        Returns
        -------
        removed : int
            Files removed (blobs, records, temporary files and files in work directories).
        """
        cutoff = (time.time() if now is None else now) - older_than_seconds
        on_removed, removed = removed, 0
        referenced: set[str] = set()
        for kind_dir in _subdirs(self.records_dir):
            for entry in _files(kind_dir):
                name = entry.name
                if name.endswith(RECORD_SUFFIX) and not name.startswith("."):
                    if _is_old(entry, cutoff) and self._purge_record(entry, cutoff, on_removed):
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
