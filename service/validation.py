"""Upload validation in a small pool of prewarmed processes: off the event loop, bounded in number and memory.

Reading a hair file of 10^6 strands and fitting it to its character is seconds of numpy, most of it
holding the GIL: run in the API's threads it stalled every request (polls of 2 ms took 12 s), and
fifty at once took the API to 1.8 GB. Here each validation runs in a child process
(:mod:`hairport.service.validation_child`, the solver's own readers) while the API only waits on a
pipe:

* **bounded in number**: ``max_concurrent_validations`` children; a request waits for a free one in
  arrival order (its upload is already on disk: the wait holds no memory), at most
  ``validation_wait_seconds``, then it is answered 503 ``validation_busy`` with ``Retry-After``
  (a client re-sending costs one upload; a request left waiting longer would outlive its client's
  and its proxy's time-outs and validate for nobody);
* **bounded in memory**: a child's heap is limited (``RLIMIT_DATA``) to its start-up size plus
  ``validation_memory_bytes``; a file that needs more is refused 413 ``over_memory_budget``, the
  child lives on;
* **bounded in time**: a validation longer than ``validation_timeout_seconds`` stops its child and
  is refused 413 ``too_large``;
* **isolated**: a child that dies (killed by the kernel's OOM killer, a crash) fails only its own
  request and is replaced; the others' children go on.

Only paths and small options go to a child, only counts, units and names come back. The pool is
one per process and per (size, budget), shared by every app built in it (the tests build many);
the app's lifespan starts it (the children import the solver while the server starts) and closes
it, and a pool first used without a lifespan starts on demand and is closed at exit. Its state
lives in threads and pipes, not in an event loop: the in-process test client runs each request on
a loop of its own.
"""

from __future__ import annotations

import asyncio
import atexit
import contextlib
import json
import os
import select
import signal
import subprocess
import sys
import threading
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor

from hairport.settings import Settings

#: the module a child runs
CHILD_MODULE = "hairport.service.validation_child"
#: a child's first line, and the line it writes when it has read a request (before it runs it)
READY, TAKEN = "ready", "taken"
#: seconds a new child may take to import the solver and prewarm (a first run on a host whose
#: kernel cache is empty compiles some kernels)
START_SECONDS = 300.0
#: seconds a stopped child has to exit after its stdin is closed, then after SIGTERM
STOP_SECONDS = 2.0
#: a child's environment, unless the deployment's says otherwise: one BLAS thread (a validation makes
#: small products; every BLAS thread has a work buffer of tens of MB inside the child's heap limit)
CHILD_ENVIRONMENT = {"OPENBLAS_NUM_THREADS": "1"}
#: bytes read from a child's answer pipe at a time
READ_BYTES = 65536
#: seconds a client is asked to wait before sending an upload again when every child stayed busy
BUSY_RETRY_SECONDS = 10


class ValidationBusy(Exception):
    """No child became free within the wait allowed (or the pool is closing)."""


class ValidationTimeout(Exception):
    """The validation ran longer than allowed; its child was stopped."""

    def __init__(self, seconds: float):
        super().__init__(f"validation took more than {seconds:g} s")
        self.seconds = seconds


class ChildDied(Exception):
    """The child running the validation died (``returncode``: its exit status, negative for a signal)."""

    def __init__(self, returncode: int | None):
        super().__init__(f"the validating process died (exit status {returncode})")
        self.returncode = returncode

    @property
    def killed(self) -> bool:
        """Killed by SIGKILL: on a host short of memory, the kernel's OOM killer."""
        return self.returncode == -signal.SIGKILL


class Child:
    """One validating process and its pipes; used by one validation at a time (the pool sees to it).

    Parameters
    ----------
    memory_bytes : int
        Heap one validation may use beyond the child's start-up size.
    """

    def __init__(self, memory_bytes: int):
        self.memory_bytes = memory_bytes
        self.process: subprocess.Popen | None = None
        self.ready = False
        self._pending = b""

    @property
    def pid(self) -> int | None:
        return None if self.process is None else self.process.pid

    def alive(self) -> bool:
        return self.process is not None and self.process.poll() is None

    def start(self) -> None:
        """Start the process; it imports the solver and prewarms while nobody waits for it."""
        self.stop()
        self.process = subprocess.Popen(
            [sys.executable, "-m", CHILD_MODULE, str(self.memory_bytes)], stdin=subprocess.PIPE,
            stdout=subprocess.PIPE, close_fds=True, env={**CHILD_ENVIRONMENT, **os.environ})
        self.ready, self._pending = False, b""

    def stop(self) -> None:
        """End the process: its stdin closed (it exits between requests), then SIGTERM, then SIGKILL."""
        process, self.process = self.process, None
        if process is None:
            return
        with contextlib.suppress(OSError):
            process.stdin.close()
        for ask in (None, process.terminate, process.kill):
            if ask is not None:
                with contextlib.suppress(OSError):
                    ask()
            try:
                process.wait(STOP_SECONDS)
                break
            except subprocess.TimeoutExpired:
                continue
        # its stdout is left to close with the last reference: a thread may still be reading it (EOF now)

    def call(self, request: dict, timeout: float) -> dict:
        """Send one request and wait for its answer (blocking: run in a thread). A child found dead before
        it took the request (it says so first: :data:`TAKEN`) is replaced and the request sent again, once.

        Raises
        ------
        ValidationTimeout
            No answer within ``timeout`` seconds: the child is stopped.
        ChildDied
            The child died after it took the request.
        """
        deadline = time.monotonic() + timeout
        for attempt in range(2):
            if not self.alive():
                self.start()
            process = self.process
            self._wait_ready(process)
            try:
                process.stdin.write((json.dumps(request) + "\n").encode())
                process.stdin.flush()
            except (OSError, ValueError):  # its end of the pipe is closed: it died, or the pool stopped it
                taken = None
            else:
                taken = self._read_line(process, deadline - time.monotonic(), timeout)
            if taken is not None:
                break
            returncode = self._died(process)  # before it took the request: a fresh child takes it
        else:
            raise ChildDied(returncode)
        line = self._read_line(process, deadline - time.monotonic(), timeout)
        if line is None:
            raise ChildDied(self._died(process))
        return json.loads(line)

    def _wait_ready(self, process: subprocess.Popen) -> None:
        """Wait for a new child's ready line (its solver imported and prewarmed)."""
        if self.ready:
            return
        try:
            line = self._read_line(process, START_SECONDS, START_SECONDS)
        except ValidationTimeout:
            raise RuntimeError(f"the validating process did not start within {START_SECONDS:g} s") from None
        if line is None or not json.loads(line).get(READY):
            raise RuntimeError(f"the validating process did not start (exit status {self._died(process)})")
        self.ready = True

    @staticmethod
    def _died(process: subprocess.Popen) -> int | None:
        """The exit status of a child that has ended or is ending (it is waited for)."""
        with contextlib.suppress(subprocess.TimeoutExpired):
            process.wait(STOP_SECONDS)
        return process.returncode

    def _read_line(self, process: subprocess.Popen, seconds: float, limit: float) -> bytes | None:
        """The next line ``process`` writes; None at end of file (it died, or the pool stopped it).
        After ``seconds`` the child is stopped and :class:`ValidationTimeout` (of ``limit`` s) raised."""
        deadline = time.monotonic() + seconds
        while b"\n" not in self._pending:
            remaining = deadline - time.monotonic()
            try:
                fd = process.stdout.fileno()
                readable = remaining > 0 and select.select([fd], [], [], remaining)[0]
                chunk = os.read(fd, READ_BYTES) if readable else None
            except (OSError, ValueError):  # the pool closed the pipe (shutting down)
                return None
            if chunk is None:
                self.stop()
                raise ValidationTimeout(limit)
            if not chunk:
                return None
            self._pending += chunk
        line, _, self._pending = self._pending.partition(b"\n")
        return line


class ValidationPool:
    """``workers`` validating children (module notes); :meth:`run` from any event loop or thread.

    Attributes
    ----------
    busy, peak_busy : int
        Validations running now, and at most so far.
    """

    def __init__(self, workers: int, memory_bytes: int):
        self.workers, self.memory_bytes = workers, memory_bytes
        self.children = [Child(memory_bytes) for _ in range(workers)]
        self._idle = deque(self.children)
        self._waiters: deque = deque()  # (event loop, future) of requests waiting for a child
        self._lock = threading.Lock()
        self._threads = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="hairport-validation")
        self.busy = self.peak_busy = 0
        self.closed = False

    def start(self) -> None:
        """Start the children that are not running (they prewarm in the background)."""
        with self._lock:
            idle = [child for child in self._idle if not child.alive()]
        for child in idle:
            child.start()

    def pids(self) -> list[int | None]:
        return [child.pid for child in self.children]

    async def run(self, check: str, field: str, arguments: dict, wait_seconds: float,
                  timeout_seconds: float) -> dict:
        """Run ``check`` (``hair`` or ``character``) on a free child; the child's answer
        (:mod:`~hairport.service.validation_child`).

        Raises
        ------
        ValidationBusy, ValidationTimeout, ChildDied
        """
        child = await self._acquire(wait_seconds)
        request = {"check": check, "field": field, "arguments": arguments}
        done = self._threads.submit(self._call, child, request, timeout_seconds)
        # shielded: a cancelled request still lets its validation finish and the child come back
        return await asyncio.shield(asyncio.wrap_future(done))

    def close(self) -> None:
        """Stop every child and refuse the waiting requests; does not wait for running validations
        (their children are stopped: they answer :class:`ChildDied`)."""
        with self._lock:
            self.closed = True
            waiters, self._waiters = list(self._waiters), deque()
        for loop, waiter in waiters:
            with contextlib.suppress(RuntimeError):  # its loop is gone
                loop.call_soon_threadsafe(_fail, waiter)
        for child in self.children:
            child.stop()
        self._threads.shutdown(wait=False, cancel_futures=True)

    def _call(self, child: Child, request: dict, timeout: float) -> dict:
        try:
            answer = child.call(request, timeout)
            if answer.get("retiring"):
                child.stop()
            return answer
        finally:
            with self._lock:  # not after close() has stopped the children
                if not self.closed and not child.alive():
                    with contextlib.suppress(OSError):  # none can start now: the next validation tries again
                        child.start()  # replaced now, so that it prewarms while it waits for work
            self._release(child)

    async def _acquire(self, wait_seconds: float) -> Child:
        loop = asyncio.get_running_loop()
        with self._lock:
            if self.closed:
                raise ValidationBusy()
            if self._idle:
                return self._take(self._idle.popleft())
            waiter = loop.create_future()
            self._waiters.append((loop, waiter))
        try:
            return await asyncio.wait_for(waiter, wait_seconds)
        except BaseException as error:
            with self._lock, contextlib.suppress(ValueError):
                self._waiters.remove((loop, waiter))
            if waiter.done() and not waiter.cancelled() and waiter.exception() is None:
                self._release(waiter.result())  # handed a child just as this request stopped waiting
            if isinstance(error, asyncio.TimeoutError):
                raise ValidationBusy() from None
            raise

    def _take(self, child: Child) -> Child:
        self.busy += 1
        self.peak_busy = max(self.peak_busy, self.busy)
        return child

    def _release(self, child: Child) -> None:
        """Hand ``child`` to the first request still waiting, else keep it idle."""
        with self._lock:
            self.busy -= 1
            while self._waiters and not self.closed:
                loop, waiter = self._waiters.popleft()
                self._take(child)
                try:
                    loop.call_soon_threadsafe(self._deliver, waiter, child)
                    return
                except RuntimeError:  # the waiter's loop is closed
                    self.busy -= 1
            self._idle.append(child)

    def _deliver(self, waiter: asyncio.Future, child: Child) -> None:
        """On the waiter's loop: give it the child, or pass the child on if it stopped waiting."""
        if waiter.done():
            self._release(child)
        else:
            waiter.set_result(child)


def _fail(waiter: asyncio.Future) -> None:
    if not waiter.done():
        waiter.set_exception(ValidationBusy())


_pools: dict[tuple[int, int], ValidationPool] = {}
_pools_lock = threading.Lock()


def shared_pool(settings: Settings) -> ValidationPool:
    """This process's pool of the settings' size and budget (started on first use)."""
    key = (settings.max_concurrent_validations, settings.validation_memory_bytes)
    with _pools_lock:
        pool = _pools.get(key)
        if pool is None or pool.closed:
            pool = _pools[key] = ValidationPool(*key)
            pool.start()
    return pool


@atexit.register
def close_pools() -> None:
    """Stop every pool's children (at exit, and when an app shuts down)."""
    with _pools_lock:
        pools = list(_pools.values())
        _pools.clear()
    for pool in pools:
        pool.close()


@contextlib.asynccontextmanager
async def lifespan(app):
    """The app's lifespan: its pool's children start with the server and stop with it."""
    shared_pool(app.state.settings)
    try:
        yield
    finally:
        close_pools()
