"""Jobs: listing, cancellation, and their output files (results converted to any hair format)."""

from __future__ import annotations

from pathlib import Path

from fastapi.responses import FileResponse
from starlette.background import BackgroundTask

from hairport import solver
from hairport.records import (
    CANCELLED,
    CHUNK_QUEUED,
    SUCCEEDED,
    TERMINAL_STATES,
    WAITING_STATES,
    BlobRef,
    JobRecord,
    now,
)
from hairport.repository import Repository
from hairport.worker.queue import TaskQueue

from ..errors import Problem
from ..schemas import RESULT_MEDIA_TYPES
from ..uploads import input_problem

#: what a lossless copy of every result is kept as (other formats are converted from it)
LOSSLESS_FORMAT = "npz"
#: a stored result is read back whole, whatever the configured input limits
UNLIMITED = solver.ReadLimits(2**62, 2**62, 2**62)


def cancel_job(repository: Repository, queue: TaskQueue, job: JobRecord) -> JobRecord:
    """Cancel a job: a queued (or stale) one at once, a running one at its solver's next iteration.

    The cancel is whole once written to the job's record, which every worker reads before it starts the job
    or a chunk of it, and a running job reads while it runs; revoking the job's messages afterwards only
    spares a worker the read, so it is tried once and a broker that is down changes nothing (see
    :meth:`TaskQueue.revoke`)."""
    job, task_ids = request_cancel(repository, job)
    queue.revoke(*task_ids)
    return job


def request_cancel(repository: Repository, job: JobRecord) -> tuple[JobRecord, list[str]]:
    """Write a job's cancel to its record: the record, and the ids of its messages no worker needs to start."""
    if job.state in TERMINAL_STATES:
        return job, []

    def change(current: JobRecord) -> JobRecord | None:
        if current.state in TERMINAL_STATES:
            return None  # it ended meanwhile
        current.cancel_requested = True
        if current.state in WAITING_STATES:
            current.state, current.stage, current.finished_at = CANCELLED, "cancelled", now()
        return current

    job = repository.change_job(job.id, change) or job
    task_ids = [job.task_id] if job.state == CANCELLED and job.task_id else []
    # the job's run stops its running chunks at their next iteration
    task_ids += [chunk.task_id for chunk in (job.fine.chunks if job.fine is not None else ())
                 if chunk.state == CHUNK_QUEUED and chunk.task_id]
    return job, task_ids


def outputs_of(job: JobRecord) -> dict[str, BlobRef]:
    """The job's stored outputs; 409 unless it succeeded."""
    if job.state != SUCCEEDED:
        raise Problem(409, "job_not_succeeded", f"job {job.id} is {job.state}; it has no outputs")
    return job.outputs


def blob_response(repository: Repository, ref: BlobRef, media_type: str, filename: str) -> FileResponse:
    blob = repository.storage.blob(ref.sha256, ref.suffix)
    if blob is None:
        raise Problem(410, "gone", "this output was removed by the retention policy")
    return FileResponse(blob.path, media_type=media_type, filename=filename)


def result_file(repository: Repository, job: JobRecord, fmt: str, folder: Path) -> Path:
    """The job's result in ``fmt``: its stored file, or one converted into ``folder`` from the lossless copy
    (410 when retention removed it; 415 for a format whose optional library this deployment lacks)."""
    outputs = outputs_of(job)
    if fmt in outputs:
        blob = repository.storage.blob(outputs[fmt].sha256, outputs[fmt].suffix)
        if blob is None:
            raise Problem(410, "gone", "this output was removed by the retention policy")
        return blob.path
    lossless = outputs[LOSSLESS_FORMAT]
    source = repository.storage.blob(lossless.sha256, lossless.suffix)
    if source is None:
        raise Problem(410, "gone", "this output was removed by the retention policy")
    path = folder / f"result.{fmt}"
    try:
        # the lossless copy is in the groom's units (it records them): convert in the same units
        units = solver.recorded_hair_units(source.path) or "m"
        lossless_copy = solver.read_hair_report(source.path, units=units, limits=UNLIMITED)
        solver.write_hair(path, lossless_copy.hair, units=units, format=fmt, up_axis=lossless_copy.up_axis or "+y")
    except solver.InputError as error:  # a format whose optional library this deployment lacks
        raise input_problem(error, "format") from None
    return path


def result_response(repository: Repository, job: JobRecord, fmt: str | None) -> FileResponse:
    """The result in ``fmt`` (default: the job's): stored, or converted from the lossless copy and
    streamed from a scratch folder that is removed after the response."""
    fmt = fmt or job.output_format
    outputs = outputs_of(job)
    if fmt in outputs:
        return blob_response(repository, outputs[fmt], RESULT_MEDIA_TYPES[fmt], f"{job.id}.{fmt}")
    work = repository.storage.work_dir()
    folder = work.__enter__()
    try:
        path = result_file(repository, job, fmt, folder)
    except BaseException:
        work.__exit__(None, None, None)
        raise
    return FileResponse(path, media_type=RESULT_MEDIA_TYPES[fmt], filename=f"{job.id}.{fmt}",
                        background=BackgroundTask(work.__exit__, None, None, None))
