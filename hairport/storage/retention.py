"""Retention: what was not written, saved or read for a while is removed (see :meth:`purge`), and blobs no
record refers to go after a grace period (see :meth:`sweep_orphans`).

With an object store (:mod:`.objects`) the blobs' lives are judged there: a stored object keeps the time
it was written (a read does not refresh it, a save of the same content does once it is older than
:data:`~.blobs.REPUBLISH_AFTER_SECONDS`), so an object no record refers to goes once that time is older
than the cutoff; each is looked at again just before it is deleted. The local folder is then only this
host's cache: a cached blob not read for the cutoff goes whether records refer to it or not (the store
still has it).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import time
from collections.abc import Callable
from pathlib import Path

from .layout import SHA256_HEX_CHARS, TEMP_NAME_BYTES, TEMP_SUFFIX, _files, _is_old, _subdirs, _tree_stats, _unlink

#: prefix of a blob moved aside by a sweep, in ``tmp/``, for the instant its mtime is checked again
SWEPT_PREFIX = "swept-"
#: the object store's keys of blobs (:func:`~.layout.blob_relpath`)
BLOBS_PREFIX = "blobs/"


class Retention:
    """The purge and the orphan sweep of a :class:`hairport.storage.LocalStorage`."""

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
        removed, referenced = self.records.purge_old(cutoff, removed)
        removed += self._remove_unreferenced(referenced, cutoff, evict_cache=True)
        for entry in _files(self.tmp_dir):
            if _is_old(entry, cutoff):
                removed += _unlink(entry)
        for folder in _subdirs(self.work_root):
            files, newest = _tree_stats(folder)
            if newest < cutoff:
                shutil.rmtree(folder, ignore_errors=True)
                removed += files
        return removed

    def sweep_orphans(self, older_than_seconds: float, now: float | None = None,
                      kept_since: Callable[[str, dict], float | None] | None = None) -> int:
        """Remove the blobs no record refers to (:func:`blob_references`) that were not saved or read for
        ``older_than_seconds``: the content of an upload whose record was never written (a process killed
        between the two), or the outputs of a run that lost its job.

        Deployment assumption: whoever saves a blob for a record writes the record within
        ``older_than_seconds`` of the save (an upload's validation, a preprocessing's artifact), or says
        so in a record of its own while it works (``kept_since``: a running job, which records its outputs
        when it ends). A blob saved after the sweep began is younger than the cutoff, so a record that
        changes while the records are scanned loses nothing.

        Parameters
        ----------
        older_than_seconds : float
            The grace period (s), e.g. ``Settings.orphan_grace_seconds``.
        now : float, optional
            The current time (s since the epoch); ``time.time()`` by default.
        kept_since : callable, optional
            ``kept_since(kind, document)``: a time (s since the epoch) since which every blob is kept for
            that record, old or not, or None.

        Returns
        -------
        removed : int
            Blobs removed.
        """
        cutoff = (time.time() if now is None else now) - older_than_seconds
        referenced, kept_from = self.records.references(kept_since)
        cutoff = min(cutoff, kept_from)
        return self._remove_unreferenced(referenced, cutoff)

    def _remove_unreferenced(self, referenced: set[str], cutoff: float, evict_cache: bool = False) -> int:
        """Remove the blobs whose digest is not in ``referenced``, last saved or read before ``cutoff``
        (with an object store: stored before ``cutoff``; ``evict_cache`` also drops from the local cache
        every blob not read since ``cutoff``, referenced or not). How many blobs are gone for good."""
        removed = 0
        cache = self.remote is not None
        for fan_dir in _subdirs(self.blobs_dir):
            for entry in _files(fan_dir):
                unreferenced = entry.name[:SHA256_HEX_CHARS] not in referenced
                if (unreferenced or (cache and evict_cache)) and _is_old(entry, cutoff):
                    removed += self._remove_old_blob(entry, cutoff) and not cache
        if cache:
            removed += self._remove_stored(referenced, cutoff)
        return removed

    def _remove_stored(self, referenced: set[str], cutoff: float) -> int:
        """Remove from the object store the blobs no record refers to, stored before ``cutoff``."""
        removed = 0
        for stored in self.remote.list(BLOBS_PREFIX):
            name = stored.key.rsplit("/", 1)[-1]
            if name[:SHA256_HEX_CHARS] in referenced or stored.modified >= cutoff:
                continue
            again = self.remote.stat(stored.key)  # a save may have written it again meanwhile
            if again is not None and again.modified < cutoff:
                self.remote.delete(stored.key)
                removed += 1
        return removed

    def _remove_old_blob(self, path: Path, cutoff: float) -> bool:
        """Remove a blob unless it is saved or read meanwhile; whether it was removed.

        A save or a read touches the blob (its mtime) before a record refers to it. The blob is moved aside
        first and its mtime checked there: a touch that came before the move shows (and the blob is put
        back: a copy saved meanwhile holds the same bytes), one after it finds no file (a save then stores
        the content again, a read finds it gone as it would a moment later)."""
        aside = self.tmp_dir / f"{SWEPT_PREFIX}{os.urandom(TEMP_NAME_BYTES).hex()}{TEMP_SUFFIX}"
        try:
            os.rename(path, aside)
        except FileNotFoundError:
            return False
        if _is_old(aside, cutoff):
            return _unlink(aside)
        with contextlib.suppress(FileExistsError):
            os.link(aside, path)
        _unlink(aside)
        return False
