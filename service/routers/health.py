"""``/healthz`` (process up), ``/readyz`` (the broker and a worker of this deployment answer), ``/metrics`` (Prometheus)."""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse, PlainTextResponse
from prometheus_client import CONTENT_TYPE_LATEST, CollectorRegistry, Gauge, generate_latest

from hairport.records import SUCCEEDED

from ..deps import RepositoryDep

router = APIRouter(tags=["health"])
#: stages whose durations /metrics reports (seconds, from succeeded jobs' timings, summed by the job index)
STAGES = ("initial_transfer", "coarse_solve", "fine_solve", "solve", "metrics", "job")


@router.get("/healthz", summary="The process is up")
def healthz() -> dict:
    return {"status": "ok"}


@router.get("/readyz", summary="The broker (and the object store and records' database, when configured) reachable "
                                "and at least one worker of this deployment answering",
            responses={503: {"description": "not ready"}})
def readyz(request: Request):
    state = request.app.state
    checks = state.readiness()
    ready = all(checks.values())
    queue = state.queue
    return JSONResponse({"status": "ready" if ready else "not ready", "checks": checks, "broker": queue.broker,
                         "worker": "embedded" if queue.broker == "memory" else "celery",
                         "deployment": state.deployment}, status_code=200 if ready else 503)


@router.get("/metrics", summary="Prometheus metrics", response_class=PlainTextResponse)
def metrics(request: Request, repository: RepositoryDep):
    registry = CollectorRegistry()
    by_state = Gauge("hairport_jobs", "Jobs by state", ["state"], registry=registry)
    durations = Gauge("hairport_stage_seconds_sum", "Total seconds spent per stage by succeeded jobs", ["stage"],
                      registry=registry)
    finished = Gauge("hairport_stage_jobs", "Succeeded jobs counted in hairport_stage_seconds_sum", registry=registry)
    depth = Gauge("hairport_queue_depth", "Messages waiting per queue", ["queue"], registry=registry)
    counts = repository.job_counts()  # from the index: no job record is read
    for state, count in counts.items():
        by_state.labels(state).set(count)
    totals = repository.stage_totals()
    for stage in STAGES:
        durations.labels(stage).set(totals.get(stage, (0.0, 0))[0])
    finished.set(counts[SUCCEEDED])
    for queue, size in request.app.state.queue_depths().items():
        depth.labels(queue).set(size)
    return PlainTextResponse(generate_latest(registry), media_type=CONTENT_TYPE_LATEST)
