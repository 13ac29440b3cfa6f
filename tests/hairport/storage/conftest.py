"""The S3-compatible server of the storage tests (tests/servers/seaweed.py): one per test process, started by
the first test that asks for it, removed at the end. Tests that stop it (the fault tests) start it again."""

import pytest

from tests.servers.seaweed import SeaweedServer, SeaweedUnavailable


@pytest.fixture(scope="session")
def seaweed():
    """A running :class:`SeaweedServer`: ``seaweed.endpoint`` is (URL, access key, secret key, bucket).

    Fails (never skips) without SeaweedFS's ``weed`` program: it is in hairport's ``test`` extra."""
    try:
        server = SeaweedServer()
        server.start()
    except SeaweedUnavailable as error:
        pytest.fail(str(error), pytrace=False)  # start() removed what it made
    try:
        yield server
    finally:
        server.close()
