"""``/v1/retargets``: one job per target character; ``Idempotency-Key`` makes retries safe."""

from __future__ import annotations

from fastapi import APIRouter, Response

from ..auth import Owner
from ..deps import IdempotencyKey, QueueDep, RepositoryDep, SettingsDep
from ..errors import problem_responses
from ..schemas import JobOut, JobsCreated, RetargetIn
from ..services import retargets

router = APIRouter(prefix="/v1/retargets", tags=["retargets"])


@router.post("", status_code=202, response_model=JobsCreated, summary="Retarget a hairstyle onto targets",
             responses=problem_responses(400, 401, 404, 413, 422, 503))
def create_retargets(
    owner: Owner,
    settings: SettingsDep,
    repository: RepositoryDep,
    queue: QueueDep,
    request: RetargetIn,
    response: Response,
    idempotency_key: IdempotencyKey = None,
) -> JobsCreated:
    jobs = retargets.create_retargets(repository, queue, settings, owner, request, idempotency_key)
    response.headers["Location"] = f"/v1/jobs/{jobs[0].id}"
    return JobsCreated(jobs=[JobOut.of(job) for job in jobs])
