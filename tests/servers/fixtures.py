"""PostgreSQL fixtures for the conftests that need them: import them into a conftest (or a test module),
``from tests.servers.fixtures import postgres_server, postgres_url  # noqa: F401``.

Under pytest-xdist a session fixture runs once per worker process: each worker gets a server of its own.
"""

from __future__ import annotations

import pytest

from tests.servers.postgres import PostgresServer, PostgresUnavailable


def _started() -> PostgresServer:
    try:
        return PostgresServer().__enter__()
    except PostgresUnavailable as error:  # no programs, or initdb/postgres failed: the message says which
        pytest.fail(str(error), pytrace=False)


@pytest.fixture(scope="session")
def postgres_server():
    """The session's PostgreSQL server (shared by the tests of one process: do not stop or restart it; a
    test that does takes ``private_postgres_server``)."""
    server = _started()
    yield server
    server.close()


@pytest.fixture(scope="session")
def postgres_url(postgres_server) -> str:
    """``postgresql://hairport@127.0.0.1:PORT/hairport_test`` of the session's server."""
    return postgres_server.url


@pytest.fixture
def private_postgres_server():
    """A PostgreSQL server of this test's own (under a second to start), which it may stop or restart."""
    server = _started()
    yield server
    server.close()
