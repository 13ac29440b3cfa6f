"""The FastAPI application: routers, errors as problem+json, CORS, storage, task queue, readiness."""

from __future__ import annotations

import logging
from collections.abc import Callable

import redis
from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware

from hairport import __version__
from hairport.repository import Repository
from hairport.settings import Settings, get_settings
from hairport.storage import deployment_for, open_storage
from hairport.worker.queue import TaskQueue, connect

from . import contract, dashboard_ui, docs, errors, headers, validation
from .auth import check_configuration
from .routers import batches, characters, hairstyles, health, jobs, retargets

log = logging.getLogger(__name__)

DESCRIPTION = """Retarget strand hairstyles between characters of one mesh topology.

Upload characters and hairstyles, start retargets (one job per target), poll jobs, download
results. Every error is `application/problem+json` (the `Problem` schema) with a stable `code`;
each operation lists the statuses it can answer and their codes. A form field sent empty counts
as not given. A file whose name has no extension is recognised by its content, and a file field may
also be sent as a plain field holding the file's text (`curl -F 'mesh=<body.obj'`). Authenticate with
`Authorization: Bearer <key>` or `X-API-Key: <key>`; what a key creates is invisible to other keys.
"""

#: multipart framing allowed on top of the upload limit (boundaries, part headers, small fields)
MULTIPART_OVERHEAD_BYTES = 64 * 1024
#: seconds a readiness check waits for Redis and for a worker's answer
READY_TIMEOUT_SECONDS = 1.0


class ContentLengthLimit:
    """Refuse a request whose declared body is over the upload limit before reading any of it
    (bodies without a Content-Length are counted while they stream into the storage)."""

    def __init__(self, app, limit: int):
        self.app, self.limit = app, limit

    async def __call__(self, scope, receive, send):
        if scope["type"] == "http":
            declared = dict(scope.get("headers") or []).get(b"content-length")
            if declared is not None and declared.isdigit() and int(declared) > self.limit + MULTIPART_OVERHEAD_BYTES:
                response = errors.problem_response(
                    413, "upload_too_large", f"request body of {int(declared):,} bytes is over the upload limit of "
                    f"{self.limit:,} bytes")
                await response(scope, receive, send)
                return
        await self.app(scope, receive, send)


def with_storage_check(readiness: Callable[[], dict], storage) -> Callable[[], dict]:
    """``readiness`` with ``storage``: whether the object store and the records' database answer (those the
    storage has)."""
    probes = storage.reachability()
    if not probes:
        return readiness

    def checks() -> dict:
        return {**readiness(), **{name: probe() for name, probe in probes.items()}}

    return checks


def redis_checks(redis_url: str, queue: TaskQueue) -> tuple[Callable[[], dict], Callable[[], dict]]:
    """Readiness (Redis answers, a worker of this deployment answers) and queue depths against a Redis broker."""
    client = redis.Redis.from_url(redis_url, socket_timeout=READY_TIMEOUT_SECONDS,
                                  socket_connect_timeout=READY_TIMEOUT_SECONDS)

    def readiness() -> dict:
        try:
            redis_ok = bool(client.ping())
        except redis.RedisError:
            return {"redis": False, "worker": False}
        try:
            workers = queue.workers(READY_TIMEOUT_SECONDS)
        except Exception:  # noqa: BLE001 - any broker trouble means not ready
            workers = []
        return {"redis": redis_ok, "worker": bool(workers)}

    def queue_depths() -> dict:
        try:
            return queue.depths()
        except Exception:  # noqa: BLE001 - no depths while the broker is away
            return {}

    return readiness, queue_depths


def create_app(settings: Settings | None = None, readiness=None, queue_depths=None,
               queue: TaskQueue | None = None) -> FastAPI:
    """The API. ``queue`` defaults to the Celery app of the configured Redis; ``readiness`` and
    ``queue_depths`` default to checks against that Redis."""
    settings = settings or get_settings()
    check_configuration(settings)
    app = FastAPI(title="hairport", version=__version__, description=DESCRIPTION, docs_url=None, redoc_url=None,
                  lifespan=validation.lifespan)
    app.state.settings = settings
    app.state.storage = open_storage(settings)
    app.state.repository = Repository(app.state.storage)
    app.state.deployment = deployment_for(settings)
    app.state.queue = queue or connect(settings.redis_url, settings.storage_dir)
    if app.state.queue.deployment != app.state.deployment:
        raise RuntimeError(f"the task queue is deployment {app.state.queue.deployment}'s, the storage "
                           f"{settings.storage_dir} is deployment {app.state.deployment}'s")
    if readiness is None or queue_depths is None:
        redis_readiness, redis_depths = redis_checks(settings.redis_url, app.state.queue)
        readiness, queue_depths = readiness or redis_readiness, queue_depths or redis_depths
    app.state.readiness = with_storage_check(readiness, app.state.storage)
    app.state.queue_depths = queue_depths
    errors.install(app)
    app.add_middleware(ContentLengthLimit, limit=settings.max_upload_bytes)
    if settings.cors_origin_list:
        app.add_middleware(CORSMiddleware, allow_origins=settings.cors_origin_list, allow_methods=["*"],
                           allow_headers=["*"], expose_headers=["Location", headers.REQUEST_ID_HEADER])
    # added last, so outermost: its headers are on every response, the 413 above and CORS preflights included
    app.add_middleware(headers.ResponseHeaders)
    for router in (characters.router, hairstyles.router, retargets.router, batches.router, jobs.router, health.router):
        app.include_router(router)
    contract.install(app)
    docs.install(app)
    dashboard_ui.install(app)
    return app
