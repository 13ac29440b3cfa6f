"""The tests' own PostgreSQL server (tests/servers/postgres.py): private, not run as root, row claims with
``FOR UPDATE SKIP LOCKED`` that never overlap, and a restart that keeps commits and breaks open connections."""

from __future__ import annotations

import os
import pwd
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from urllib.parse import urlsplit

import psycopg
import pytest

from tests.servers.fixtures import postgres_server, postgres_url, private_postgres_server  # noqa: F401
from tests.servers.postgres import SUPERUSER, UNPRIVILEGED_USERS, _version_key

# child processes (a PostgreSQL server): not a unit test (tests/conftest.py)
pytestmark = pytest.mark.integration

#: the machine's own cluster, if any, listens there: the tests' server never does
SYSTEM_PORT = 5432
#: rows in the queue that the workers drain
QUEUE_ROWS = 20
#: seconds a worker holds its claimed row before marking it (so that the other worker claims meanwhile)
HOLD_SECONDS = 0.01
#: rows each of the two interleaved claims takes
BATCH = 3


def claim(connection: psycopg.Connection, table: str, limit: int) -> list[int]:
    """Lock up to ``limit`` unclaimed rows of ``table`` in the connection's open transaction, skipping rows that
    another transaction holds (what a job queue's worker does)."""
    rows = connection.execute(
        f"SELECT id FROM {table} WHERE claimed_by IS NULL ORDER BY id LIMIT %s FOR UPDATE SKIP LOCKED", (limit,))
    return [row[0] for row in rows]


def make_queue(url: str, table: str, rows: int) -> None:
    with psycopg.connect(url, autocommit=True) as connection:
        connection.execute(f"DROP TABLE IF EXISTS {table}")
        connection.execute(f"CREATE TABLE {table} (id integer PRIMARY KEY, claimed_by text)")
        connection.execute(f"INSERT INTO {table} (id) SELECT generate_series(1, {rows})")


def owner_uid(pid: int) -> int:
    """The real user id of a running process."""
    status = Path(f"/proc/{pid}/status").read_text()
    return int(next(line for line in status.splitlines() if line.startswith("Uid:")).split()[1])


def test_server_is_private_with_test_settings(postgres_server, postgres_url):  # noqa: F811
    url = urlsplit(postgres_url)
    assert (url.scheme, url.hostname, url.username, url.path) == ("postgresql", "127.0.0.1", SUPERUSER,
                                                                 "/hairport_test")
    assert url.port == postgres_server.port != SYSTEM_PORT
    with psycopg.connect(postgres_url) as connection:
        settings = {name: connection.execute(f"SHOW {name}").fetchone()[0]
                    for name in ("fsync", "full_page_writes", "synchronous_commit", "server_encoding",
                                 "data_directory", "unix_socket_directories", "listen_addresses")}
    assert settings == {"fsync": "off", "full_page_writes": "off", "synchronous_commit": "on",
                        "server_encoding": "UTF8", "data_directory": str(postgres_server.folder / "data"),
                        "unix_socket_directories": str(postgres_server.folder), "listen_addresses": "127.0.0.1"}
    # as root the server runs as the first unprivileged user the machine has; otherwise as ourselves
    uid = owner_uid(postgres_server.process.pid)
    if os.geteuid() == 0:
        assert uid == next(pwd.getpwnam(name).pw_uid for name in UNPRIVILEGED_USERS if _has_user(name))
        assert uid != 0
    else:
        assert uid == os.getuid()


def _has_user(name: str) -> bool:
    try:
        pwd.getpwnam(name)
        return True
    except KeyError:
        return False


def test_newest_debian_version_first():
    folders = [Path(f"/usr/lib/postgresql/{version}/bin") for version in ("9.6", "15", "10", "16")]
    newest_first = sorted(folders, key=_version_key, reverse=True)
    assert [folder.parent.name for folder in newest_first] == ["16", "15", "10", "9.6"]


def test_skip_locked_claims_are_disjoint(postgres_url):  # noqa: F811
    make_queue(postgres_url, "claims", QUEUE_ROWS)
    with psycopg.connect(postgres_url) as first, psycopg.connect(postgres_url) as second:
        # both transactions stay open: the first one's locks are held while the second one claims
        first_rows = claim(first, "claims", BATCH)
        second_rows = claim(second, "claims", BATCH)
        assert first_rows == [1, 2, 3]
        assert second_rows == [4, 5, 6]
        # the rows really are locked: without SKIP LOCKED the second transaction would wait for them
        second.execute("SET LOCAL lock_timeout = '100ms'")
        with pytest.raises(psycopg.errors.LockNotAvailable):
            second.execute("SELECT id FROM claims WHERE id = 1 FOR UPDATE")
        second.rollback()
        first.rollback()
        # released at the end of the first transaction: claimable again
        assert claim(second, "claims", BATCH) == [1, 2, 3]


def test_two_concurrent_workers_drain_the_queue_once(postgres_url):  # noqa: F811
    make_queue(postgres_url, "drained", QUEUE_ROWS)
    together = threading.Barrier(2)

    def work(name: str) -> list[int]:
        claimed = []
        with psycopg.connect(postgres_url) as connection:
            together.wait()
            while True:
                with connection.transaction():
                    rows = claim(connection, "drained", 1)
                    if not rows:
                        return claimed
                    threading.Event().wait(HOLD_SECONDS)
                    connection.execute("UPDATE drained SET claimed_by = %s WHERE id = %s", (name, rows[0]))
                claimed += rows

    with ThreadPoolExecutor(2) as pool:
        a, b = pool.map(work, ["a", "b"])
    assert not set(a) & set(b)
    assert sorted(a + b) == list(range(1, QUEUE_ROWS + 1))
    assert a and b  # both worked: each claimed while the other held a row
    with psycopg.connect(postgres_url) as connection:
        marked = dict(connection.execute("SELECT id, claimed_by FROM drained").fetchall())
    assert marked == {**{row: "a" for row in a}, **{row: "b" for row in b}}


def test_restart_keeps_commits_and_breaks_open_connections(private_postgres_server):  # noqa: F811
    server = private_postgres_server
    port = server.port
    with psycopg.connect(server.url, autocommit=True) as connection:
        connection.execute("CREATE TABLE jobs (id integer PRIMARY KEY, state text)")
        connection.execute("INSERT INTO jobs VALUES (1, 'queued'), (2, 'running')")
    open_connection = psycopg.connect(server.url)
    open_connection.execute("INSERT INTO jobs VALUES (3, 'uncommitted')")

    server.restart()

    # what the application's retry logic sees: the connection it held is broken for good
    with pytest.raises(psycopg.OperationalError) as broken:
        open_connection.execute("SELECT 1")
    assert open_connection.broken
    open_connection.close()
    assert isinstance(broken.value, psycopg.errors.AdminShutdown)  # SQLSTATE 57P01, a fast shutdown
    assert server.port == port
    with psycopg.connect(server.url) as connection:
        assert connection.execute("SELECT id, state FROM jobs ORDER BY id").fetchall() == [(1, "queued"),
                                                                                           (2, "running")]

    # while it is down, a new connection is refused with the same error class
    server.stop()
    with pytest.raises(psycopg.OperationalError):
        psycopg.connect(server.url, connect_timeout=2)
    server.start_again()
    with psycopg.connect(server.url) as connection:
        assert connection.execute("SELECT count(*) FROM jobs").fetchone()[0] == 2
