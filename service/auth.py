"""API keys: ``Authorization: Bearer <key>`` or ``X-API-Key: <key>``.

Keys come from ``HAIRPORT_API_KEYS`` (comma-separated). Each key owns what it creates; the
owner recorded is a hash of the key, never the key. ``HAIRPORT_INSECURE_DEV=true`` accepts
requests without a key as owner ``dev`` (for a laptop only).
"""

from __future__ import annotations

import hashlib
import hmac
from typing import Annotated

from fastapi import Depends, Request
from fastapi.security import APIKeyHeader, HTTPAuthorizationCredentials, HTTPBearer

from hairport.settings import Settings

from .errors import Problem

DEV_OWNER = "dev"
#: the two ways to present a key, declared as OpenAPI security schemes (the Authorize button of /docs);
#: neither refuses by itself (auto_error off): :func:`current_owner` answers 401 as a problem
BEARER = HTTPBearer(auto_error=False, scheme_name="bearer", description="`Authorization: Bearer <key>`")
API_KEY = APIKeyHeader(name="X-API-Key", auto_error=False, scheme_name="apiKey", description="`X-API-Key: <key>`")


def owner_of(key: str) -> str:
    return "k" + hashlib.sha256(key.encode()).hexdigest()[:24]


async def current_owner(
    request: Request,
    bearer: Annotated[HTTPAuthorizationCredentials | None, Depends(BEARER)] = None,
    x_api_key: Annotated[str | None, Depends(API_KEY)] = None,
) -> str:
    """The owner of the request's key (a bearer token before an ``X-API-Key``); 401 without a valid one."""
    settings: Settings = request.app.state.settings
    key = x_api_key
    if bearer is not None and bearer.credentials.strip():
        key = bearer.credentials.strip()
    if not key:
        if settings.insecure_dev:
            return DEV_OWNER
        raise Problem(401, "unauthorized", "an API key is required (Authorization: Bearer <key> or X-API-Key)",
                      headers={"WWW-Authenticate": "Bearer"})
    if not any(hmac.compare_digest(key.encode(), known.encode()) for known in settings.api_key_list):
        raise Problem(401, "unauthorized", "unknown API key", headers={"WWW-Authenticate": "Bearer"})
    return owner_of(key)


Owner = Annotated[str, Depends(current_owner)]


def check_configuration(settings: Settings) -> None:
    """Refuse to start without keys unless the insecure dev mode is explicit."""
    if not settings.api_key_list and not settings.insecure_dev:
        raise RuntimeError("no API keys configured: set HAIRPORT_API_KEYS, or HAIRPORT_INSECURE_DEV=true for a laptop")
