"""``/v1/jobs``: state and progress, results, preview, report, cancellation, listing."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query
from fastapi.responses import FileResponse

from ..auth import Owner
from ..deps import OwnedJob, QueueDep, RepositoryDep
from ..errors import problem_responses
from ..schemas import RESULT_DESCRIPTION, HairFormat, JobOut, JobPage, JobState, result_content
from ..services import jobs

router = APIRouter(prefix="/v1/jobs", tags=["jobs"])
#: largest page of GET /v1/jobs
MAX_PAGE = 200
DEFAULT_PAGE = 50


@router.get("", response_model=JobPage, summary="The caller's jobs, newest first",
            responses=problem_responses(401, 422))
def list_jobs(
    owner: Owner,
    repository: RepositoryDep,
    state: Annotated[JobState | None, Query(description="only jobs in this state")] = None,
    limit: Annotated[int, Query(ge=1, le=MAX_PAGE)] = DEFAULT_PAGE,
    offset: Annotated[int, Query(ge=0)] = 0,
) -> JobPage:
    page, total = repository.list_jobs(owner, state, limit, offset)
    following = offset + limit if offset + limit < total else None
    return JobPage(jobs=[JobOut.of(job) for job in page], total=total, limit=limit, offset=offset,
                   next_offset=following)


@router.get("/{job_id}", response_model=JobOut, summary="A job's state, progress, timings and metrics",
            responses=problem_responses(401, 404, 422))
async def get_job(job: OwnedJob) -> JobOut:
    # async (on the event loop, no threadpool hop): the poll path is one lock-free record read
    return JobOut.of(job)


@router.get("/{job_id}/result", summary="The retargeted hair file", response_class=FileResponse,
            responses={200: {"description": RESULT_DESCRIPTION, "content": result_content()},
                       **problem_responses(401, 404, 409, 410, 415, 422)})
def get_result(repository: RepositoryDep, job: OwnedJob, format: HairFormat | None = None):
    return jobs.result_response(repository, job, format)


@router.get("/{job_id}/preview.png", summary="Source next to result", response_class=FileResponse,
            responses={200: {"content": {"image/png": {"schema": {"type": "string", "format": "binary"}}}},
                       **problem_responses(401, 404, 409, 410, 422)})
def get_preview(repository: RepositoryDep, job: OwnedJob):
    return jobs.blob_response(repository, jobs.outputs_of(job)["preview"], "image/png", f"{job.id}.png")


@router.get("/{job_id}/report", summary="Metrics and per-stage timings (JSON)", response_class=FileResponse,
            responses={200: {"content": {"application/json": {}}}, **problem_responses(401, 404, 409, 410, 422)})
def get_report(repository: RepositoryDep, job: OwnedJob):
    return jobs.blob_response(repository, jobs.outputs_of(job)["report"], "application/json", f"{job.id}.json")


@router.delete("/{job_id}", response_model=JobOut, summary="Cancel a job",
               responses=problem_responses(401, 404, 422))
def cancel_job(repository: RepositoryDep, queue: QueueDep, job: OwnedJob) -> JobOut:
    return JobOut.of(jobs.cancel_job(repository, queue, job))
