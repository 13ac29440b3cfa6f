"""The record index: small SQL tables in the storage that answer listings, totals and counts without
reading the records.

What it keeps:

* one row per job (id, owner, state, creation time, time of the last indexed change, the stage timings
  of jobs whose timings are summed, and for a job of a batch its batch, progress and end time);
* one row per record of the other listed kinds (characters, hairstyles, batches): kind, id, owner,
  creation time;
* running tables, kept by triggers in the same transaction as every row change: jobs by (owner,
  state), per-stage second totals, jobs and summed progress by (batch, state), and records by
  (kind, owner).

So a page of an owner's jobs or records is an index range read (``O(log n + offset + limit)``), its
total one read of a running table, and a batch's counts by state, progress and end a few reads,
whatever the number of records, owners and jobs per batch.

The index is derived data: the records stay the truth. The caller writes a record's row under the
record's lock after the record (``put_*``), drops the rows of purged or deleted records (``drop_*``),
and gives a ``source`` of every row, read from the records, for a rebuild. The index is rebuilt when
its file is missing, was never filled, is corrupt, or a write to it failed (a marker file asks the next
reader to rebuild). Rows are whole values (an upsert), never increments, so a write replayed after a
rebuild is harmless.

:class:`Index` is the interface the repository uses; :class:`SqliteIndex` implements it in a SQLite
file of the storage (``root/index/records.sqlite3``). The queries are plain SQL (``INSERT ... ON
CONFLICT DO UPDATE``, ``LIMIT ... OFFSET``, ``IN``, ``max``) that PostgreSQL runs as they are (with
``%s`` placeholders); the SQLite-specific parts are the DDL (``WITHOUT ROWID``), the triggers (in
PostgreSQL, trigger functions or one statement per change in the same transaction) and ``json_each``
of the stage totals (``jsonb_each``).

Deployment assumption (as for ``flock``, see :mod:`hairport.storage`): every process using the
storage runs on hosts where SQLite's locking works on that volume. WAL mode needs shared memory
between the processes, i.e. one host (a local disk or a Docker volume of one host). SQLite over
NFS is unsafe (its locks are unreliable there): a multi-host deployment over NFS must not use
this index as it is (see docs/operations.md, several hosts).
"""

from __future__ import annotations

import contextlib
import fcntl
import logging
import os
import sqlite3
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import NamedTuple, Protocol

from .layout import FILE_MODE, _unlink

log = logging.getLogger(__name__)

#: the index file, under the storage root
INDEX_FILE = "index/records.sqlite3"
#: schema version: a file of another version is rebuilt
SCHEMA_VERSION = "1"
#: seconds a write waits for another process's transaction (a rebuild of 10^5 records takes a few)
BUSY_TIMEOUT_SECONDS = 60.0
#: microseconds per second: creation times are kept as integer µs so that order is exact
MICROSECONDS = 1_000_000
#: ids per ``IN (...)`` list: below SQLite's oldest limit of bound parameters (999)
IDS_PER_QUERY = 500
#: the name :meth:`SqliteIndex.rebuild` counts job rows under
JOBS = "jobs"

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta(key TEXT PRIMARY KEY, value TEXT NOT NULL) WITHOUT ROWID;
CREATE TABLE IF NOT EXISTS jobs(
    id TEXT PRIMARY KEY, owner TEXT NOT NULL, state TEXT NOT NULL, created_us INTEGER NOT NULL,
    updated_at REAL NOT NULL, timings TEXT, batch_id TEXT, progress_units INTEGER NOT NULL, finished_at REAL)
    WITHOUT ROWID;
CREATE INDEX IF NOT EXISTS jobs_by_owner ON jobs(owner, created_us, id);
CREATE INDEX IF NOT EXISTS jobs_by_owner_state ON jobs(owner, state, created_us, id);
CREATE INDEX IF NOT EXISTS jobs_by_state ON jobs(state);
CREATE INDEX IF NOT EXISTS jobs_by_batch ON jobs(batch_id, finished_at) WHERE batch_id IS NOT NULL;
CREATE TABLE IF NOT EXISTS counts(owner TEXT, state TEXT, jobs INTEGER NOT NULL, PRIMARY KEY(owner, state))
    WITHOUT ROWID;
CREATE TABLE IF NOT EXISTS stage_totals(stage TEXT PRIMARY KEY, seconds REAL NOT NULL, jobs INTEGER NOT NULL)
    WITHOUT ROWID;
CREATE TABLE IF NOT EXISTS batch_counts(batch_id TEXT, state TEXT, jobs INTEGER NOT NULL,
    progress_units INTEGER NOT NULL, PRIMARY KEY(batch_id, state)) WITHOUT ROWID;
CREATE TABLE IF NOT EXISTS owned(kind TEXT, id TEXT, owner TEXT NOT NULL, created_us INTEGER NOT NULL,
    PRIMARY KEY(kind, id)) WITHOUT ROWID;
CREATE INDEX IF NOT EXISTS owned_by_owner ON owned(kind, owner, created_us, id);
CREATE TABLE IF NOT EXISTS owned_counts(kind TEXT, owner TEXT, records INTEGER NOT NULL, PRIMARY KEY(kind, owner))
    WITHOUT ROWID;
CREATE TRIGGER IF NOT EXISTS jobs_added AFTER INSERT ON jobs BEGIN
    INSERT INTO counts VALUES (NEW.owner, NEW.state, 1) ON CONFLICT DO UPDATE SET jobs = jobs + 1;
    INSERT INTO stage_totals SELECT key, value, 1 FROM json_each(NEW.timings) WHERE type IN ('real', 'integer')
        ON CONFLICT DO UPDATE SET seconds = seconds + excluded.seconds, jobs = jobs + 1;
END;
CREATE TRIGGER IF NOT EXISTS jobs_removed AFTER DELETE ON jobs BEGIN
    UPDATE counts SET jobs = jobs - 1 WHERE owner = OLD.owner AND state = OLD.state;
    UPDATE stage_totals SET seconds = seconds - (SELECT value FROM json_each(OLD.timings) WHERE key = stage),
        jobs = jobs - 1 WHERE stage IN (SELECT key FROM json_each(OLD.timings) WHERE type IN ('real', 'integer'));
END;
CREATE TRIGGER IF NOT EXISTS jobs_changed AFTER UPDATE OF owner, state, timings ON jobs BEGIN
    UPDATE counts SET jobs = jobs - 1 WHERE owner = OLD.owner AND state = OLD.state;
    INSERT INTO counts VALUES (NEW.owner, NEW.state, 1) ON CONFLICT DO UPDATE SET jobs = jobs + 1;
    UPDATE stage_totals SET seconds = seconds - (SELECT value FROM json_each(OLD.timings) WHERE key = stage),
        jobs = jobs - 1 WHERE stage IN (SELECT key FROM json_each(OLD.timings) WHERE type IN ('real', 'integer'));
    INSERT INTO stage_totals SELECT key, value, 1 FROM json_each(NEW.timings) WHERE type IN ('real', 'integer')
        ON CONFLICT DO UPDATE SET seconds = seconds + excluded.seconds, jobs = jobs + 1;
END;
CREATE TRIGGER IF NOT EXISTS batch_job_added AFTER INSERT ON jobs WHEN NEW.batch_id IS NOT NULL BEGIN
    INSERT INTO batch_counts VALUES (NEW.batch_id, NEW.state, 1, NEW.progress_units)
        ON CONFLICT DO UPDATE SET jobs = jobs + 1, progress_units = progress_units + excluded.progress_units;
END;
CREATE TRIGGER IF NOT EXISTS batch_job_removed AFTER DELETE ON jobs WHEN OLD.batch_id IS NOT NULL BEGIN
    UPDATE batch_counts SET jobs = jobs - 1, progress_units = progress_units - OLD.progress_units
        WHERE batch_id = OLD.batch_id AND state = OLD.state;
    DELETE FROM batch_counts WHERE batch_id = OLD.batch_id AND state = OLD.state AND jobs = 0;
END;
CREATE TRIGGER IF NOT EXISTS batch_job_changed AFTER UPDATE OF batch_id, state, progress_units ON jobs BEGIN
    UPDATE batch_counts SET jobs = jobs - 1, progress_units = progress_units - OLD.progress_units
        WHERE batch_id = OLD.batch_id AND state = OLD.state;
    DELETE FROM batch_counts WHERE batch_id = OLD.batch_id AND state = OLD.state AND jobs = 0;
    INSERT INTO batch_counts SELECT NEW.batch_id, NEW.state, 1, NEW.progress_units WHERE NEW.batch_id IS NOT NULL
        ON CONFLICT DO UPDATE SET jobs = jobs + 1, progress_units = progress_units + excluded.progress_units;
END;
CREATE TRIGGER IF NOT EXISTS owned_added AFTER INSERT ON owned BEGIN
    INSERT INTO owned_counts VALUES (NEW.kind, NEW.owner, 1) ON CONFLICT DO UPDATE SET records = records + 1;
END;
CREATE TRIGGER IF NOT EXISTS owned_removed AFTER DELETE ON owned BEGIN
    UPDATE owned_counts SET records = records - 1 WHERE kind = OLD.kind AND owner = OLD.owner;
END;
CREATE TRIGGER IF NOT EXISTS owned_changed AFTER UPDATE OF kind, owner ON owned BEGIN
    UPDATE owned_counts SET records = records - 1 WHERE kind = OLD.kind AND owner = OLD.owner;
    INSERT INTO owned_counts VALUES (NEW.kind, NEW.owner, 1) ON CONFLICT DO UPDATE SET records = records + 1;
END;
"""

#: the tables a rebuild empties (the running tables included: refilled by the triggers)
_DATA_TABLES = ("jobs", "counts", "stage_totals", "batch_counts", "owned", "owned_counts")


class JobRow(NamedTuple):
    """What the index keeps of a job. ``timings`` (JSON text of ``{stage: seconds}``) only for jobs whose
    stage times are summed (e.g. succeeded ones), else None; ``batch_id``, ``progress_units`` (the
    progress as an integer, so that sums are exact) and ``finished_at`` feed the batch totals."""

    id: str
    owner: str
    state: str
    created_at: float
    updated_at: float
    timings: str | None = None
    batch_id: str | None = None
    progress_units: int = 0
    finished_at: float | None = None


class OwnedRow(NamedTuple):
    """What the index keeps of a listed record that is not a job: its kind, id, owner and creation time."""

    kind: str
    id: str
    owner: str
    created_at: float


class BatchCounts(NamedTuple):
    """A batch's jobs as the index sums them: ``{state: (jobs, progress units)}`` and the latest ``finished_at``."""

    states: dict[str, tuple[int, int]]
    finished_at: float | None


Row = JobRow | OwnedRow


class Index(Protocol):
    """The record index the repository uses (:class:`SqliteIndex`; a PostgreSQL one would implement the same).

    Writes run under the record's lock, after the record was written, and never fail the caller: an
    index that could not be written rebuilds itself from the records before its next read."""

    def put_job(self, row: JobRow) -> None:
        """Insert or replace a job's row."""

    def put_owned(self, row: OwnedRow) -> None:
        """Insert or replace a listed record's row."""

    def drop_job(self, job_id: str) -> None:
        """Remove a job's row (its record was purged or deleted)."""

    def drop_owned(self, kind: str, record_id: str) -> None:
        """Remove a listed record's row."""

    def job_page(self, owner: str, state: str | None, limit: int, offset: int) -> tuple[list[str], int]:
        """Ids of ``owner``'s jobs newest first (optionally in ``state``): the page and the total."""

    def owned_page(self, kind: str, owner: str, limit: int, offset: int) -> tuple[list[str], int]:
        """Ids of ``owner``'s records of ``kind`` newest first: the page and the total."""

    def job_counts(self) -> dict[str, int]:
        """Jobs by state over every owner (states with no job are absent or 0)."""

    def stage_totals(self) -> dict[str, tuple[float, int]]:
        """``{stage: (seconds, jobs)}`` summed over the job rows that have timings."""

    def ids_in_state(self, state: str) -> list[str]:
        """Ids of every job in ``state``."""

    def batch_counts(self, batch_ids: Iterable[str]) -> dict[str, BatchCounts]:
        """Each batch's jobs by state with their summed progress, and its latest end (every id asked for)."""

    def rebuild(self) -> dict[str, int]:
        """Refill the index from the records; rows written by kind (jobs under :data:`JOBS`)."""


class SqliteIndex:
    """The :class:`Index` of one storage in ``root/index/records.sqlite3``; safe between threads and processes.

    Parameters
    ----------
    root : Path
        The storage root.
    source : callable
        Every :class:`JobRow` and :class:`OwnedRow`, read from the records (for a rebuild).
    durable : bool
        Commit with ``synchronous=FULL`` (a committed change survives a power loss, as the
        records do); off for tests and throwaway stores.
    """

    def __init__(self, root: Path, source: Callable[[], Iterable[Row]], *, durable: bool = True):
        self.path = Path(root) / INDEX_FILE
        self.stale_marker = self.path.with_name(self.path.name + ".stale")
        self.rebuild_lock = self.path.with_name(self.path.name + ".lock")
        self.source = source
        self.durable = durable
        self._local = threading.local()

    # ------------------------------------------------------------------ writes

    def put_job(self, row: JobRow) -> None:
        self._write("INSERT INTO jobs VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?) ON CONFLICT(id) DO UPDATE SET "
                    "owner = excluded.owner, state = excluded.state, created_us = excluded.created_us, "
                    "updated_at = excluded.updated_at, timings = excluded.timings, batch_id = excluded.batch_id, "
                    "progress_units = excluded.progress_units, finished_at = excluded.finished_at", _job_values(row))

    def put_owned(self, row: OwnedRow) -> None:
        self._write("INSERT INTO owned VALUES (?, ?, ?, ?) ON CONFLICT(kind, id) DO UPDATE SET "
                    "owner = excluded.owner, created_us = excluded.created_us", _owned_values(row))

    def drop_job(self, job_id: str) -> None:
        self._write("DELETE FROM jobs WHERE id = ?", (job_id,))

    def drop_owned(self, kind: str, record_id: str) -> None:
        self._write("DELETE FROM owned WHERE kind = ? AND id = ?", (kind, record_id))

    def _write(self, sql: str, values: tuple) -> None:
        # the record is written already: a failed index write must not fail the caller's change, so
        # it marks the index for a rebuild instead (the next read rebuilds from the records)
        try:
            with self._transaction() as db:
                db.execute(sql, values)
        except sqlite3.Error as error:
            log.error("record index write failed (%s): it will be rebuilt from the records", error)
            self._mark_stale()

    # ------------------------------------------------------------------ reads

    def job_page(self, owner: str, state: str | None, limit: int, offset: int) -> tuple[list[str], int]:
        if state is None:
            return self._page("SELECT id FROM jobs WHERE owner = ? ORDER BY created_us DESC, id DESC LIMIT ? OFFSET ?",
                              "SELECT coalesce(sum(jobs), 0) FROM counts WHERE owner = ?", (owner,), limit, offset)
        return self._page("SELECT id FROM jobs WHERE owner = ? AND state = ? ORDER BY created_us DESC, id DESC "
                          "LIMIT ? OFFSET ?", "SELECT coalesce(sum(jobs), 0) FROM counts WHERE owner = ? AND state = ?",
                          (owner, state), limit, offset)

    def owned_page(self, kind: str, owner: str, limit: int, offset: int) -> tuple[list[str], int]:
        return self._page("SELECT id FROM owned WHERE kind = ? AND owner = ? ORDER BY created_us DESC, id DESC "
                          "LIMIT ? OFFSET ?", "SELECT coalesce(sum(records), 0) FROM owned_counts "
                          "WHERE kind = ? AND owner = ?", (kind, owner), limit, offset)

    def _page(self, ids: str, total: str, where: tuple, limit: int, offset: int) -> tuple[list[str], int]:
        def read(db: sqlite3.Connection) -> tuple[list[str], int]:
            page = [row[0] for row in db.execute(ids, (*where, limit, offset))]
            return page, db.execute(total, where).fetchone()[0]

        return self._read(read)

    def job_counts(self) -> dict[str, int]:
        return self._read(lambda db: dict(db.execute("SELECT state, sum(jobs) FROM counts GROUP BY state")))

    def stage_totals(self) -> dict[str, tuple[float, int]]:
        return self._read(lambda db: {stage: (seconds, jobs) for stage, seconds, jobs in db.execute(
            "SELECT stage, seconds, jobs FROM stage_totals WHERE jobs > 0")})

    def ids_in_state(self, state: str) -> list[str]:
        return self._read(lambda db: [row[0] for row in db.execute("SELECT id FROM jobs WHERE state = ?", (state,))])

    def batch_counts(self, batch_ids: Iterable[str]) -> dict[str, BatchCounts]:
        wanted = list(dict.fromkeys(batch_ids))

        def read(db: sqlite3.Connection) -> dict[str, BatchCounts]:
            states: dict[str, dict[str, tuple[int, int]]] = {batch_id: {} for batch_id in wanted}
            for start in range(0, len(wanted), IDS_PER_QUERY):
                chunk = wanted[start:start + IDS_PER_QUERY]
                for batch_id, state, jobs, units in db.execute(
                        "SELECT batch_id, state, jobs, progress_units FROM batch_counts WHERE jobs > 0 AND batch_id IN "
                        f"({', '.join('?' * len(chunk))})", chunk):
                    states[batch_id][state] = (jobs, units)
            # one index seek per batch (jobs_by_batch ends with finished_at): the same for 10 jobs or 10^4
            return {batch_id: BatchCounts(counts, db.execute(
                "SELECT max(finished_at) FROM jobs WHERE batch_id = ?", (batch_id,)).fetchone()[0])
                for batch_id, counts in states.items()}

        return self._read(read)

    def job_rows(self) -> list[JobRow]:
        """Every job row (for tests and checks), by id."""
        return self._read(lambda db: [
            JobRow(id, owner, state, created_us / MICROSECONDS, *rest)
            for id, owner, state, created_us, *rest in db.execute("SELECT * FROM jobs ORDER BY id")])

    def owned_rows(self) -> list[OwnedRow]:
        """Every row of the other listed kinds (for tests and checks), by kind and id."""
        return self._read(lambda db: [
            OwnedRow(kind, id, owner, created_us / MICROSECONDS)
            for kind, id, owner, created_us in db.execute("SELECT * FROM owned ORDER BY kind, id")])

    def _read(self, query: Callable[[sqlite3.Connection], object]):
        """``query`` in one read transaction (every figure of one answer from one snapshot)."""
        try:
            if self.stale_marker.exists():
                self.rebuild(only_if_stale=True)
            return _snapshot(self._connection(), query)
        except sqlite3.OperationalError:  # busy past the timeout, or the disk: not the file's fault
            raise
        except sqlite3.DatabaseError as error:  # a corrupt or foreign file: rebuilt from the records, once
            log.error("record index unreadable (%s): rebuilding it from the records", error)
            self._recover()
            return _snapshot(self._connection(), query)

    # ------------------------------------------------------------------ rebuild

    def rebuild(self, only_if_stale: bool = False) -> dict[str, int]:
        """Refill the index from the records in one transaction (writers wait for it); rows written by kind.

        ``only_if_stale``: do nothing unless a failed write marked the index (checked once this process
        holds the write lock, so that processes finding the marker together rebuild once)."""
        written: Counter = Counter()
        with self._transaction() as db:
            if only_if_stale and not self.stale_marker.exists():
                return {}
            _unlink(self.stale_marker)  # a write failing from now on marks it again
            for table in _DATA_TABLES:
                db.execute(f"DELETE FROM {table}")
            for row in self.source():
                if isinstance(row, JobRow):
                    db.execute("INSERT OR REPLACE INTO jobs VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)", _job_values(row))
                    written[JOBS] += 1
                else:
                    db.execute("INSERT OR REPLACE INTO owned VALUES (?, ?, ?, ?)", _owned_values(row))
                    written[row.kind] += 1
            db.execute("INSERT OR REPLACE INTO meta VALUES ('built_at', ?)", (repr(time.time()),))
        log.info("record index rebuilt from the records: %s", dict(written) or "none")
        return dict(written)

    def _recover(self) -> None:
        """Move an unreadable file aside (once, between processes) and rebuild a new one."""
        with self._rebuild_lock():
            self._close()
            try:
                self._connection().execute("SELECT count(*) FROM meta").fetchone()
                return  # another process recovered it meanwhile
            except sqlite3.DatabaseError:
                self._close()
            for suffix in ("", "-wal", "-shm"):
                with contextlib.suppress(FileNotFoundError):
                    os.replace(f"{self.path}{suffix}", f"{self.path}.corrupt{suffix}")
        self._connection()

    # ------------------------------------------------------------------ connections

    def _connection(self) -> sqlite3.Connection:
        """This thread's connection, opened (and the file created, or rebuilt if never filled) on first use,
        and opened again after a fork or when the file was replaced."""
        local = self._local
        db = getattr(local, "db", None)
        if db is not None:
            try:
                same = os.stat(self.path).st_ino == local.inode and local.pid == os.getpid()
            except FileNotFoundError:
                same = False
            if same:
                return db
            self._close()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if not self.path.exists():  # create it with the storage's file mode (sqlite would use 0o644)
            with contextlib.suppress(FileExistsError):
                os.close(os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, FILE_MODE))
        db = sqlite3.connect(self.path, timeout=BUSY_TIMEOUT_SECONDS, isolation_level=None, check_same_thread=False)
        try:
            db.execute("PRAGMA journal_mode=WAL")
            db.execute(f"PRAGMA synchronous={'FULL' if self.durable else 'OFF'}")
            local.db, local.inode, local.pid = db, os.stat(self.path).st_ino, os.getpid()
        except BaseException:
            db.close()
            raise
        self._ensure_schema(db)
        return db

    def _ensure_schema(self, db: sqlite3.Connection) -> None:
        version = None
        with contextlib.suppress(sqlite3.OperationalError):  # no meta table yet
            row = db.execute("SELECT value FROM meta WHERE key = 'schema'").fetchone()
            built = db.execute("SELECT value FROM meta WHERE key = 'built_at'").fetchone()
            version = row[0] if row and built else None
        if version == SCHEMA_VERSION:
            return
        with self._transaction(db) as db:
            row = None
            with contextlib.suppress(sqlite3.OperationalError):
                row = db.execute("SELECT value FROM meta WHERE key = 'schema'").fetchone()
            if row is not None and row[0] != SCHEMA_VERSION:  # another layout: start again
                for kind, name in db.execute("SELECT type, name FROM sqlite_master WHERE type IN ('table', 'trigger') "
                                             "AND name NOT LIKE 'sqlite_%'").fetchall():
                    db.execute(f"DROP {kind} IF EXISTS {name}")
            for statement in _statements(_SCHEMA):
                db.execute(statement)
            db.execute("INSERT OR REPLACE INTO meta VALUES ('schema', ?)", (SCHEMA_VERSION,))
            built = db.execute("SELECT value FROM meta WHERE key = 'built_at'").fetchone()
        if built is None:  # a new (or emptied) file: filled from the records by the first process here
            self.rebuild()

    @contextlib.contextmanager
    def _transaction(self, db: sqlite3.Connection | None = None) -> Iterator[sqlite3.Connection]:
        """A write transaction (``BEGIN IMMEDIATE``: waits for other writers up to the busy timeout)."""
        db = db or self._connection()
        db.execute("BEGIN IMMEDIATE")
        try:
            yield db
        except BaseException:
            db.execute("ROLLBACK")
            raise
        db.execute("COMMIT")

    @contextlib.contextmanager
    def _rebuild_lock(self) -> Iterator[None]:
        fd = os.open(self.rebuild_lock, os.O_RDWR | os.O_CREAT, FILE_MODE)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            yield
        finally:
            os.close(fd)

    def _mark_stale(self) -> None:
        with contextlib.suppress(OSError):
            os.close(os.open(self.stale_marker, os.O_WRONLY | os.O_CREAT, FILE_MODE))

    def _close(self) -> None:
        db = getattr(self._local, "db", None)
        self._local.db = None
        if db is not None:
            with contextlib.suppress(sqlite3.Error):
                db.close()


def _snapshot(db: sqlite3.Connection, query: Callable[[sqlite3.Connection], object]):
    db.execute("BEGIN")
    try:
        return query(db)
    finally:
        db.execute("COMMIT")


def _job_values(row: JobRow) -> tuple:
    return (row.id, row.owner, row.state, _microseconds(row.created_at), row.updated_at, row.timings, row.batch_id,
            row.progress_units, row.finished_at)


def _owned_values(row: OwnedRow) -> tuple:
    return row.kind, row.id, row.owner, _microseconds(row.created_at)


def _microseconds(seconds: float) -> int:
    return round(seconds * MICROSECONDS)


def _statements(script: str) -> list[str]:
    """The statements of a schema script (triggers hold ``;`` inside ``BEGIN ... END``)."""
    statements, current = [], []
    for line in script.strip().splitlines():
        current.append(line)
        text = "\n".join(current).strip()
        if text.endswith(";") and sqlite3.complete_statement(text):
            statements.append(text)
            current = []
    return statements
