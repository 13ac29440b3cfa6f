"""``/v1/retargets``: one job per target character; ``Idempotency-Key`` makes retries safe."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Header, Response

from hairport.solver import pipeline
from hairport.worker import jobs

from ..auth import Owner
from ..deps import SettingsDep, StorageDep
from ..errors import Problem
from ..schemas import JobsCreated, RetargetIn
from ..uploads import input_problem
from .characters import owned_character
from .hairstyles import owned_hairstyle
from .jobs import job_out

router = APIRouter(prefix="/v1/retargets", tags=["retargets"])
#: longest Idempotency-Key accepted (characters)
MAX_IDEMPOTENCY_KEY = 200


@router.post("", status_code=202, response_model=JobsCreated, summary="Retarget a hairstyle onto targets")
def create_retargets(
    owner: Owner,
    settings: SettingsDep,
    storage: StorageDep,
    request: RetargetIn,
    response: Response,
    idempotency_key: Annotated[str | None, Header(description="repeat a request safely")] = None,
) -> JobsCreated:
    body = request.model_dump(mode="json")
    replay_id = None
    if idempotency_key is not None:
        if not 0 < len(idempotency_key) <= MAX_IDEMPOTENCY_KEY:
            raise Problem(422, "bad_idempotency_key", f"Idempotency-Key must have 1-{MAX_IDEMPOTENCY_KEY} characters")
        replay_id = jobs.owned_id(owner, jobs.digest("idempotency", idempotency_key))
        previous = storage.get_record("idempotency", replay_id)
        if previous is not None:
            if previous["request"] != jobs.digest(body):
                raise Problem(422, "idempotency_conflict", "this Idempotency-Key was used with a different request")
            return _created(storage, response, previous["jobs"])
    if len(request.target_character_ids) > settings.max_targets_per_request:
        raise Problem(422, "too_many_targets",
                      f"at most {settings.max_targets_per_request} targets per request, got {len(request.target_character_ids)}")
    hairstyle = owned_hairstyle(storage, owner, request.hairstyle_id)
    targets = [owned_character(storage, owner, target_id) for target_id in request.target_character_ids]
    options = request.options.model_dump()
    preprocess_options = {"k": options.pop("k") or hairstyle["options"]["k"],
                          "guides": options.pop("guides") or hairstyle["options"]["guides"]}
    hairline = body["hairline"]
    try:
        pipeline.RetargetOptions(**options).validate()
        pipeline.PreprocessOptions(**preprocess_options).validate()
    except pipeline.InputError as error:
        raise input_problem(error, "options") from None
    if hairline is not None:
        try:
            pipeline.RetargetOptions(**options, hairline=pipeline.hairline_edit_from_request(hairline)).validate()
        except pipeline.InputError as error:
            raise input_problem(error, "hairline") from None
    key = hairstyle["artifact_key"]
    if preprocess_options != hairstyle["options"]:
        key = jobs.variant_key(storage, hairstyle, preprocess_options, pipeline.ARTIFACT_FORMAT_VERSION)
    created = []
    for target in targets:
        job_id = jobs.new_job_id()
        storage.put_record("jobs", job_id, {
            "id": job_id, "owner": owner, "kind": "retarget", "state": jobs.QUEUED, "stage": "queued",
            "progress": 0.0, "hairstyle_id": hairstyle["id"], "target_character_id": target["id"],
            "options": options, "hairline": hairline, "preprocess_options": preprocess_options, "artifact_key": key,
            "output_format": request.output_format, "attempts": 0,
            "created_at": jobs.now(), "updated_at": jobs.now(),
        })
        created.append(job_id)
    if replay_id is not None:
        storage.put_record("idempotency", replay_id, {"request": jobs.digest(body), "jobs": created,
                                                       "created_at": jobs.now()})
    if jobs.preprocessing_status(storage, hairstyle, key)["state"] in (jobs.QUEUED, jobs.FAILED):
        jobs.start_preprocessing(storage, hairstyle, preprocess_options if key != hairstyle["artifact_key"] else None, key)
    for job_id in created:
        jobs.set_job(storage, job_id, task_id=jobs.enqueue_retarget(job_id))
    return _created(storage, response, created)


def _created(storage, response: Response, job_ids: list[str]) -> JobsCreated:
    records = [storage.get_record("jobs", job_id) for job_id in job_ids]
    response.headers["Location"] = f"/v1/jobs/{job_ids[0]}"
    return JobsCreated(jobs=[job_out(record) for record in records if record is not None])
