"""``/v1/batches``: every hairstyle onto every target character, one job per pair; state, cancel, results."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Response
from fastapi.responses import FileResponse

from hairport.records import BatchRecord

from ..auth import Owner
from ..deps import DEFAULT_PAGE, IdempotencyKey, PageLimit, PageOffset, QueueDep, RepositoryDep, SettingsDep, owned
from ..errors import problem_responses
from ..schemas import BatchIn, BatchOut, BatchPage
from ..services import batches

router = APIRouter(prefix="/v1/batches", tags=["batches"])


async def owned_batch(batch_id: str, owner: Owner, repository: RepositoryDep) -> BatchRecord:
    return owned(repository, BatchRecord, owner, batch_id, "batch")


OwnedBatch = Annotated[BatchRecord, Depends(owned_batch)]


@router.post("", status_code=202, response_model=BatchOut, summary="Retarget hairstyles x targets in one batch",
             responses=problem_responses(400, 401, 404, 413, 422, 503))
def create_batch(
    owner: Owner,
    settings: SettingsDep,
    repository: RepositoryDep,
    queue: QueueDep,
    request: BatchIn,
    response: Response,
    idempotency_key: IdempotencyKey = None,
) -> BatchOut:
    batch = batches.create_batch(repository, queue, settings, owner, request, idempotency_key)
    response.headers["Location"] = f"/v1/batches/{batch.id}"
    return batches.batch_out(repository, batch)


@router.get("", response_model=BatchPage, summary="The caller's batches, newest first (without their jobs)",
            responses=problem_responses(401, 422))
def list_batches(
    owner: Owner,
    repository: RepositoryDep,
    limit: PageLimit = DEFAULT_PAGE,
    offset: PageOffset = 0,
) -> BatchPage:
    return batches.list_batches(repository, owner, limit, offset)


@router.get("/{batch_id}", response_model=BatchOut, summary="A batch's state, counts by state, progress and jobs",
            responses=problem_responses(401, 404, 422))
def get_batch(repository: RepositoryDep, batch: OwnedBatch) -> BatchOut:
    return batches.batch_out(repository, batch)


@router.delete("/{batch_id}", response_model=BatchOut, summary="Cancel a batch's jobs that have not ended",
               responses=problem_responses(401, 404, 422))
def cancel_batch(repository: RepositoryDep, queue: QueueDep, batch: OwnedBatch) -> BatchOut:
    return batches.cancel_batch(repository, queue, batch)


@router.get("/{batch_id}/results", summary="Every result of a batch and a manifest, as one zip",
            response_class=FileResponse,
            responses={200: {"content": {"application/zip": {"schema": {"type": "string", "format": "binary"}}}},
                       **problem_responses(401, 404, 409, 410, 422)})
def get_results(repository: RepositoryDep, batch: OwnedBatch):
    return batches.results_response(repository, batch)
