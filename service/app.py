"""The FastAPI application: routers, errors as problem+json, CORS, storage, readiness."""

from __future__ import annotations

from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware

from hairport import __version__
from hairport.settings import Settings, get_settings
from hairport.worker import jobs
from hairport.worker.app import celery_app

from . import errors
from .auth import check_configuration
from .routers import characters, hairstyles, health, retargets
from .routers import jobs as jobs_router

DESCRIPTION = """Retarget strand hairstyles between characters of one mesh topology.

Upload characters and hairstyles, start retargets (one job per target), poll jobs, download
results. Every error is `application/problem+json` with a stable `code`. Authenticate with
`Authorization: Bearer <key>` or `X-API-Key: <key>`; what a key creates is invisible to other keys.
"""


def create_app(settings: Settings | None = None, readiness=None, queue_depths=None) -> FastAPI:
    """The API. ``readiness``/``queue_depths`` default to checks against the Redis broker."""
    settings = settings or get_settings()
    check_configuration(settings)
    app = FastAPI(title="hairport", version=__version__, description=DESCRIPTION)
    app.state.settings = settings
    app.state.storage = jobs.get_storage(settings)
    if readiness is None or queue_depths is None:
        redis_readiness, redis_depths = health.redis_checks(settings.redis_url, celery_app)
        readiness, queue_depths = readiness or redis_readiness, queue_depths or redis_depths
    app.state.readiness = readiness
    app.state.queue_depths = queue_depths
    errors.install(app)
    if settings.cors_origin_list:
        app.add_middleware(CORSMiddleware, allow_origins=settings.cors_origin_list, allow_methods=["*"],
                           allow_headers=["*"], expose_headers=["Location"])
    for router in (characters.router, hairstyles.router, retargets.router, jobs_router.router, health.router):
        app.include_router(router)
    return app
