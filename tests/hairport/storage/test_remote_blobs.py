"""Blobs in an object store (HAIRPORT_STORAGE_URL): each host's folder is a cache, the store is where blobs live.

Two "hosts" are two LocalStorage folders over one store (a FolderObjects here; the S3 store runs the same
interface in tests/hairport/storage/test_objects.py)."""

import asyncio
import hashlib
import os
import time

import pytest

from hairport.storage import LocalStorage, object_store_for_url
from hairport.storage.blobs import REPUBLISH_AFTER_SECONDS
from hairport.storage.layout import blob_relpath
from hairport.storage.objects import FolderObjects

MB = 1 << 20


@pytest.fixture
def hosts(tmp_path):
    store = FolderObjects(tmp_path / "store", durable=False)
    return store, LocalStorage(tmp_path / "a", durable=False, remote=store), LocalStorage(
        tmp_path / "b", durable=False, remote=store)


async def _chunks(parts):
    for part in parts:
        yield part


def test_what_one_host_saves_another_reads_through_the_store(hosts):
    store, a, b = hosts
    content = os.urandom(3 * MB + 17)
    saved = asyncio.run(a.save_stream(_chunks([content[:MB], content[MB:]]), max_bytes=10 * MB, suffix=".obj"))
    sha = hashlib.sha256(content).hexdigest()
    assert saved.sha256 == sha and saved.created and store.stat(blob_relpath(sha, ".obj")).size == len(content)
    read = b.blob(sha, ".obj")
    assert read.path.parent.parent.parent == b.root and read.path.read_bytes() == content and read.size == len(content)
    assert b.blob(sha, ".ply") is None and b.blob("0" * 64, ".obj") is None
    # the same content saved on the other host is in the store already: not created again
    again = b.save_bytes(content, ".obj")
    assert again.sha256 == sha and not again.created


def test_a_refused_upload_leaves_nothing_in_the_store_and_a_shared_one_stays(hosts):
    store, a, b = hosts
    fresh = a.save_bytes(b"a refused upload", ".obj")
    assert a.discard_new(fresh) == 1
    assert store.stat(blob_relpath(fresh.sha256, ".obj")) is None and not fresh.path.exists()
    kept = a.save_bytes(b"another record's content", ".obj")
    shared = b.save_bytes(b"another record's content", ".obj")
    assert b.discard_new(shared) == 0 and store.stat(blob_relpath(kept.sha256, ".obj")) is not None


def test_a_produced_file_moved_in_is_published_before_it_enters_the_cache(hosts, tmp_path):
    store, a, b = hosts
    produced = tmp_path / "result.npz"
    produced.write_bytes(b"result " * 1000)
    blob = a.save_file(produced, ".npz", move=True)
    assert not produced.exists() and blob.path.exists()
    assert store.stat(blob_relpath(blob.sha256, ".npz")).size == 7000
    assert b.blob(blob.sha256, ".npz").path.read_bytes() == b"result " * 1000


def test_old_content_saved_again_is_written_again_so_the_sweep_judges_it_young(hosts):
    store, a, _ = hosts
    blob = a.save_bytes(b"an artifact", ".hpa")
    key = blob_relpath(blob.sha256, ".hpa")
    old = time.time() - 2 * REPUBLISH_AFTER_SECONDS
    os.utime(store.root / key, (old, old))
    a.save_bytes(b"an artifact", ".hpa")
    assert store.stat(key).modified > time.time() - 60


def test_the_sweep_removes_unreferenced_stored_blobs_and_the_purge_empties_the_cache(hosts):
    store, a, b = hosts
    orphan = a.save_bytes(b"nobody refers to me", ".obj")
    kept = a.save_bytes(b"a record refers to me", ".obj")
    a.put_record("characters", "c1", {"mesh": {"sha256": kept.sha256, "suffix": ".obj"}})
    later = time.time() + 7200
    assert a.sweep_orphans(3600, now=later) == 1
    assert store.stat(blob_relpath(orphan.sha256, ".obj")) is None
    assert store.stat(blob_relpath(kept.sha256, ".obj")) is not None
    # the purge drops the cached copy (the store keeps it for the record, which is young) ...
    os.utime(kept.path, (time.time() - 7200,) * 2)
    a.purge(3600)
    assert not kept.path.exists() and store.stat(blob_relpath(kept.sha256, ".obj")) is not None
    # ... and the next read fetches it again
    assert a.blob(kept.sha256, ".obj").path.read_bytes() == b"a record refers to me"


def test_readiness_probes_the_store(hosts):
    store, a, _ = hosts
    assert {name: probe() for name, probe in a.reachability().items()} == {"storage": True}
    store.root.rename(store.root.with_name("moved"))
    assert a.reachability()["storage"]() is False
    assert LocalStorage(a.root).reachability() == {}  # a folder alone has nothing to probe


def test_the_url_names_the_store(tmp_path):
    folder = object_store_for_url(str(tmp_path / "objects"), durable=False)
    assert isinstance(folder, FolderObjects) and folder.url == (tmp_path / "objects").as_uri()
    assert object_store_for_url((tmp_path / "objects").as_uri()).root == tmp_path / "objects"
    with pytest.raises(ValueError, match="'ftp' is not one of file://, s3://"):
        object_store_for_url("ftp://host/bucket")
    for bad in ("", "/abs", "a/../b", "a//b", "./a"):
        with pytest.raises(ValueError, match="not an object key"):
            folder.stat(bad)
