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
    SweepClock,
    artifact_key,
    now,
)
from hairport.storage import LocalStorage
from hairport.storage.job_index import IndexRow, JobIndex

R = TypeVar("R", bound=Record)

PURGE_CLOCK_ID = "purge"
SWEEP_CLOCK_ID = "sweep"
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
        # pydantic parses the JSON text itself: several times faster than json.loads then validation,
        # which matters on polls and listings (a job's metrics are a few kB)
        text = self.storage.get_record_text(model.KIND, record_id)
        return None if text is None else model.model_validate_json(text)

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

    def list_owned(self, model: type[R], owner: str, limit: int, offset: int) -> tuple[list[R], int]:
        """``owner``'s records of a kind, newest first: the page and the total (reads every record of the kind:
        unlike jobs, these have no index)."""
        mine = [model.model_validate(document) for document in self.storage.list_records(model.KIND)
                if document.get("owner") == owner]
        mine.sort(key=lambda record: record.created_at, reverse=True)
        return mine[offset:offset + limit], len(mine)

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

    def delete_job(self, job: JobRecord) -> None:
        """Remove a job that never ran (its request failed) and its index entry."""
        self.storage.delete_record(JobRecord.KIND, job.id)
        self.job_index.drop(job.id)

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
        return artifact_key(character, hairstyle.hair.sha256, hairstyle.units, options, format_version, hairstyle.prim)

    def preprocessing_status(self, hairstyle: HairstyleRecord, key: str | None = None) -> PreprocessingRecord:
        """The state of a hairstyle's preprocessing (its own, or of the variant ``key``), shared by every
        hairstyle of the same inputs."""
        key = key or hairstyle.artifact_key
        if self.exists(ArtifactRecord, key):
            return PreprocessingRecord(key=key, state=READY)
        status = self.get(PreprocessingRecord, key)
        return status if status is not None else PreprocessingRecord(key=key, state=QUEUED)

    def claim_preprocessing(self, key: str, stale_after: float, hairstyle_id: str | None = None,
                            options: dict | None = None, task_id: str | None = None) -> bool:
        """Whether the caller should start preprocessing ``key`` (of ``hairstyle_id``, with ``options``, by
        the message ``task_id``): no artifact yet, and no run under way (a queued or running claim older
        than ``stale_after`` seconds, or a failed one, is taken over)."""
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
            return PreprocessingRecord(key=key, state=QUEUED, updated_at=now(), hairstyle_id=hairstyle_id,
                                       options=options, task_id=task_id, enqueued_at=now())

        self.update(PreprocessingRecord, key, claim)
        return claimed

    def release_preprocessing(self, key: str, task_id: str) -> None:
        """Drop the claim of ``key`` made for the message ``task_id`` (its sending failed), so that the next
        request claims it again; a claim made since by someone else stays."""
        status = self.get(PreprocessingRecord, key)
        if status is not None and status.task_id == task_id and status.state == QUEUED:
            self.storage.delete_record(PreprocessingRecord.KIND, key)

    def set_preprocessing(self, key: str, state: str, error: ErrorInfo | None = None,
                          seconds: float | None = None) -> None:
        """The state of ``key``'s preprocessing (who runs it and the claim are kept)."""
        if not self.exists(PreprocessingRecord, key):
            self.put(PreprocessingRecord(key=key, state=state, error=error, seconds=seconds, updated_at=now()), key)
            return
        self.change_preprocessing(key, lambda status: status.model_copy(update=dict(
            state=state, error=error, seconds=seconds)))

    def change_preprocessing(self, key: str, change: Callable[[PreprocessingRecord], PreprocessingRecord | None]
                             ) -> PreprocessingRecord | None:
        """Read-modify-write of a preprocessing record under its lock (``updated_at`` set)."""

        def apply(status: PreprocessingRecord) -> PreprocessingRecord | None:
            new = change(status)
            if new is not None:
                new.updated_at = now()
            return new

        return self.update(PreprocessingRecord, key, apply)

    def preprocessing_in(self, states: tuple[str, ...]) -> Iterator[PreprocessingRecord]:
        """Every preprocessing record in one of ``states`` (reads every preprocessing record: one per
        hairstyle variant, not per job)."""
        for document in self.storage.list_records(PreprocessingRecord.KIND):
            status = PreprocessingRecord.model_validate(document)
            if status.state in states:
                yield status

    # ---------------------------------------------------------------- maintenance

    def purge_if_due(self, older_than_seconds: float, interval_seconds: float) -> int | None:
        """Purge at most every ``interval_seconds`` (the clock is shared by all workers); files removed,
        or None when it was not due."""
        due = self._clock_due(PurgeClock, PURGE_CLOCK_ID, "last_purge", interval_seconds)
        return self.purge(older_than_seconds) if due else None

    def sweep_due(self, interval_seconds: float) -> bool:
        """Whether the caller should sweep now: at most one sweep every ``interval_seconds`` in a deployment."""
        return self._clock_due(SweepClock, SWEEP_CLOCK_ID, "last_sweep", interval_seconds)

    def _clock_due(self, model: type[R], clock_id: str, field: str, interval_seconds: float) -> bool:
        due = False

        def claim(clock):
            nonlocal due
            if now() - getattr(clock, field) < interval_seconds:
                return None
            due = True
            return model(**{field: now()})

        if not self.exists(model, clock_id):
            self.put(model(), clock_id)
        self.update(model, clock_id, claim)
        return due

    def purge(self, older_than_seconds: float) -> int:
        """Remove what is older than the retention (see :meth:`hairport.storage.LocalStorage.purge`), dropping
        the index rows of purged jobs (under their records' locks); files removed."""

        def purged(kind: str, record_id: str) -> None:
            if kind == JobRecord.KIND:
                self.job_index.drop(record_id)

        return self.storage.purge(older_than_seconds, removed=purged)
