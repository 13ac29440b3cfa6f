"""The app: the declared-size limit before any body is read, CORS."""

from fastapi.testclient import TestClient

from hairport.service.app import create_app

from .conftest import AUTH


def test_a_declared_body_over_the_limit_is_refused_unread(settings):
    small = TestClient(create_app(settings.model_copy(update={"max_upload_bytes": 1000}),
                                  readiness=lambda: {}, queue_depths=lambda: {}))
    response = small.post("/v1/characters", headers={**AUTH, "Content-Length": str(10**9)}, content=b"")
    assert response.status_code == 413 and response.json()["code"] == "upload_too_large"
    assert "1,000,000,000 bytes" in response.json()["detail"]


def test_cors_only_for_configured_origins(settings):
    app = create_app(settings.model_copy(update={"cors_origins": "https://studio.example"}), readiness=lambda: {},
                     queue_depths=lambda: {})
    client = TestClient(app)
    preflight = {"Access-Control-Request-Method": "POST"}
    allowed = client.options("/v1/jobs", headers={"Origin": "https://studio.example", **preflight})
    assert allowed.headers["access-control-allow-origin"] == "https://studio.example"
    other = client.options("/v1/jobs", headers={"Origin": "https://evil.example", **preflight})
    assert "access-control-allow-origin" not in other.headers
