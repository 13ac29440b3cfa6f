"""Operations commands: the OpenAPI contract, purging, and refusing to serve without keys."""

import os
import time
from pathlib import Path

import yaml

from hairport import __version__
from hairport.cli import main
from hairport.cli.ops import openapi_yaml
from hairport.records import BatchRecord, JobRecord, PreprocessSettings
from hairport.repository import Repository
from hairport.storage import LocalStorage

ROOT = Path(__file__).resolve().parents[3]


def test_openapi_yaml_is_generated_from_the_app():
    committed = (ROOT / "openapi.yaml").read_text()
    assert openapi_yaml() == committed, "openapi.yaml drifted from the app: run `hairport openapi --out openapi.yaml`"
    assert yaml.safe_load(committed)["info"]["version"] == __version__


def test_openapi_command_writes_the_contract_and_nothing_else(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the default storage folder is relative: nothing may appear here
    assert main(["openapi", "--out", "api.yaml"]) == 0
    assert (tmp_path / "api.yaml").read_text() == (ROOT / "openapi.yaml").read_text()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["api.yaml"]


def test_purge_command_removes_old_records_and_their_index_entries(tmp_path, monkeypatch, capsys):
    from hairport.settings import get_settings

    storage = LocalStorage(tmp_path)
    repository = Repository(storage)
    job = JobRecord(id="a" * 32, owner="kowner", hairstyle_id="h" * 32, target_character_id="c" * 32, options={},
                    preprocess_options=PreprocessSettings(k=5, guides=9), artifact_key="e" * 64,
                    output_format="data", created_at=1.0, updated_at=1.0)
    repository.create_job(job)
    record = tmp_path / "records" / "jobs" / f"{job.id}.json"
    os.utime(record, (0, 0))
    orphan, young = storage.save_bytes(b"an upload whose record never came"), storage.save_bytes(b"being validated")
    two_hours_ago = time.time() - 7200  # past the default grace of an hour, well within the retention of a day
    os.utime(orphan.path, (two_hours_ago, two_hours_ago))
    monkeypatch.setenv("HAIRPORT_STORAGE_DIR", str(tmp_path))
    monkeypatch.setenv("HAIRPORT_RETENTION_DAYS", "1")
    get_settings.cache_clear()
    try:
        assert main(["purge"]) == 0
    finally:
        get_settings.cache_clear()
    assert "removed 1 files older than 1 days and 1 stored files no record refers to" in capsys.readouterr().out
    assert not record.exists() and repository.list_jobs("kowner") == ([], 0)
    assert repository.index.job_rows() == [] and sum(repository.job_counts().values()) == 0
    assert not orphan.path.exists() and young.path.exists()


def test_reindex_command_rebuilds_the_record_index_from_the_records(tmp_path, monkeypatch, capsys):
    from hairport.settings import get_settings
    from hairport.storage.index import INDEX_FILE

    repository = Repository(LocalStorage(tmp_path))
    for number, state in enumerate(("queued", "running", "succeeded")):
        repository.create_job(JobRecord(id=f"{number:032x}", owner="kowner", hairstyle_id="h" * 32,
                                        target_character_id="c" * 32, options={},
                                        preprocess_options=PreprocessSettings(k=5, guides=9), artifact_key="e" * 64,
                                        output_format="data", created_at=1.0, updated_at=1.0, state=state))
    repository.put(BatchRecord(id="b" * 32, owner="kowner", created_at=2.0, hairstyle_ids=["h" * 32],
                               target_character_ids=["c" * 32], output_format="data", job_ids=[]), "b" * 32)
    repository.index._close()
    with repository.index._transaction() as db:  # an index that lost its rows
        db.execute("DELETE FROM jobs")
        db.execute("DELETE FROM owned")
    assert repository.list_jobs("kowner")[1] == 0 and repository.list_owned(BatchRecord, "kowner", 10, 0) == ([], 0)
    monkeypatch.setenv("HAIRPORT_STORAGE_DIR", str(tmp_path))
    get_settings.cache_clear()
    try:
        assert main(["reindex"]) == 0
    finally:
        get_settings.cache_clear()
    assert f"indexed 3 jobs, 0 characters, 0 hairstyles, 1 batches of {tmp_path}" in capsys.readouterr().out
    assert repository.list_jobs("kowner")[1] == 3 and repository.job_counts()["running"] == 1
    assert [batch.id for batch in repository.list_owned(BatchRecord, "kowner", 10, 0)[0]] == ["b" * 32]
    assert (tmp_path / INDEX_FILE).is_file()


def test_serve_refuses_several_workers_with_the_embedded_queue(monkeypatch, capsys):
    from hairport.settings import get_settings

    monkeypatch.setenv("HAIRPORT_INSECURE_DEV", "true")
    get_settings.cache_clear()
    try:
        assert main(["serve", "--embedded", "--workers", "2"]) == 2
        assert main(["serve", "--workers", "0"]) == 2
    finally:
        get_settings.cache_clear()
    assert capsys.readouterr().err.count("hairport: error: --workers must be 1 or more") == 2
