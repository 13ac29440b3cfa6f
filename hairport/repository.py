"""Typed access to the records in the shared storage, the job index, and preprocessing claims.

The API and the worker read and write records only through :class:`Repository`, which turns
storage documents into :mod:`hairport.records` models and back, keeps the job index in step
with the job records, and decides who runs a hairstyle's preprocessing.

The job index (:class:`hairport.storage.job_index.JobIndex`, a SQLite table in the storage) gets
a job's row under the job record's lock whenever its state changes, so listing an owner's jobs
(newest first, optionally by state, with a total), the counts by state and the stage totals of
succeeded jobs read the index and the records of the page asked for only, whatever the history
kept. The index is rebuilt from the records when it is missing, corrupt or behind
(:meth:`Repository.rebuild_job_index`, ``hairport reindex``).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from typing import TypeVar

from hairport.records import (
    FAILED,
    JOB_STATES,
    QUEUED,
    READY,
    RUNNING,
    SUCCEEDED,
    ArtifactRecord,
    CharacterRecord,
    ErrorInfo,
    HairstyleRecord,
    JobRecord,
    PreprocessingRecord,
    PreprocessSettings,
    PurgeClock,
    Record,
    artifact_key,
    now,
)
from hairport.storage import LocalStorage
from hairport.storage.job_index import IndexRow, JobIndex

R = TypeVar("R", bound=Record)

PURGE_CLOCK_ID = "purge"
#: the state whose jobs' stage timings the index sums (``/metrics``)
TIMED_STATE = SUCCEEDED


def index_row(job: JobRecord) -> IndexRow:
    """What the job index keeps of a job: its stage timings only once it succeeded."""
    timings = json.dumps(job.timings) if job.state == TIMED_STATE and job.timings else None
    return IndexRow(job.id, job.owner, job.state, job.created_at, job.updated_at, timings)


class Repository:
    """Typed records over a :class:`hairport.storage.LocalStorage`."""

    def __init__(self, storage: LocalStorage):
        self.storage = storage
        self.job_index = JobIndex(storage.root, self._index_rows, durable=storage.durable)

    # ---------------------------------------------------------------- any record

    def get(self, model: type[R], record_id: str) -> R | None:
        document = self.storage.get_record(model.KIND, record_id)
        return None if document is None else model.model_validate(document)

    def exists(self, model: type[Record], record_id: str) -> bool:
        return self.storage.has_record(model.KIND, record_id)

    def put(self, record: Record, record_id: str) -> None:
        self.storage.put_record(record.KIND, record_id, record.model_dump(mode="json"))

    def update(self, model: type[R], record_id: str, change: Callable[[R], R | None]) -> R | None:
        """Read-modify-write under the record's lock; ``change`` returns the new record or None (no write)."""

        def apply(document: dict) -> dict | None:
            new = change(model.model_validate(document))
            return None if new is None else new.model_dump(mode="json")

        document = self.storage.update_record(model.KIND, record_id, apply)
        return None if document is None else model.model_validate(document)

    # ---------------------------------------------------------------- jobs

    def create_job(self, job: JobRecord) -> None:
        """Store a new job and its index entry."""
        self.storage.put_record(job.KIND, job.id, job.model_dump(mode="json"), written=self._reindex)

    def job(self, job_id: str) -> JobRecord | None:
        return self.get(JobRecord, job_id)

    def change_job(self, job_id: str, change: Callable[[JobRecord], JobRecord | None]) -> JobRecord | None:
        """Read-modify-write of a job under its lock (``updated_at`` set, the index kept in step)."""

        def apply(document: dict) -> dict | None:
            new = change(JobRecord.model_validate(document))
            if new is None:
                return None
            new.updated_at = now()
            return new.model_dump(mode="json")

        document = self.storage.update_record(JobRecord.KIND, job_id, apply, written=self._reindex)
        return None if document is None else JobRecord.model_validate(document)

    def set_job(self, job_id: str, **fields) -> JobRecord | None:
        """Set fields of a job (validated), under its lock; the new record, or None if it is gone."""

        def change(job: JobRecord) -> JobRecord:
            return job.model_validate({**job.model_dump(), **fields})

        return self.change_job(job_id, change)

    def list_jobs(self, owner: str, state: str | None = None, limit: int = 50,
                  offset: int = 0) -> tuple[list[JobRecord], int]:
        """``owner``'s jobs newest first (optionally in one state): the page and the total count.

        Only the index and the page's records are read."""
        ids, total = self.job_index.page(owner, state, limit, offset)
        page = [job for job in map(self.job, ids) if job is not None]
        return page, total

    def job_counts(self) -> dict[str, int]:
        """Jobs by state over every owner, from the index."""
        return dict.fromkeys(JOB_STATES, 0) | self.job_index.counts()

    def stage_totals(self) -> dict[str, tuple[float, int]]:
        """``{stage: (seconds, jobs)}`` over the succeeded jobs kept, from the index."""
        return self.job_index.stage_totals()

    def jobs_in_state(self, state: str) -> Iterator[JobRecord]:
        """Every job in ``state`` (the index finds them; only those records are read, and a job whose record
        is gone or has moved on meanwhile is skipped)."""
        for job_id in self.job_index.ids_in_state(state):
            job = self.job(job_id)
            if job is not None and job.state == state:
                yield job

    def _reindex(self, old: dict | None, new: dict) -> None:
        # under the job record's lock: the index changes in the order the record does. Progress writes
        # (every ~0.5 s while a job runs) change none of the indexed fields and skip the index.
        if old is not None and all(old.get(field) == new.get(field) for field in ("state", "owner", "timings")):
            return
        self.job_index.put(index_row(JobRecord.model_validate(new)))

    def _index_rows(self) -> Iterator[IndexRow]:
        for document in self.storage.list_records(JobRecord.KIND):
            yield index_row(JobRecord.model_validate(document))

    def rebuild_job_index(self) -> int:
        """Refill the job index from the job records; jobs indexed."""
        return self.job_index.rebuild()

    # ---------------------------------------------------------------- preprocessing

    def artifact(self, key: str) -> ArtifactRecord | None:
        return self.get(ArtifactRecord, key)

    def variant_key(self, hairstyle: HairstyleRecord, options: PreprocessSettings, format_version: int) -> str:
        """The artifact key of a hairstyle preprocessed with other options (e.g. another guide count)."""
        character = self.get(CharacterRecord, hairstyle.source_character_id)
        return artifact_key(character, hairstyle.hair.sha256, hairstyle.units, options, format_version)

    def preprocessing_status(self, hairstyle: HairstyleRecord, key: str | None = None) -> PreprocessingRecord:
        """The state of a hairstyle's preprocessing (its own, or of the variant ``key``), shared by every
        hairstyle of the same inputs."""
        key = key or hairstyle.artifact_key
        if self.exists(ArtifactRecord, key):
            return PreprocessingRecord(key=key, state=READY)
        status = self.get(PreprocessingRecord, key)
        return status if status is not None else PreprocessingRecord(key=key, state=QUEUED)

    def claim_preprocessing(self, key: str, stale_after: float) -> bool:
        """Whether the caller should start preprocessing ``key``: no artifact yet, and no run under way
        (a queued or running claim older than ``stale_after`` seconds, or a failed one, is taken over)."""
        if self.exists(ArtifactRecord, key):
            return False
        if not self.exists(PreprocessingRecord, key):
            self.put(PreprocessingRecord(key=key, state=FAILED), key)
        claimed = False

        def claim(status: PreprocessingRecord) -> PreprocessingRecord | None:
            nonlocal claimed
            if status.state in (QUEUED, RUNNING) and now() - status.updated_at < stale_after:
                return None
            claimed = True
            return PreprocessingRecord(key=key, state=QUEUED, updated_at=now())

        self.update(PreprocessingRecord, key, claim)
        return claimed

    def set_preprocessing(self, key: str, state: str, error: ErrorInfo | None = None,
                          seconds: float | None = None) -> None:
        self.put(PreprocessingRecord(key=key, state=state, error=error, seconds=seconds, updated_at=now()), key)

    # ---------------------------------------------------------------- retention

    def purge_if_due(self, older_than_seconds: float, interval_seconds: float) -> int | None:
        """Purge at most every ``interval_seconds`` (the clock is shared by all workers); files removed,
        or None when it was not due."""
        due = False

        def claim(clock: PurgeClock) -> PurgeClock | None:
            nonlocal due
            if now() - clock.last_purge < interval_seconds:
                return None
            due = True
            return PurgeClock(last_purge=now())

        if not self.exists(PurgeClock, PURGE_CLOCK_ID):
            self.put(PurgeClock(), PURGE_CLOCK_ID)
        self.update(PurgeClock, PURGE_CLOCK_ID, claim)
        return self.purge(older_than_seconds) if due else None

    def purge(self, older_than_seconds: float) -> int:
        """Remove what is older than the retention (see :meth:`hairport.storage.LocalStorage.purge`), dropping
        the index rows of purged jobs (under their records' locks); files removed."""

        def purged(kind: str, record_id: str) -> None:
            if kind == JobRecord.KIND:
                self.job_index.drop(record_id)

        return self.storage.purge(older_than_seconds, removed=purged)
