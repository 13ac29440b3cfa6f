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
