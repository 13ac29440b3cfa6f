"""Records and their index in PostgreSQL (hairport/storage/postgres.py), against a real server the tests start:
the same answers as the folder's records and the SQLite index, row locks between processes, the schema's
version and upgrade, and a server restarted under a running repository."""

import multiprocessing
import uuid

import psycopg
import pytest

from hairport.repository import Repository
from hairport.storage import LocalStorage, open_records
from hairport.storage.objects import StorageUnavailable
from hairport.storage.postgres import SCHEMA_VERSION, Database, SchemaMismatch, schema_version, upgrade
from tests.hairport.storage.test_index import indexed, make_job, populate, truth
from tests.servers.fixtures import postgres_server, postgres_url, private_postgres_server  # noqa: F401

pytestmark = pytest.mark.integration


def fresh_database(server_url: str) -> str:
    """The URL of a new empty database on the server of ``server_url``."""
    name = f"t{uuid.uuid4().hex[:16]}"
    with psycopg.connect(server_url, autocommit=True) as connection:
        connection.execute(f"CREATE DATABASE {name}")
    return server_url.rsplit("/", 1)[0] + f"/{name}"


@pytest.fixture
def database_url(postgres_url):  # noqa: F811
    return fresh_database(postgres_url)


@pytest.fixture
def storage(tmp_path, database_url):
    return LocalStorage(tmp_path, durable=False, records=open_records(database_url))


def test_an_empty_database_gets_the_schema_and_records_behave_as_in_the_folder(storage, database_url):
    assert Database(database_url).run(schema_version) == SCHEMA_VERSION
    assert storage.get_record("jobs", "j1") is None and list(storage.list_records("jobs")) == []
    storage.put_record("jobs", "j2", {"id": "j2", "state": "queued"})
    storage.put_record("jobs", "j1", {"id": "j1", "state": "running", "progress": 0.5})
    storage.put_record("characters", "c1", {"id": "c1"})
    assert storage.get_record("jobs", "j1") == {"id": "j1", "state": "running", "progress": 0.5}
    assert [r["id"] for r in storage.list_records("jobs")] == ["j1", "j2"] and storage.has_record("jobs", "j2")
    assert storage.update_record("jobs", "missing", lambda job: job) is None
    new = storage.update_record("jobs", "j2", lambda job: {**job, "state": "running"})
    assert new == {"id": "j2", "state": "running"} == storage.get_record("jobs", "j2")
    assert storage.update_record("jobs", "j2", lambda job: None) == new
    storage.delete_record("jobs", "j1")
    storage.delete_record("jobs", "never-existed")
    assert storage.get_record_text("jobs", "j1") is None and not storage.has_record("jobs", "j1")
    with pytest.raises(ValueError):
        storage.get_record("jobs", "../etc")


def _increment(url: str, field: str, times: int) -> None:
    records = open_records(url)
    for _ in range(times):
        records.update_record("jobs", "shared", lambda job: {**job, "counter": job["counter"] + 1, field: True})


def test_updates_from_two_processes_lose_nothing(storage, database_url):
    storage.put_record("jobs", "shared", {"counter": 0})
    context = multiprocessing.get_context("spawn")
    workers = [context.Process(target=_increment, args=(database_url, f"seen_by_{i}", 150)) for i in range(2)]
    for worker in workers:
        worker.start()
    for worker in workers:
        worker.join(timeout=120)
    assert [worker.exitcode for worker in workers] == [0, 0]
    assert storage.get_record("jobs", "shared") == {"counter": 300, "seen_by_0": True, "seen_by_1": True}


def test_the_index_in_the_database_answers_as_the_sqlite_one(storage, tmp_path):
    repository = Repository(storage)
    populate(repository, 90)
    expected = truth(repository)
    assert sum(expected["counts"].values()) == 90 and expected["job_seconds"] > 0
    assert indexed(repository) == expected
    # the same changes in the folder's records and the SQLite index give the same figures
    folder = Repository(LocalStorage(tmp_path / "folder", durable=False))
    populate(folder, 90)
    assert truth(folder) == expected and indexed(folder) == expected
    assert repository.rebuild_index() == {"jobs": 90, "characters": 30, "hairstyles": 30, "batches": 30}
    assert indexed(repository) == expected


def test_a_record_and_its_index_row_change_together(storage, monkeypatch):
    repository = Repository(storage)
    repository.create_job(make_job(1))
    job_id = f"{1:032x}"
    written = repository.index.put_job

    def write_then_fail(row):
        written(row)  # the index row is written in the record's transaction ...
        raise RuntimeError("... which then fails")

    monkeypatch.setattr(repository.index, "put_job", write_then_fail)
    with pytest.raises(RuntimeError):
        repository.set_job(job_id, state="running")
    monkeypatch.undo()
    # neither the record nor its index row kept the change
    assert repository.job(job_id).state == "queued" and repository.job_counts()["queued"] == 1
    assert repository.job_counts()["running"] == 0


def test_purge_and_orphan_sweep_work_from_the_database(storage):
    blob = storage.save_bytes(b"referenced", ".obj")
    orphan = storage.save_bytes(b"orphan", ".obj")
    storage.put_record("characters", "c1", {"mesh": {"sha256": blob.sha256, "suffix": ".obj"}})
    assert storage.sweep_orphans(0.0, now=orphan.path.stat().st_mtime + 10) == 1
    assert storage.blob(blob.sha256, ".obj") is not None and storage.blob(orphan.sha256, ".obj") is None
    removed = []
    assert storage.purge(0.0, now=10 ** 10, removed=lambda kind, rid: removed.append((kind, rid))) >= 1
    assert removed == [("characters", "c1")] and storage.get_record("characters", "c1") is None


def test_the_schema_version_is_kept_and_checked(database_url):
    database = Database(database_url)
    assert upgrade(database) == (0, SCHEMA_VERSION) and upgrade(database) == (SCHEMA_VERSION, SCHEMA_VERSION)
    database.run(lambda connection: connection.execute("UPDATE hairport_schema SET version = %s",
                                                       (SCHEMA_VERSION + 1,)))
    with pytest.raises(SchemaMismatch, match="newer than this hairport"):
        upgrade(database)
    with pytest.raises(SchemaMismatch, match="hairport db upgrade"):
        database.check()
    # a process refuses to read or write a schema it does not know, from its first use on
    with pytest.raises(SchemaMismatch, match="hairport db upgrade"):
        open_records(database_url).get_record("jobs", "any")
    with pytest.raises(ValueError, match="mysql:// is not one of postgresql://"):
        open_records("mysql://host/db")
    assert open_records(None) is None and open_records("sqlite:") is None


def test_a_database_restart_is_unavailable_then_answers_again(private_postgres_server, tmp_path):  # noqa: F811
    url = fresh_database(private_postgres_server.url)
    storage = LocalStorage(tmp_path, durable=False, records=open_records(url))
    storage.put_record("jobs", "j", {"state": "running"})
    assert {name: probe() for name, probe in storage.reachability().items()} == {"database": True}
    private_postgres_server.stop()
    with pytest.raises(StorageUnavailable, match="the database postgresql://"):
        storage.get_record("jobs", "j")
    assert storage.reachability()["database"]() is False
    private_postgres_server.start_again()
    assert storage.get_record("jobs", "j") == {"state": "running"}
    storage.update_record("jobs", "j", lambda job: {**job, "state": "succeeded"})
    assert storage.get_record("jobs", "j") == {"state": "succeeded"}


def test_the_db_upgrade_command_makes_and_keeps_the_schema(database_url, monkeypatch, capsys):
    from hairport.cli import main
    from hairport.settings import get_settings

    monkeypatch.setenv("HAIRPORT_DATABASE_URL", database_url)
    get_settings.cache_clear()
    try:
        assert main(["db", "upgrade"]) == 0
        assert f"upgraded from schema version 0 to schema version {SCHEMA_VERSION}" in capsys.readouterr().out
        records = open_records(database_url)
        records.put_record("jobs", "kept", {"state": "queued"})
        assert main(["db", "upgrade"]) == 0
        assert f"already at schema version {SCHEMA_VERSION}" in capsys.readouterr().out
        assert records.get_record("jobs", "kept") == {"state": "queued"}
        monkeypatch.setenv("HAIRPORT_DATABASE_URL", database_url.rsplit(":", 1)[0] + ":1/none")
        get_settings.cache_clear()
        assert main(["db", "upgrade"]) == 2
        assert "cannot be reached" in capsys.readouterr().err
    finally:
        get_settings.cache_clear()
