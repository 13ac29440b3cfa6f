"""``/healthz`` (process up), ``/readyz`` (Redis and a worker answer), ``/metrics`` (Prometheus)."""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse, PlainTextResponse
from prometheus_client import CollectorRegistry, Gauge, generate_latest
from prometheus_client.exposition import CONTENT_TYPE_LATEST

from hairport.worker import jobs
from hairport.worker.app import QUEUES

from ..deps import StorageDep

router = APIRouter(tags=["health"])
#: seconds a readiness check waits for Redis and for a worker's answer
READY_TIMEOUT_SECONDS = 1.0
#: stages whose durations /metrics reports (seconds, from finished jobs' timings)
STAGES = ("initial_transfer", "coarse_solve", "fine_solve", "solve", "metrics", "job")


@router.get("/healthz", summary="The process is up")
def healthz() -> dict:
    return {"status": "ok"}


@router.get("/readyz", summary="Redis reachable and at least one worker answering",
            responses={503: {"description": "not ready"}})
def readyz(request: Request):
    checks = request.app.state.readiness()
    ready = all(checks.values())
    return JSONResponse({"status": "ready" if ready else "not ready", "checks": checks}, status_code=200 if ready else 503)


@router.get("/metrics", summary="Prometheus metrics", response_class=PlainTextResponse)
def metrics(request: Request, storage: StorageDep):
    registry = CollectorRegistry()
    by_state = Gauge("hairport_jobs", "Jobs by state", ["state"], registry=registry)
    durations = Gauge("hairport_stage_seconds_sum", "Total seconds spent per stage by succeeded jobs", ["stage"],
                      registry=registry)
    finished = Gauge("hairport_stage_jobs", "Succeeded jobs counted in hairport_stage_seconds_sum", registry=registry)
    depth = Gauge("hairport_queue_depth", "Messages waiting per queue", ["queue"], registry=registry)
    counts = dict.fromkeys(jobs.JOB_STATES, 0)
    totals = dict.fromkeys(STAGES, 0.0)
    done = 0
    for record in storage.list_records("jobs"):
        counts[record["state"]] = counts.get(record["state"], 0) + 1
        if record["state"] == jobs.SUCCEEDED:
            done += 1
            for stage in STAGES:
                totals[stage] += float((record.get("timings") or {}).get(stage, 0.0))
    for state, count in counts.items():
        by_state.labels(state).set(count)
    for stage, seconds in totals.items():
        durations.labels(stage).set(seconds)
    finished.set(done)
    for queue, size in request.app.state.queue_depths().items():
        depth.labels(queue).set(size)
    return PlainTextResponse(generate_latest(registry), media_type=CONTENT_TYPE_LATEST)


def redis_checks(redis_url: str, celery_app):
    """Readiness and queue depth against a Redis broker."""
    import redis

    client = redis.Redis.from_url(redis_url, socket_timeout=READY_TIMEOUT_SECONDS,
                                  socket_connect_timeout=READY_TIMEOUT_SECONDS)

    def readiness() -> dict:
        try:
            redis_ok = bool(client.ping())
        except redis.RedisError:
            return {"redis": False, "worker": False}
        try:
            workers = celery_app.control.ping(timeout=READY_TIMEOUT_SECONDS)
        except Exception:  # noqa: BLE001 - any broker trouble means not ready
            workers = []
        return {"redis": redis_ok, "worker": bool(workers)}

    def queue_depths() -> dict:
        try:
            return {queue: int(client.llen(queue)) for queue in QUEUES}
        except redis.RedisError:
            return {}

    return readiness, queue_depths
