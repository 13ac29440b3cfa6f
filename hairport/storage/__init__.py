"""Storage shared by the web service and the Celery workers: content-addressed blobs and JSON records.

Layout of a :class:`LocalStorage` under its ``root`` (``Settings.storage_dir``)::

    root/blobs/<aa>/<sha256><suffix>    immutable file contents; aa = first two hex characters
    root/records/<kind>/<id>.json       small JSON documents (characters, hairstyles, jobs, ...)
    root/records/<kind>/<id>.lock       empty file, ``flock``-ed around every write of that record
    root/tmp/                           uploads and copies being written (same file system as blobs/)
    root/work/<dir>/                    scratch directories of jobs (:meth:`LocalStorage.work_dir`)
    root/index/records.sqlite3          the record index (:mod:`.index`): listings and counts without reading records
    root/deployment.json                the deployment id (:mod:`.deployment`), written once

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
it), and in any case as long as a surviving record refers to it by a ``"sha256"`` field. A blob no
record refers to goes earlier, once it was not saved or read for a grace period
(:meth:`LocalStorage.sweep_orphans`, ``Settings.orphan_grace_seconds``): the upload of a process
killed before its record was written, the outputs of a run that lost its job.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Callable, Iterator
from pathlib import Path
from urllib.parse import urlparse

from .blobs import UPLOAD_CHUNK_BYTES, Blob, BlobStore, UploadTooLarge, iter_upload
from .deployment import DEPLOYMENT_FILE, deployment_for, deployment_id, queue_name
from .documents import FolderRecords, Written
from .layout import (
    FILE_MODE,
    LOCK_SUFFIX,
    RECORD_SUFFIX,
    SECONDS_PER_DAY,
    TEMP_SUFFIX,
    blob_references,
    blob_relpath,
    check_name,
    check_sha256,
    check_suffix,
    retention_seconds,
)
from .objects import FOLDER_SCHEME, S3_SCHEME, FolderObjects, ObjectInfo, ObjectStore, StorageUnavailable
from .postgres import Database, PostgresRecords, SchemaMismatch, upgrade
from .retention import Retention
from .s3 import S3Objects

log = logging.getLogger(__name__)

#: the URL schemes of ``HAIRPORT_DATABASE_URL``: SQLite (the records in the storage folder) or PostgreSQL
SQLITE_SCHEME = "sqlite"
POSTGRES_SCHEMES = ("postgresql://", "postgres://")

__all__ = [
    "Blob", "DEPLOYMENT_FILE", "FILE_MODE", "LOCK_SUFFIX", "LocalStorage", "RECORD_SUFFIX", "SECONDS_PER_DAY", "TEMP_SUFFIX",
    "UPLOAD_CHUNK_BYTES", "UploadTooLarge", "blob_references", "blob_relpath", "check_name", "check_sha256",
    "check_suffix", "deployment_id", "iter_upload", "queue_name", "retention_seconds", "ObjectInfo", "ObjectStore",
    "StorageUnavailable", "object_store_for_url", "open_storage", "deployment_for", "open_records", "Database",
    "PostgresRecords", "SchemaMismatch", "upgrade",
]


class LocalStorage(BlobStore, Retention):
    """Blobs and records in a local directory (see the module docstring for layout and assumptions).

    Parameters
    ----------
    root : Path
        The storage directory; ``blobs/``, ``records/``, ``tmp/`` and ``work/`` are created.
    durable : bool
        ``fsync`` every written file and the directory of every rename (the default). Off
        only for tests and throwaway stores: a crash could then leave an old or empty file,
        but atomicity between processes and the locking are the same.
    remote : ObjectStore, optional
        Where blobs live for every host (``HAIRPORT_STORAGE_URL``); ``root/blobs`` is then this
        host's cache of them (:mod:`.blobs`).
    records : FolderRecords or PostgresRecords, optional
        Where the records live: by default ``root/records`` (:class:`~.documents.FolderRecords`),
        or a database (``HAIRPORT_DATABASE_URL``, :class:`~.postgres.PostgresRecords`).
    """

    def __init__(self, root: Path, *, durable: bool = True, remote: ObjectStore | None = None, records=None):
        self.root = Path(root)
        self.durable = durable
        self.remote = remote
        self.blobs_dir = self.root / "blobs"
        self.records_dir = self.root / "records"
        self.tmp_dir = self.root / "tmp"
        self.work_root = self.root / "work"
        for folder in (self.blobs_dir, self.tmp_dir, self.work_root):
            folder.mkdir(parents=True, exist_ok=True)
        self.records = FolderRecords(self.records_dir, durable) if records is None else records

    # the records: handed on to the record store (one of two, with the same methods)

    def put_record(self, kind: str, record_id: str, document: dict, written: Written | None = None) -> None:
        self.records.put_record(kind, record_id, document, written)

    def get_record(self, kind: str, record_id: str) -> dict | None:
        return self.records.get_record(kind, record_id)

    def get_record_text(self, kind: str, record_id: str) -> str | None:
        return self.records.get_record_text(kind, record_id)

    def update_record(self, kind: str, record_id: str, change: Callable[[dict], dict | None],
                      written: Written | None = None) -> dict | None:
        return self.records.update_record(kind, record_id, change, written)

    def list_records(self, kind: str) -> Iterator[dict]:
        return self.records.list_records(kind)

    def delete_record(self, kind: str, record_id: str) -> None:
        self.records.delete_record(kind, record_id)

    def has_record(self, kind: str, record_id: str) -> bool:
        return self.records.has_record(kind, record_id)

    def reachability(self) -> dict[str, Callable[[], bool]]:
        """``{"storage": probe, "database": probe}`` for the object store and the records' database this storage
        has (none for a folder alone): each probe says whether it answers, and logs why not."""
        checks = {}
        if self.remote is not None:
            checks["storage"] = self.remote.check
        database = getattr(self.records, "database", None)
        if database is not None:
            checks["database"] = database.check
        return {name: functools.partial(_answers, name, check) for name, check in checks.items()}

    def __repr__(self) -> str:
        remote = "" if self.remote is None else f", remote={self.remote.url!r}"
        return f"LocalStorage({str(self.root)!r}, durable={self.durable}{remote})"


def object_store_for_url(url: str, *, durable: bool = True, **s3_options) -> ObjectStore:
    """The store a ``HAIRPORT_STORAGE_URL`` names: a folder (``file://`` URL or a plain path) or ``s3://bucket/prefix``
    (``s3_options``: explicit endpoint, region and keys over the ``AWS_*`` variables, :class:`~.s3.S3Objects`).

    Raises
    ------
    ValueError
        For another scheme, naming the ones taken.
    """
    parsed = urlparse(url)
    if parsed.scheme in ("", FOLDER_SCHEME):
        return FolderObjects(Path(parsed.path if parsed.scheme else url), durable=durable)
    if parsed.scheme == S3_SCHEME:
        return S3Objects.from_url(url, **s3_options)
    raise ValueError(f"HAIRPORT_STORAGE_URL {url!r}: the scheme {parsed.scheme!r} is not one of "
                     f"{FOLDER_SCHEME}://, {S3_SCHEME}:// or a folder path")


def _answers(name: str, check: Callable[[], None]) -> bool:
    """Whether ``check()`` passes (a readiness probe); why not, in the log."""
    try:
        check()
        return True
    except (StorageUnavailable, SchemaMismatch) as error:
        log.warning("%s not ready: %s", name, error)
        return False


def open_storage(settings) -> LocalStorage:
    """The storage a deployment's settings name: ``storage_dir``, with the object store of ``storage_url``
    (S3 credentials from the standard ``AWS_*`` variables unless the ``s3_*`` settings override them) when set.

    Parameters
    ----------
    settings : hairport.settings.Settings
    """
    url = settings.storage_url
    remote = object_store_for_url(url, **settings.s3_overrides()) if url else None
    return LocalStorage(settings.storage_dir, remote=remote, records=open_records(settings.database_url))


def open_records(database_url: str | None):
    """The record store a ``HAIRPORT_DATABASE_URL`` names: None (the storage folder's) when unset or SQLite's
    default, else the PostgreSQL database's (its schema made, when the database is empty, or checked on first use:
:class:`SchemaMismatch` for another version).

    Raises
    ------
    ValueError
        A URL of another kind than ``postgresql://``.
    """
    if not database_url or database_url.startswith(SQLITE_SCHEME):
        return None
    if not database_url.startswith(POSTGRES_SCHEMES):
        raise ValueError(f"HAIRPORT_DATABASE_URL: {database_url.split('://')[0]}:// is not one of "
                         f"{', '.join(POSTGRES_SCHEMES)} or {SQLITE_SCHEME}")
    # one per process and URL: its connections (one per thread) serve every repository; it connects, and
    # makes or checks the schema, on its first use
    if database_url not in _DATABASES:
        _DATABASES[database_url] = Database(database_url)
    return PostgresRecords(_DATABASES[database_url])


#: the databases this process opened, by URL (:func:`open_records`)
_DATABASES: dict[str, Database] = {}
