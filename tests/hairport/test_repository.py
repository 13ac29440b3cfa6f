"""Typed records over the storage: the job index, listing by pages, preprocessing claims, purging."""

import os

import pytest

from hairport.records import (
    ArtifactRecord,
    BlobRef,
    CharacterRecord,
    ErrorInfo,
    HairstyleRecord,
    JobRecord,
    PreprocessingRecord,
    PreprocessSettings,
    artifact_key,
    now,
)
from hairport.repository import Repository
from hairport.storage import LocalStorage


@pytest.fixture
def repository(tmp_path) -> Repository:
    return Repository(LocalStorage(tmp_path, durable=False))


def make_job(number: int, owner: str = "kowner", created_at: float | None = None) -> JobRecord:
    return JobRecord(id=f"{number:032x}", owner=owner, hairstyle_id="h" * 32, target_character_id="c" * 32,
                     options={}, preprocess_options=PreprocessSettings(k=5, guides=20), artifact_key="a" * 64,
                     output_format="data", created_at=created_at if created_at is not None else 1000.0 + number,
                     updated_at=0.0)


def test_jobs_are_listed_newest_first_with_totals_and_states(repository):
    for number in range(10):
        repository.create_job(make_job(number))
    repository.create_job(make_job(99, owner="kother"))
    for number in (1, 4, 7):
        repository.set_job(f"{number:032x}", state="succeeded")
    repository.set_job(f"{2:032x}", state="running")
    page, total = repository.list_jobs("kowner", limit=3)
    assert total == 10 and [job.id for job in page] == [f"{n:032x}" for n in (9, 8, 7)]
    page, total = repository.list_jobs("kowner", limit=3, offset=8)
    assert total == 10 and [job.id for job in page] == [f"{n:032x}" for n in (1, 0)]
    page, total = repository.list_jobs("kowner", state="succeeded")
    assert total == 3 and [job.id for job in page] == [f"{n:032x}" for n in (7, 4, 1)]
    assert all(job.state == "succeeded" for job in page)
    assert repository.list_jobs("kowner", state="cancelled") == ([], 0)
    assert repository.list_jobs("nobody") == ([], 0)
    assert repository.job_counts() == {"queued": 7, "running": 1, "stale": 0, "succeeded": 3, "failed": 0, "cancelled": 0}
    assert sorted(job.id for job in repository.jobs_in_state("succeeded")) == [f"{n:032x}" for n in (1, 4, 7)]


def test_a_page_reads_only_its_own_records(repository, monkeypatch):
    for number in range(50):
        repository.create_job(make_job(number))
    reads = []
    original = repository.storage.get_record_text
    monkeypatch.setattr(repository.storage, "get_record_text", lambda kind, rid: reads.append(rid) or original(kind, rid))
    page, total = repository.list_jobs("kowner", limit=2, offset=10)
    assert total == 50 and len(page) == 2 and len(reads) == 2


def test_index_follows_every_state_change_and_drops_purged_jobs(repository):
    job = make_job(1)
    repository.create_job(job)
    for state in ("running", "running", "failed", "running", "succeeded"):
        repository.set_job(job.id, state=state, progress=0.5)
        [row] = repository.index.job_rows()
        assert (row.id, row.owner, row.state) == (job.id, "kowner", state)
        assert repository.job_counts()[state] == 1 and sum(repository.job_counts().values()) == 1
    assert repository.job(job.id).updated_at > 0
    record = repository.storage.root / "records" / "jobs" / f"{job.id}.json"
    os.utime(record, (0, 0))
    assert repository.purge(older_than_seconds=3600.0) == 1
    assert repository.index.job_rows() == [] and repository.list_jobs("kowner") == ([], 0)
    assert repository.job_counts()["succeeded"] == 0
    assert repository.set_job(job.id, state="failed") is None


def test_equal_creation_times_sort_by_id_and_order_is_exact_to_the_microsecond(repository):
    repository.create_job(make_job(1, created_at=10.000001))
    repository.create_job(make_job(2, created_at=10.0))
    repository.create_job(make_job(3, created_at=10.0))
    repository.create_job(make_job(4, created_at=9.5))
    page, total = repository.list_jobs("kowner")
    assert total == 4 and [job.id for job in page] == [f"{n:032x}" for n in (1, 3, 2, 4)]


def test_stage_totals_sum_the_succeeded_jobs_only(repository):
    for number, seconds in enumerate((1.5, 2.0, 4.0)):
        repository.create_job(make_job(number))
        repository.set_job(f"{number:032x}", state="running", timings={"job": 99.0})  # not summed: running
    assert repository.stage_totals() == {}
    for number, seconds in enumerate((1.5, 2.0, 4.0)):
        repository.set_job(f"{number:032x}", state="succeeded", timings={"job": seconds, "solve": seconds / 2})
    totals = repository.stage_totals()
    assert totals["job"] == (pytest.approx(7.5), 3) and totals["solve"] == (pytest.approx(3.75), 3)
    repository.set_job(f"{2:032x}", state="failed")  # leaves the sum
    assert repository.stage_totals()["job"] == (pytest.approx(3.5), 2)
    record = repository.storage.root / "records" / "jobs" / f"{0:032x}.json"
    os.utime(record, (0, 0))
    repository.purge(older_than_seconds=3600.0)  # a purged succeeded job leaves it too
    assert repository.stage_totals()["job"] == (pytest.approx(2.0), 1)
    assert repository.job_counts() == {"queued": 0, "running": 0, "stale": 0, "succeeded": 1, "failed": 1, "cancelled": 0}


def test_progress_writes_do_not_touch_the_index(repository, monkeypatch):
    repository.create_job(make_job(1))
    writes = []
    monkeypatch.setattr(repository.index, "put_job", writes.append)
    for progress in (0.1, 0.2, 0.3):
        repository.set_job(f"{1:032x}", progress=progress, stage="solve")
    assert writes == []
    repository.set_job(f"{1:032x}", state="running")
    assert [row.state for row in writes] == ["running"]


def test_set_job_validates_its_fields(repository):
    repository.create_job(make_job(3))
    done = repository.set_job(f"{3:032x}", state="failed", error=ErrorInfo(code="bad_input", message="no"))
    assert done.error.code == "bad_input" and repository.job(f"{3:032x}").error.message == "no"
    with pytest.raises(ValueError):
        repository.set_job(f"{3:032x}", state="exploded")
    assert repository.job(f"{3:032x}").state == "failed"


def hairstyle_and_character(repository) -> tuple[HairstyleRecord, CharacterRecord]:
    character = CharacterRecord(id="c" * 32, owner="kowner", created_at=0.0, mesh=BlobRef(sha256="a" * 64),
                                vertices=3, faces=1, bones=["head"])
    options = PreprocessSettings(k=5, guides=20)
    key = artifact_key(character, "b" * 64, "m", options, 1)
    hairstyle = HairstyleRecord(id="h" * 32, owner="kowner", created_at=0.0, source_character_id=character.id,
                                hair=BlobRef(sha256="b" * 64, suffix=".data"), format="data", units="m",
                                options=options, artifact_key=key, strands=2, particles=4)
    repository.put(character, character.id)
    repository.put(hairstyle, hairstyle.id)
    return hairstyle, character


def test_preprocessing_status_and_claims(repository):
    hairstyle, _ = hairstyle_and_character(repository)
    key = hairstyle.artifact_key
    assert repository.preprocessing_status(hairstyle).state == "queued"
    assert repository.claim_preprocessing(key, stale_after=60.0) is True
    assert repository.claim_preprocessing(key, stale_after=60.0) is False  # under way
    assert repository.claim_preprocessing(key, stale_after=0.0) is True  # stale: taken over
    repository.set_preprocessing(key, "failed", error=ErrorInfo(code="truncated", message="cut"))
    status = repository.preprocessing_status(hairstyle)
    assert status.state == "failed" and status.error.code == "truncated"
    assert repository.claim_preprocessing(key, stale_after=60.0) is True  # a failed run is tried again
    repository.put(ArtifactRecord(key=key, sha256="f" * 64, size=1, format_version=1, seconds=0.1, guides=20,
                                  created_at=0.0), key)
    assert repository.preprocessing_status(hairstyle) == PreprocessingRecord(key=key, state="ready")
    assert repository.claim_preprocessing(key, stale_after=0.0) is False


def test_variant_key_is_the_artifact_key_of_the_other_options(repository):
    hairstyle, character = hairstyle_and_character(repository)
    assert repository.variant_key(hairstyle, hairstyle.options, 1) == hairstyle.artifact_key
    other = PreprocessSettings(k=5, guides=10)
    assert repository.variant_key(hairstyle, other, 1) == artifact_key(character, "b" * 64, "m", other, 1)


def test_purge_runs_at_most_once_per_interval(repository):
    assert repository.purge_if_due(older_than_seconds=1e9, interval_seconds=3600.0) == 0
    assert repository.purge_if_due(older_than_seconds=1e9, interval_seconds=3600.0) is None
    assert repository.purge_if_due(older_than_seconds=1e9, interval_seconds=0.0) == 0


def test_the_orphan_sweep_keeps_what_a_running_job_saved_until_it_ends(repository):
    """A running job records its outputs when it ends: what it saved since its start stays, however old."""
    storage = repository.storage
    two_hours_ago = now() - 7200
    job = make_job(5, created_at=two_hours_ago - 60)
    repository.create_job(job)
    repository.set_job(job.id, state="running", started_at=two_hours_ago)
    output = storage.save_bytes(b"a result written an hour and a half into the job", ".npz")
    before = storage.save_bytes(b"an orphan older than the job", ".npz")
    for blob, moment in ((output, two_hours_ago + 1800), (before, two_hours_ago - 600)):
        os.utime(blob.path, (moment, moment))
    assert repository.sweep_orphans(grace_seconds=3600.0) == 1
    assert output.path.exists() and not before.path.exists()
    repository.set_job(job.id, state="succeeded", outputs={"npz": BlobRef(sha256=output.sha256, suffix=".npz")})
    assert repository.sweep_orphans(grace_seconds=3600.0) == 0 and output.path.exists()  # now its record refers to it
    lost = storage.save_bytes(b"the result of a run that lost its job", ".npz")
    os.utime(lost.path, (two_hours_ago, two_hours_ago))
    assert repository.sweep_orphans(grace_seconds=3600.0) == 1 and not lost.path.exists()


def test_the_orphan_sweep_runs_once_per_interval_in_a_deployment(repository, tmp_path):
    orphan = repository.storage.save_bytes(b"an orphan", ".obj")
    old = now() - 7200
    os.utime(orphan.path, (old, old))
    other = Repository(LocalStorage(tmp_path, durable=False))  # another process of the deployment
    assert repository.sweep_orphans_if_due(3600.0, interval_seconds=3600.0) == 1 and not orphan.path.exists()
    again = repository.storage.save_bytes(b"another orphan", ".obj")
    os.utime(again.path, (old, old))
    assert other.sweep_orphans_if_due(3600.0, interval_seconds=3600.0) is None and again.path.exists()
