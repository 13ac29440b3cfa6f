"""Errors as problem+json with a stable code; a defect as an ``internal`` problem with a logged request id."""

import re

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


def raising_client(settings):
    """The app with one more route that fails as a defect would (an exception no handler knows)."""
    from fastapi.testclient import TestClient

    from hairport.service.app import create_app

    app = create_app(settings, readiness=lambda: {}, queue_depths=lambda: {})

    @app.get("/v1/defect")
    def defect():
        raise RuntimeError("secret-internals-7731")

    return TestClient(app, raise_server_exceptions=False)


def test_an_unexpected_error_is_an_internal_problem_whose_request_id_is_logged(settings, caplog):
    client = raising_client(settings)
    with caplog.at_level("ERROR", logger="hairport.service.errors"):
        given = client.get("/v1/defect", headers={"X-Request-ID": "trace-42.a"})
        made = client.get("/v1/defect")
    for response in (given, made):
        assert response.status_code == 500 and response.headers["content-type"] == "application/problem+json"
        body = response.json()
        assert body["code"] == "internal" and body["type"].endswith("/internal") and body["status"] == 500
        assert body["request_id"] == response.headers["x-request-id"]
        assert response.headers["x-content-type-options"] == "nosniff"  # set outside the middlewares too
        assert response.headers["connection"] == "close"  # the server closes it after an unhandled error
        assert "secret-internals-7731" not in response.text and "Traceback" not in response.text
    assert given.json()["request_id"] == "trace-42.a"
    assert re.fullmatch(r"[0-9a-f]{32}", made.json()["request_id"])
    logged = [record for record in caplog.records if record.name == "hairport.service.errors"]
    assert [record.getMessage().split(":")[0] for record in logged] == [
        "internal error, request id trace-42.a", f"internal error, request id {made.json()['request_id']}"]
    for record in logged:  # the traceback, with what the client was not told
        assert record.exc_info[0] is RuntimeError and "/v1/defect" in record.getMessage()
        assert "secret-internals-7731" in caplog.text


def test_every_operation_documents_its_internal_problem(client):
    document = client.get("/openapi.json").json()
    assert "request_id" in document["components"]["schemas"]["Problem"]["properties"]
    operations = [operation for path, methods in document["paths"].items() if path.startswith("/v1/")
                  for operation in methods.values()]
    assert len(operations) >= 20
    for operation in operations:
        internal = operation["responses"]["500"]
        assert "`internal`" in internal["description"] and "X-Request-ID" in internal["headers"]
