"""Typed access to the records in the shared storage, the record index, and preprocessing claims.

The API and the worker read and write records only through :class:`Repository`, which turns
storage documents into :mod:`hairport.records` models and back, keeps the record index in step
with the records, and decides who runs a hairstyle's preprocessing.

The record index (:class:`hairport.storage.index.Index`, SQLite tables in the storage) gets a
row under the record's lock whenever a job's indexed fields change (state, owner, timings, and for
a job of a batch its progress and end) and whenever a character, hairstyle or batch is written,
and loses it when the record is purged or deleted. So listing an owner's jobs (newest first,
optionally by state, with a total) or characters, hairstyles and batches, a batch's counts by
state, progress and end, the counts by state and the stage totals of succeeded jobs read the
index and the records of the page asked for only, whatever the history kept. The index is rebuilt
from the records when it is missing, corrupt or behind (:meth:`Repository.rebuild_index`,
``hairport reindex``).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Iterator
from typing import TypeVar

from hairport.records import (
    FAILED,
    JOB_STATES,
    QUEUED,
    READY,
    RUNNING,
    SUCCEEDED,
    TERMINAL_STATES,
    ArtifactRecord,
    BatchRecord,
    BatchTotals,
    CharacterRecord,
    ErrorInfo,
    HairstyleRecord,
    JobRecord,
    OrphanSweepClock,
    PreprocessingRecord,
    PreprocessSettings,
    PurgeClock,
    Record,
    SweepClock,
    artifact_key,
    now,
    progress_units,
)
from hairport.storage import LocalStorage
from hairport.storage.index import Index, JobRow, OwnedRow, Row, SqliteIndex
from hairport.storage.postgres import PostgresIndex

R = TypeVar("R", bound=Record)

PURGE_CLOCK_ID = "purge"
SWEEP_CLOCK_ID = "sweep"
ORPHAN_CLOCK_ID = "orphans"
#: the state whose jobs' stage timings the index sums (``/metrics``)
TIMED_STATE = SUCCEEDED
#: the kinds listed by owner from the index besides jobs (``GET /v1/characters``, ...)
OWNED_KINDS: dict[str, type[Record]] = {model.KIND: model for model in (CharacterRecord, HairstyleRecord, BatchRecord)}


def index_row(job: JobRecord) -> JobRow:
    """What the record index keeps of a job: its stage timings only once it succeeded, its progress only when it
    is a batch's (the batch totals sum it; a job's own page reads its record)."""
    timings = json.dumps(job.timings) if job.state == TIMED_STATE and job.timings else None
    units = progress_units(job.progress) if job.batch_id is not None else 0
    return JobRow(job.id, job.owner, job.state, job.created_at, job.updated_at, timings, job.batch_id, units,
                  job.finished_at)


def running_since(kind: str, document: dict) -> float | None:
    """Since when a record's blobs may be unrecorded yet: a running job's start (its outputs are written to its
    record when it ends)."""
    if kind == JobRecord.KIND and document.get("state") == RUNNING:
        return document.get("started_at") or document.get("created_at") or 0.0
    return None


def owned_row(kind: str, document: dict) -> OwnedRow:
    """What the record index keeps of a character, hairstyle or batch."""
    return OwnedRow(kind, document["id"], document["owner"], document["created_at"])


class Repository:
    """Typed records over a :class:`hairport.storage.LocalStorage`."""

    def __init__(self, storage: LocalStorage, index: Index | None = None):
        self.storage = storage
        self.index: Index = index or self._default_index()

    def _default_index(self) -> Index:
        """The index next to the records: in their database, or a SQLite file in the storage folder."""
        database = getattr(self.storage.records, "database", None)
        if database is not None:
            return PostgresIndex(database, self._index_rows)
        return SqliteIndex(self.storage.root, self._index_rows, durable=self.storage.durable)

    # ---------------------------------------------------------------- any record

    def get(self, model: type[R], record_id: str) -> R | None:
        # pydantic parses the JSON text itself: several times faster than json.loads then validation,
        # which matters on polls and listings (a job's metrics are a few kB)
        text = self.storage.get_record_text(model.KIND, record_id)
        return None if text is None else model.model_validate_json(text)

    def exists(self, model: type[Record], record_id: str) -> bool:
        return self.storage.has_record(model.KIND, record_id)

    def put(self, record: Record, record_id: str) -> None:
        """Write a record (and its index row, for an indexed kind)."""
        self.storage.put_record(record.KIND, record_id, record.model_dump(mode="json"),
                                written=self._index_writer(record.KIND))

    def update(self, model: type[R], record_id: str, change: Callable[[R], R | None]) -> R | None:
        """Read-modify-write under the record's lock; ``change`` returns the new record or None (no write)."""

        def apply(document: dict) -> dict | None:
            new = change(model.model_validate(document))
            return None if new is None else new.model_dump(mode="json")

        document = self.storage.update_record(model.KIND, record_id, apply, written=self._index_writer(model.KIND))
        return None if document is None else model.model_validate(document)

    def delete(self, model: type[Record], record_id: str) -> None:
        """Remove a record and its index row (nothing happens if it does not exist)."""
        self.storage.delete_record(model.KIND, record_id)
        self._unindex(model.KIND, record_id)

    def list_owned(self, model: type[R], owner: str, limit: int, offset: int) -> tuple[list[R], int]:
        """``owner``'s characters, hairstyles or batches newest first: the page and the total. Only the index and
        the page's records are read (a record removed meanwhile is left out)."""
        if model.KIND not in OWNED_KINDS:
            raise ValueError(f"{model.KIND} are not listed by owner")
        ids, total = self.index.owned_page(model.KIND, owner, limit, offset)
        return [record for record in (self.get(model, record_id) for record_id in ids) if record is not None], total

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

    def delete_job(self, job: JobRecord) -> None:
        """Remove a job that never ran (its request failed) and its index entry."""
        self.delete(JobRecord, job.id)

    def list_jobs(self, owner: str, state: str | None = None, limit: int = 50,
                  offset: int = 0) -> tuple[list[JobRecord], int]:
        """``owner``'s jobs newest first (optionally in one state): the page and the total count.

        Only the index and the page's records are read."""
        ids, total = self.index.job_page(owner, state, limit, offset)
        page = [job for job in map(self.job, ids) if job is not None]
        return page, total

    def job_counts(self) -> dict[str, int]:
        """Jobs by state over every owner, from the index."""
        return dict.fromkeys(JOB_STATES, 0) | self.index.job_counts()

    def stage_totals(self) -> dict[str, tuple[float, int]]:
        """``{stage: (seconds, jobs)}`` over the succeeded jobs kept, from the index."""
        return self.index.stage_totals()

    def jobs_in_state(self, state: str) -> Iterator[JobRecord]:
        """Every job in ``state`` (the index finds them; only those records are read, and a job whose record
        is gone or has moved on meanwhile is skipped)."""
        for job_id in self.index.ids_in_state(state):
            job = self.job(job_id)
            if job is not None and job.state == state:
                yield job

    def batch_totals(self, batch_ids: Iterable[str]) -> dict[str, BatchTotals]:
        """Each batch's jobs summed (counts by state, progress, latest end), from the index: no job record is
        read, whatever the batches' sizes."""
        totals = {}
        for batch_id, counts in self.index.batch_counts(batch_ids).items():
            unended = [units for state, (_, units) in counts.states.items() if state not in TERMINAL_STATES]
            totals[batch_id] = BatchTotals(
                counts=dict.fromkeys(JOB_STATES, 0) | {state: jobs for state, (jobs, _) in counts.states.items()},
                progress_units=sum(unended), finished_at=counts.finished_at)
        return totals

    # ---------------------------------------------------------------- the index

    def _index_writer(self, kind: str) -> Callable[[dict | None, dict], None] | None:
        """What keeps the index in step with a write of a record of ``kind`` (None: not indexed)."""
        if kind == JobRecord.KIND:
            return self._reindex
        if kind in OWNED_KINDS:
            return lambda old, new: self._reindex_owned(kind, old, new)
        return None

    def _reindex(self, old: dict | None, new: dict) -> None:
        # under the job record's lock: the index changes in the order the record does. Writes that change none
        # of the indexed fields (heartbeats, and the progress of a job outside a batch) skip the index.
        row = index_row(JobRecord.model_validate(new))
        if old is not None and index_row(JobRecord.model_validate(old))._replace(updated_at=row.updated_at) == row:
            return
        self.index.put_job(row)

    def _reindex_owned(self, kind: str, old: dict | None, new: dict) -> None:
        row = owned_row(kind, new)
        if old is None or owned_row(kind, old) != row:
            self.index.put_owned(row)

    def _unindex(self, kind: str, record_id: str) -> None:
        """Drop the index row of a record that is gone (a no-op for kinds not indexed)."""
        if kind == JobRecord.KIND:
            self.index.drop_job(record_id)
        elif kind in OWNED_KINDS:
            self.index.drop_owned(kind, record_id)

    def _index_rows(self) -> Iterator[Row]:
        for document in self.storage.list_records(JobRecord.KIND):
            yield index_row(JobRecord.model_validate(document))
        for kind in OWNED_KINDS:
            for document in self.storage.list_records(kind):
                yield owned_row(kind, document)

    def rebuild_index(self) -> dict[str, int]:
        """Refill the record index from the records; rows indexed by kind."""
        return self.index.rebuild()

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
        the index rows of purged records (under their locks); files removed."""
        return self.storage.purge(older_than_seconds, removed=self._unindex)

    def sweep_orphans(self, grace_seconds: float) -> int:
        """Remove the blobs no record refers to that were not saved or read for ``grace_seconds``, keeping every
        blob saved since the start of a job still running (it records its outputs when it ends); blobs removed.

        The running jobs are found in the records the sweep reads (not the index: what is removed is decided
        on the truth)."""
        return self.storage.sweep_orphans(grace_seconds, kept_since=running_since)

    def sweep_orphans_if_due(self, grace_seconds: float, interval_seconds: float) -> int | None:
        """:meth:`sweep_orphans` at most every ``interval_seconds`` in a deployment; blobs removed, or None when it
        was not due."""
        due = self._clock_due(OrphanSweepClock, ORPHAN_CLOCK_ID, "last_sweep", interval_seconds)
        return self.sweep_orphans(grace_seconds) if due else None
