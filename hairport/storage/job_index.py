"""The job index: a small SQLite table in the storage that answers listings and counts without
reading the job records.

One row per job (id, owner, state, creation time, time of the last state change, and the
per-stage timings of jobs whose timings are summed); triggers keep two running tables in the
same transaction as every row change: jobs by (owner, state), and per-stage second totals.
So a page of an owner's jobs is an index range read (``O(log n + offset + limit)``), a total
or the counts by state one read of the running table (independent of the jobs kept).

The index is derived data: the records stay the truth. The caller writes a job's row under
the job record's lock after the record (:meth:`JobIndex.put`), drops the rows of purged jobs
(:meth:`JobIndex.drop`), and gives a ``source`` of rows rebuilt from the records, used when
the file is missing, was never filled, is corrupt, or a write to it failed (then a marker file
asks the next reader to rebuild). Rows are whole values (an upsert), never increments, so a
write replayed after a rebuild is harmless.

Deployment assumption (as for ``flock``, see :mod:`hairport.storage`): every process using the
storage runs on hosts where SQLite's locking works on that volume. WAL mode needs shared memory
between the processes, i.e. one host (a local disk or a Docker volume of one host). SQLite over
NFS is unsafe (its locks are unreliable there): a multi-host deployment over NFS must not use
this index as it is (see the README's architecture section).
"""

from __future__ import annotations

import contextlib
import fcntl
import logging
import os
import sqlite3
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import NamedTuple

from .layout import FILE_MODE, _unlink

log = logging.getLogger(__name__)

#: the index file, under the storage root
INDEX_FILE = "index/jobs.sqlite3"
#: schema version: a file of another version is rebuilt
SCHEMA_VERSION = "1"
#: seconds a write waits for another process's transaction (a rebuild of 10^5 records takes a few)
BUSY_TIMEOUT_SECONDS = 60.0
#: microseconds per second: creation times are kept as integer µs so that order is exact
MICROSECONDS = 1_000_000

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta(key TEXT PRIMARY KEY, value TEXT NOT NULL) WITHOUT ROWID;
CREATE TABLE IF NOT EXISTS jobs(
    id TEXT PRIMARY KEY, owner TEXT NOT NULL, state TEXT NOT NULL, created_us INTEGER NOT NULL,
    updated_at REAL NOT NULL, timings TEXT) WITHOUT ROWID;
CREATE INDEX IF NOT EXISTS jobs_by_owner ON jobs(owner, created_us, id);
CREATE INDEX IF NOT EXISTS jobs_by_owner_state ON jobs(owner, state, created_us, id);
CREATE INDEX IF NOT EXISTS jobs_by_state ON jobs(state);
CREATE TABLE IF NOT EXISTS counts(owner TEXT, state TEXT, jobs INTEGER NOT NULL, PRIMARY KEY(owner, state))
    WITHOUT ROWID;
CREATE TABLE IF NOT EXISTS stage_totals(stage TEXT PRIMARY KEY, seconds REAL NOT NULL, jobs INTEGER NOT NULL)
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
"""


class IndexRow(NamedTuple):
    """What the index keeps of a job: ``timings`` (JSON text of ``{stage: seconds}``) only for jobs
    whose stage times are summed (e.g. succeeded ones), else None."""

    id: str
    owner: str
    state: str
    created_at: float
    updated_at: float
    timings: str | None = None


class JobIndex:
    """The job index of one storage (``root/index/jobs.sqlite3``); safe between threads and processes.

    Parameters
    ----------
    root : Path
        The storage root.
    source : callable
        Every job's :class:`IndexRow`, read from the records (for a rebuild).
    durable : bool
        Commit with ``synchronous=FULL`` (a committed change survives a power loss, as the
        records do); off for tests and throwaway stores.
    """

    def __init__(self, root: Path, source: Callable[[], Iterable[IndexRow]], *, durable: bool = True):
        self.path = Path(root) / INDEX_FILE
        self.stale_marker = self.path.with_name(self.path.name + ".stale")
        self.rebuild_lock = self.path.with_name(self.path.name + ".lock")
        self.source = source
        self.durable = durable
        self._local = threading.local()

    # ------------------------------------------------------------------ writes

    def put(self, row: IndexRow) -> None:
        """Insert or replace a job's row (under the job record's lock: rows of one job are written in order)."""
        self._write("INSERT INTO jobs VALUES (?, ?, ?, ?, ?, ?) ON CONFLICT(id) DO UPDATE SET owner = excluded.owner, "
                    "state = excluded.state, created_us = excluded.created_us, updated_at = excluded.updated_at, "
                    "timings = excluded.timings", _values(row))

    def drop(self, job_id: str) -> None:
        """Remove a job's row (its record was purged or deleted)."""
        self._write("DELETE FROM jobs WHERE id = ?", (job_id,))

    def _write(self, sql: str, values: tuple) -> None:
        # the record is written already: a failed index write must not fail the caller's change, so
        # it marks the index for a rebuild instead (the next read rebuilds from the records)
        try:
            with self._transaction() as db:
                db.execute(sql, values)
        except sqlite3.Error as error:
            log.error("job index write failed (%s): it will be rebuilt from the records", error)
            self._mark_stale()

    # ------------------------------------------------------------------ reads

    def page(self, owner: str, state: str | None, limit: int, offset: int) -> tuple[list[str], int]:
        """Ids of ``owner``'s jobs newest first (optionally in ``state``): the page and the total."""
        if state is None:
            ids = "SELECT id FROM jobs WHERE owner = ? ORDER BY created_us DESC, id DESC LIMIT ? OFFSET ?"
            total = "SELECT coalesce(sum(jobs), 0) FROM counts WHERE owner = ?"
            where = (owner,)
        else:
            ids = ("SELECT id FROM jobs WHERE owner = ? AND state = ? ORDER BY created_us DESC, id DESC "
                   "LIMIT ? OFFSET ?")
            total = "SELECT coalesce(sum(jobs), 0) FROM counts WHERE owner = ? AND state = ?"
            where = (owner, state)

        def read(db: sqlite3.Connection) -> tuple[list[str], int]:
            db.execute("BEGIN")  # one read transaction: the page and the total of one snapshot
            try:
                page = [row[0] for row in db.execute(ids, (*where, limit, offset))]
                return page, db.execute(total, where).fetchone()[0]
            finally:
                db.execute("COMMIT")

        return self._read(read)

    def counts(self) -> dict[str, int]:
        """Jobs by state over every owner (states with no job are absent or 0)."""
        return self._read(lambda db: dict(db.execute("SELECT state, sum(jobs) FROM counts GROUP BY state")))

    def stage_totals(self) -> dict[str, tuple[float, int]]:
        """``{stage: (seconds, jobs)}`` summed over the rows that have timings."""
        return self._read(lambda db: {stage: (seconds, jobs) for stage, seconds, jobs in db.execute(
            "SELECT stage, seconds, jobs FROM stage_totals WHERE jobs > 0")})

    def ids_in_state(self, state: str) -> list[str]:
        """Ids of every job in ``state``."""
        return self._read(lambda db: [row[0] for row in db.execute("SELECT id FROM jobs WHERE state = ?", (state,))])

    def rows(self) -> list[IndexRow]:
        """Every row (for tests and checks), by id."""
        return self._read(lambda db: [
            IndexRow(id, owner, state, created_us / MICROSECONDS, updated_at, timings)
            for id, owner, state, created_us, updated_at, timings in db.execute("SELECT * FROM jobs ORDER BY id")])

    def _read(self, query: Callable[[sqlite3.Connection], object]):
        try:
            if self.stale_marker.exists():
                self.rebuild(only_if_stale=True)
            return query(self._connection())
        except sqlite3.OperationalError:  # busy past the timeout, or the disk: not the file's fault
            raise
        except sqlite3.DatabaseError as error:  # a corrupt or foreign file: rebuilt from the records, once
            log.error("job index unreadable (%s): rebuilding it from the records", error)
            self._recover()
            return query(self._connection())

    # ------------------------------------------------------------------ rebuild

    def rebuild(self, only_if_stale: bool = False) -> int:
        """Refill the index from the records in one transaction (writers wait for it); rows written.

        ``only_if_stale``: do nothing unless a failed write marked the index (checked once this process
        holds the write lock, so that processes finding the marker together rebuild once)."""
        with self._transaction() as db:
            if only_if_stale and not self.stale_marker.exists():
                return 0
            _unlink(self.stale_marker)  # a write failing from now on marks it again
            db.execute("DELETE FROM jobs")
            db.execute("DELETE FROM counts")
            db.execute("DELETE FROM stage_totals")
            count = 0
            for row in self.source():
                db.execute("INSERT OR REPLACE INTO jobs VALUES (?, ?, ?, ?, ?, ?)", _values(row))
                count += 1
            db.execute("INSERT OR REPLACE INTO meta VALUES ('built_at', ?)", (repr(time.time()),))
        log.info("job index rebuilt from %d job records", count)
        return count

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


def _values(row: IndexRow) -> tuple:
    return (row.id, row.owner, row.state, round(row.created_at * MICROSECONDS), row.updated_at, row.timings)


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
