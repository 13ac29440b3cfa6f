"""``/v1/retargets``: one queued job per target, options checked at the door, idempotent repeats (no worker here)."""

import pytest

from hairport.worker.app import RETARGET_QUEUE

from ..conftest import AUTH
from .test_hairstyles import waiting
from .uploads import upload_character, write_inputs


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    return write_inputs(tmp_path_factory.mktemp("retargets"))


@pytest.fixture
def ids(client, files) -> dict:
    source, target = upload_character(client, files, "source"), upload_character(client, files, "target")
    hairstyle = client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": source, "guides": "5"},
                            files={"hair": ("g.data", files["groom.data"])}).json()["id"]
    return {"source": source, "target": target, "hairstyle": hairstyle}


def test_one_job_per_target(client, ids):
    response = client.post("/v1/retargets", headers=AUTH, json={
        "hairstyle_id": ids["hairstyle"], "target_character_ids": [ids["target"], ids["source"]],
        "options": {"max_iterations": 4}, "output_format": "ply"})
    assert response.status_code == 202
    jobs = response.json()["jobs"]
    assert response.headers["location"] == f"/v1/jobs/{jobs[0]['id']}"
    assert [job["target_character_id"] for job in jobs] == [ids["target"], ids["source"]]
    assert all(job["state"] == "queued" and job["output_format"] == "ply" for job in jobs)
    assert jobs[0]["options"]["max_iterations"] == 4 and "guides" not in jobs[0]["options"]
    assert waiting(client, RETARGET_QUEUE) == 2
    assert client.get("/v1/jobs", headers=AUTH).json()["total"] == 2


def test_idempotency(client, ids):
    request = {"hairstyle_id": ids["hairstyle"], "target_character_ids": [ids["target"]]}
    headers = {**AUTH, "Idempotency-Key": "order-17"}
    first = client.post("/v1/retargets", headers=headers, json=request).json()
    again = client.post("/v1/retargets", headers=headers, json=request).json()
    assert [job["id"] for job in first["jobs"]] == [job["id"] for job in again["jobs"]]
    assert waiting(client, RETARGET_QUEUE) == 1
    conflict = client.post("/v1/retargets", headers=headers, json={**request, "output_format": "npz"})
    assert (conflict.status_code, conflict.json()["code"]) == (422, "idempotency_conflict")
    long_key = client.post("/v1/retargets", headers={**AUTH, "Idempotency-Key": "k" * 201}, json=request)
    # the schema states the length, so the framework refuses it as any schema violation
    assert (long_key.status_code, long_key.json()["code"]) == (422, "invalid_request")
    assert "idempotency-key" in long_key.json()["detail"] and "200" in long_key.json()["detail"]


@pytest.mark.parametrize("change, code", [
    ({"options": {"method": "teleport"}}, "unknown_method"),
    ({"options": {"beta": -1}}, "bad_option"),
    ({"options": {"max_iterations": 0}}, "bad_option"),
    ({"options": {"wrap": "sometimes"}}, "invalid_request"),
    ({"options": {"method": "rbf-warp"}, "hairline": {"preset": "round"}}, "bad_option"),
    ({"hairline": {"preset": "round", "amount": 2}}, "invalid_request"),
    ({"target_character_ids": ["0" * 32]}, "not_found"),
])
def test_refusals_at_the_door(client, ids, change, code):
    request = {"hairstyle_id": ids["hairstyle"], "target_character_ids": [ids["target"]], **change}
    response = client.post("/v1/retargets", headers=AUTH, json=request)
    assert response.json()["code"] == code and response.status_code in (404, 422)
    assert waiting(client, RETARGET_QUEUE) == 0 and client.get("/v1/jobs", headers=AUTH).json()["total"] == 0


def test_the_wrap_mode_is_taken_and_kept_on_the_job(client, ids):
    response = client.post("/v1/retargets", headers=AUTH, json={
        "hairstyle_id": ids["hairstyle"], "target_character_ids": [ids["target"]], "options": {"wrap": "off"}})
    assert response.status_code == 202 and response.json()["jobs"][0]["options"]["wrap"] == "off"
    default = client.post("/v1/retargets", headers=AUTH, json={
        "hairstyle_id": ids["hairstyle"], "target_character_ids": [ids["target"]]}).json()
    assert default["jobs"][0]["options"]["wrap"] == "auto"
    refused = client.post("/v1/retargets", headers=AUTH, json={
        "hairstyle_id": ids["hairstyle"], "target_character_ids": [ids["target"]], "options": {"wrap": "never"}})
    assert (refused.status_code, refused.json()["code"]) == (422, "invalid_request")
    assert "options.wrap" in refused.json()["detail"] and "'auto', 'always' or 'off'" in refused.json()["detail"]


MARKS = {"source": {"crown": [0.0, 1.7, 0.0], "chin": [0.0, 1.5, 0.1]},
         "target": {"crown": [0.0, 1.8, 0.0], "chin": [0.0, 1.6, 0.1]}}


@pytest.mark.parametrize("change, code, words", [
    ({"landmarks": {**MARKS, "target": {"crown": [0.0, 1.8, 0.0]}}}, "bad_landmarks", "'chin' named on the source only"),
    ({"landmarks": MARKS, "options": {"wrap": "off"}}, "bad_landmarks", "never wraps"),
    ({"landmarks": MARKS, "target_character_ids": ["T", "T"]}, "bad_landmarks", "one target"),
    ({"landmarks": {**MARKS, "source": {"crown": [0.0, 1.7]}}}, "invalid_request", "landmarks.source.crown"),
    ({"landmarks": {**MARKS, "source": {"crown": [0.0, "nan", 0.0]}}}, "invalid_request", "landmarks.source.crown"),
    ({"landmarks": {**MARKS, "source": {}}}, "invalid_request", "landmarks.source"),
    ({"landmarks": {**MARKS, "source": {f"p{i}": [0.0, 0.0, 0.0] for i in range(33)}}}, "invalid_request",
     "landmarks.source"),
])
def test_landmarks_are_checked_at_the_door(client, ids, change, code, words):
    request = {"hairstyle_id": ids["hairstyle"], "target_character_ids": [ids["target"]], **change}
    request["target_character_ids"] = [ids["target"] if t == "T" else t for t in request["target_character_ids"]]
    response = client.post("/v1/retargets", headers=AUTH, json=request)
    assert (response.status_code, response.json()["code"]) == (422, code) and words in response.json()["detail"]
    assert waiting(client, RETARGET_QUEUE) == 0 and client.get("/v1/jobs", headers=AUTH).json()["total"] == 0


def test_landmarks_are_kept_on_the_job(client, ids):
    response = client.post("/v1/retargets", headers=AUTH, json={
        "hairstyle_id": ids["hairstyle"], "target_character_ids": [ids["target"]], "landmarks": MARKS})
    assert response.status_code == 202 and response.json()["jobs"][0]["landmarks"] == MARKS
    job = client.get(f"/v1/jobs/{response.json()['jobs'][0]['id']}", headers=AUTH).json()
    assert job["landmarks"] == MARKS


def test_too_many_targets(client, ids, settings):
    request = {"hairstyle_id": ids["hairstyle"], "target_character_ids": [ids["target"]] * 65}
    response = client.post("/v1/retargets", headers=AUTH, json=request)
    assert (response.status_code, response.json()["code"]) == (422, "too_many_targets")
    assert str(settings.max_targets_per_request) in response.json()["detail"]
