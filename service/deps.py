"""Dependencies shared by the routers (``Annotated`` aliases)."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request

from hairport.settings import Settings
from hairport.worker.storage import LocalStorage


def get_app_settings(request: Request) -> Settings:
    return request.app.state.settings


def get_app_storage(request: Request) -> LocalStorage:
    return request.app.state.storage


SettingsDep = Annotated[Settings, Depends(get_app_settings)]
StorageDep = Annotated[LocalStorage, Depends(get_app_storage)]


def owned_record(storage: LocalStorage, kind: str, owner: str, record_id: str, noun: str) -> dict:
    """The record if ``owner`` owns it; 404 otherwise (also for ids that cannot exist)."""
    from .errors import Problem

    is_id = 0 < len(record_id) <= 64 and all(c in "0123456789abcdef" for c in record_id)
    record = storage.get_record(kind, record_id) if is_id else None
    if record is None or record.get("owner") != owner:
        raise Problem(404, "not_found", f"no {noun} {record_id}")
    return record
