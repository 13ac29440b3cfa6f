"""Dependencies of the routes (``Annotated`` aliases): settings, storage, records, the task
queue, the caller, and the caller's own characters, hairstyles and jobs (404 for anything else).

They are ``async``: each takes microseconds (an attribute, or one small record read without a
lock, which atomic replaces make safe), so they run on the event loop. A sync dependency would
cost a hop to the threadpool and back per request, and under many pollers those hops (and the
threads' fight for the GIL) were most of a poll's latency."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Header, Query, Request

from hairport.records import CharacterRecord, HairstyleRecord, JobRecord, Record
from hairport.repository import Repository
from hairport.settings import Settings
from hairport.storage import LocalStorage
from hairport.worker.queue import TaskQueue

from .auth import Owner
from .errors import Problem

#: longest id accepted in a path; anything else cannot exist
MAX_ID_CHARS = 64
HEX = frozenset("0123456789abcdef")


async def get_app_settings(request: Request) -> Settings:
    return request.app.state.settings


async def get_app_storage(request: Request) -> LocalStorage:
    return request.app.state.storage


async def get_repository(request: Request) -> Repository:
    return request.app.state.repository


async def get_queue(request: Request) -> TaskQueue:
    return request.app.state.queue


SettingsDep = Annotated[Settings, Depends(get_app_settings)]
StorageDep = Annotated[LocalStorage, Depends(get_app_storage)]
RepositoryDep = Annotated[Repository, Depends(get_repository)]
QueueDep = Annotated[TaskQueue, Depends(get_queue)]

#: largest page of a listing (GET /v1/jobs, /v1/batches, /v1/characters, /v1/hairstyles)
MAX_PAGE = 200
DEFAULT_PAGE = 50
PageLimit = Annotated[int, Query(ge=1, le=MAX_PAGE, description="most items in the page")]
#: largest offset a listing takes: far beyond the records any deployment keeps (retention purges them; 10^9 jobs
#: would be terabytes of records), and small enough that an offset plus a page (10^9 + 200) is a signed 32-bit
#: integer, the size most generated clients give an OpenAPI integer: every accepted offset and every
#: ``next_offset`` fits them, and no storage (SQLite's 64-bit OFFSET) ever sees an overflowing one
MAX_OFFSET = 1_000_000_000
PageOffset = Annotated[int, Query(ge=0, le=MAX_OFFSET, description="items skipped, newest first")]

#: longest Idempotency-Key accepted (characters)
MAX_IDEMPOTENCY_KEY = 200
IdempotencyKey = Annotated[str | None, Header(description="repeat a request safely", min_length=1,
                                              max_length=MAX_IDEMPOTENCY_KEY)]


def owned(repository: Repository, model: type[Record], owner: str, record_id: str, noun: str):
    """The record if ``owner`` owns it; 404 otherwise (also for ids that cannot exist)."""
    is_id = 0 < len(record_id) <= MAX_ID_CHARS and set(record_id) <= HEX
    record = repository.get(model, record_id) if is_id else None
    if record is None or record.owner != owner:
        raise Problem(404, "not_found", f"no {noun} {record_id}")
    return record


async def owned_character(character_id: str, owner: Owner, repository: RepositoryDep) -> CharacterRecord:
    return owned(repository, CharacterRecord, owner, character_id, "character")


async def owned_hairstyle(hairstyle_id: str, owner: Owner, repository: RepositoryDep) -> HairstyleRecord:
    return owned(repository, HairstyleRecord, owner, hairstyle_id, "hairstyle")


async def owned_job(job_id: str, owner: Owner, repository: RepositoryDep) -> JobRecord:
    return owned(repository, JobRecord, owner, job_id, "job")


OwnedCharacter = Annotated[CharacterRecord, Depends(owned_character)]
OwnedHairstyle = Annotated[HairstyleRecord, Depends(owned_hairstyle)]
OwnedJob = Annotated[JobRecord, Depends(owned_job)]
