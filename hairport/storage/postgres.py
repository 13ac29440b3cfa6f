"""Records and their index in a PostgreSQL database (``HAIRPORT_DATABASE_URL=postgresql://...``).

:class:`PostgresRecords` keeps every record as a row ``(kind, id, document, written_at)`` and answers
the methods of :class:`~.documents.FolderRecords`: a read-modify-write is one transaction holding the
row (``SELECT ... FOR UPDATE``), so API processes and workers on any number of hosts change a job one
at a time. :class:`PostgresIndex` is the record index of :mod:`.index` in the same database: the same
tables, with the running totals kept by trigger functions, written in the record's own transaction
(a record and its index row change together or not at all).

:class:`Database` owns the connections (one per thread and process) and runs each unit of work as a
transaction, again when PostgreSQL aborts it for a deadlock or a serialization failure; a server that
cannot be reached raises :class:`~.objects.StorageUnavailable` (a ``ConnectionError``: the API answers
503, a worker's task is retried). The schema has a version (``hairport_schema``); :func:`upgrade`
brings a database to :data:`SCHEMA_VERSION` step by step (``hairport db upgrade``), and a process
refuses a database of another version instead of writing into it.
"""

from __future__ import annotations

import json
import logging
import math
import os
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable, Iterator

import psycopg
from psycopg import errors as pg_errors

from .documents import Written, record_text
from .index import IDS_PER_QUERY, JOBS, BatchCounts, JobRow, OwnedRow, Row, _job_values, _owned_values
from .layout import blob_references, check_name
from .objects import StorageUnavailable

log = logging.getLogger(__name__)

#: the schema this version of hairport reads and writes
SCHEMA_VERSION = 1
#: seconds to wait for a connection to the server
CONNECT_TIMEOUT_SECONDS = 5
#: times a unit of work runs when PostgreSQL aborts it for a deadlock or a serialization failure
TRANSACTION_ATTEMPTS = 5
#: records read per round trip when listing or scanning
FETCH_ROWS = 500

#: the schema, one list of statements per version (a version's statements bring the previous one to it)
MIGRATIONS: dict[int, list[str]] = {1: [
    """CREATE TABLE records(kind text NOT NULL, id text NOT NULL, document text NOT NULL,
           written_at double precision NOT NULL, PRIMARY KEY (kind, id))""",
    "CREATE INDEX records_by_written ON records(written_at)",
    """CREATE TABLE jobs(id text PRIMARY KEY, owner text NOT NULL, state text NOT NULL, created_us bigint NOT NULL,
           updated_at double precision NOT NULL, timings jsonb, batch_id text, progress_units bigint NOT NULL,
           finished_at double precision)""",
    "CREATE INDEX jobs_by_owner ON jobs(owner, created_us, id)",
    "CREATE INDEX jobs_by_owner_state ON jobs(owner, state, created_us, id)",
    "CREATE INDEX jobs_by_state ON jobs(state)",
    "CREATE INDEX jobs_by_batch ON jobs(batch_id, finished_at) WHERE batch_id IS NOT NULL",
    "CREATE TABLE counts(owner text, state text, jobs bigint NOT NULL, PRIMARY KEY (owner, state))",
    "CREATE TABLE stage_totals(stage text PRIMARY KEY, seconds double precision NOT NULL, jobs bigint NOT NULL)",
    """CREATE TABLE batch_counts(batch_id text, state text, jobs bigint NOT NULL, progress_units bigint NOT NULL,
           PRIMARY KEY (batch_id, state))""",
    """CREATE TABLE owned(kind text, id text, owner text NOT NULL, created_us bigint NOT NULL,
           PRIMARY KEY (kind, id))""",
    "CREATE INDEX owned_by_owner ON owned(kind, owner, created_us, id)",
    "CREATE TABLE owned_counts(kind text, owner text, records bigint NOT NULL, PRIMARY KEY (kind, owner))",
    """CREATE FUNCTION jobs_totals() RETURNS trigger LANGUAGE plpgsql AS $$
    BEGIN
        IF TG_OP IN ('UPDATE', 'DELETE') THEN
            UPDATE counts SET jobs = jobs - 1 WHERE owner = OLD.owner AND state = OLD.state;
            UPDATE stage_totals AS s SET seconds = s.seconds - t.value::double precision, jobs = s.jobs - 1
                FROM jsonb_each(coalesce(OLD.timings, '{}'::jsonb)) AS t
                WHERE s.stage = t.key AND jsonb_typeof(t.value) = 'number';
            IF OLD.batch_id IS NOT NULL THEN
                UPDATE batch_counts SET jobs = jobs - 1, progress_units = progress_units - OLD.progress_units
                    WHERE batch_id = OLD.batch_id AND state = OLD.state;
                DELETE FROM batch_counts WHERE batch_id = OLD.batch_id AND state = OLD.state AND jobs = 0;
            END IF;
        END IF;
        IF TG_OP IN ('INSERT', 'UPDATE') THEN
            INSERT INTO counts VALUES (NEW.owner, NEW.state, 1)
                ON CONFLICT (owner, state) DO UPDATE SET jobs = counts.jobs + 1;
            INSERT INTO stage_totals
                SELECT t.key, t.value::double precision, 1 FROM jsonb_each(coalesce(NEW.timings, '{}'::jsonb)) AS t
                WHERE jsonb_typeof(t.value) = 'number'
                ON CONFLICT (stage) DO UPDATE SET seconds = stage_totals.seconds + excluded.seconds,
                    jobs = stage_totals.jobs + 1;
            IF NEW.batch_id IS NOT NULL THEN
                INSERT INTO batch_counts VALUES (NEW.batch_id, NEW.state, 1, NEW.progress_units)
                    ON CONFLICT (batch_id, state) DO UPDATE SET jobs = batch_counts.jobs + 1,
                        progress_units = batch_counts.progress_units + excluded.progress_units;
            END IF;
        END IF;
        RETURN NULL;
    END $$""",
    "CREATE TRIGGER jobs_totals AFTER INSERT OR UPDATE OR DELETE ON jobs FOR EACH ROW EXECUTE FUNCTION jobs_totals()",
    """CREATE FUNCTION owned_totals() RETURNS trigger LANGUAGE plpgsql AS $$
    BEGIN
        IF TG_OP IN ('UPDATE', 'DELETE') THEN
            UPDATE owned_counts SET records = records - 1 WHERE kind = OLD.kind AND owner = OLD.owner;
        END IF;
        IF TG_OP IN ('INSERT', 'UPDATE') THEN
            INSERT INTO owned_counts VALUES (NEW.kind, NEW.owner, 1)
                ON CONFLICT (kind, owner) DO UPDATE SET records = owned_counts.records + 1;
        END IF;
        RETURN NULL;
    END $$""",
    "CREATE TRIGGER owned_totals AFTER INSERT OR UPDATE OR DELETE ON owned FOR EACH ROW EXECUTE FUNCTION owned_totals()",
]}
#: tables a rebuild of the index empties (the running totals included: refilled by the triggers)
INDEX_TABLES = ("jobs", "counts", "stage_totals", "batch_counts", "owned", "owned_counts")
#: errors after which a unit of work runs again (PostgreSQL aborted it; nothing of it was kept)
RETRIED = (pg_errors.DeadlockDetected, pg_errors.SerializationFailure)


class SchemaMismatch(RuntimeError):
    """The database holds another schema version than this hairport's (``hairport db upgrade``)."""


class Database:
    """A PostgreSQL database: one connection per thread (and per process after a fork), transactions with retries.

    Parameters
    ----------
    url : str
        ``postgresql://user@host:port/name`` (libpq's URL; a password in it is never logged).
    """

    def __init__(self, url: str):
        self.url = url
        self._local = threading.local()
        self._schema_ready = False

    def describe(self) -> str:
        """The URL without its password."""
        info = psycopg.conninfo.conninfo_to_dict(self.url)
        return f"postgresql://{info.get('user', '')}@{info.get('host', '')}:{info.get('port', 5432)}/" \
               f"{info.get('dbname', '')}"

    def run(self, work: Callable[[psycopg.Connection], object]):
        """``work(connection)`` in one transaction (joining the caller's when one is open in this thread),
        run again when PostgreSQL aborts it for a deadlock or a serialization failure.

        Raises
        ------
        StorageUnavailable
            The server cannot be reached or dropped the connection.
        """
        local = self._local
        if getattr(local, "depth", 0):
            return work(local.connection)
        if not self._schema_ready:
            self._prepare()
        for attempt in range(1, TRANSACTION_ATTEMPTS + 1):
            connection = self._connection()
            local.depth = 1
            try:
                with connection.transaction():
                    return work(connection)
            except RETRIED:
                if attempt == TRANSACTION_ATTEMPTS:
                    raise
                time.sleep(0.01 * attempt)
            except psycopg.OperationalError as error:
                self._drop()
                raise StorageUnavailable(f"the database {self.describe()} is unavailable: "
                                         f"{str(error).strip().splitlines()[0]}") from None
            finally:
                local.depth = 0
        raise AssertionError("unreachable")

    def check(self) -> None:
        """Raise :class:`StorageUnavailable` unless the server answers, :class:`SchemaMismatch` unless the
        schema is this hairport's."""
        version = self.run(schema_version)
        if version != SCHEMA_VERSION:
            raise SchemaMismatch(f"the database {self.describe()} has schema version {version}, this hairport "
                                 f"{SCHEMA_VERSION}: run `hairport db upgrade`")

    def _prepare(self) -> None:
        """Before this process's first unit of work: an empty database gets the schema, another version is
        refused (a process never writes into a schema it does not know)."""
        self._schema_ready = True  # the checks below run units of work themselves
        try:
            if self.run(schema_version) == 0:
                upgrade(self)
            self.check()
        except BaseException:
            self._schema_ready = False
            raise

    def _connection(self) -> psycopg.Connection:
        local = self._local
        connection = getattr(local, "connection", None)
        if connection is not None and not connection.closed and local.pid == os.getpid():
            return connection
        try:
            connection = psycopg.connect(self.url, connect_timeout=CONNECT_TIMEOUT_SECONDS, autocommit=True)
        except psycopg.OperationalError as error:
            raise StorageUnavailable(f"the database {self.describe()} cannot be reached: "
                                     f"{str(error).strip().splitlines()[0]}") from None
        local.connection, local.pid = connection, os.getpid()
        return connection

    def _drop(self) -> None:
        connection = getattr(self._local, "connection", None)
        self._local.connection = None
        if connection is not None:
            try:
                connection.close()
            except psycopg.Error:
                pass


def schema_version(connection: psycopg.Connection) -> int:
    """The database's schema version (0 for an empty database)."""
    exists = connection.execute("SELECT to_regclass('hairport_schema')").fetchone()[0]
    if exists is None:
        return 0
    row = connection.execute("SELECT version FROM hairport_schema").fetchone()
    return 0 if row is None else int(row[0])


def upgrade(database: Database) -> tuple[int, int]:
    """Bring the database to :data:`SCHEMA_VERSION`, one version per transaction (a failed step keeps the
    previous version whole); the versions before and after. A newer database than this hairport is refused."""

    def step(connection: psycopg.Connection) -> int | None:
        # one upgrader at a time, between hosts
        connection.execute("SELECT pg_advisory_xact_lock(hashtext('hairport_schema'))")
        version = schema_version(connection)
        if version > SCHEMA_VERSION:
            raise SchemaMismatch(f"the database {database.describe()} has schema version {version}, newer than "
                                 f"this hairport's {SCHEMA_VERSION}")
        if version == SCHEMA_VERSION:
            return None
        if version == 0:
            connection.execute("CREATE TABLE hairport_schema(version integer NOT NULL)")
            connection.execute("INSERT INTO hairport_schema VALUES (0)")
        for statement in MIGRATIONS[version + 1]:
            connection.execute(statement)
        connection.execute("UPDATE hairport_schema SET version = %s", (version + 1,))
        return version + 1

    database._schema_ready = True  # this is what prepares the schema: no check of it before each step
    before = database.run(schema_version)
    while database.run(step) is not None:
        pass
    return before, database.run(schema_version)


class PostgresRecords:
    """Records in the database, with the methods of :class:`~.documents.FolderRecords`.

    Parameters
    ----------
    database : Database
    """

    def __init__(self, database: Database):
        self.database = database

    def put_record(self, kind: str, record_id: str, document: dict, written: Written | None = None) -> None:
        """Write (create or replace) a record; ``written(old, new)`` runs in the same transaction."""
        if not isinstance(document, dict):
            raise TypeError(f"a record is a dict, got {type(document).__name__}")
        _check(kind, record_id)

        def work(connection: psycopg.Connection) -> None:
            old = None
            if written is not None:
                old = _document(connection.execute(
                    "SELECT document FROM records WHERE kind = %s AND id = %s FOR UPDATE", (kind, record_id)).fetchone())
            connection.execute(
                "INSERT INTO records VALUES (%s, %s, %s, %s) ON CONFLICT (kind, id) DO UPDATE SET "
                "document = excluded.document, written_at = excluded.written_at",
                (kind, record_id, record_text(document), time.time()))
            if written is not None:
                written(old, document)

        self.database.run(work)

    def get_record(self, kind: str, record_id: str) -> dict | None:
        text = self.get_record_text(kind, record_id)
        return None if text is None else _loads(text)

    def get_record_text(self, kind: str, record_id: str) -> str | None:
        _check(kind, record_id)
        row = self.database.run(lambda connection: connection.execute(
            "SELECT document FROM records WHERE kind = %s AND id = %s", (kind, record_id)).fetchone())
        return None if row is None else row[0]

    def update_record(self, kind: str, record_id: str, change: Callable[[dict], dict | None],
                      written: Written | None = None) -> dict | None:
        """Read-modify-write of a record holding its row (see :meth:`~.documents.FolderRecords.update_record`)."""
        _check(kind, record_id)

        def work(connection: psycopg.Connection) -> dict | None:
            row = connection.execute(
                "SELECT document FROM records WHERE kind = %s AND id = %s FOR UPDATE", (kind, record_id)).fetchone()
            if row is None:
                return None
            old = _loads(row[0])
            new = change(_loads(row[0]))  # the change gets its own copy: ``old`` stays as it was for ``written``
            if new is None:
                return old
            if not isinstance(new, dict):
                raise TypeError(f"change must return a dict or None, got {type(new).__name__}")
            connection.execute("UPDATE records SET document = %s, written_at = %s WHERE kind = %s AND id = %s",
                               (record_text(new), time.time(), kind, record_id))
            if written is not None:
                written(old, new)
            return new

        return self.database.run(work)

    def list_records(self, kind: str) -> Iterator[dict]:
        """Every record of a kind, in id order (read in pages: records deleted meanwhile are skipped)."""
        check_name(kind, "record kind")
        after = ""
        while True:
            rows = self.database.run(lambda connection, after=after: connection.execute(
                "SELECT id, document FROM records WHERE kind = %s AND id > %s ORDER BY id LIMIT %s",
                (kind, after, FETCH_ROWS)).fetchall())
            for _, document in rows:
                yield _loads(document)
            if len(rows) < FETCH_ROWS:
                return
            after = rows[-1][0]

    def delete_record(self, kind: str, record_id: str) -> None:
        _check(kind, record_id)
        self.database.run(lambda connection: connection.execute(
            "DELETE FROM records WHERE kind = %s AND id = %s", (kind, record_id)))

    def has_record(self, kind: str, record_id: str) -> bool:
        _check(kind, record_id)
        return self.database.run(lambda connection: connection.execute(
            "SELECT 1 FROM records WHERE kind = %s AND id = %s", (kind, record_id)).fetchone()) is not None

    # ------------------------------------------------------------------ retention

    def purge_old(self, cutoff: float, removed: Callable[[str, str], None] | None = None) -> tuple[int, set[str]]:
        """Remove the records not written since ``cutoff`` (each in its transaction, checked again there);
        the count removed and the digests the remaining records refer to."""
        count = 0
        old = self.database.run(lambda connection: connection.execute(
            "SELECT kind, id FROM records WHERE written_at < %s", (cutoff,)).fetchall())
        for kind, record_id in old:
            def work(connection: psycopg.Connection, kind=kind, record_id=record_id) -> bool:
                gone = connection.execute("DELETE FROM records WHERE kind = %s AND id = %s AND written_at < %s "
                                          "RETURNING id", (kind, record_id, cutoff)).fetchone()
                if gone is not None and removed is not None:
                    removed(kind, record_id)
                return gone is not None

            count += self.database.run(work)
        referenced, _ = self.references()
        return count, referenced

    def references(self, kept_since: Callable[[str, dict], float | None] | None = None) -> tuple[set[str], float]:
        """The digests every record refers to, and the earliest time ``kept_since`` keeps blobs from."""
        referenced: set[str] = set()
        earliest = math.inf
        for kind, document in self._scan():
            referenced |= blob_references(document)
            since = None if kept_since is None else kept_since(kind, document)
            if since is not None:
                earliest = min(earliest, since)
        return referenced, earliest

    def _scan(self) -> Iterator[tuple[str, dict]]:
        """Every record, in pages."""
        after = ("", "")
        while True:
            rows = self.database.run(lambda connection, after=after: connection.execute(
                "SELECT kind, id, document FROM records WHERE (kind, id) > (%s, %s) ORDER BY kind, id LIMIT %s",
                (*after, FETCH_ROWS)).fetchall())
            for kind, _, document in rows:
                yield kind, _loads(document)
            if len(rows) < FETCH_ROWS:
                return
            after = rows[-1][:2]


class PostgresIndex:
    """The record index (:class:`~.index.Index`) in the database of the records.

    Its writes join the record's transaction (the repository writes them from the record store's
    ``written``); a failed one fails that transaction, and the record with it.

    Parameters
    ----------
    database : Database
    source : callable
        Every row, read from the records (for :meth:`rebuild`).
    """

    def __init__(self, database: Database, source: Callable[[], Iterable[Row]]):
        self.database = database
        self.source = source

    def put_job(self, row: JobRow) -> None:
        self._write("INSERT INTO jobs VALUES (%s, %s, %s, %s, %s, %s, %s, %s, %s) ON CONFLICT (id) DO UPDATE SET "
                    "owner = excluded.owner, state = excluded.state, created_us = excluded.created_us, "
                    "updated_at = excluded.updated_at, timings = excluded.timings, batch_id = excluded.batch_id, "
                    "progress_units = excluded.progress_units, finished_at = excluded.finished_at", _job_values(row))

    def put_owned(self, row: OwnedRow) -> None:
        self._write("INSERT INTO owned VALUES (%s, %s, %s, %s) ON CONFLICT (kind, id) DO UPDATE SET "
                    "owner = excluded.owner, created_us = excluded.created_us", _owned_values(row))

    def drop_job(self, job_id: str) -> None:
        self._write("DELETE FROM jobs WHERE id = %s", (job_id,))

    def drop_owned(self, kind: str, record_id: str) -> None:
        self._write("DELETE FROM owned WHERE kind = %s AND id = %s", (kind, record_id))

    def _write(self, sql: str, values: tuple) -> None:
        self.database.run(lambda connection: connection.execute(sql, values))

    def job_page(self, owner: str, state: str | None, limit: int, offset: int) -> tuple[list[str], int]:
        if state is None:
            return self._page("SELECT id FROM jobs WHERE owner = %s ORDER BY created_us DESC, id DESC LIMIT %s OFFSET %s",
                              "SELECT coalesce(sum(jobs), 0) FROM counts WHERE owner = %s", (owner,), limit, offset)
        return self._page("SELECT id FROM jobs WHERE owner = %s AND state = %s ORDER BY created_us DESC, id DESC "
                          "LIMIT %s OFFSET %s",
                          "SELECT coalesce(sum(jobs), 0) FROM counts WHERE owner = %s AND state = %s",
                          (owner, state), limit, offset)

    def owned_page(self, kind: str, owner: str, limit: int, offset: int) -> tuple[list[str], int]:
        return self._page("SELECT id FROM owned WHERE kind = %s AND owner = %s ORDER BY created_us DESC, id DESC "
                          "LIMIT %s OFFSET %s", "SELECT coalesce(sum(records), 0) FROM owned_counts "
                          "WHERE kind = %s AND owner = %s", (kind, owner), limit, offset)

    def _page(self, ids: str, total: str, where: tuple, limit: int, offset: int) -> tuple[list[str], int]:
        def read(connection: psycopg.Connection) -> tuple[list[str], int]:
            page = [row[0] for row in connection.execute(ids, (*where, limit, offset))]
            return page, int(connection.execute(total, where).fetchone()[0])

        return self.database.run(read)

    def job_counts(self) -> dict[str, int]:
        return {state: int(jobs) for state, jobs in self.database.run(lambda connection: connection.execute(
            "SELECT state, sum(jobs) FROM counts GROUP BY state").fetchall())}

    def stage_totals(self) -> dict[str, tuple[float, int]]:
        return {stage: (seconds, int(jobs)) for stage, seconds, jobs in self.database.run(
            lambda connection: connection.execute("SELECT stage, seconds, jobs FROM stage_totals WHERE jobs > 0"
                                                  ).fetchall())}

    def ids_in_state(self, state: str) -> list[str]:
        return [row[0] for row in self.database.run(lambda connection: connection.execute(
            "SELECT id FROM jobs WHERE state = %s", (state,)).fetchall())]

    def batch_counts(self, batch_ids: Iterable[str]) -> dict[str, BatchCounts]:
        wanted = list(dict.fromkeys(batch_ids))

        def read(connection: psycopg.Connection) -> dict[str, BatchCounts]:
            states: dict[str, dict[str, tuple[int, int]]] = {batch_id: {} for batch_id in wanted}
            for start in range(0, len(wanted), IDS_PER_QUERY):
                for batch_id, state, jobs, units in connection.execute(
                        "SELECT batch_id, state, jobs, progress_units FROM batch_counts WHERE jobs > 0 "
                        "AND batch_id = ANY(%s)", (wanted[start:start + IDS_PER_QUERY],)):
                    states[batch_id][state] = (int(jobs), int(units))
            return {batch_id: BatchCounts(counts, connection.execute(
                "SELECT max(finished_at) FROM jobs WHERE batch_id = %s", (batch_id,)).fetchone()[0])
                for batch_id, counts in states.items()}

        return self.database.run(read)

    def rebuild(self, only_if_stale: bool = False) -> dict[str, int]:
        """Refill the index from the records in one transaction; rows written by kind. (Nothing marks it stale:
        its writes share the records' transactions.)"""
        if only_if_stale:
            return {}

        def work(connection: psycopg.Connection) -> dict[str, int]:
            written: Counter = Counter()
            connection.execute(f"TRUNCATE {', '.join(INDEX_TABLES)}")
            for row in self.source():
                if isinstance(row, JobRow):
                    connection.execute("INSERT INTO jobs VALUES (%s, %s, %s, %s, %s, %s, %s, %s, %s)", _job_values(row))
                    written[JOBS] += 1
                else:
                    connection.execute("INSERT INTO owned VALUES (%s, %s, %s, %s)", _owned_values(row))
                    written[row.kind] += 1
            return dict(written)

        return self.database.run(work)


def _check(kind: str, record_id: str) -> None:
    check_name(kind, "record kind")
    check_name(record_id, "record id")


def _loads(text: str) -> dict:
    return json.loads(text)


def _document(row) -> dict | None:
    return None if row is None else _loads(row[0])
