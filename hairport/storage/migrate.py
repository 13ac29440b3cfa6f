"""Moving a one-host deployment (records and blobs in a storage folder) to hosts that share URLs (records in
PostgreSQL, blobs in an object store): ``hairport migrate``.

Blobs go first, then records, so that no record in the new place ever names a blob it lacks; each is copied
as it is (a blob under its digest, a record under its kind and id), so a second run copies only what the
first did not (an interrupted migration is run again). The folder is left as it was: it is the way back until
the new deployment is trusted. Stop the API and the workers first: what they write during the copy may be
missed.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

from .layout import RECORD_SUFFIX, SHA256_HEX_CHARS, _files, _subdirs, blob_references


@dataclass
class MigrationReport:
    """What a migration copied and found: blobs copied and already there, records by kind, and the blobs some
    record names that the folder did not have (listed, never invented)."""

    blobs_copied: int = 0
    blobs_present: int = 0
    records: Counter = field(default_factory=Counter)
    missing_blobs: set[str] = field(default_factory=set)


def migrate(source, target, progress: Callable[[str], None] = lambda message: None) -> MigrationReport:
    """Copy every blob and record of ``source`` (a folder :class:`~hairport.storage.LocalStorage`) into ``target``
    (a storage with an object store and a database). The target's record index is not written here: the
    caller rebuilds it (:meth:`hairport.repository.Repository.rebuild_index`).

    Raises
    ------
    ValueError
        When the target has no object store or keeps its records in the folder (nothing would move).
    """
    if target.remote is None or getattr(target.records, "database", None) is None:
        raise ValueError("the target must have an object store (HAIRPORT_STORAGE_URL) and a database "
                         "(HAIRPORT_DATABASE_URL)")
    report = MigrationReport()
    stored = {info.key for info in target.remote.list("blobs/")}
    present = {key.rsplit("/", 1)[-1][:SHA256_HEX_CHARS] for key in stored}
    for fan_dir in _subdirs(source.blobs_dir):
        for entry in _files(fan_dir):
            key = f"blobs/{fan_dir.name}/{entry.name}"
            present.add(entry.name[:SHA256_HEX_CHARS])
            if key in stored:
                report.blobs_present += 1
            else:
                target.remote.put_file(key, entry)
                report.blobs_copied += 1
    progress(f"blobs: {report.blobs_copied} copied, {report.blobs_present} already there")
    for kind_dir in _subdirs(source.records_dir):
        for entry in _files(kind_dir):
            if not entry.name.endswith(RECORD_SUFFIX) or entry.name.startswith("."):
                continue
            record_id = entry.name[:-len(RECORD_SUFFIX)]  # some kinds are keyed by a digest, not an ``id`` field
            document = source.get_record(kind_dir.name, record_id)
            if document is None:  # removed meanwhile
                continue
            report.missing_blobs |= blob_references(document) - present
            target.put_record(kind_dir.name, record_id, document)
            report.records[kind_dir.name] += 1
    progress(f"records: {dict(report.records)}")
    return report
