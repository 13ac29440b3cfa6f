"""The job index: in step with the records through creation, state changes, purges and rebuilds,
between processes, and rebuilt from the records when its file is missing, corrupt or behind."""

import multiprocessing
import os
import random
import sqlite3

import pytest

from hairport.records import JOB_STATES, JobRecord, PreprocessSettings
from hairport.repository import Repository
from hairport.storage import LocalStorage
from hairport.storage.job_index import INDEX_FILE, JobIndex

OWNERS = ("kalpha", "kbeta", "kgamma")
#: processes and state changes of the concurrency test
WRITERS = 4
CHANGES_PER_WRITER = 60


def make_job(number: int, owner: str = "kalpha", created_at: float | None = None) -> JobRecord:
    return JobRecord(id=f"{number:032x}", owner=owner, hairstyle_id="h" * 32, target_character_id="c" * 32,
                     options={}, preprocess_options=PreprocessSettings(k=5, guides=20), artifact_key="a" * 64,
                     output_format="data", created_at=1000.0 + number if created_at is None else created_at,
                     updated_at=0.0)


def truth(repository: Repository) -> dict:
    """Counts by state, per-owner totals and pages, and stage totals computed from the records alone."""
    jobs = [JobRecord.model_validate(d) for d in repository.storage.list_records("jobs")]
    counts = dict.fromkeys(JOB_STATES, 0)
    for job in jobs:
        counts[job.state] += 1
    pages = {}
    for owner in OWNERS:
        mine = sorted((j for j in jobs if j.owner == owner), key=lambda j: (round(j.created_at * 1e6), j.id),
                      reverse=True)
        pages[owner] = [j.id for j in mine]
        for state in JOB_STATES:
            pages[owner, state] = [j.id for j in mine if j.state == state]
    seconds = sum(j.timings["job"] for j in jobs if j.state == "succeeded" and j.timings)
    return {"counts": counts, "pages": pages, "job_seconds": round(seconds, 6)}


def indexed(repository: Repository) -> dict:
    """The same numbers as :func:`truth`, from the index."""
    pages = {}
    for owner in OWNERS:
        page, total = repository.list_jobs(owner, limit=10_000)
        assert total == len(page)
        pages[owner] = [j.id for j in page]
        for state in JOB_STATES:
            page, total = repository.list_jobs(owner, state=state, limit=10_000)
            assert total == len(page)
            pages[owner, state] = [j.id for j in page]
    seconds = repository.stage_totals().get("job", (0.0, 0))[0]
    return {"counts": repository.job_counts(), "pages": pages, "job_seconds": round(seconds, 6)}


def populate(repository: Repository, jobs: int, seed: int = 0) -> None:
    rng = random.Random(seed)
    for number in range(jobs):
        repository.create_job(make_job(number, owner=OWNERS[number % len(OWNERS)], created_at=1000.0 + number // 2))
    for _ in range(jobs * 2):
        number = rng.randrange(jobs)
        state = rng.choice(JOB_STATES)
        repository.set_job(f"{number:032x}", state=state, timings={"job": float(number % 7)})


@pytest.fixture
def repository(tmp_path) -> Repository:
    return Repository(LocalStorage(tmp_path, durable=False))


def test_the_index_matches_the_records_after_changes_and_a_rebuild(repository):
    populate(repository, 90)
    expected = truth(repository)
    assert sum(expected["counts"].values()) == 90 and expected["job_seconds"] > 0
    assert indexed(repository) == expected
    page, total = repository.list_jobs("kalpha", limit=7, offset=5)
    assert total == 30 and [j.id for j in page] == expected["pages"]["kalpha"][5:12]
    assert repository.rebuild_job_index() == 90
    assert indexed(repository) == expected
    for state in JOB_STATES:
        assert sorted(j.id for j in repository.jobs_in_state(state)) == sorted(
            i for owner in OWNERS for i in expected["pages"][owner, state])


def test_a_missing_index_file_is_rebuilt_from_the_records(tmp_path, repository):
    populate(repository, 30)
    expected = truth(repository)
    for suffix in ("", "-wal", "-shm"):
        (tmp_path / f"{INDEX_FILE}{suffix}").unlink(missing_ok=True)
    fresh = Repository(LocalStorage(tmp_path, durable=False))
    assert indexed(fresh) == expected
    assert indexed(repository) == expected  # the first one notices the new file and reopens it


def test_a_corrupt_index_file_is_rebuilt_from_the_records(tmp_path, repository):
    populate(repository, 30)
    expected = truth(repository)
    repository.job_index._close()
    for suffix in ("-wal", "-shm"):
        (tmp_path / f"{INDEX_FILE}{suffix}").unlink(missing_ok=True)
    (tmp_path / INDEX_FILE).write_bytes(b"this is not a database" * 500)
    fresh = Repository(LocalStorage(tmp_path, durable=False))
    assert indexed(fresh) == expected
    assert (tmp_path / f"{INDEX_FILE}.corrupt").read_bytes().startswith(b"this is not a database")
    fresh.set_job(f"{3:032x}", state="cancelled")  # and writes go on into the new file
    assert indexed(repository) == truth(repository)


def test_a_failed_index_write_marks_the_index_and_the_next_read_rebuilds_it(tmp_path, repository, monkeypatch):
    populate(repository, 12)

    def broken(*args, **kwargs):
        raise sqlite3.OperationalError("disk I/O error")

    monkeypatch.setattr(repository.job_index, "_transaction", broken)
    repository.set_job(f"{4:032x}", state="cancelled")  # the record changes, the index write fails quietly
    assert repository.job(f"{4:032x}").state == "cancelled"
    assert (tmp_path / f"{INDEX_FILE}.stale").exists()
    monkeypatch.undo()
    assert indexed(repository) == truth(repository)
    assert not (tmp_path / f"{INDEX_FILE}.stale").exists()


def test_an_index_of_another_schema_version_is_rebuilt(tmp_path, repository):
    populate(repository, 9)
    expected = truth(repository)
    repository.job_index._close()
    with sqlite3.connect(tmp_path / INDEX_FILE) as db:
        db.execute("UPDATE meta SET value = '0' WHERE key = 'schema'")
        db.execute("DELETE FROM jobs")
    assert indexed(Repository(LocalStorage(tmp_path, durable=False))) == expected


def _writer(root: str, seed: int, jobs: int) -> None:
    repository = Repository(LocalStorage(root, durable=False))
    rng = random.Random(seed)
    for change in range(CHANGES_PER_WRITER):
        number = rng.randrange(jobs)
        if change % 10 == 0:  # new jobs too, while the others change states
            repository.create_job(make_job(1000 * (seed + 1) + change, owner=OWNERS[change % len(OWNERS)]))
        repository.set_job(f"{number:032x}", state=rng.choice(JOB_STATES), timings={"job": float(seed + 1)})


def test_writers_in_several_processes_keep_the_index_consistent(tmp_path, repository):
    populate(repository, 24)
    context = multiprocessing.get_context("spawn")  # fresh processes, as workers on a host are
    processes = [context.Process(target=_writer, args=(str(tmp_path), seed, 24)) for seed in range(WRITERS)]
    for process in processes:
        process.start()
    for process in processes:
        process.join(timeout=120)
        assert process.exitcode == 0
    expected = truth(repository)
    assert sum(expected["counts"].values()) == 24 + WRITERS * CHANGES_PER_WRITER // 10
    assert indexed(repository) == expected
    assert not (tmp_path / f"{INDEX_FILE}.stale").exists()  # no write was lost to a busy database


def test_the_index_file_is_shared_by_every_repository_of_the_storage(tmp_path):
    first = Repository(LocalStorage(tmp_path, durable=False))
    second = Repository(LocalStorage(tmp_path, durable=False))
    first.create_job(make_job(1))
    second.set_job(f"{1:032x}", state="running")
    assert first.job_counts()["running"] == 1 and [j.id for j in first.jobs_in_state("running")] == [f"{1:032x}"]
    assert oct(os.stat(tmp_path / INDEX_FILE).st_mode & 0o777) == oct(0o666 & ~_umask())
    assert isinstance(first.job_index, JobIndex)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
