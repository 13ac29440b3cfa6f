"""The sweeper: ends the jobs no worker will finish, within a minute rather than an hour.

It runs as a thread in every worker's main process and in the API process (``hairport serve``),
so it keeps working when a worker host dies; a clock record shared by the deployment lets one
sweep run per ``Settings.sweep_seconds``, whichever process gets there first. Each sweep:

* marks ``stale`` a running job (or preprocessing) whose heartbeat is older than
  ``Settings.stale_after_seconds`` and sends it again under a new task id (the dead run's
  message, if the broker ever hands it out again, is then a no-op); after ``max_attempts``
  starts it fails with ``worker_lost`` instead;
* sends again a job (or preprocessing) waiting longer than ``Settings.lost_after_seconds``
  whose message the broker does not hold (in its queues, or delivered and unacknowledged): a
  non-persistent Redis restarted, a queue deleted; after ``max_attempts`` such losses the job
  fails with ``message_lost``.

Once per :data:`ORPHAN_SWEEP_INTERVAL_SECONDS` for the deployment (a clock of its own), it also removes
the stored files no record refers to that are older than ``Settings.orphan_grace_seconds``
(:meth:`hairport.repository.Repository.sweep_orphans`).

Every change is made under the record's lock and only if the record is still as the sweep
saw it, so sweepers in several processes, and workers, never undo each other.
"""

from __future__ import annotations

import logging
import threading

from hairport.records import (
    FAILED,
    MESSAGE_LOST,
    QUEUED,
    RUNNING,
    STALE,
    WAITING_STATES,
    ErrorInfo,
    JobRecord,
    PreprocessingRecord,
    now,
)
from hairport.repository import Repository
from hairport.settings import Settings

from .runs import new_task_id, silent, worker_lost

log = logging.getLogger(__name__)

#: a sweeper thread looks at the shared clock this many times per sweep period, so that sweeps keep
#: their period when the process that swept last dies
TICKS_PER_PERIOD = 3
#: the orphan sweep runs at most this often in a deployment (s): it reads every record, as the hourly purge
#: does, and an orphan then goes between the grace period and an hour after it
ORPHAN_SWEEP_INTERVAL_SECONDS = 3600.0


class Sweeper:
    """Sweeps one deployment's records (see the module docstring) through ``queue`` (a ``TaskQueue``)."""

    def __init__(self, repository: Repository, queue, settings: Settings):
        self.repository, self.queue, self.settings = repository, queue, settings
        self.stopped = threading.Event()
        self.thread: threading.Thread | None = None

    # ---------------------------------------------------------------- the thread

    def start(self) -> threading.Thread:
        self.thread = threading.Thread(target=self._loop, name="hairport-sweeper", daemon=True)
        self.thread.start()
        return self.thread

    def stop(self) -> None:
        self.stopped.set()

    def _loop(self) -> None:
        while not self.stopped.wait(self.settings.sweep_seconds / TICKS_PER_PERIOD):
            try:
                if self.repository.sweep_due(self.settings.sweep_seconds):
                    self.sweep()
            except Exception:  # noqa: BLE001 - a failed sweep (storage or broker trouble) is tried next period
                log.exception("sweep failed")
            try:
                self.sweep_orphans()
            except Exception:  # noqa: BLE001 - storage trouble: the orphans wait for the next sweep
                log.exception("orphan sweep failed")

    # ---------------------------------------------------------------- one sweep

    def sweep(self) -> dict[str, int]:
        """One sweep; how many records it marked stale, sent again, or failed."""
        counts = dict(stale=0, resent=0, failed=0)
        settings, moment = self.settings, now()
        for job in self.repository.jobs_in_state(RUNNING):
            if silent(job, settings.stale_after_seconds, moment, job.started_at):
                self._count(counts, self._recover(self._job_change(job.id), job.run_token, "it"),
                            lambda task_id, job=job: self.queue.send_retarget(job.id, task_id))
        preprocessing = list(self.repository.preprocessing_in((QUEUED, RUNNING)))
        for status in preprocessing:
            if status.state == RUNNING and silent(status, settings.stale_after_seconds, moment, status.updated_at):
                self._count(counts, self._recover(self._preprocessing_change(status.key), status.run_token,
                                                  "its preprocessing", stale_state=QUEUED),
                            self._preprocess_sender(status))
        waiting = [job for state in WAITING_STATES for job in self.repository.jobs_in_state(state)
                   if moment - (job.enqueued_at or job.created_at) > settings.lost_after_seconds]
        queued = [status for status in preprocessing if status.state == QUEUED and status.hairstyle_id
                  and moment - (status.enqueued_at or status.updated_at) > settings.lost_after_seconds]
        if waiting or queued:
            held = self.queue.task_ids_in_broker()
            if held is not None:
                for job in waiting:
                    if job.task_id not in held:
                        self._count(counts, self._resend(self._job_change(job.id), job.task_id, WAITING_STATES),
                                    lambda task_id, job=job: self.queue.send_retarget(job.id, task_id))
                for status in queued:
                    if status.task_id not in held:
                        self._count(counts, self._resend(self._preprocessing_change(status.key), status.task_id,
                                                         (QUEUED,)), self._preprocess_sender(status))
        if any(counts.values()):
            log.warning("sweep: %s", counts)
        return counts

    def sweep_orphans(self) -> int | None:
        """The orphan sweep, when it is due for the deployment; blobs removed, or None when it was not due."""
        removed = self.repository.sweep_orphans_if_due(self.settings.orphan_grace_seconds,
                                                       ORPHAN_SWEEP_INTERVAL_SECONDS)
        if removed:
            log.warning("orphan sweep: removed %d stored files no record refers to", removed)
        return removed

    def _job_change(self, job_id: str):
        return lambda change: self.repository.change_job(job_id, change)

    def _preprocessing_change(self, key: str):
        return lambda change: self.repository.change_preprocessing(key, change)

    def _preprocess_sender(self, status: PreprocessingRecord):
        return lambda task_id: self.queue.send_preprocess(status.hairstyle_id, status.options, task_id)

    def _recover(self, change, token: str | None, what: str, stale_state: str = STALE) -> tuple[str, str | None]:
        """Mark a silent run stale and give its record a new task id (or fail it after ``max_attempts``)."""
        settings = self.settings
        outcome: tuple[str, str | None] = ("none", None)

        def apply(current):
            nonlocal outcome
            if current.state != RUNNING or current.run_token != token or not silent(
                    current, settings.stale_after_seconds, now(), getattr(current, "started_at", None)
                    or current.updated_at):
                return None
            if current.attempts >= settings.max_attempts:
                outcome = ("failed", None)
                extra = {"finished_at": now()} if isinstance(current, JobRecord) else {}
                return current.model_copy(update=dict(state=FAILED, error=worker_lost(current, settings, what),
                                                      run_token=None, **extra))
            task_id = new_task_id()
            outcome = ("stale", task_id)
            extra = {"stage": STALE} if isinstance(current, JobRecord) else {}
            return current.model_copy(update=dict(state=stale_state, stale_at=now(), run_token=None, task_id=task_id,
                                                  enqueued_at=now(), **extra))

        change(apply)
        return outcome

    def _resend(self, change, task_id: str | None, waiting: tuple[str, ...]) -> tuple[str, str | None]:
        """Give a waiting record whose message is lost a new task id (or fail it after ``max_attempts``)."""
        settings = self.settings
        outcome: tuple[str, str | None] = ("none", None)

        def apply(current):
            nonlocal outcome
            if current.state not in waiting or current.task_id != task_id:
                return None
            if current.requeues >= settings.max_attempts:
                outcome = ("failed", None)
                extra = {"finished_at": now()} if isinstance(current, JobRecord) else {}
                return current.model_copy(update=dict(state=FAILED, error=ErrorInfo(
                    code=MESSAGE_LOST, message=f"the task queue lost its message {current.requeues + 1} times"),
                    **extra))
            new = new_task_id()
            outcome = ("resent", new)
            return current.model_copy(update=dict(task_id=new, enqueued_at=now(), requeues=current.requeues + 1))

        change(apply)
        return outcome

    @staticmethod
    def _count(counts: dict, outcome: tuple[str, str | None], send) -> None:
        kind, task_id = outcome
        if kind == "none":
            return
        counts[kind] += 1
        if task_id is not None:
            try:
                send(task_id)
            except Exception:  # noqa: BLE001 - the record names a message that was not sent: the next sweeps
                log.exception("sending task %s failed; the next sweep sends it again", task_id)  # find it lost
