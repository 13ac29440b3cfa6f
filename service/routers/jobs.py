"""``/v1/jobs``: state and progress, results, preview, report, cancellation, listing."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query, Response
from fastapi.responses import FileResponse

from hairport.solver import display as wire
from hairport.solver import sequence as solver_sequence

from ..auth import Owner
from ..deps import DEFAULT_PAGE, OwnedJob, PageLimit, PageOffset, QueueDep, RepositoryDep
from ..errors import problem_responses
from ..schemas import (
    DISPLAY_RESPONSE,
    RESULT_DESCRIPTION,
    BodyLayer,
    HairFormat,
    HairlineOut,
    JobOut,
    JobPage,
    JobState,
    StrandLayer,
    result_content,
)
from ..services import display, jobs

router = APIRouter(prefix="/v1/jobs", tags=["jobs"])
#: most strands a display request may name: each strand drawn is at least its root and its tip, and a display
#: holds at most MAX_DISPLAY_VERTICES vertices
MAX_DISPLAY_STRANDS = wire.MAX_DISPLAY_VERTICES // 2
#: one frame of a sequence job (numbered from 0 in the order solved; 422 bad_frames for a job onto one body)
Frame = Annotated[int | None, Query(ge=0, le=solver_sequence.MAX_FRAMES - 1, description=(
    "a sequence job's frame, numbered from 0 in the order solved (default: the whole animated result, or frame 0 "
    "to draw); 422 bad_frames for a job onto one body"))]


@router.get("", response_model=JobPage, summary="The caller's jobs, newest first",
            responses=problem_responses(401, 422))
def list_jobs(
    owner: Owner,
    repository: RepositoryDep,
    state: Annotated[JobState | None, Query(description="only jobs in this state")] = None,
    limit: PageLimit = DEFAULT_PAGE,
    offset: PageOffset = 0,
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
def get_result(repository: RepositoryDep, job: OwnedJob, format: HairFormat | None = None, frame: Frame = None):
    return jobs.result_response(repository, job, format, frame)


@router.get("/{job_id}/preview.png", summary="Source next to result", response_class=FileResponse,
            responses={200: {"content": {"image/png": {"schema": {"type": "string", "format": "binary"}}}},
                       **problem_responses(401, 404, 409, 410, 422)})
def get_preview(repository: RepositoryDep, job: OwnedJob):
    return jobs.blob_response(repository, jobs.outputs_of(job)["preview"], "image/png", f"{job.id}.png")


@router.get("/{job_id}/report", summary="Metrics and per-stage timings (JSON)", response_class=FileResponse,
            responses={200: {"content": {"application/json": {}}}, **problem_responses(401, 404, 409, 410, 422)})
def get_report(repository: RepositoryDep, job: OwnedJob):
    return jobs.blob_response(repository, jobs.outputs_of(job)["report"], "application/json", f"{job.id}.json")


@router.get("/{job_id}/display", summary="The result or source strands, decimated for drawing",
            response_class=Response, responses={**DISPLAY_RESPONSE, **problem_responses(401, 404, 409, 410, 422)})
def get_display(
    repository: RepositoryDep,
    job: OwnedJob,
    layer: Annotated[StrandLayer, Query(description="result: the retargeted groom with the particles inside the "
                                                    "target and the segments through it flagged; source: the groom "
                                                    "on its source character")
                     ] = "result",
    strands: Annotated[int | None, Query(ge=1, le=MAX_DISPLAY_STRANDS, description=(
        "strands drawn, spread over the groom (default: as many as the vertex budget allows)"))] = None,
    stride: Annotated[int | None, Query(ge=1, le=wire.MAX_STRIDE, description=(
        "every stride-th particle of a strand, and its tip (default: the smallest that fits the budget)"))] = None,
    max_vertices: Annotated[int, Query(ge=1, le=wire.MAX_DISPLAY_VERTICES, description=(
        "the vertex budget when strands or stride is left out"))] = wire.DEFAULT_DISPLAY_VERTICES,
    frame: Frame = None,
):
    return Response(display.strands(repository, job, layer, strands, stride, max_vertices, frame),
                    media_type=wire.MEDIA_TYPE)


@router.get("/{job_id}/body", summary="The target (as solved), source or wrapped body, for drawing",
            response_class=Response, responses={**DISPLAY_RESPONSE, **problem_responses(401, 404, 409, 410, 422)})
def get_body(repository: RepositoryDep, job: OwnedJob, layer: Annotated[BodyLayer, Query(description=(
        "target: the target body as solved; source: the source character's body; wrapped: the source body wrapped "
        "onto a target of another mesh topology (409 no_wrap when the job's target was not wrapped)"))] = "target",
             frame: Frame = None):
    return Response(display.body(repository, job, layer, frame), media_type=wire.MEDIA_TYPE)


@router.get("/{job_id}/hairline", response_model=HairlineOut,
            summary="The target's current front hairline and each preset's edit of it, to draw a new one from",
            responses=problem_responses(401, 404, 409, 410, 422))
def get_hairline(repository: RepositoryDep, job: OwnedJob) -> HairlineOut:
    return HairlineOut(**display.hairline(repository, job))


@router.delete("/{job_id}", response_model=JobOut, summary="Cancel a job",
               responses=problem_responses(401, 404, 422))
def cancel_job(repository: RepositoryDep, queue: QueueDep, job: OwnedJob) -> JobOut:
    return JobOut.of(jobs.cancel_job(repository, queue, job))
