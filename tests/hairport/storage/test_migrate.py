"""``hairport migrate``: a one-host deployment (records and blobs in a folder) copied into PostgreSQL and an
S3-compatible store, both real servers of the tests; nothing lost, listings the same, a second run copies
nothing again."""

import pytest

from hairport.cli import main
from hairport.records import BlobRef, CharacterRecord, JobRecord
from hairport.repository import Repository
from hairport.settings import get_settings
from hairport.storage import LocalStorage, object_store_for_url, open_records
from tests.hairport.storage.test_index import indexed, populate, truth
from tests.hairport.storage.test_postgres import fresh_database
from tests.servers.fixtures import postgres_server, postgres_url  # noqa: F401

pytestmark = pytest.mark.integration


@pytest.fixture
def folder_deployment(tmp_path):
    """A folder deployment: 60 jobs with their index, characters, hairstyles and batches, and blobs records name
    (plus one a record names that the folder lost)."""
    repository = Repository(LocalStorage(tmp_path / "deployment", durable=False))
    populate(repository, 60)
    storage = repository.storage
    meshes = [storage.save_bytes(f"v {i} 0 0\n".encode() * 100, ".obj") for i in range(3)]
    for number, mesh in enumerate(meshes):
        repository.put(CharacterRecord(id=f"z{number:031x}", owner="kalpha", created_at=5000.0 + number,
                                       mesh=BlobRef(sha256=mesh.sha256, suffix=".obj"), vertices=1, faces=0,
                                       bones=[]), f"z{number:031x}")
    repository.put(CharacterRecord(id="y" * 32, owner="kbeta", created_at=6000.0, mesh=BlobRef(sha256="f" * 64),
                                   vertices=1, faces=0, bones=[]), "y" * 32)
    storage.put_record("clocks", "purge", {"at": 1.0})  # a kind keyed by name, not by an id field
    return repository


def test_a_folder_deployment_moves_to_the_database_and_the_store_whole(folder_deployment, postgres_url, seaweed,  # noqa: F811
                                                                       monkeypatch, tmp_path, capsys):
    endpoint, access_key, secret_key, bucket = seaweed.endpoint
    database_url, storage_url = fresh_database(postgres_url), f"s3://{bucket}/migrated-{tmp_path.name}"
    for name, value in {"HAIRPORT_STORAGE_DIR": str(folder_deployment.storage.root),
                        "HAIRPORT_S3_ENDPOINT_URL": endpoint,
                        "HAIRPORT_S3_ACCESS_KEY_ID": access_key, "HAIRPORT_S3_SECRET_ACCESS_KEY": secret_key,
                        "HAIRPORT_S3_REGION": "us-east-1"}.items():
        monkeypatch.setenv(name, value)
    get_settings.cache_clear()
    try:
        assert main(["migrate", "--to-database", database_url, "--to-storage", storage_url]) == 0
        out, err = capsys.readouterr()
        assert "copied 3 blobs (0 already there) and 125 records" in out and "1 clocks, 20 hairstyles, 60 jobs" in out
        # the records of the index tests name made-up digests, and one character's mesh was lost: said, not invented
        assert "blobs that records name were not in the folder either" in err
        # a second run finds everything there
        assert main(["migrate", "--to-database", database_url, "--to-storage", storage_url]) == 0
        assert "copied 0 blobs (3 already there)" in capsys.readouterr().out
    finally:
        get_settings.cache_clear()
    store = object_store_for_url(storage_url, endpoint_url=endpoint, access_key_id=access_key,
                                 secret_access_key=secret_key, region="us-east-1")
    moved = Repository(LocalStorage(tmp_path / "new-host-cache", durable=False, remote=store,
                                    records=open_records(database_url)))
    # the same jobs, listings, counts and totals, from the database's own index
    assert truth(moved) == truth(folder_deployment) and indexed(moved) == indexed(folder_deployment)
    assert moved.storage.get_record("clocks", "purge") == {"at": 1.0}
    for number in range(3):
        character = moved.get(CharacterRecord, f"z{number:031x}")
        blob = moved.storage.blob(character.mesh.sha256, ".obj")
        assert blob.path.read_bytes() == f"v {number} 0 0\n".encode() * 100
    assert moved.job(f"{5:032x}") == folder_deployment.job(f"{5:032x}")
    assert isinstance(moved.job(f"{5:032x}"), JobRecord)
    # the folder is left as it was: the way back
    assert folder_deployment.storage.get_record("clocks", "purge") == {"at": 1.0}


def test_migrate_refuses_a_deployment_that_already_uses_urls(monkeypatch, tmp_path, capsys):
    monkeypatch.setenv("HAIRPORT_STORAGE_DIR", str(tmp_path))
    monkeypatch.setenv("HAIRPORT_DATABASE_URL", "postgresql://nobody@127.0.0.1:1/none")
    get_settings.cache_clear()
    try:
        assert main(["migrate", "--to-database", "postgresql://x@127.0.0.1:1/y", "--to-storage", "s3://b/p"]) == 2
        assert "unset HAIRPORT_DATABASE_URL" in capsys.readouterr().err
    finally:
        get_settings.cache_clear()
