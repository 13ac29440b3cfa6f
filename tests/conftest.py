"""Fixtures shared by the test modules: a private Redis server for the service tests, and for
the hairline tests the MakeHuman average female with the scalp of a 300-strand "short" groom
on her (seed 0)."""

import shutil
import socket
import subprocess
import time
from pathlib import Path

import pytest

from hairport.solver.body.head_frame import head_frame
from hairport.solver.hairline.scalp import extract_scalp
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import PRESETS, build_character

TESTS = Path(__file__).parent
#: test folders whose tests carry their own marker; everything else is a unit test
MARKED_FOLDERS = ("integration", "quality")


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


@pytest.fixture(scope="session")
def character():
    return build_character(PRESETS["average-female"])


@pytest.fixture(scope="session")
def frame(character):
    return head_frame(character)


@pytest.fixture(scope="session")
def query(character):
    return MeshQuery(character.vertices, character.faces)


@pytest.fixture(scope="session")
def roots(character, query):
    """(S, 3) root positions and (S,) faces holding them."""
    hair = generate_groom(character, "short", 300, 8, seed=0)
    points = hair.points[hair.roots]
    return points, query.signed_distance(points).faces


@pytest.fixture(scope="session")
def scalp(character, roots, frame):
    return extract_scalp(character, roots[1], frame)
