"""Who runs a job or a preprocessing: starting a run (:func:`start_run`), its guarded writes
(:class:`OwnRun`), its heartbeat, and telling a dead run from a live one.

Every message sent for a record carries the record's ``task_id`` (chosen before sending); a
message whose id is not the record's current one is obsolete and changes nothing (e.g. the
unacknowledged message of a dead worker, handed out again by the broker an hour later, after
the sweeper queued the job again under a new id). Every start writes a new ``run_token``, and
every later write of that run checks it under the record's lock, so that two runs never both
write: a run whose token was replaced stops at its next check.

A run is gone when its heartbeat is older than ``Settings.stale_after_seconds``, or at once
when it ran on this host in a process that no longer exists (a pool child the OOM killer or
a crash took: the broker hands its message straight back).
"""

from __future__ import annotations

import logging
import os
import socket
import threading
import uuid
from collections.abc import Callable

from hairport.records import CANCELLED, FAILED, QUEUED, RUNNING, WORKER_LOST, ErrorInfo, RunInfo, now
from hairport.settings import Settings

log = logging.getLogger(__name__)

#: the name of this host, as runs record it
HOST = socket.gethostname()
#: errors worth retrying (I/O, the broker): the task retries them with backoff, and the run hands its record
#: back to the queue instead of failing it
TRANSIENT_ERRORS = (ConnectionError, TimeoutError, InterruptedError, BlockingIOError)


def new_task_id() -> str:
    """The id of a task to send: chosen before sending, so the record names its message before it exists."""
    return str(uuid.uuid4())


def pid_alive(pid: int) -> bool:
    """Whether a process of that id runs on this host (one of another user counts; a zombie, killed and
    not yet reaped, does not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return True


def silent(run: RunInfo, stale_after: float, moment: float, started: float | None = None) -> bool:
    """Whether the run's last heartbeat (or its start) is older than ``stale_after`` seconds."""
    last = run.heartbeat_at or started
    return last is None or moment - last > stale_after


def run_gone(run: RunInfo, stale_after: float, started: float | None = None) -> bool:
    """Whether the run recorded in ``run`` is over: silent, or its process on this host is gone."""
    if silent(run, stale_after, now(), started):
        return True
    return run.worker_host == HOST and run.worker_pid is not None and not pid_alive(run.worker_pid)


def start_fields(run: RunInfo, worker: str) -> dict:
    """The fields of a new run by this process (``attempts`` counts it)."""
    return dict(attempts=run.attempts + 1, run_token=uuid.uuid4().hex, heartbeat_at=now(), worker=worker,
                worker_host=HOST, worker_pid=os.getpid())


def worker_lost(run: RunInfo, settings: Settings, what: str) -> ErrorInfo:
    """Why a job or a preprocessing whose worker died ``max_attempts`` times is not run again."""
    return ErrorInfo(code=WORKER_LOST, message=(
        f"its worker died {run.attempts} times while running {what} (the last on {run.worker or 'a worker'}); "
        f"it is not run again: it may need more memory than a worker has (the memory budget is "
        f"{settings.memory_budget_bytes:,} bytes) or crash its worker"))


class Heartbeat:
    """A thread that calls ``beat()`` every ``interval`` seconds while a run lasts (``with Heartbeat(...)``);
    it stops when ``beat`` returns False (the run is not the record's any more)."""

    def __init__(self, beat: Callable[[], bool], interval: float):
        self.beat, self.interval = beat, interval
        self.stopped = threading.Event()
        self.thread = threading.Thread(target=self._loop, name="hairport-heartbeat", daemon=True)

    def __enter__(self) -> Heartbeat:
        self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stopped.set()
        self.thread.join()

    def _loop(self) -> None:
        while not self.stopped.wait(self.interval):
            try:
                if not self.beat():
                    return
            except Exception:  # noqa: BLE001 - a failed beat (storage hiccup) is retried at the next
                log.exception("heartbeat failed")


class OwnRun:
    """The writes of one run of a record (a job or a preprocessing), each applied only while the record is
    still running under this run's token (see :mod:`.runs`)."""

    def __init__(self, change, token: str):
        self.change, self.token = change, token

    def write(self, **fields) -> bool:
        """Set ``fields`` if the run is still the record's; whether it was."""
        return self._if_ours(lambda current: current.model_validate({**current.model_dump(), **fields}))

    def beat(self) -> bool:
        return self.write(heartbeat_at=now())

    def release(self) -> bool:
        """Hand the record back to the queue (a transient error: the task is retried, the run did not die)."""
        return self._if_ours(lambda current: current.model_copy(update=dict(
            state=QUEUED, run_token=None, heartbeat_at=None, attempts=max(current.attempts - 1, 0))))

    def _if_ours(self, update) -> bool:
        """Apply ``update`` (record -> new record) if the record still runs under this run's token; whether it did."""
        applied = False

        def apply(current):
            nonlocal applied
            if current.run_token != self.token or current.state != RUNNING:
                return None
            applied = True
            return update(current)

        self.change(apply)
        return applied


def start_run(change, settings: Settings, task_id: str | None, worker: str, what: str,
              waiting: tuple[str, ...], fields: dict | None = None) -> OwnRun | None:
    """Start a run of a record through ``change`` (its read-modify-write under the lock): the run, or None
    when this message must not run it (obsolete, finished, running elsewhere, or failed now with
    ``worker_lost`` after ``max_attempts`` starts)."""
    token = None

    def apply(current):
        nonlocal token
        if task_id is not None and current.task_id not in (None, task_id):
            return None  # an older message: the record was queued again since
        if current.state not in waiting and current.state != RUNNING:
            return None
        if current.state == RUNNING and not run_gone(current, settings.stale_after_seconds,
                                                     getattr(current, "started_at", None) or current.updated_at):
            return None  # its run is alive: this is a duplicate delivery
        if getattr(current, "cancel_requested", False):
            return current.model_copy(update=dict(state=CANCELLED, stage="cancelled", run_token=None,
                                                  **_finished(current)))
        if current.attempts >= settings.max_attempts:
            return current.model_copy(update=dict(state=FAILED, error=worker_lost(current, settings, what),
                                                  run_token=None, **_finished(current)))
        started = start_fields(current, worker)
        token = started["run_token"]
        return current.model_validate({**current.model_dump(), "state": RUNNING, "error": None, **started,
                                       **(fields or {})})

    change(apply)
    return None if token is None else OwnRun(change, token)


def _finished(record) -> dict:
    return {"finished_at": now()} if hasattr(record, "finished_at") else {}
