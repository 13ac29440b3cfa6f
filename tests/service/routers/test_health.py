"""``/healthz``, ``/readyz`` and ``/metrics``."""


def test_health_readiness_and_metrics(client):
    assert client.get("/healthz").json() == {"status": "ok"}
    ready = client.get("/readyz")
    deployment = client.app.state.deployment
    assert ready.status_code == 503 and ready.json() == {
        "status": "not ready", "checks": {"redis": True, "worker": False}, "broker": "memory", "worker": "embedded",
        "deployment": deployment}
    assert (client.app.state.settings.storage_dir / "deployment.json").read_text().count(deployment) == 1
    text = client.get("/metrics").text
    assert 'hairport_queue_depth{queue="retarget"} 3.0' in text
    assert 'hairport_jobs{state="queued"} 0.0' in text and 'hairport_jobs{state="stale"} 0.0' in text and "hairport_stage_jobs 0.0" in text
