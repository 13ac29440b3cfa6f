"""Errors as problem+json with a stable code."""

from hairport.service.errors import problem_response

from .conftest import AUTH


def test_problem_document():
    response = problem_response(409, "job_not_succeeded", "job x is failed")
    assert response.status_code == 409 and response.media_type == "application/problem+json"
    assert response.body == (b'{"type":"https://hairport.dev/problems/job_not_succeeded","title":"job not succeeded",'
                             b'"status":409,"detail":"job x is failed","code":"job_not_succeeded"}')


def test_framework_errors_become_problems(client):
    invalid = client.get("/v1/jobs", headers=AUTH, params={"limit": 0})
    assert invalid.status_code == 422 and invalid.json()["code"] == "invalid_request"
    assert "limit" in invalid.json()["detail"]
    missing = client.get("/v1/nowhere", headers=AUTH)
    assert missing.status_code == 404 and missing.json()["code"] == "not_found"
    wrong = client.put("/v1/jobs", headers=AUTH)
    assert wrong.status_code == 405 and wrong.json()["code"] == "method_not_allowed"
