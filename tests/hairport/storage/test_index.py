"""The record index: in step with the records through creation, state changes, purges and rebuilds,
between processes, and rebuilt from the records when its file is missing, corrupt or behind."""

import multiprocessing
import os
import random
import sqlite3
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, precondition, rule

from hairport.records import (
    JOB_STATES,
    TERMINAL_STATES,
    BatchRecord,
    BatchTotals,
    BlobRef,
    CharacterRecord,
    HairstyleRecord,
    JobRecord,
    PreprocessSettings,
)
from hairport.repository import OWNED_KINDS, Repository
from hairport.storage import LocalStorage
from hairport.storage.index import INDEX_FILE, SqliteIndex

OWNERS = ("kalpha", "kbeta", "kgamma")
#: batch ids of the jobs of :func:`populate` (None: a job outside any batch)
BATCHES = ("b" * 32, "c" * 32, "d" * 32, None)
#: processes and state changes of the concurrency test
WRITERS = 4
CHANGES_PER_WRITER = 60
#: examples (random sequences of changes) of the batch property test, and changes per example at most
EXAMPLES = 25
STEPS = 40


def make_job(number: int, owner: str = "kalpha", created_at: float | None = None,
             batch_id: str | None = None) -> JobRecord:
    return JobRecord(id=f"{number:032x}", owner=owner, hairstyle_id="h" * 32, target_character_id="c" * 32,
                     options={}, preprocess_options=PreprocessSettings(k=5, guides=20), artifact_key="a" * 64,
                     output_format="data", created_at=1000.0 + number if created_at is None else created_at,
                     updated_at=0.0, batch_id=batch_id)


def make_owned(kind: str, number: int, owner: str, created_at: float):
    """A character, hairstyle or batch record (``kind``) of ``owner``."""
    record_id = f"{kind[0]}{number:031x}"
    if kind == CharacterRecord.KIND:
        return CharacterRecord(id=record_id, owner=owner, created_at=created_at, mesh=BlobRef(sha256="a" * 64),
                               vertices=3, faces=1, bones=[])
    if kind == HairstyleRecord.KIND:
        return HairstyleRecord(id=record_id, owner=owner, created_at=created_at, source_character_id="c" * 32,
                               hair=BlobRef(sha256="b" * 64), format="data", units="m",
                               options=PreprocessSettings(k=5, guides=20), artifact_key="e" * 64, strands=2,
                               particles=4)
    return BatchRecord(id=record_id, owner=owner, created_at=created_at, hairstyle_ids=["h" * 32],
                       target_character_ids=["c" * 32], output_format="data", job_ids=[])


def truth(repository: Repository) -> dict:
    """Counts by state, per-owner totals and pages of jobs and of the other listed kinds, stage totals and batch
    totals computed from the records alone."""
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
        for kind in OWNED_KINDS:
            documents = [d for d in repository.storage.list_records(kind) if d["owner"] == owner]
            documents.sort(key=lambda d: (round(d["created_at"] * 1e6), d["id"]), reverse=True)
            pages[kind, owner] = [d["id"] for d in documents]
    seconds = sum(j.timings["job"] for j in jobs if j.state == "succeeded" and j.timings)
    batches = {batch_id: BatchTotals.of_jobs([j for j in jobs if j.batch_id == batch_id])
               for batch_id in BATCHES if batch_id is not None}
    return {"counts": counts, "pages": pages, "job_seconds": round(seconds, 6), "batches": batches}


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
        for kind, model in OWNED_KINDS.items():
            page, total = repository.list_owned(model, owner, 10_000, 0)
            assert total == len(page)
            pages[kind, owner] = [record.id for record in page]
    seconds = repository.stage_totals().get("job", (0.0, 0))[0]
    batches = repository.batch_totals(batch_id for batch_id in BATCHES if batch_id is not None)
    return {"counts": repository.job_counts(), "pages": pages, "job_seconds": round(seconds, 6), "batches": batches}


def populate(repository: Repository, jobs: int, seed: int = 0) -> None:
    rng = random.Random(seed)
    for number in range(jobs):
        repository.create_job(make_job(number, owner=OWNERS[number % len(OWNERS)], created_at=1000.0 + number // 2,
                                       batch_id=BATCHES[number % len(BATCHES)]))
    for number in range(jobs // 3):
        for kind in OWNED_KINDS:
            repository.put(make_owned(kind, number, OWNERS[number % len(OWNERS)], 1000.0 + number // 2),
                           f"{kind[0]}{number:031x}")
    for _ in range(jobs * 2):
        number = rng.randrange(jobs)
        state = rng.choice(JOB_STATES)
        ended = 2000.0 + rng.randrange(100) if state in TERMINAL_STATES else None
        repository.set_job(f"{number:032x}", state=state, timings={"job": float(number % 7)},
                           progress=round(rng.random(), 4), finished_at=ended)


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
    assert repository.rebuild_index() == {"jobs": 90, "characters": 30, "hairstyles": 30, "batches": 30}
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
    repository.index._close()
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

    monkeypatch.setattr(repository.index, "_transaction", broken)
    repository.set_job(f"{4:032x}", state="cancelled")  # the record changes, the index write fails quietly
    assert repository.job(f"{4:032x}").state == "cancelled"
    assert (tmp_path / f"{INDEX_FILE}.stale").exists()
    monkeypatch.undo()
    assert indexed(repository) == truth(repository)
    assert not (tmp_path / f"{INDEX_FILE}.stale").exists()


def test_an_index_of_another_schema_version_is_rebuilt(tmp_path, repository):
    populate(repository, 9)
    expected = truth(repository)
    repository.index._close()
    with sqlite3.connect(tmp_path / INDEX_FILE) as db:
        db.execute("UPDATE meta SET value = '0' WHERE key = 'schema'")
        db.execute("DELETE FROM jobs")
    assert indexed(Repository(LocalStorage(tmp_path, durable=False))) == expected


def _writer(root: str, seed: int, jobs: int) -> None:
    repository = Repository(LocalStorage(root, durable=False))
    rng = random.Random(seed)
    for change in range(CHANGES_PER_WRITER):
        number = rng.randrange(jobs)
        if change % 10 == 0:  # new jobs and records too, while the others change states
            repository.create_job(make_job(1000 * (seed + 1) + change, owner=OWNERS[change % len(OWNERS)],
                                           batch_id=BATCHES[change % len(BATCHES)]))
            kind = list(OWNED_KINDS)[change % len(OWNED_KINDS)]
            repository.put(make_owned(kind, 1000 * (seed + 1) + change, OWNERS[seed % len(OWNERS)], 5.0 + change),
                           f"{kind[0]}{1000 * (seed + 1) + change:031x}")
        repository.set_job(f"{number:032x}", state=rng.choice(JOB_STATES), timings={"job": float(seed + 1)},
                           progress=round(rng.random(), 4), finished_at=rng.choice((None, 3000.0 + change)))


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
    assert isinstance(first.index, SqliteIndex)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_characters_hairstyles_and_batches_are_listed_by_owner_from_the_index(tmp_path, repository):
    for kind in OWNED_KINDS:
        for number, (owner, created_at) in enumerate((("kalpha", 10.0), ("kbeta", 20.0), ("kalpha", 30.0),
                                                      ("kalpha", 10.0), ("kalpha", 9.999999))):
            repository.put(make_owned(kind, number, owner, created_at), f"{kind[0]}{number:031x}")
    for kind, model in OWNED_KINDS.items():
        ids = [f"{kind[0]}{number:031x}" for number in (2, 3, 0, 4)]  # newest first, equal times by id descending
        page, total = repository.list_owned(model, "kalpha", 10, 0)
        assert total == 4 and [record.id for record in page] == ids
        page, total = repository.list_owned(model, "kalpha", 2, 1)
        assert total == 4 and [record.id for record in page] == ids[1:3]
        assert [r.id for r in repository.list_owned(model, "kbeta", 10, 0)[0]] == [f"{kind[0]}{1:031x}"]
        assert repository.list_owned(model, "nobody", 10, 0) == ([], 0)
    repository.delete(BatchRecord, f"b{2:031x}")
    assert [b.id for b in repository.list_owned(BatchRecord, "kalpha", 10, 0)[0]] == [f"b{n:031x}" for n in (3, 0, 4)]
    old = tmp_path / "records" / "characters" / f"c{3:031x}.json"
    os.utime(old, (0, 0))
    repository.purge(older_than_seconds=3600.0)
    page, total = repository.list_owned(CharacterRecord, "kalpha", 10, 0)
    assert total == 3 and [c.id for c in page] == [f"c{n:031x}" for n in (2, 0, 4)]
    assert len(repository.index.owned_rows()) == 3 * 5 - 2
    with pytest.raises(ValueError):
        repository.list_owned(JobRecord, "kalpha", 10, 0)


def test_a_listing_reads_the_page_only_whatever_the_records_of_other_owners(repository, monkeypatch):
    for number in range(300):
        for kind in OWNED_KINDS:
            repository.put(make_owned(kind, number, "kalpha" if number < 12 else "kbeta", float(number)),
                           f"{kind[0]}{number:031x}")
    reads = []
    original = repository.storage.get_record_text
    monkeypatch.setattr(repository.storage, "get_record_text",
                        lambda kind, rid: reads.append(kind) or original(kind, rid))
    for model in OWNED_KINDS.values():
        page, total = repository.list_owned(model, "kalpha", 5, 2)
        assert total == 12 and [record.id[1:] for record in page] == [f"{n:031x}" for n in (9, 8, 7, 6, 5)]
    assert sorted(reads) == sorted(list(OWNED_KINDS) * 5)


def test_a_batch_jobs_progress_reaches_the_index_and_its_heartbeats_do_not(repository, monkeypatch):
    repository.create_job(make_job(1, batch_id="b" * 32))
    repository.create_job(make_job(2))
    writes = []
    original = repository.index.put_job
    monkeypatch.setattr(repository.index, "put_job", lambda row: writes.append(row) or original(row))
    repository.set_job(f"{1:032x}", state="running", progress=0.0)
    repository.set_job(f"{1:032x}", progress=0.25)
    repository.set_job(f"{1:032x}", heartbeat_at=5.0)
    repository.set_job(f"{2:032x}", progress=0.5)  # outside a batch: its own page reads its record
    assert [(row.id, row.state, row.progress_units) for row in writes] == [
        (f"{1:032x}", "running", 0), (f"{1:032x}", "running", 250_000)]
    totals = repository.batch_totals(["b" * 32, "e" * 32])
    assert totals["b" * 32].progress == 0.25 and totals["b" * 32].state == "running"
    assert totals["e" * 32] == BatchTotals(counts=dict.fromkeys(JOB_STATES, 0))  # no job: done, as an empty batch


class BatchChanges(RuleBasedStateMachine):
    """Random sequences of what happens to batches' jobs (created, run, progressing, ended, cancelled, purged,
    deleted, the index rebuilt or lost): after each, the index's totals of every batch and its listing equal
    what the records say."""

    @initialize()
    def open_storage(self):
        self.folder = tempfile.TemporaryDirectory()
        self.root = Path(self.folder.name)
        self.repository = Repository(LocalStorage(self.root, durable=False))
        self.jobs: list[str] = []
        self.number = 0

    def teardown(self):
        if hasattr(self, "folder"):
            self.repository.index._close()
            self.folder.cleanup()

    @rule(batch=st.sampled_from(BATCHES), owner=st.sampled_from(OWNERS))
    def create(self, batch, owner):
        self.number += 1
        job = make_job(self.number, owner=owner, batch_id=batch)
        self.repository.create_job(job)
        self.jobs.append(job.id)
        if batch is not None and not self.repository.exists(BatchRecord, batch):
            self.repository.put(BatchRecord(id=batch, owner=owner, created_at=float(self.number),
                                            hairstyle_ids=["h" * 32], target_character_ids=["c" * 32],
                                            output_format="data", job_ids=[]), batch)

    @precondition(lambda self: self.jobs)
    @rule(data=st.data(), state=st.sampled_from(JOB_STATES), progress=st.floats(0, 1), ended=st.booleans())
    def change(self, data, state, progress, ended):
        job_id = data.draw(st.sampled_from(self.jobs))
        self.repository.set_job(job_id, state=state, progress=round(progress, 4),
                                finished_at=float(self.number) if ended or state in TERMINAL_STATES else None)

    @precondition(lambda self: self.jobs)
    @rule(data=st.data(), progress=st.floats(0, 1))
    def progress(self, data, progress):
        self.repository.set_job(data.draw(st.sampled_from(self.jobs)), progress=round(progress, 4), stage="solve")

    @rule(batch=st.sampled_from(BATCHES[:-1]))
    def cancel(self, batch):
        for job in [self.repository.job(job_id) for job_id in self.jobs]:
            if job is not None and job.batch_id == batch and job.state not in TERMINAL_STATES:
                self.repository.set_job(job.id, state="cancelled", finished_at=float(self.number))

    @precondition(lambda self: self.jobs)
    @rule(data=st.data())
    def purge(self, data):
        job_id = data.draw(st.sampled_from(self.jobs))
        record = self.root / "records" / "jobs" / f"{job_id}.json"
        if record.exists():
            os.utime(record, (0, 0))
        self.repository.purge(older_than_seconds=3600.0)

    @precondition(lambda self: self.jobs)
    @rule(data=st.data())
    def delete(self, data):
        job = self.repository.job(data.draw(st.sampled_from(self.jobs)))
        if job is not None:
            self.repository.delete_job(job)

    @rule()
    def rebuild(self):
        self.repository.rebuild_index()

    @rule()
    def lose_the_index(self):
        self.repository.index._close()
        for suffix in ("", "-wal", "-shm"):
            (self.root / f"{INDEX_FILE}{suffix}").unlink(missing_ok=True)

    @invariant()
    def the_index_says_what_the_records_say(self):
        if hasattr(self, "repository"):
            expected = truth(self.repository)
            assert indexed(self.repository) == expected


BatchChanges.TestCase.settings = settings(max_examples=EXAMPLES, stateful_step_count=STEPS, derandomize=True,
                                          database=None, deadline=None,
                                          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
test_batch_totals_and_listings_follow_random_changes = BatchChanges.TestCase
