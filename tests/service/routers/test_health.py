"""``/healthz``, ``/readyz`` and ``/metrics``."""


def test_health_readiness_and_metrics(client):
    assert client.get("/healthz").json() == {"status": "ok"}
    ready = client.get("/readyz")
    assert ready.status_code == 503 and ready.json() == {"status": "not ready",
                                                          "checks": {"redis": True, "worker": False}}
    text = client.get("/metrics").text
    assert 'hairport_queue_depth{queue="retarget"} 3.0' in text
    assert 'hairport_jobs{state="queued"} 0.0' in text and "hairport_stage_jobs 0.0" in text
