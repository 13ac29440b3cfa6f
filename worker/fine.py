"""One job's multi-scale fine level over many workers.

The job's own run solves everything up to the guides (the coarse level), then hands the
fine level (Eq. 14: the normal strands, independent once the guides are adapted) to
:class:`SpreadFineLevel`. When the level is larger than ``Settings.fine_chunk_particles``,
it splits the normal strands into chunks of whole strands (:func:`plan_chunks`), saves the
level's inputs (:class:`hairport.distributed.FineInputs`) as a blob of the storage (on another
host, read from the object store by its digest: no folder is shared), lists the chunks and
that digest in the job's record (``fine``) and sends one ``fine`` task per chunk. A worker's
task claims its chunk under the job record's lock, rebuilds the chunk's problem from the
artifact, the target and those inputs (the same rows as the job's run would have built, so
the same numbers bit for bit), solves it and saves its points as a blob whose digest the
chunk records (:func:`run_fine_chunk`).

The job's run does not idle meanwhile: it claims and solves the chunks no task has taken,
and the chunks whose worker died (its process gone, or its heartbeat silent), so a killed
worker or a lost message costs that chunk only, and a job finishes even when no other worker
is free. A chunk that fails fails the job once, with the chunk's reason. Cancelling the job
stops its chunks at their next iteration and revokes those not started. When every chunk is
done, the run assembles the points and goes on as a job solved in one process (penetration
check, metrics, outputs). The inputs and the chunks' points are no record's outputs: the orphan
sweep removes them once the job has ended (a running job keeps every blob saved since it began).

If the job's run dies, its heartbeat stops, the sweeper queues the job again, and the new
run starts its fine level afresh under its own token: the chunk tasks of the dead run find
another token and do nothing.
"""

from __future__ import annotations

import json
import logging
import math
import os
import time
import traceback
import uuid
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from hairport import solver
from hairport.outputs import json_default
from hairport.records import (
    CHUNK_DONE,
    CHUNK_FAILED,
    CHUNK_QUEUED,
    CHUNK_RUNNING,
    RUNNING,
    ErrorInfo,
    FineChunk,
    FineRun,
    JobRecord,
    now,
)
from hairport.repository import Repository
from hairport.settings import Settings
from hairport.solver import distributed

from . import bodies
from .loading import error_info, job_inputs
from .runs import HOST, TRANSIENT_ERRORS, Heartbeat, OwnRun, new_task_id, run_gone

log = logging.getLogger(__name__)

#: how often the job's run looks at its chunks while it waits for other workers (s)
CHUNK_POLL_SECONDS = 0.2
#: a chunk writes its progress (and reads whether it should stop) at most this often (s)
CHUNK_PROGRESS_SECONDS = 0.5
#: the suffix of the fine level's blobs (its inputs, each chunk's points)
FINE_SUFFIX = ".npz"


@dataclass(frozen=True)
class FineDispatch:
    """How a job's run reaches the ``fine`` queue: ``send(job_id, run_token, index, task_id)`` and ``revoke(task_id)``."""

    send: Callable[[str, str, int, str], object]
    revoke: Callable[[str], None]


class ChunkFailed(Exception):
    """A chunk failed on something other than bad input (its error is the job's)."""


class FineBlobGone(FileNotFoundError):
    """A blob of the fine level is no longer in the storage."""


def plan_chunks(counts: np.ndarray, chunk_particles: int, max_chunks: int) -> list[tuple[int, int]]:
    """Runs of whole normal strands, ``(first, stop)``, of about ``chunk_particles`` particles each (larger when
    that would make more than ``max_chunks``); ``counts : (R,) int`` particles per normal strand."""
    total = int(np.sum(counts))
    size = max(int(chunk_particles), math.ceil(total / max(1, int(max_chunks))))
    return [(int(run[0]), int(run[-1]) + 1) for run in distributed.chunk_strands(np.asarray(counts), size)]


def fine_blob(repository: Repository, digest: str, what: str) -> Path:
    """The local path of a fine-level blob (fetched from the object store when this host has none).

    Raises
    ------
    FineBlobGone
        When the storage no longer has it (the job ended and the sweep removed it).
    """
    blob = repository.storage.blob(digest, FINE_SUFFIX)
    if blob is None:
        raise FineBlobGone(f"the fine level's {what} ({digest[:12]}) are gone")
    return blob.path


def save_chunk_result(repository: Repository, points: np.ndarray, report: distributed.SolveReport) -> str:
    """A chunk's points ``(n, 3) float64`` and its solver report, as one ``.npz`` blob: its digest."""
    document = json.dumps(asdict(report), default=json_default)

    def write(path: Path) -> None:
        with open(path, "wb") as handle:
            np.savez(handle, points=points, report=np.array(document))

    return repository.storage.save_written(write, FINE_SUFFIX).sha256


def load_chunk_result(repository: Repository, digest: str, particles: int) -> tuple[np.ndarray, distributed.SolveReport]:
    """A chunk's points ``(particles, 3) float64`` and report from its blob."""
    with np.load(fine_blob(repository, digest, "chunk points"), allow_pickle=False) as archive:
        points, document = np.asarray(archive["points"], dtype=np.float64), str(archive["report"])
    if points.shape != (particles, 3):
        raise ChunkFailed(f"chunk result {digest[:12]} holds {points.shape} points, not ({particles}, 3)")
    return points, distributed.SolveReport(**json.loads(document))


class ChunkClaim:
    """One run of one chunk, by this process: its guarded writes to the chunk in the job's record."""

    def __init__(self, repository: Repository, job_id: str, run_token: str, index: int, token: str):
        self.repository, self.job_id, self.run_token, self.index, self.token = (
            repository, job_id, run_token, index, token)

    def write(self, **fields) -> bool:
        """Set ``fields`` of the chunk if the job still runs this fine level and the chunk is still this
        claim's; whether it was."""
        return self._if_ours(lambda chunk: chunk.model_copy(update=fields))

    def release(self) -> bool:
        """Hand the chunk back to the queue (a transient error: the task is retried, the run did not die)."""
        return self._if_ours(lambda chunk: chunk.model_copy(update=dict(
            state=CHUNK_QUEUED, claim=None, attempts=max(0, chunk.attempts - 1))))

    def _if_ours(self, update: Callable[[FineChunk], FineChunk]) -> bool:
        """Apply ``update`` to the chunk under the job record's lock while it is this claim's; whether it was."""
        applied = False

        def change(job: JobRecord) -> JobRecord | None:
            nonlocal applied
            chunk = _current_chunk(job, self.run_token, self.index)
            if chunk is None or chunk.claim != self.token or chunk.state != CHUNK_RUNNING:
                return None
            job.fine.chunks[self.index] = update(chunk)
            applied = True
            return job

        self.repository.change_job(self.job_id, change)
        return applied

    def beat(self) -> bool:
        return self.write(heartbeat_at=now())


def _current_chunk(job: JobRecord | None, run_token: str, index: int) -> FineChunk | None:
    """The chunk of the job's fine level of run ``run_token``, while the job runs it."""
    if job is None or job.state != RUNNING or job.fine is None or job.fine.run_token != run_token:
        return None
    if not 0 <= index < len(job.fine.chunks):
        return None
    return job.fine.chunks[index]


def claim_chunk(repository: Repository, settings: Settings, job_id: str, run_token: str, index: int,
                worker: str, task_id: str | None = None) -> ChunkClaim | None:
    """Take chunk ``index`` for this process if no live run holds it (queued, or its worker is gone) and,
    with ``task_id``, the message is the chunk's current one: the claim, or None."""
    token = uuid.uuid4().hex

    def change(job: JobRecord) -> JobRecord | None:
        chunk = _current_chunk(job, run_token, index)
        if chunk is None or job.cancel_requested or (task_id is not None and chunk.task_id != task_id):
            return None
        if chunk.state == CHUNK_RUNNING and not chunk_gone(chunk, settings):
            return None
        if chunk.state not in (CHUNK_QUEUED, CHUNK_RUNNING):
            return None
        job.fine.chunks[index] = chunk.model_copy(update=dict(
            state=CHUNK_RUNNING, claim=token, attempts=chunk.attempts + 1, worker=worker, worker_host=HOST,
            worker_pid=os.getpid(), heartbeat_at=now(), progress=0.0, error=None))
        return job

    job = repository.change_job(job_id, change)
    chunk = _current_chunk(job, run_token, index)
    return ChunkClaim(repository, job_id, run_token, index, token) if chunk is not None and chunk.claim == token else None


def chunk_gone(chunk: FineChunk, settings: Settings) -> bool:
    """Whether a running chunk's run is over: silent, or its process on this host is gone."""
    return chunk.state == CHUNK_RUNNING and run_gone(chunk, settings.stale_after_seconds, chunk.heartbeat_at)


class ChunkProgress:
    """A chunk's progress writer and stop test (a :data:`hairport.solver.ProgressFn`)."""

    def __init__(self, claim: ChunkClaim):
        self.claim = claim
        self.last = 0.0
        self.stopped = False

    def __call__(self, stage: str, fraction: float, message: str) -> None:
        moment = time.monotonic()
        if moment - self.last >= CHUNK_PROGRESS_SECONDS:
            self.last = moment
            if not self.claim.write(progress=round(float(fraction), 4), heartbeat_at=now()):
                self.stopped = True

    def should_stop(self) -> bool:
        moment = time.monotonic()
        if not self.stopped and moment - self.last >= CHUNK_PROGRESS_SECONDS:
            self.last = moment
            job = self.claim.repository.job(self.claim.job_id)
            chunk = _current_chunk(job, self.claim.run_token, self.claim.index)
            self.stopped = chunk is None or job.cancel_requested or chunk.claim != self.claim.token
        return self.stopped


def run_fine_chunk(repository: Repository, settings: Settings, job_id: str, run_token: str, index: int,
                   worker: str, task_id: str | None = None) -> None:
    """Solve chunk ``index`` of the fine level of the job's run ``run_token`` (a ``fine`` task's body): nothing
    when the message is obsolete, the job is over or cancelled, or a live run holds the chunk."""
    claim = claim_chunk(repository, settings, job_id, run_token, index, worker, task_id)
    if claim is None:
        return
    began = time.perf_counter()
    progress = ChunkProgress(claim)
    try:
        with Heartbeat(claim.beat, settings.heartbeat_seconds):
            job = repository.job(job_id)
            chunk = _current_chunk(job, run_token, index)
            if chunk is None:
                return
            artifact = repository.artifact(job.artifact_key)
            if artifact is None:
                raise solver.InputError("the hairstyle's artifact is gone", code="gone")
            adaptable, target, _ = job_inputs(repository, settings, job, artifact)
            inputs = distributed.FineInputs.load(fine_blob(repository, job.fine.inputs, "inputs"), adaptable.hair,
                                                 adaptable.multiscale.guides)
            options = solver.RetargetOptions(**job.options)
            surface, _ = bodies.collision_surface(repository, settings, target)
            points, report = distributed.solve_fine_chunk(adaptable, target, options, inputs, chunk.first_strand,
                                                     chunk.stop_strand, progress, progress.should_stop,
                                                     collision_surface=surface)
            result = save_chunk_result(repository, points, report)
        claim.write(state=CHUNK_DONE, progress=1.0, seconds=time.perf_counter() - began, solve_seconds=report.seconds,
                    result=result)
    except solver.Cancelled:
        return  # the job is being cancelled or another run took the chunk: it decides
    except TRANSIENT_ERRORS:
        claim.release()
        raise
    except FineBlobGone as error:
        if _current_chunk(repository.job(job_id), run_token, index) is None:
            return  # the job's run ended and its inputs were swept: nothing is lost
        claim.write(state=CHUNK_FAILED, error=ErrorInfo(code="internal", message=str(error)))
    except Exception as error:  # noqa: BLE001 - the chunk fails with a reason, the job's run fails the job
        claim.write(state=CHUNK_FAILED, error=error_info(error, settings.task_soft_time_limit))
        if not isinstance(error, solver.InputError):
            traceback.print_exc()


class SpreadFineLevel:
    """A :data:`hairport.distributed.FineRunner` for a job's run: its fine level over the ``fine`` queue's workers
    and itself (see the module docstring); in this process alone when the level is small or there is no
    queue to send to."""

    def __init__(self, repository: Repository, settings: Settings, job_id: str, run: OwnRun, worker: str,
                 dispatch: FineDispatch | None):
        self.repository, self.settings, self.job_id, self.run = repository, settings, job_id, run
        self.worker, self.dispatch = worker, dispatch

    def __call__(self, level: distributed.FineLevel, progress: solver.ProgressFn | None,
                 should_stop: Callable[[], bool] | None) -> tuple[np.ndarray, list[distributed.SolveReport], int]:
        counts = level.counts
        plan = plan_chunks(counts, self.settings.fine_chunk_particles, self.settings.max_fine_chunks)
        if len(plan) < 2 or self.dispatch is None:
            return distributed.solve_here(level, progress, should_stop)
        return self._spread(level, plan, counts, progress or solver.no_progress, should_stop)

    def _spread(self, level, plan, counts, progress, should_stop):
        token = self.run.token
        inputs = self.repository.storage.save_written(level.inputs.save, FINE_SUFFIX).sha256
        chunks = [FineChunk(index=i, first_strand=first, stop_strand=stop, particles=int(counts[first:stop].sum()),
                            task_id=new_task_id()) for i, (first, stop) in enumerate(plan)]
        if not self.run.write(fine=FineRun(run_token=token, inputs=inputs, chunks=chunks)):
            raise solver.Cancelled("the job's run was taken over")
        for chunk in reversed(chunks):  # the job's run takes chunks from the front, tasks from the back
            try:
                self.dispatch.send(self.job_id, token, chunk.index, chunk.task_id)
            except Exception as error:  # noqa: BLE001 - an unsent chunk is solved here
                log.warning("job %s: chunk %d not sent (%s): this run solves it", self.job_id, chunk.index, error)
        results: dict[int, tuple[np.ndarray, distributed.SolveReport]] = {}
        total = float(counts.sum())
        while len(results) < len(chunks):
            if should_stop is not None and should_stop():
                self._revoke(self.repository.job(self.job_id))
                raise solver.Cancelled("solve cancelled")
            job = self.repository.job(self.job_id)
            current = job.fine.chunks if job is not None and job.fine is not None else []
            if job is None or job.fine is None or job.fine.run_token != token:
                raise solver.Cancelled("the job's run was taken over")
            failed = next((chunk for chunk in current if chunk.state == CHUNK_FAILED), None)
            if failed is not None:
                self._revoke(job)
                raise _chunk_error(failed)
            for chunk in current:
                if chunk.state == CHUNK_DONE and chunk.index not in results:
                    results[chunk.index] = load_chunk_result(self.repository, chunk.result, chunk.particles)
            done = sum(chunk.particles for chunk in current if chunk.index in results)
            running = sum(chunk.particles * chunk.progress for chunk in current
                          if chunk.state == CHUNK_RUNNING and chunk.index not in results)
            progress(distributed.SOLVE_STAGE, (done + running) / total,
                     f"strands: {len(results)} of {len(chunks)} chunks done")
            free = [chunk for chunk in current if chunk.index not in results and (
                chunk.state == CHUNK_QUEUED or chunk_gone(chunk, self.settings))]
            if free and self._solve_here(level, free[0], token, results, progress, should_stop, done + running, total):
                continue
            time.sleep(CHUNK_POLL_SECONDS)
        ordered = [results[index] for index in range(len(chunks))]
        job = self.repository.job(self.job_id)
        workers = {chunk.worker for chunk in job.fine.chunks} if job is not None and job.fine is not None else {None}
        return np.concatenate([points for points, _ in ordered]), [report for _, report in ordered], len(workers)

    def _solve_here(self, level, chunk: FineChunk, token, results, progress, should_stop, before: float,
                    total: float) -> bool:
        """Claim ``chunk`` for this run and solve it here (the job's progress moving with it from ``before`` of
        ``total`` particles); whether it was claimed."""
        claim = claim_chunk(self.repository, self.settings, self.job_id, token, chunk.index, self.worker)
        if claim is None:
            return False
        chunk_progress = ChunkProgress(claim)

        def report(stage: str, fraction: float, message: str) -> None:
            chunk_progress(stage, fraction, message)
            progress(distributed.SOLVE_STAGE, (before + chunk.particles * fraction) / total,
                     f"strands: {len(results)} chunks done, chunk {chunk.index} here: {message}")

        began = time.perf_counter()
        with Heartbeat(claim.beat, self.settings.heartbeat_seconds):
            results[chunk.index] = distributed.solve_level_run(level, chunk.first_strand, chunk.stop_strand, report,
                                                          should_stop)
        claim.write(state=CHUNK_DONE, progress=1.0, seconds=time.perf_counter() - began,
                    solve_seconds=results[chunk.index][1].seconds)
        return True

    def _revoke(self, job: JobRecord | None) -> None:
        if job is None or job.fine is None or self.dispatch is None:
            return
        for chunk in job.fine.chunks:
            if chunk.state == CHUNK_QUEUED and chunk.task_id:
                try:
                    self.dispatch.revoke(chunk.task_id)
                except Exception as error:  # noqa: BLE001 - an unrevoked chunk task finds the job over: a no-op
                    log.warning("job %s: chunk %d not revoked (%s)", self.job_id, chunk.index, error)


def _chunk_error(chunk: FineChunk) -> Exception:
    error = chunk.error or ErrorInfo(code="internal", message="a chunk failed")
    message = f"chunk {chunk.index} of the fine level (strands {chunk.first_strand}..{chunk.stop_strand - 1}): " \
              f"{error.message}"
    if error.code == "internal":
        return ChunkFailed(message)
    return solver.InputError(message, code=error.code)
