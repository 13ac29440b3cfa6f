"""``/v1/jobs``: state and progress, results, preview, report, cancellation, listing."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query
from fastapi.responses import FileResponse
from starlette.background import BackgroundTask

from hairport.solver import pipeline
from hairport.worker import jobs

from ..auth import Owner
from ..deps import StorageDep, owned_record
from ..errors import Problem
from ..schemas import HairFormat, JobOut, JobPage, JobState

router = APIRouter(prefix="/v1/jobs", tags=["jobs"])
MEDIA_TYPES = {"data": "application/octet-stream", "hair": "application/octet-stream",
               "ply": "application/octet-stream", "npz": "application/octet-stream", "obj": "text/plain"}
#: largest page of GET /v1/jobs
MAX_PAGE = 200


def job_out(record: dict) -> JobOut:
    base = f"/v1/jobs/{record['id']}"
    links = {"self": base}
    if record["state"] == jobs.SUCCEEDED:
        links.update(result=f"{base}/result", preview=f"{base}/preview.png", report=f"{base}/report")
    fields = {name: record.get(name) for name in JobOut.model_fields if name != "links" and name in record}
    return JobOut(**fields, links=links)


def owned_job(storage, owner: str, job_id: str) -> dict:
    return owned_record(storage, "jobs", owner, job_id, "job")


def _finished(record: dict) -> dict:
    if record["state"] != jobs.SUCCEEDED:
        raise Problem(409, "job_not_succeeded", f"job {record['id']} is {record['state']}; it has no outputs")
    return record["outputs"]


def _blob_response(storage, ref: dict, media_type: str, filename: str) -> FileResponse:
    blob = storage.blob(ref["sha256"], ref.get("suffix", ""))
    if blob is None:
        raise Problem(410, "gone", "this output was removed by the retention policy")
    return FileResponse(blob.path, media_type=media_type, filename=filename)


@router.get("", response_model=JobPage, summary="The caller's jobs, newest first")
def list_jobs(
    owner: Owner,
    storage: StorageDep,
    state: Annotated[JobState | None, Query(description="only jobs in this state")] = None,
    limit: Annotated[int, Query(ge=1, le=MAX_PAGE)] = 50,
    offset: Annotated[int, Query(ge=0)] = 0,
) -> JobPage:
    mine = [r for r in storage.list_records("jobs") if r.get("owner") == owner and (state is None or r["state"] == state)]
    mine.sort(key=lambda r: (r["created_at"], r["id"]), reverse=True)
    page = mine[offset:offset + limit]
    following = offset + limit if offset + limit < len(mine) else None
    return JobPage(jobs=[job_out(r) for r in page], total=len(mine), limit=limit, offset=offset, next_offset=following)


@router.get("/{job_id}", response_model=JobOut, summary="A job's state, progress, timings and metrics")
def get_job(owner: Owner, storage: StorageDep, job_id: str) -> JobOut:
    return job_out(owned_job(storage, owner, job_id))


@router.get("/{job_id}/result", summary="The retargeted hair file", response_class=FileResponse,
            responses={200: {"content": {"application/octet-stream": {}}}})
def get_result(owner: Owner, storage: StorageDep, job_id: str, format: HairFormat | None = None):
    record = owned_job(storage, owner, job_id)
    outputs = _finished(record)
    fmt = format or record["output_format"]
    if fmt in outputs:
        return _blob_response(storage, outputs[fmt], MEDIA_TYPES[fmt], f"{job_id}.{fmt}")
    source = storage.blob(outputs["npz"]["sha256"], outputs["npz"].get("suffix", ".npz"))
    if source is None:
        raise Problem(410, "gone", "this output was removed by the retention policy")
    # another format than the job wrote: converted from the lossless copy, streamed, then removed
    work = storage.work_dir()
    folder = work.__enter__()
    path = folder / f"result.{fmt}"
    try:
        hair = pipeline.read_hair_file(source.path, max_strands=2**62, max_particles=2**62, max_bytes=2**62)
        pipeline.write_hair_file(path, hair, fmt)
    except BaseException:
        work.__exit__(None, None, None)
        raise
    return FileResponse(path, media_type=MEDIA_TYPES[fmt], filename=f"{job_id}.{fmt}",
                        background=BackgroundTask(work.__exit__, None, None, None))


@router.get("/{job_id}/preview.png", summary="Source next to result", response_class=FileResponse,
            responses={200: {"content": {"image/png": {}}}})
def get_preview(owner: Owner, storage: StorageDep, job_id: str):
    outputs = _finished(owned_job(storage, owner, job_id))
    return _blob_response(storage, outputs["preview"], "image/png", f"{job_id}.png")


@router.get("/{job_id}/report", summary="Metrics and per-stage timings (JSON)", response_class=FileResponse,
            responses={200: {"content": {"application/json": {}}}})
def get_report(owner: Owner, storage: StorageDep, job_id: str):
    outputs = _finished(owned_job(storage, owner, job_id))
    return _blob_response(storage, outputs["report"], "application/json", f"{job_id}.json")


@router.delete("/{job_id}", response_model=JobOut, summary="Cancel a job")
def cancel_job(owner: Owner, storage: StorageDep, job_id: str) -> JobOut:
    record = owned_job(storage, owner, job_id)
    if record["state"] in jobs.TERMINAL_STATES:
        return job_out(record)

    def change(job: dict) -> dict:
        job["cancel_requested"] = True
        if job["state"] == jobs.QUEUED:
            job.update(state=jobs.CANCELLED, stage="cancelled", finished_at=jobs.now())
        job["updated_at"] = jobs.now()
        return job

    record = storage.update_record("jobs", job_id, change)
    if record["state"] == jobs.CANCELLED and record.get("task_id"):
        jobs.revoke(record["task_id"])
    return job_out(record)
