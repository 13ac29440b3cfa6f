"""Object stores: one conformance suite run over a folder (FolderObjects) and an S3 bucket (S3Objects on the
SeaweedFS server of tests/servers/seaweed.py, with real key authentication). What only S3 has: test_s3.py."""

import errno
import hashlib
import os
import resource
import signal
import time
import uuid
from contextlib import contextmanager

import pytest

from hairport.storage.objects import FolderObjects
from hairport.storage.s3 import S3Objects

MB = 1 << 20
#: seconds within which a stopped server must be reported (client timeouts and retries bound it)
UNAVAILABLE_WITHIN_SECONDS = 10.0
#: keys a store must refuse (absolute, climbing out, empty parts)
BAD_KEYS = ("", "/abs", "a/../b", "a//b", "./a", "a/.", "..", "a/")


def s3_store(endpoint, prefix=None, **overrides) -> S3Objects:
    """A store on the test server under a prefix of its own (tests share the bucket, never a prefix)."""
    options = {"endpoint_url": endpoint.url, "access_key_id": endpoint.access_key,
               "secret_access_key": endpoint.secret_key, **overrides}
    return S3Objects(endpoint.bucket, prefix or f"tests/{uuid.uuid4().hex}", **options)


@pytest.fixture(params=["folder", pytest.param("s3", marks=pytest.mark.integration)])
def store(request, tmp_path):
    if request.param == "folder":
        return FolderObjects(tmp_path / "store", durable=False)
    return s3_store(request.getfixturevalue("seaweed").endpoint)


def write(path, content: bytes):
    path.write_bytes(content)
    return path


def files_in(folder) -> list[str]:
    """The names in a test's folder, but the FolderObjects' own (``store``)."""
    return sorted(path.name for path in folder.iterdir() if path.name != "store")


@contextmanager
def file_size_limit(limit_bytes: int):
    """Writes past ``limit_bytes`` of any file fail with EFBIG (a disk that fills up), in this process only."""
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    previous = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # an error from write(), not a killed process
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, previous)


# ------------------------------------------------------------------------------------------ conformance
def test_a_multi_megabyte_file_round_trips_byte_for_byte(store, tmp_path):
    content = os.urandom(20 * MB + 17)  # three 8 MiB parts on S3, the last one short
    source = write(tmp_path / "source.bin", content)
    store.put_file("blobs/ab/big.bin", source)
    assert store.stat("blobs/ab/big.bin").size == len(content)
    target = write(tmp_path / "target.bin", b"an older file, replaced whole")
    assert store.get_file("blobs/ab/big.bin", target) is True
    assert hashlib.sha256(target.read_bytes()).hexdigest() == hashlib.sha256(content).hexdigest()
    assert files_in(tmp_path) == ["source.bin", "target.bin"]  # no temporary file left


def test_stat_gives_sizes_and_the_time_of_the_write(store, tmp_path):
    began = time.time()
    for key, size in (("sizes/empty", 0), ("sizes/one", 1), ("sizes/kib", 1024)):
        store.put_file(key, write(tmp_path / "source", os.urandom(size)))
    for key, size in (("sizes/empty", 0), ("sizes/one", 1), ("sizes/kib", 1024)):
        info = store.stat(key)
        assert (info.key, info.size) == (key, size)
        assert began - 2 <= info.modified <= time.time() + 2  # S3 keeps whole seconds; clocks of one machine


def test_list_takes_string_prefixes(store, tmp_path):
    sizes = {"blobs/ab/one.obj": 3, "blobs/abc/two.obj": 5, "blobs/b/three ü+%.x": 7, "records/jobs/x.json": 11}
    for key, size in sizes.items():
        store.put_file(key, write(tmp_path / "source", os.urandom(size)))

    def listed(prefix):
        return sorted((info.key, info.size) for info in store.list(prefix))

    assert listed("") == sorted(sizes.items())  # keys come back as given (S3 lists them URL-encoded)
    assert listed("blobs/ab") == [("blobs/ab/one.obj", 3), ("blobs/abc/two.obj", 5)]  # not only a folder
    assert listed("blobs/ab/") == [("blobs/ab/one.obj", 3)]
    assert listed("records/") == [("records/jobs/x.json", 11)]
    assert listed("nothing/") == []


def test_delete_is_idempotent(store, tmp_path):
    store.put_file("gone/soon", write(tmp_path / "source", b"bytes"))
    store.delete("gone/soon")
    assert store.stat("gone/soon") is None
    assert store.get_file("gone/soon", tmp_path / "target") is False
    store.delete("gone/soon")  # not there: no error
    store.delete("never/there")
    assert list(store.list("gone/")) == []


def test_a_missing_key_is_none_false_and_leaves_the_destination_alone(store, tmp_path):
    assert store.stat("no/such/key") is None
    target = write(tmp_path / "target", b"kept")
    assert store.get_file("no/such/key", target) is False
    assert target.read_bytes() == b"kept"
    assert store.get_file("no/such/key", tmp_path / "absent") is False
    assert not (tmp_path / "absent").exists()
    assert files_in(tmp_path) == ["target"]  # no temporary file left


@pytest.mark.parametrize("key", BAD_KEYS)
def test_bad_keys_are_refused_by_every_call(store, tmp_path, key):
    source = write(tmp_path / "source", b"x")
    for call in (lambda: store.put_file(key, source), lambda: store.get_file(key, tmp_path / "target"),
                 lambda: store.stat(key), lambda: store.delete(key)):
        with pytest.raises(ValueError, match="not an object key"):
            call()
    assert list(store.list("")) == []
    assert files_in(tmp_path) == ["source"]


def test_a_get_that_fails_midway_leaves_no_partial_file(store, tmp_path):
    content = os.urandom(12 * MB)
    store.put_file("big/blob", write(tmp_path / "source", content))
    target = write(tmp_path / "target", b"the previous content")
    with file_size_limit(4 * MB), pytest.raises(OSError) as failed:  # the disk fills up after 4 MiB
        store.get_file("big/blob", target)
    assert failed.value.errno == errno.EFBIG
    assert target.read_bytes() == b"the previous content"
    assert files_in(tmp_path) == ["source", "target"]
    assert store.get_file("big/blob", target) and target.read_bytes() == content  # room again: it works


def test_check_passes_when_the_store_answers(store):
    store.check()
