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

from pathlib import Path

from .blobs import UPLOAD_CHUNK_BYTES, Blob, BlobStore, UploadTooLarge, iter_upload
from .deployment import DEPLOYMENT_FILE, deployment_id, queue_name
from .documents import DocumentStore
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
from .retention import Retention

__all__ = [
    "Blob", "DEPLOYMENT_FILE", "FILE_MODE", "LOCK_SUFFIX", "LocalStorage", "RECORD_SUFFIX", "SECONDS_PER_DAY", "TEMP_SUFFIX",
    "UPLOAD_CHUNK_BYTES", "UploadTooLarge", "blob_references", "blob_relpath", "check_name", "check_sha256",
    "check_suffix", "deployment_id", "iter_upload", "queue_name", "retention_seconds",
]


class LocalStorage(BlobStore, DocumentStore, Retention):
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
