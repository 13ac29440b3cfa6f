"""``/v1/batches``: one queued job per hairstyle x target pair, per-pair options, counts read from the jobs,
cancel, the results zip and its manifest (no worker here: job outcomes are written by hand)."""

import io
import json
import os
import zipfile

import pytest

from hairport.records import BlobRef, JobRecord
from hairport.worker.app import RETARGET_QUEUE

from ..conftest import AUTH
from .test_hairstyles import waiting
from .uploads import upload_character, write_inputs


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    return write_inputs(tmp_path_factory.mktemp("batches"))


@pytest.fixture
def ids(client, files) -> dict:
    source, target = upload_character(client, files, "source"), upload_character(client, files, "target")
    styles = [client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": source, "guides": guides},
                          files={"hair": ("g.data", files["groom.data"])}).json()["id"] for guides in ("5", "7")]
    return {"source": source, "target": target, "hairstyles": styles}


def batch(client, ids, **fields):
    return client.post("/v1/batches", headers=AUTH, json={
        "hairstyle_ids": ids["hairstyles"], "target_character_ids": [ids["source"], ids["target"]], **fields})


def test_one_job_per_pair_with_per_pair_options(client, ids):
    first, second = ids["hairstyles"]
    response = batch(client, ids, options={"max_iterations": 4}, output_format="ply", items=[
        {"hairstyle_id": second, "target_character_id": ids["target"], "options": {"max_iterations": 9},
         "hairline": {"preset": "round", "amount": 0.5}}])
    assert response.status_code == 202, response.text
    body = response.json()
    assert response.headers["location"] == f"/v1/batches/{body['id']}" == body["links"]["self"]
    assert body["state"] == "queued" and body["counts"]["queued"] == 4 and sum(body["counts"].values()) == 4
    assert body["progress"] == 0.0 and "results" not in body["links"]
    pairs = [(job["hairstyle_id"], job["target_character_id"]) for job in body["jobs"]]
    assert pairs == [(first, ids["source"]), (first, ids["target"]), (second, ids["source"]), (second, ids["target"])]
    jobs = [client.get(job["links"]["self"], headers=AUTH).json() for job in body["jobs"]]
    assert [job["options"]["max_iterations"] for job in jobs] == [4, 4, 4, 9]
    assert all(job["output_format"] == "ply" for job in jobs)
    records = [client.app.state.repository.job(job["id"]) for job in jobs]
    assert [record.hairline for record in records][:3] == [None] * 3 and records[3].hairline["preset"] == "round"
    assert {record.batch_id for record in records} == {body["id"]}
    assert waiting(client, RETARGET_QUEUE) == 4
    listed = client.get("/v1/batches", headers=AUTH).json()
    assert listed["total"] == 1 and listed["batches"][0]["id"] == body["id"]


@pytest.mark.parametrize("change, status, code", [
    ({"items": [{"hairstyle_id": "0" * 32, "target_character_id": "1" * 32}]}, 422, "unknown_pair"),
    ({"hairstyle_ids": ["0" * 32]}, 404, "not_found"),
    ({"options": {"max_iterations": 0}}, 422, "bad_option"),
    ({"options": {"method": "teleport"}}, 422, "unknown_method"),
    ({"hairstyle_ids": []}, 422, "invalid_request"),
    ({"unknown": 1}, 422, "invalid_request"),
])
def test_a_refused_batch_keeps_nothing(client, ids, change, status, code):
    response = batch(client, ids, **change)
    assert (response.status_code, response.json()["code"]) == (status, code), response.text
    assert client.get("/v1/batches", headers=AUTH).json()["total"] == 0
    assert client.get("/v1/jobs", headers=AUTH).json()["total"] == 0
    assert waiting(client, RETARGET_QUEUE) == 0


def test_repeated_ids_a_bad_item_and_too_many_pairs_are_refused(client, ids, settings):
    first = ids["hairstyles"][0]
    twice = batch(client, ids, hairstyle_ids=[first, first])
    assert (twice.status_code, twice.json()["code"]) == (422, "duplicate_ids") and first in twice.json()["detail"]
    item = {"hairstyle_id": first, "target_character_id": ids["target"], "options": {"beta": -1}}
    bad = batch(client, ids, items=[item])
    assert (bad.status_code, bad.json()["code"]) == (422, "bad_option")
    repeated = batch(client, ids, items=[{**item, "options": {}}, {**item, "options": {}}])
    assert (repeated.status_code, repeated.json()["code"]) == (422, "duplicate_ids")
    settings.max_batch_jobs = 3
    try:
        big = batch(client, ids)
    finally:
        settings.max_batch_jobs = 256
    assert (big.status_code, big.json()["code"]) == (422, "too_many_jobs") and "has 4" in big.json()["detail"]
    assert client.get("/v1/jobs", headers=AUTH).json()["total"] == 0


def test_a_repeated_request_with_its_key_is_the_same_batch(client, ids):
    headers = {**AUTH, "Idempotency-Key": "grid-1"}
    request = {"hairstyle_ids": ids["hairstyles"], "target_character_ids": [ids["target"]]}
    first = client.post("/v1/batches", headers=headers, json=request).json()
    again = client.post("/v1/batches", headers=headers, json=request).json()
    assert first["id"] == again["id"] and waiting(client, RETARGET_QUEUE) == 2
    other = client.post("/v1/batches", headers=headers, json={**request, "output_format": "npz"})
    assert (other.status_code, other.json()["code"]) == (422, "idempotency_conflict")


def test_another_owner_sees_no_batch(client, ids, settings):
    body = batch(client, ids).json()
    settings.api_keys = "unit-key,other-key"
    other = {"Authorization": "Bearer other-key"}
    assert client.get(f"/v1/batches/{body['id']}", headers=other).status_code == 404
    assert client.delete(f"/v1/batches/{body['id']}", headers=other).status_code == 404
    assert client.get("/v1/batches", headers=other).json()["total"] == 0


def succeed(repository, job_id: str, payload: bytes) -> None:
    """Mark a job succeeded with a result and a report, as a worker would."""
    job = repository.job(job_id)
    result = repository.storage.save_bytes(payload, f".{job.output_format}")
    report = repository.storage.save_bytes(b'{"metrics": {}}\n', ".json")
    outputs = {job.output_format: BlobRef(sha256=result.sha256, suffix=f".{job.output_format}", size=result.size),
               "report": BlobRef(sha256=report.sha256, suffix=".json", size=report.size)}
    repository.set_job(job_id, state="succeeded", progress=1.0, finished_at=1.0, outputs=outputs,
                       metrics={"penetrating_particles": 0})


def test_a_batch_cancel_with_the_broker_down_cancels_every_waiting_job(client, client_without_broker, ids, caplog):
    """Never half-cancelled: with the broker down, every job that has not ended is cancelled (the queued ones at
    once, the running one at its next iteration) and their messages are revoked in one try, logged as failed."""
    repository = client.app.state.repository
    body = batch(client, ids).json()
    job_ids = [job["id"] for job in body["jobs"]]
    repository.set_job(job_ids[0], state="running")
    with caplog.at_level("WARNING", logger="hairport.worker.queue"):
        cancelled = client_without_broker.delete(body["links"]["self"], headers=AUTH)
    assert cancelled.status_code == 200, cancelled.text
    assert (cancelled.json()["counts"]["cancelled"], cancelled.json()["counts"]["running"]) == (3, 1)
    assert all(repository.job(job_id).cancel_requested for job_id in job_ids)
    unrevoked = [record.getMessage() for record in caplog.records if "not revoked" in record.getMessage()]
    assert len(unrevoked) == 1  # one broadcast for the batch, not one wait per job
    assert all(repository.job(job_id).task_id in unrevoked[0] for job_id in job_ids[1:])
    again = client_without_broker.delete(body["links"]["self"], headers=AUTH)
    assert again.json()["counts"] == cancelled.json()["counts"]


def test_counts_cancel_and_the_results_zip(client, ids):
    repository = client.app.state.repository
    body = batch(client, ids, output_format="ply").json()
    first, second = body["jobs"][0]["id"], body["jobs"][1]["id"]
    succeed(repository, first, b"ply result bytes")
    repository.set_job(second, state="running", progress=0.5)
    running = client.get(body["links"]["self"], headers=AUTH).json()
    assert running["state"] == "running"
    assert (running["counts"]["succeeded"], running["counts"]["running"], running["counts"]["queued"]) == (1, 1, 2)
    assert running["progress"] == pytest.approx((1.0 + 0.5) / 4)
    early = client.get(f"{body['links']['self']}/results", headers=AUTH)
    assert (early.status_code, early.json()["code"]) == (409, "batch_not_finished")

    cancelled = client.delete(body["links"]["self"], headers=AUTH).json()
    assert cancelled["counts"]["succeeded"] == 1 and cancelled["counts"]["cancelled"] == 2
    assert cancelled["counts"]["running"] == 1  # a running job stops at its solver's next iteration
    assert repository.job(second).cancel_requested
    repository.set_job(second, state="cancelled", finished_at=2.0)
    done = client.get(body["links"]["self"], headers=AUTH).json()
    assert done["state"] == "done" and done["progress"] == 1.0 and done["links"]["results"].endswith("/results")

    response = client.get(done["links"]["results"], headers=AUTH)
    assert response.status_code == 200 and response.headers["content-type"] == "application/zip"
    archive = zipfile.ZipFile(io.BytesIO(response.content))
    manifest = json.loads(archive.read("manifest.json"))
    assert [pair["state"] for pair in manifest["pairs"]] == ["succeeded", "cancelled", "cancelled", "cancelled"]
    folder = f"{ids['hairstyles'][0]}__{ids['source']}"
    assert manifest["pairs"][0]["files"] == {"result": f"{folder}/result.ply", "report": f"{folder}/report.json"}
    assert archive.read(f"{folder}/result.ply") == b"ply result bytes"
    assert sorted(archive.namelist()) == sorted(["manifest.json", f"{folder}/result.ply", f"{folder}/report.json"])
    assert all(pair["files"] == {} for pair in manifest["pairs"][1:])
    assert list(repository.storage.work_root.iterdir()) == []  # the zip's scratch folder is gone


def test_a_purged_result_is_gone(client, ids):
    repository = client.app.state.repository
    body = batch(client, ids, hairstyle_ids=ids["hairstyles"][:1], target_character_ids=[ids["target"]]).json()
    job_id = body["jobs"][0]["id"]
    succeed(repository, job_id, b"result")
    job: JobRecord = repository.job(job_id)
    ref = job.outputs[job.output_format]
    repository.storage.blob(ref.sha256, ref.suffix).path.unlink()
    response = client.get(f"/v1/batches/{body['id']}/results", headers=AUTH)
    assert (response.status_code, response.json()["code"]) == (410, "gone")
    assert list(repository.storage.work_root.iterdir()) == []


def listed_and_own(client) -> tuple[list[dict], list[dict]]:
    """The batches of the listing, and each one's own page without its jobs."""
    listed = client.get("/v1/batches", headers=AUTH).json()["batches"]
    own = [client.get(item["links"]["self"], headers=AUTH).json() for item in listed]
    return listed, [{key: value for key, value in page.items() if key != "jobs"} for page in own]


def test_a_listing_shows_each_batch_as_its_own_page_does_without_its_jobs(client, ids):
    repository = client.app.state.repository
    first = batch(client, ids).json()
    second = batch(client, ids, hairstyle_ids=ids["hairstyles"][:1]).json()
    jobs = [job["id"] for job in first["jobs"]]
    succeed(repository, jobs[0], b"result")
    repository.set_job(jobs[1], state="running", progress=0.3)
    repository.set_job(jobs[1], progress=0.6125)
    listed, own = listed_and_own(client)
    assert [item["id"] for item in listed] == [second["id"], first["id"]] and listed == own
    assert "jobs" not in listed[0] and listed[1]["progress"] == round((1 + 0.6125) / 4, 4)
    assert listed[1]["counts"]["running"] == 1 and listed[1]["state"] == "running"
    assert client.delete(second["links"]["self"], headers=AUTH).status_code == 200
    listed, own = listed_and_own(client)
    assert listed == own and listed[0]["state"] == "done" and listed[0]["counts"]["cancelled"] == 2
    assert listed[0]["finished_at"] is not None and listed[0]["links"]["results"].endswith("/results")
    for job_id in jobs[1:]:
        repository.set_job(job_id, state="failed", finished_at=5.0)
    record = repository.storage.records_dir / "jobs" / f"{jobs[0]}.json"
    os.utime(record, (0, 0))
    repository.purge(older_than_seconds=3600.0)  # the succeeded job goes: its batch counts 3 failed ones
    repository.rebuild_index()
    listed, own = listed_and_own(client)
    assert listed == own and listed[1]["counts"]["failed"] == 3 and sum(listed[1]["counts"].values()) == 3
    assert listed[1]["finished_at"] == 5.0 and listed[1]["progress"] == 1.0


def test_a_listing_reads_the_batch_records_of_its_page_and_no_job_record(client, ids, monkeypatch):
    small = batch(client, ids, hairstyle_ids=ids["hairstyles"][:1], target_character_ids=[ids["target"]]).json()
    large = batch(client, ids).json()
    assert len(small["jobs"]) == 1 and len(large["jobs"]) == 4
    storage = client.app.state.repository.storage
    reads = []
    original = storage.get_record_text
    monkeypatch.setattr(storage, "get_record_text", lambda kind, rid: reads.append(kind) or original(kind, rid))
    page = client.get("/v1/batches", headers=AUTH, params={"limit": 1}).json()
    assert [item["id"] for item in page["batches"]] == [large["id"]] and page["total"] == 2
    assert page["batches"][0]["counts"]["queued"] == 4 and reads == ["batches"]
    reads.clear()
    assert client.get("/v1/batches", headers=AUTH).json()["total"] == 2 and reads == ["batches", "batches"]
