"""The validation pool: uploads validated in prewarmed child processes, bounded in number, memory and time;
a child that dies is replaced and fails only its own request."""

from __future__ import annotations

import array
import asyncio
import fcntl
import os
import signal
import termios
import time

import pytest

from hairport.service.errors import Problem
from hairport.service.uploads import validated
from hairport.service.validation import (
    ChildDied,
    ValidationBusy,
    ValidationPool,
    ValidationTimeout,
    close_pools,
    shared_pool,
)
from hairport.settings import Settings

#: integration, not unit: the pool's child processes, started, killed and replaced
pytestmark = pytest.mark.integration

#: strands of the groom large enough to need more than the small budget (two points each: 1.2 x 10^6
#: particles, 14 MB as a .data file, ~100 MB to validate)
LARGE_STRANDS = 600_000
#: a heap budget far below what validating the large groom needs
SMALL_BUDGET = 32 * 2**20
#: a budget every test input fits
BUDGET = 1024**3
#: seconds of waiting allowed where a test does not mean to hit a bound
GENEROUS = 300.0


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict:
    from hairport.solver import write_hair
    from hairport.solver.synthetic import toy
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import write_character

    folder = tmp_path_factory.mktemp("validation")
    source = toy.toy_character(name="source")
    write_character(source, folder / "source.obj", folder / "source.skeleton.json")
    write_hair(folder / "groom.data", generate_groom(source, "short", 20, 6, seed=0))
    write_hair(folder / "large.data", generate_groom(source, "short", LARGE_STRANDS, 2, seed=1))
    (folder / "cut.data").write_bytes((folder / "groom.data").read_bytes()[:200])
    (folder / "broken.obj").write_text("v 0 0 0\nf 1 2 3\n")
    return {name: str(folder / name) for name in ("source.obj", "source.skeleton.json", "groom.data", "large.data",
                                                  "cut.data", "broken.obj")}


def hair_arguments(files: dict, hair: str, units: str = "auto", guides_from: str | None = None) -> dict:
    """A hair check's arguments as the hairstyles service sends them."""
    settings = Settings()
    return {"hair": files[hair], "units": units, "prim": None,
            "limits": {"max_strands": settings.max_strands, "max_particles": settings.max_particles,
                       "max_bytes": settings.max_upload_bytes, "memory_budget_bytes": settings.memory_budget_bytes},
            "source": {"mesh": files["source.obj"], "skeleton": files["source.skeleton.json"], "units": None,
                       "up": None, "front": None, "max_vertices": settings.max_vertices,
                       "max_faces": settings.max_faces, "max_bytes": settings.max_file_bytes},
            "guides_from": guides_from, "max_guides": 1000}


def run(pool: ValidationPool, arguments: dict, wait: float = GENEROUS, timeout: float = GENEROUS) -> dict:
    return asyncio.run(pool.run("hair", "hair", arguments, wait, timeout))


def request_pending(pool: ValidationPool, index: int = 0) -> int:
    """Bytes written to child ``index`` that it has not read (FIONREAD of its stdin pipe)."""
    count = array.array("i", [0])
    fcntl.ioctl(pool.children[index].process.stdin.fileno(), termios.FIONREAD, count)
    return count[0]


async def until(condition) -> None:
    while not condition():
        await asyncio.sleep(0.01)


def bytes_read(pid: int) -> int:
    """Bytes process ``pid`` has read (``rchar`` of /proc/PID/io)."""
    with open(f"/proc/{pid}/io") as io:
        return next(int(line.split()[1]) for line in io if line.startswith("rchar:"))


async def kill_once_taken(pool: ValidationPool, pid: int) -> None:
    """SIGKILL the (frozen) child ``pid`` while it validates the request sent to it: once it has read a MB of
    the hair file (it said it took the request before)."""
    await until(lambda: request_pending(pool) > 0)
    before = bytes_read(pid)
    os.kill(pid, signal.SIGCONT)
    await until(lambda: bytes_read(pid) > before + 2**20)
    freeze(pid)
    os.kill(pid, signal.SIGKILL)


def freeze(pid: int) -> None:
    """SIGSTOP a child and wait until it is stopped (a request written after that stays in its pipe)."""
    os.kill(pid, signal.SIGSTOP)
    while open(f"/proc/{pid}/stat").read().rpartition(")")[2].split()[0] != "T":
        time.sleep(0.01)


@pytest.fixture
def pool():
    pools = []

    def make(workers: int = 1, memory_bytes: int = BUDGET) -> ValidationPool:
        pools.append(ValidationPool(workers, memory_bytes))
        pools[-1].start()
        return pools[-1]

    yield make
    for made in pools:
        made.close()


def test_a_validation_answers_what_the_record_keeps(pool, files):
    answer = run(pool(), hair_arguments(files, "groom.data"))
    assert answer == {"result": {"units": None, "strands": 20, "particles": 120}, "retiring": False}


def test_validations_run_at_most_as_many_at_once_as_there_are_children(pool, files):
    validating = pool(workers=2)

    async def five():
        return await asyncio.gather(*(validating.run("hair", "hair", hair_arguments(files, "large.data"), GENEROUS,
                                                     GENEROUS) for _ in range(5)))

    answers = asyncio.run(five())
    assert [answer["result"]["strands"] for answer in answers] == [LARGE_STRANDS] * 5
    assert (validating.peak_busy, validating.busy) == (2, 0)


def test_a_request_waits_for_a_free_child_then_is_answered_busy(pool, files):
    validating = pool(workers=1)
    run(validating, hair_arguments(files, "groom.data"))  # started and ready
    pid = validating.pids()[0]
    freeze(pid)  # the only child holds its request until it is continued

    async def scenario():
        first = asyncio.create_task(validating.run("hair", "hair", hair_arguments(files, "groom.data"), GENEROUS,
                                                   GENEROUS))
        await until(lambda: request_pending(validating) > 0)
        with pytest.raises(ValidationBusy):
            await validating.run("hair", "hair", hair_arguments(files, "groom.data"), 0.2, GENEROUS)
        os.kill(pid, signal.SIGCONT)
        return await first

    assert asyncio.run(scenario())["result"]["strands"] == 20
    assert validating.pids() == [pid]


def test_over_the_memory_budget_is_refused_and_the_next_validation_has_a_fresh_child(pool, files):
    validating = pool(memory_bytes=SMALL_BUDGET)
    run(validating, hair_arguments(files, "groom.data"))
    pid = validating.pids()[0]
    refused = run(validating, hair_arguments(files, "large.data"))
    assert refused["error"]["code"] == "over_memory_budget" and refused["error"]["field"] == "hair"
    assert "32 MB" in refused["error"]["problem"] and refused["retiring"] is True
    for _ in range(2):
        assert run(validating, hair_arguments(files, "groom.data"))["result"]["particles"] == 120
    assert validating.pids()[0] not in (pid, None)


def test_a_child_killed_while_validating_fails_its_request_and_is_replaced(pool, files):
    validating = pool(workers=1)
    run(validating, hair_arguments(files, "groom.data"))
    pid = validating.pids()[0]
    freeze(pid)

    async def killed():
        task = asyncio.create_task(validating.run("hair", "hair", hair_arguments(files, "large.data"), GENEROUS,
                                                  GENEROUS))
        await kill_once_taken(validating, pid)
        with pytest.raises(ChildDied) as died:
            await task
        return died.value

    died = asyncio.run(killed())
    assert died.killed and died.returncode == -signal.SIGKILL
    assert validating.pids()[0] not in (pid, None)
    assert run(validating, hair_arguments(files, "groom.data"))["result"]["strands"] == 20
    # killed while idle, just before a request: it never took it, its replacement does
    replaced = validating.pids()[0]
    os.kill(replaced, signal.SIGKILL)
    assert run(validating, hair_arguments(files, "groom.data"))["result"]["strands"] == 20
    assert validating.pids()[0] not in (pid, replaced, None)


def test_a_validation_over_its_time_is_stopped_and_its_child_replaced(pool, files):
    validating = pool(workers=1)
    run(validating, hair_arguments(files, "groom.data"))
    pid = validating.pids()[0]
    freeze(pid)  # never answers
    with pytest.raises(ValidationTimeout):
        run(validating, hair_arguments(files, "groom.data"), timeout=0.5)
    assert validating.pids()[0] not in (pid, None)
    assert run(validating, hair_arguments(files, "groom.data"))["result"]["strands"] == 20


def test_closing_stops_every_child_even_a_stopped_one(pool, files):
    validating = pool(workers=2)
    run(validating, hair_arguments(files, "groom.data"))
    processes = [child.process for child in validating.children]
    freeze(processes[0].pid)
    validating.close()
    assert [process.poll() is not None for process in processes] == [True, True]
    with pytest.raises(ValidationBusy):
        run(validating, hair_arguments(files, "groom.data"))


# ------------------------------------------------------------------ through the service's validated()


def problem(settings: Settings, check: str, field: str, **arguments) -> Problem:
    with pytest.raises(Problem) as refused:
        asyncio.run(validated(settings, check, field, **arguments))
    return refused.value


def test_input_errors_come_back_with_their_code_and_field(files):
    settings = Settings()
    cut = problem(settings, "hair", "hair", **hair_arguments(files, "cut.data"))
    assert (cut.status, cut.code) == (422, "truncated") and cut.detail.startswith("hair: ")
    other_units = problem(settings, "hair", "hair", **hair_arguments(files, "groom.data", units="cm"))
    assert (other_units.status, other_units.code) == (422, "units_mismatch") and "hair in m" in other_units.detail
    flags = problem(settings, "hair", "hair", **hair_arguments(files, "groom.data", guides_from="guide"))
    assert (flags.status, flags.code) == (422, "no_guide_flags") and flags.detail.startswith("guides_from: ")
    mesh = problem(settings, "character", "mesh", mesh=files["broken.obj"], skeleton=None, units=None,
                   max_vertices=10, max_faces=10, max_bytes=10**6)
    assert mesh.status == 422 and mesh.detail.startswith("mesh: ")
    character = asyncio.run(validated(settings, "character", "mesh", mesh=files["source.obj"],
                                      skeleton=files["source.skeleton.json"], units=None, max_vertices=10**6,
                                      max_faces=10**6, max_bytes=10**8))
    assert character["units"] == "m" and character["vertices"] > 1000 and "head" in character["bones"]


def test_over_the_budget_is_413_and_a_busy_pool_503_with_retry_after(files):
    settings = Settings(max_concurrent_validations=1, validation_memory_bytes=SMALL_BUDGET,
                        validation_wait_seconds=0.2)
    try:
        over = problem(settings, "hair", "hair", **hair_arguments(files, "large.data"))
        assert (over.status, over.code) == (413, "over_memory_budget") and over.detail.startswith("hair: ")
        # the refused validation's child retired: its successor answers (so it is ready) before it is frozen
        assert asyncio.run(validated(settings, "hair", "hair", **hair_arguments(files, "groom.data")))["strands"] == 20
        validating = shared_pool(settings)
        pid = validating.pids()[0]
        freeze(pid)

        async def busy():
            first = asyncio.create_task(validated(settings, "hair", "hair", **hair_arguments(files, "groom.data")))
            await until(lambda: request_pending(validating) > 0)
            with pytest.raises(Problem) as refused:
                await validated(settings, "hair", "hair", **hair_arguments(files, "groom.data"))
            os.kill(pid, signal.SIGCONT)
            return refused.value, await first

        refused, first = asyncio.run(busy())
        assert (refused.status, refused.code, refused.headers) == (503, "validation_busy", {"Retry-After": "10"})
        assert first["strands"] == 20
    finally:
        close_pools()


def test_a_child_the_kernel_kills_is_an_upload_over_the_budget(files):
    settings = Settings(max_concurrent_validations=1)
    try:
        assert asyncio.run(validated(settings, "hair", "hair", **hair_arguments(files, "groom.data")))["strands"] == 20
        validating = shared_pool(settings)
        freeze(pid := validating.pids()[0])

        async def killed():  # SIGKILL, as the OOM killer sends
            task = asyncio.create_task(validated(settings, "hair", "hair", **hair_arguments(files, "large.data")))
            await kill_once_taken(validating, pid)
            with pytest.raises(Problem) as refused:
                await task
            return refused.value

        died = asyncio.run(killed())
        assert (died.status, died.code) == (413, "over_memory_budget") and died.detail.startswith("hair: ")
        assert "killed" in died.detail
        assert asyncio.run(validated(settings, "hair", "hair", **hair_arguments(files, "groom.data")))["strands"] == 20
    finally:
        close_pools()
