"""Headers on every response: nosniff, a request id (the client's if sane), a policy on every page."""

import re

import pytest
from fastapi.testclient import TestClient

from hairport.service import dashboard_ui
from hairport.service.app import create_app
from hairport.service.headers import REQUEST_ID_HEADER, SELF_ONLY_POLICY, is_document, response_headers

from .conftest import AUTH

NEW_ID = re.compile(r"[0-9a-f]{32}")


def test_every_kind_of_response_has_nosniff_and_a_request_id(client, settings):
    small = TestClient(create_app(settings.model_copy(update={"max_upload_bytes": 1000}), readiness=lambda: {},
                                  queue_depths=lambda: {}))
    responses = {
        "route": client.get("/healthz"), "metrics": client.get("/metrics"), "problem": client.get("/v1/jobs"),
        "not found": client.get("/nowhere"), "invalid": client.get("/v1/jobs", headers=AUTH, params={"limit": 0}),
        "redirect": client.get("/ui", follow_redirects=False), "page": client.get("/ui/"),
        "bundle": client.get("/ui/static/app.js"), "docs asset": client.get("/docs-assets/favicon.png"),
        "413 before routing": small.post("/v1/characters", headers={**AUTH, "Content-Length": str(10**9)}, content=b""),
    }
    statuses = {name: response.status_code for name, response in responses.items()}
    assert statuses == {"route": 200, "metrics": 200, "problem": 401, "not found": 404, "invalid": 422,
                        "redirect": 307, "page": 200, "bundle": 200, "docs asset": 200, "413 before routing": 413}
    for name, response in responses.items():
        assert response.headers["x-content-type-options"] == "nosniff", name
        assert NEW_ID.fullmatch(response.headers[REQUEST_ID_HEADER]), name
    assert len({response.headers[REQUEST_ID_HEADER] for response in responses.values()}) == len(responses)


def test_every_html_file_has_a_policy_and_a_page_keeps_its_own(client):
    static_page = client.get("/ui/static/index.html")
    assert static_page.status_code == 200 and static_page.headers["content-type"].startswith("text/html")
    assert static_page.headers["content-security-policy"] == SELF_ONLY_POLICY == dashboard_ui.CONTENT_SECURITY_POLICY
    assert client.get("/ui/").headers["content-security-policy"] == SELF_ONLY_POLICY
    for page in ("/docs", "/redoc"):  # their own policies, with the hashes of their inline blocks
        policy = client.get(page).headers["content-security-policy"]
        assert policy != SELF_ONLY_POLICY and "'sha256-" in policy and "unsafe-inline" not in policy, page
    assert "content-security-policy" not in client.get("/ui/static/app.js").headers  # a script is no document


@pytest.mark.parametrize("media_type, document", [
    ("text/html; charset=utf-8", True), ("TEXT/HTML", True), ("application/xhtml+xml", True),
    ("image/svg+xml", True), ("application/problem+json", False), ("text/plain", False), (None, False)])
def test_documents_are_the_media_types_a_browser_runs_scripts_in(media_type, document):
    assert is_document(media_type) is document
    assert ("Content-Security-Policy" in response_headers("id", media_type)) is document


@pytest.mark.parametrize("sent, kept", [
    ("3f2a9c1e-7b4d-4e8a-9c0f-1a2b3c4d5e6f", True), ("00-4bf92f3577b34da6a3ce929d0e0e4736-00f067aa0ba902b7-01", True),
    ("lb.edge:42_x", True), ("x" * 128, True), ("x" * 129, False), ("two words", False), ("a\tb", False),
    ("", False), ("id;drop", False)])
def test_a_client_request_id_is_kept_only_when_sane(client, sent, kept):
    answered = client.get("/healthz", headers={REQUEST_ID_HEADER: sent}).headers[REQUEST_ID_HEADER]
    assert answered == sent if kept else NEW_ID.fullmatch(answered) and answered != sent
