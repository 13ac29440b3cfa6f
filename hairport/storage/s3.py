"""Objects in an S3 bucket (AWS S3 or any S3-compatible server), through boto3: ``s3://bucket/prefix``.

Credentials, region and endpoint come from the standard variables (``AWS_ACCESS_KEY_ID``,
``AWS_SECRET_ACCESS_KEY``, ``AWS_REGION``, ``AWS_ENDPOINT_URL``) unless given explicitly (hairport's ``s3_*``
settings); without keys, boto3's own chain (session token, shared config, instance or task role) applies.

Why boto3 (bench/object_store.py, against SeaweedFS on 2 cores): obstore answered 1 KiB requests 2 to 3 times
faster (p50 0.5 to 1.2 ms against 1.4 to 2.1 ms) and got a 256 MiB object up to 1.4 times faster (puts within
10 %), but it is not fork-safe: a process forked after its parent used obstore hangs on its first request, even
with a new store (its Tokio runtime's threads do not survive ``fork``; 5 hangs in 5 runs), and Celery's prefork
parent uses the store (the sweeper, the readiness check) before it forks replacement children. s3fs held the
whole 256 MiB object in memory. boto3 puts at the server's pace, gets at 0.7 times obstore's, holds about 30 MiB
(put) or 60 MiB (get) of parts in flight, and a client made after a fork answers at once. A millisecond per
request is noise against S3's own latency (tens of milliseconds) for blobs of megabytes.

Transfers: a put streams the file in :data:`PART_BYTES` parts (one request below that size); the object appears
only when the last part is in, so an interrupted put leaves nothing under the key (its parts are aborted, or
expire by the bucket's ``AbortIncompleteMultipartUpload`` lifecycle rule when the abort cannot reach the
server). A get streams into a temporary file beside the destination, renamed when complete.

Failures: a refused or lost connection, a timeout, a 5xx, refused credentials, a missing bucket raise
:class:`~.objects.StorageUnavailable`, its reason one line naming the endpoint and bucket (never the secret), after
at most :data:`ATTEMPTS` attempts: a stopped server is reported within seconds. A missing key is not an error.
"""

from __future__ import annotations

import math
import os
import re
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from urllib.parse import urlparse

import boto3
from boto3.s3.transfer import TransferConfig
from botocore.config import Config
from botocore.exceptions import BotoCoreError, ClientError
from botocore.utils import determine_content_length
from s3transfer.exceptions import RetriesExceededError
from s3transfer.manager import TransferManager

from .layout import _create_temp, _unlink
from .objects import S3_SCHEME, ObjectInfo, StorageUnavailable, check_key

MIB = 1 << 20
#: seconds to open a connection before the attempt fails
CONNECT_SECONDS = 2.0
#: seconds without a byte from the server before the attempt fails (a stall, not a slow transfer)
READ_SECONDS = 10.0
#: attempts of one request (botocore's "standard" retries: 5xx, throttling, connection errors, with backoff)
ATTEMPTS = 3
#: bytes of each part of a multipart put and each ranged get of a large object; smaller objects take one request
PART_BYTES = 8 * MIB
#: parts in flight at once for one transfer (memory: about this many parts)
TRANSFER_THREADS = 10
#: pooled connections per process (the transfer threads of a few concurrent transfers)
POOL_CONNECTIONS = 20
#: keys per page of a listing (S3's maximum)
LIST_PAGE_KEYS = 1000
#: seconds a confirmed bucket is trusted: a 404 of a HEAD is a missing key, not a missing bucket (HEAD answers
#: carry no error code, so a miss after this long asks the bucket again)
BUCKET_TRUST_SECONDS = 30.0
#: S3 bucket names (AWS's rules, loosened to the upper case and '_' of older and S3-compatible servers)
BUCKET_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{1,61}[A-Za-z0-9]")
#: seconds a presigned URL may last (SigV4's limit: 7 days)
PRESIGN_MAX_SECONDS = 7 * 86_400
#: the region signed for when none is given (S3-compatible servers take any; AWS's default region)
DEFAULT_REGION = "us-east-1"
#: error codes of a key that is not there (HEAD answers a bare 404)
MISSING_CODES = frozenset({"404", "NoSuchKey", "NotFound"})
#: error codes of a bucket that is not there
NO_BUCKET_CODES = frozenset({"NoSuchBucket"})
#: what a transfer raises when the store failed it (anything else, e.g. a local OSError, is the caller's)
REMOTE_ERRORS = (ClientError, BotoCoreError, RetriesExceededError, ConnectionError, TimeoutError)


class S3Objects:
    """An object store in an S3 bucket under a key prefix (see the module docstring).

    Parameters
    ----------
    bucket : str
    prefix : str
        Keys are stored as ``prefix/key`` (``""``: at the bucket's root).
    endpoint_url, region, access_key_id, secret_access_key : str, optional
        None: boto3's defaults (AWS's endpoint for the region, its credential chain).
    """

    def __init__(self, bucket: str, prefix: str = "", *, endpoint_url: str | None = None, region: str | None = None,
                 access_key_id: str | None = None, secret_access_key: str | None = None):
        self.bucket = bucket
        self.prefix = prefix.strip("/")
        self.url = f"{S3_SCHEME}://{bucket}/{self.prefix}".rstrip("/")
        self.list_page_keys = LIST_PAGE_KEYS
        self._secret = secret_access_key
        self._client_options = {"endpoint_url": endpoint_url, "region_name": region or DEFAULT_REGION,
                                "aws_access_key_id": access_key_id, "aws_secret_access_key": secret_access_key,
                                "config": _client_config(compatible=endpoint_url is not None)}
        self._lock = threading.Lock()
        self._pid: int | None = None
        self._client = None
        self._bucket_seen = -math.inf  # monotonic seconds when a request last showed that the bucket exists
        self.endpoint = self._s3().meta.endpoint_url

    @classmethod
    def from_url(cls, url: str, **overrides) -> S3Objects:
        """The store of ``s3://bucket/prefix``: endpoint, region and keys from ``overrides`` (``endpoint_url``,
        ``region``, ``access_key_id``, ``secret_access_key``), else the ``AWS_*`` variables."""
        parsed = urlparse(url)
        if parsed.scheme != S3_SCHEME or not BUCKET_PATTERN.fullmatch(parsed.netloc):
            raise ValueError(f"not an S3 URL (s3://bucket/prefix, the bucket 3 to 63 of a-z, 0-9, '.', '-'): "
                             f"{url!r}")
        given = {name: value for name, value in overrides.items() if value is not None}
        options = {"endpoint_url": os.environ.get("AWS_ENDPOINT_URL") or None,
                   "region": os.environ.get("AWS_REGION") or os.environ.get("AWS_DEFAULT_REGION") or None}
        if "access_key_id" in given or "secret_access_key" in given:  # one given: the other from the variables
            options.update(access_key_id=os.environ.get("AWS_ACCESS_KEY_ID") or None,
                           secret_access_key=os.environ.get("AWS_SECRET_ACCESS_KEY") or None)
        # no keys given: boto3's chain reads AWS_ACCESS_KEY_ID, AWS_SECRET_ACCESS_KEY and AWS_SESSION_TOKEN itself
        # (then ~/.aws, then an instance or task role)
        return cls(parsed.netloc, parsed.path, **{**options, **given})

    def __repr__(self) -> str:
        return f"S3Objects({self.url!r}, endpoint={self.endpoint!r})"

    # ---------------------------------------------------------------- the ObjectStore protocol
    def put_file(self, key: str, path: Path) -> None:
        """Store the file's bytes under ``key``, streamed from disk (whole or not at all)."""
        name = self._name(key)
        with self._answer("put", key), TransferManager(self._s3(), _transfer_config()) as transfers:
            transfers.upload(str(path), self.bucket, name).result()
        self._bucket_seen = time.monotonic()

    def get_file(self, key: str, path: Path) -> bool:
        """Write the object to ``path`` through a temporary file beside it (renamed when whole); False when the
        store has no such object (``path`` untouched)."""
        name = self._name(key)
        path = Path(path)
        fd, temporary = _create_temp(path.parent, ".get-")
        try:
            with os.fdopen(fd, "wb") as sink:
                found = self._download(key, name, sink)
            if found:
                os.replace(temporary, path)
            else:
                _unlink(temporary)
            return found
        except BaseException:
            _unlink(temporary)
            raise

    def stat(self, key: str) -> ObjectInfo | None:
        """The object's size (bytes) and last write (seconds since the epoch, whole seconds), or None."""
        name = self._name(key)
        with self._answer("stat", key):
            try:
                head = self._s3().head_object(Bucket=self.bucket, Key=name)
            except ClientError as error:
                if self._missing(error):
                    return None
                raise
        self._bucket_seen = time.monotonic()
        return ObjectInfo(key, head["ContentLength"], head["LastModified"].timestamp())

    def delete(self, key: str) -> None:
        """Remove the object (no error when it is not there)."""
        name = self._name(key)
        with self._answer("delete", key):
            try:
                self._s3().delete_object(Bucket=self.bucket, Key=name)
            except ClientError as error:
                if not self._missing(error):  # S3 answers 204 for a missing key; some servers 404
                    raise

    def list(self, prefix: str) -> Iterator[ObjectInfo]:
        """Every object whose key starts with ``prefix`` (a string prefix, not only whole folders), in key order,
        fetched a page of :data:`LIST_PAGE_KEYS` at a time."""
        cut = len(self._name_root())
        pages = self._s3().get_paginator("list_objects_v2").paginate(
            Bucket=self.bucket, Prefix=self._name_root() + prefix, PaginationConfig={"PageSize": self.list_page_keys})
        for page in self._remote_pages(pages, prefix):
            for item in page.get("Contents", ()):
                yield ObjectInfo(item["Key"][cut:], item["Size"], item["LastModified"].timestamp())

    def check(self) -> None:
        """Raise :class:`StorageUnavailable` unless the bucket answers a listing with these credentials."""
        with self._answer("check"):
            self._s3().list_objects_v2(Bucket=self.bucket, Prefix=self._name_root(), MaxKeys=1)
        self._bucket_seen = time.monotonic()

    # ---------------------------------------------------------------- beyond the protocol
    def presign_get(self, key: str, expires_seconds: int) -> str:
        """A URL that downloads the object without credentials for ``expires_seconds`` (at most
        :data:`PRESIGN_MAX_SECONDS`); signed locally, so it is returned whether or not the object exists."""
        name = self._name(key)
        if not 1 <= expires_seconds <= PRESIGN_MAX_SECONDS:
            raise ValueError(f"a presigned URL lasts 1 to {PRESIGN_MAX_SECONDS} s, not {expires_seconds}")
        with self._answer("presign", key):
            return self._s3().generate_presigned_url("get_object", Params={"Bucket": self.bucket, "Key": name},
                                                     ExpiresIn=int(expires_seconds))

    # ---------------------------------------------------------------- helpers
    def _s3(self):
        """This process's client: made again after a fork (a client's pooled connections are its parent's)."""
        with self._lock:
            if self._pid != os.getpid():
                self._client = boto3.session.Session().client("s3", **self._client_options)
                self._client.meta.events.register("before-call.s3", _no_continue_for_empty_bodies)
                self._pid = os.getpid()
            return self._client

    def _name(self, key: str) -> str:
        check_key(key)
        return self._name_root() + key

    def _name_root(self) -> str:
        return f"{self.prefix}/" if self.prefix else ""

    def _download(self, key: str, name: str, sink) -> bool:
        """Stream the object into ``sink`` (ranged GETs of :data:`PART_BYTES` for a large one); False if missing."""
        with self._answer("get", key), TransferManager(self._s3(), _transfer_config()) as transfers:
            try:
                transfers.download(self.bucket, name, sink).result()
            except ClientError as error:
                if self._missing(error):
                    return False
                raise
        self._bucket_seen = time.monotonic()
        return True

    def _remote_pages(self, pages, prefix: str) -> Iterator[dict]:
        """The pages of a listing, each request's failure raised as :class:`StorageUnavailable`."""
        iterator = iter(pages)
        while True:
            with self._answer("list", prefix):
                page = next(iterator, None)
            if page is None:
                return
            yield page

    def _missing(self, error: ClientError) -> bool:
        """Whether ``error`` says that the key is not there (the bucket is: a missing bucket raises)."""
        code = error.response.get("Error", {}).get("Code", "")
        if code in NO_BUCKET_CODES:
            raise error
        if code not in MISSING_CODES:
            return False
        if time.monotonic() - self._bucket_seen > BUCKET_TRUST_SECONDS:
            self.check()
        return True

    @contextmanager
    def _answer(self, action: str, key: str = ""):
        """Raise the store's failures as :class:`StorageUnavailable` with a one-line reason."""
        try:
            yield
        except REMOTE_ERRORS as error:
            raise StorageUnavailable(self._reason(action, key, error)) from error

    def _reason(self, action: str, key: str, error: BaseException) -> str:
        """``the S3 store ENDPOINT bucket BUCKET: ACTION KEY failed: WHAT`` on one line, without the secret."""
        if isinstance(error, RetriesExceededError) and error.last_exception is not None:
            error = error.last_exception
        if isinstance(error, ClientError):
            status = error.response.get("ResponseMetadata", {}).get("HTTPStatusCode", "?")
            code = error.response.get("Error", {}).get("Code", "")
            what = f"HTTP {status} {code}: {_hint(code, status)}"
        else:
            what = f"{type(error).__name__}: {error}"
        where = f"{action} {key}".rstrip()
        reason = " ".join(f"the S3 store {self.endpoint} bucket {self.bucket}: {where} failed: {what}".split())
        for secret in (self._secret, os.environ.get("AWS_SECRET_ACCESS_KEY")):
            reason = reason.replace(secret, "***") if secret else reason  # never seen in botocore's messages
        return reason


def _hint(code: str, status) -> str:
    """A few words on an S3 error code."""
    if code in NO_BUCKET_CODES:
        return "the bucket does not exist"
    if status in (401, 403):
        return "the credentials were refused (access key, secret key or their permissions)"
    if isinstance(status, int) and status >= 500:
        return "the server failed"
    return "the request was refused"


def _no_continue_for_empty_bodies(params, **_) -> None:
    """Drop the ``Expect: 100-continue`` botocore asks for an empty body (what its experimental
    BOTO_EXPERIMENTAL__NO_EMPTY_CONTINUE does): a server answering it at once may leave a late ``100 Continue`` in
    the connection, and the next request reads it as its answer (SeaweedFS 4.48: a READ_SECONDS stall)."""
    headers, body = params.get("headers", {}), params.get("body")
    if headers.get("Expect") and body is not None and determine_content_length(body) == 0:
        del headers["Expect"]


def _client_config(compatible: bool) -> Config:
    """Timeouts and retries bounding a failure to seconds; for an S3-compatible endpoint, path-style URLs
    (``endpoint/bucket/key``: no DNS name per bucket) and checksums only where S3 requires them (several
    servers refuse the CRC trailers boto3 sends by default since 1.36)."""
    options = {}
    if compatible:
        options = {"s3": {"addressing_style": "path"}, "request_checksum_calculation": "when_required",
                   "response_checksum_validation": "when_required"}
    return Config(connect_timeout=CONNECT_SECONDS, read_timeout=READ_SECONDS, signature_version="s3v4",
                  retries={"mode": "standard", "total_max_attempts": ATTEMPTS},
                  max_pool_connections=POOL_CONNECTIONS, **options)


def _transfer_config() -> TransferConfig:
    return TransferConfig(multipart_threshold=PART_BYTES, multipart_chunksize=PART_BYTES,
                          max_concurrency=TRANSFER_THREADS, use_threads=True)
