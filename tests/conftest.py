"""Fixtures shared by the test modules: a private Redis server for the service tests, and the
markers by test folder. (The hairline tests' MakeHuman head is in tests/solver/hairline/conftest.py.)"""

import os
import shutil
import socket
import subprocess
import tempfile
import time
from pathlib import Path

import pytest

TESTS = Path(__file__).parent
#: test folders whose tests carry their own marker; everything else is a unit test
MARKED_FOLDERS = ("integration", "quality")


def pytest_configure(config):
    """The default storage folder (``$XDG_DATA_HOME/hairport``) of every test is a temporary one: a test that
    builds default settings never writes a deployment id into the home folder."""
    os.environ["XDG_DATA_HOME"] = tempfile.mkdtemp(prefix="hairport-tests-data-")


def pytest_collection_modifyitems(config, items):
    """Mark every test by its folder: ``-m unit``, ``-m integration`` and ``-m quality`` select them
    (a module outside those folders may mark itself ``integration``, e.g. one running a subprocess)."""
    for item in items:
        parts = Path(item.fspath).resolve().relative_to(TESTS.resolve()).parts
        if parts[0] in MARKED_FOLDERS:
            item.add_marker(parts[0])
        elif item.get_closest_marker("integration") is None and item.get_closest_marker("quality") is None:
            item.add_marker("unit")


#: seconds the private Redis server may take to answer
REDIS_START_SECONDS = 20


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.fixture(scope="session")
def redis_url(tmp_path_factory):
    """A Redis server of the tests' own, on a free port, nothing kept on disk; stopped at the end.

    The tests never use a Redis they did not start (a shared one may hold other work)."""
    import redis

    server = shutil.which("redis-server")
    if server is None:
        pytest.fail("the service tests need redis-server on PATH (.ci/run installs it with apt-get)")
    folder = tmp_path_factory.mktemp("redis")
    port = free_port()
    process = subprocess.Popen(
        [server, "--port", str(port), "--bind", "127.0.0.1", "--save", "", "--appendonly", "no", "--dir", str(folder),
         "--logfile", str(folder / "redis.log")],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    url = f"redis://127.0.0.1:{port}/0"
    client = redis.Redis.from_url(url)
    deadline = time.monotonic() + REDIS_START_SECONDS
    while True:
        try:
            client.ping()
            break
        except redis.ConnectionError:
            if process.poll() is not None or time.monotonic() > deadline:
                process.kill()
                pytest.fail(f"redis-server did not start on port {port}: {(folder / 'redis.log').read_text()[-500:]}")
            time.sleep(0.05)
    yield url
    client.close()
    process.terminate()
    try:
        process.wait(timeout=10)
    except subprocess.TimeoutExpired:
        process.kill()

