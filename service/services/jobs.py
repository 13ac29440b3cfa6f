"""Jobs: listing, cancellation, and their output files (results converted to any hair format)."""

from __future__ import annotations

from pathlib import Path

from fastapi.responses import FileResponse
from starlette.background import BackgroundTask

from hairport import solver
from hairport.records import (
    CANCELLED,
    CHUNK_QUEUED,
    FRAMES_OUTPUT,
    LOSSLESS_OUTPUT,
    SUCCEEDED,
    TERMINAL_STATES,
    WAITING_STATES,
    BlobRef,
    JobRecord,
    now,
)
from hairport.repository import Repository
from hairport.solver import sequence as solver_sequence
from hairport.worker.queue import TaskQueue

from ..errors import Problem
from ..schemas import RESULT_MEDIA_TYPES
from ..uploads import input_problem

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


def require_sequence(job: JobRecord) -> None:
    """422 ``bad_frames`` when a frame is asked of a job onto one body."""
    if job.sequence is None:
        raise Problem(422, "bad_frames", f"frame: job {job.id} retargeted onto one body; it has no frames")


def blob_response(repository: Repository, ref: BlobRef, media_type: str, filename: str) -> FileResponse:
    return FileResponse(stored_path(repository, ref), media_type=media_type, filename=filename)


def stored_path(repository: Repository, ref: BlobRef) -> Path:
    """The local path of a stored output (410 when retention removed it)."""
    blob = repository.storage.blob(ref.sha256, ref.suffix)
    if blob is None:
        raise Problem(410, "gone", "this output was removed by the retention policy")
    return blob.path


def result_file(repository: Repository, job: JobRecord, fmt: str, folder: Path, frame: int | None = None) -> Path:
    """The job's result in ``fmt``: its stored file, or one converted into ``folder`` from the lossless copy (and, of a
    sequence, its kept frames: one frame of it in any format, or every frame in an animated format). 410 when
    retention removed it; 415 for a format whose optional library this deployment lacks; 422 ``bad_frames`` for a
    frame of a job that is not a sequence, or a sequence asked for whole in a format of one frame."""
    outputs = outputs_of(job)
    if frame is None and fmt in outputs:
        return stored_path(repository, outputs[fmt])
    if frame is not None:
        require_sequence(job)
    if job.sequence is not None and frame is None and fmt not in solver_sequence.ANIMATED_FORMATS:
        raise Problem(422, "bad_frames", f"format: a {fmt} file holds one frame; ask for one frame of the sequence "
                                         f"(frame=K) or an animated format ({', '.join(solver_sequence.ANIMATED_FORMATS)})")
    source = stored_path(repository, outputs[LOSSLESS_OUTPUT])
    path = folder / f"result.{fmt}"
    try:
        # the lossless copy is in the groom's units (it records them): convert in the same units
        units = solver.recorded_hair_units(source) or "m"
        lossless_copy = solver.read_hair_report(source, units=units, limits=UNLIMITED)
        up_axis = lossless_copy.up_axis or "+y"
        if job.sequence is None:
            solver.write_hair(path, lossless_copy.hair, units=units, format=fmt, up_axis=up_axis)
            return path
        kept = solver_sequence.SolvedFrames.load(stored_path(repository, outputs[FRAMES_OUTPUT]))
        if frame is None:
            solver_sequence.write_hair_frames(path, lossless_copy.hair, kept.animation(), units=units, format=fmt,
                                              up_axis=up_axis)
        else:
            solver.write_hair(path, kept.hair_at(lossless_copy.hair, kept.check_frame(frame)), units=units,
                              format=fmt, up_axis=up_axis)
    except solver.InputError as error:  # a frame it does not have, a format whose optional library is missing
        raise input_problem(error, "frame" if error.code == "bad_frames" else "format") from None
    return path


def result_response(repository: Repository, job: JobRecord, fmt: str | None, frame: int | None = None) -> FileResponse:
    """The result in ``fmt`` (default: the job's), whole or (a sequence's) one frame: stored, or converted from the
    lossless copy and streamed from a scratch folder that is removed after the response."""
    fmt = fmt or job.output_format
    outputs = outputs_of(job)
    name = f"{job.id}.{fmt}" if frame is None else f"{job.id}.{frame:04d}.{fmt}"
    if frame is None and fmt in outputs:
        return blob_response(repository, outputs[fmt], RESULT_MEDIA_TYPES[fmt], name)
    work = repository.storage.work_dir()
    folder = work.__enter__()
    try:
        path = result_file(repository, job, fmt, folder, frame)
    except BaseException:
        work.__exit__(None, None, None)
        raise
    return FileResponse(path, media_type=RESULT_MEDIA_TYPES[fmt], filename=name,
                        background=BackgroundTask(work.__exit__, None, None, None))
