"""Batches: every hairstyle onto every target character in one request, one job per pair.

A batch is a record listing its jobs (hairstyles x targets, row by row); its state, counts and
progress are its jobs' (:class:`hairport.records.BatchTotals`): summed from the job records when one
batch is asked for (with its jobs), and read from the record index for a listing, whose items carry
no jobs, so that a page of batches reads the page's batch records only. Per-pair options (and
hairline edits) replace the batch's for that pair. Cancelling a batch cancels its jobs that have
not ended; its results are one zip of every succeeded pair's result and report, with a manifest
of every pair.
"""

from __future__ import annotations

import json
import zipfile
from collections import Counter
from pathlib import Path

from fastapi.responses import FileResponse
from starlette.background import BackgroundTask

from hairport.records import (
    BATCH_DONE,
    FROM_ANIMATION,
    SUCCEEDED,
    BatchRecord,
    BatchTotals,
    CharacterRecord,
    HairstyleRecord,
    IdempotencyRecord,
    JobRecord,
    digest,
    new_job_id,
    now,
)
from hairport.repository import Repository
from hairport.settings import Settings
from hairport.worker.queue import TaskQueue

from ..deps import owned
from ..errors import Problem
from ..schemas import BatchIn, BatchJobOut, BatchOut, BatchPage, BatchSummary
from . import jobs as job_service
from . import sequences
from .retargets import idempotent_replay, plan_job, submit_jobs

MANIFEST = "manifest.json"


def create_batch(repository: Repository, queue: TaskQueue, settings: Settings, owner: str, request: BatchIn,
                 idempotency_key: str | None) -> BatchRecord:
    """Create a batch and one job per hairstyle x target pair, and send them (or replay an earlier request)."""
    body = request.model_dump(mode="json")
    replay_id, previous = idempotent_replay(repository, owner, idempotency_key, body)
    if previous is not None and previous.batch_id is not None:
        batch = repository.get(BatchRecord, previous.batch_id)
        if batch is not None:
            return batch
    pairs = len(request.hairstyle_ids) * len(request.target_character_ids)
    if pairs > settings.max_batch_jobs:
        raise Problem(422, "too_many_jobs", f"a batch may have at most {settings.max_batch_jobs} hairstyle x target "
                                            f"pairs (HAIRPORT_MAX_BATCH_JOBS), this one has {pairs}")
    for field, ids in (("hairstyle_ids", request.hairstyle_ids), ("target_character_ids", request.target_character_ids)):
        repeated = sorted(name for name, count in Counter(ids).items() if count > 1)
        if repeated:
            raise Problem(422, "duplicate_ids", f"{field} lists {', '.join(repeated)} more than once")
    hairstyles = [owned(repository, HairstyleRecord, owner, i, "hairstyle") for i in request.hairstyle_ids]
    targets = [owned(repository, CharacterRecord, owner, i, "character") for i in request.target_character_ids]
    overrides = {}
    for item in request.items:
        pair = (item.hairstyle_id, item.target_character_id)
        if item.hairstyle_id not in request.hairstyle_ids or item.target_character_id not in request.target_character_ids:
            raise Problem(422, "unknown_pair", f"items: {pair[0]} x {pair[1]} is not a pair of this batch")
        if pair in overrides:
            raise Problem(422, "duplicate_ids", f"items: {pair[0]} x {pair[1]} is given more than once")
        overrides[pair] = item
    output_format = sequences.output_format(request.output_format, request.sequence)
    if request.sequence is not None and request.sequence.frames_from != FROM_ANIMATION:
        raise Problem(422, "bad_frames", f"sequence.frames_from: a batch's targets are each an animated character "
                                         f"({FROM_ANIMATION}); send the frames of characters as a retarget request")
    batch_id = new_job_id()
    planned = []
    for hairstyle in hairstyles:
        for target in targets:
            item = overrides.get((hairstyle.id, target.id))
            options = request.options if item is None or item.options is None else item.options
            hairline = body["hairline"] if item is None or "hairline" not in item.model_fields_set else (
                None if item.hairline is None else item.hairline.model_dump(mode="json"))
            plan = None if request.sequence is None else sequences.sequence_plans(
                request.sequence, [target], hairstyle, options, settings, None)[0][1]
            planned.append(plan_job(repository, settings, owner, hairstyle, target, options, hairline,
                                    output_format, request.flag_guides, batch_id, sequence=plan))
    batch = BatchRecord(id=batch_id, owner=owner, created_at=now(), hairstyle_ids=request.hairstyle_ids,
                        target_character_ids=request.target_character_ids, output_format=output_format,
                        job_ids=[plan.job.id for plan in planned])
    repository.put(batch, batch.id)
    remember = None if replay_id is None else (replay_id, IdempotencyRecord(
        request=digest(body), jobs=batch.job_ids, batch_id=batch.id, created_at=now()))
    submit_jobs(repository, queue, settings, planned, remember,
                undo=lambda: repository.delete(BatchRecord, batch.id))
    return batch


def batch_jobs(repository: Repository, batch: BatchRecord) -> list[JobRecord]:
    """The batch's jobs, in its order (a job purged by retention is left out)."""
    return [job for job in map(repository.job, batch.job_ids) if job is not None]


def batch_out(repository: Repository, batch: BatchRecord) -> BatchOut:
    """The batch as the API shows it: its state, counts by state and progress, and its jobs, from its jobs' records."""
    jobs = batch_jobs(repository, batch)
    return BatchOut(
        **summary_fields(batch, BatchTotals.of_jobs(jobs)),
        jobs=[BatchJobOut(id=job.id, hairstyle_id=job.hairstyle_id, target_character_id=job.target_character_id,
                          state=job.state, progress=job.progress, error=job.error,
                          links={"self": f"/v1/jobs/{job.id}"}) for job in jobs],
    )


def list_batches(repository: Repository, owner: str, limit: int, offset: int) -> BatchPage:
    """A page of the owner's batches, newest first, without their jobs: the page's batch records and the record
    index are read, no job record."""
    page, total = repository.list_owned(BatchRecord, owner, limit, offset)
    totals = repository.batch_totals(batch.id for batch in page)
    return BatchPage(batches=[BatchSummary(**summary_fields(batch, totals[batch.id])) for batch in page], total=total,
                     limit=limit, offset=offset, next_offset=offset + limit if offset + limit < total else None)


def summary_fields(batch: BatchRecord, totals: BatchTotals) -> dict:
    """What a listing and a batch's own page both show of it."""
    state = totals.state
    base = f"/v1/batches/{batch.id}"
    links = {"self": base} | ({"results": f"{base}/results"} if state == BATCH_DONE else {})
    return dict(id=batch.id, state=state, counts=totals.counts, progress=totals.progress, created_at=batch.created_at,
                finished_at=totals.ended_at, hairstyle_ids=batch.hairstyle_ids,
                target_character_ids=batch.target_character_ids, output_format=batch.output_format, links=links)


def batch_state(jobs: list[JobRecord]) -> str:
    return BatchTotals.of_jobs(jobs).state


def cancel_batch(repository: Repository, queue: TaskQueue, batch: BatchRecord) -> BatchOut:
    """Cancel every job of the batch that has not ended (a running one stops at its solver's next iteration):
    every cancel is written to its job's record first, then their messages are revoked in one broadcast,
    which a broker that is down skips without undoing any cancel (see :func:`jobs.cancel_job`)."""
    task_ids = []
    for job in batch_jobs(repository, batch):
        task_ids += job_service.request_cancel(repository, job)[1]
    queue.revoke(*task_ids)
    return batch_out(repository, batch)


def results_response(repository: Repository, batch: BatchRecord) -> FileResponse:
    """One zip: ``manifest.json`` (every pair: its job, state, error, files, metrics) and, per succeeded pair, its
    result and report under ``<hairstyle>__<target>/``; 409 until every job has ended."""
    jobs = batch_jobs(repository, batch)
    if batch_state(jobs) != BATCH_DONE:
        raise Problem(409, "batch_not_finished", f"batch {batch.id} has jobs that have not ended; its results are "
                                                 "ready when its state is done")
    work = repository.storage.work_dir()
    folder = work.__enter__()
    path = folder / f"{batch.id}.zip"
    try:
        _write_zip(repository, batch, jobs, path)
    except BaseException:
        work.__exit__(None, None, None)
        raise
    return FileResponse(path, media_type="application/zip", filename=f"batch-{batch.id}.zip",
                        background=BackgroundTask(work.__exit__, None, None, None))


def _write_zip(repository: Repository, batch: BatchRecord, jobs: list[JobRecord], path: Path) -> None:
    manifest = {"batch": batch.id, "created_at": batch.created_at, "output_format": batch.output_format, "pairs": []}
    with zipfile.ZipFile(path, "w", allowZip64=True) as archive:
        for job in jobs:
            folder = f"{job.hairstyle_id}__{job.target_character_id}"
            entry = {"job": job.id, "hairstyle_id": job.hairstyle_id, "target_character_id": job.target_character_id,
                     "state": job.state, "error": None if job.error is None else job.error.model_dump(),
                     "metrics": job.metrics, "files": {}}
            if job.state == SUCCEEDED:
                result = job_service.result_file(repository, job, job.output_format, path.parent)
                report = repository.storage.blob(job.outputs["report"].sha256, job.outputs["report"].suffix)
                if report is None:
                    raise Problem(410, "gone", f"job {job.id}'s report was removed by the retention policy")
                # results are binary arrays that barely compress; reports are text
                entry["files"]["result"] = f"{folder}/result.{job.output_format}"
                archive.write(result, entry["files"]["result"], zipfile.ZIP_STORED)
                entry["files"]["report"] = f"{folder}/report.json"
                archive.write(report.path, entry["files"]["report"], zipfile.ZIP_DEFLATED)
            manifest["pairs"].append(entry)
        archive.writestr(MANIFEST, json.dumps(manifest, indent=2) + "\n", zipfile.ZIP_DEFLATED)
