"""Headers on every response: ``X-Content-Type-Options: nosniff``, the request id (``X-Request-ID``), and a
Content-Security-Policy on every document a browser could run (an HTML page, an SVG image).

:class:`ResponseHeaders`, the outermost of the app's own middlewares, sets them on whatever answers: the
routes, the mounted static files (the docs' assets, the dashboard's bundle), the 413 of the upload limit, CORS
preflights. A page that names its own policy (``/ui/``, ``/docs``, ``/redoc``) keeps it; any other document
gets :data:`SELF_ONLY_POLICY`, so a page served by a static mount is never left without one. The only
response this middleware cannot see is the 500 that Starlette's ``ServerErrorMiddleware`` (outside every
middleware) sends for an unhandled exception: service/errors.py's catch-all sets the same headers on it
with :func:`response_headers`.
"""

from __future__ import annotations

import re
import uuid

from starlette.datastructures import Headers, MutableHeaders
from starlette.types import ASGIApp, Message, Receive, Scope, Send

NOSNIFF = "nosniff"
REQUEST_ID_HEADER = "X-Request-ID"
#: a client's X-Request-ID is kept when it is 1-128 of these characters (a UUID, a W3C trace id, a load
#: balancer's id); anything else (spaces or control characters that could forge log lines, an overlong value)
#: is replaced by a new id, so that the id is always safe to log and to echo
SANE_REQUEST_ID = re.compile(r"[A-Za-z0-9._:-]{1,128}")
#: where the request's id is kept for the app (``request.state.request_id``)
STATE_KEY = "request_id"
#: the policy of a page that names none: it may load only what hairport serves (and draw into blobs and data
#: URLs: the dashboard's thumbnails and downloads), run no inline script, and be framed by no one
SELF_ONLY_POLICY = ("default-src 'self'; img-src 'self' data: blob:; style-src 'self'; script-src 'self'; "
                    "connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'")
#: media types a browser renders as a document whose scripts run: each gets a policy
DOCUMENT_MEDIA_TYPES = frozenset({"text/html", "application/xhtml+xml", "image/svg+xml"})


def request_id(scope: Scope) -> str:
    """The request's id: the one given to it already, else the client's ``X-Request-ID`` if sane, else a new
    one; kept in the request's state."""
    state = scope.setdefault("state", {})
    if STATE_KEY not in state:
        sent = Headers(scope=scope).get(REQUEST_ID_HEADER, "")
        state[STATE_KEY] = sent if SANE_REQUEST_ID.fullmatch(sent) else uuid.uuid4().hex
    return state[STATE_KEY]


def response_headers(request_id: str, media_type: str | None) -> dict[str, str]:
    """What every response carries (a response that sets one of them itself keeps its own)."""
    headers = {"X-Content-Type-Options": NOSNIFF, REQUEST_ID_HEADER: request_id}
    if is_document(media_type):
        headers["Content-Security-Policy"] = SELF_ONLY_POLICY
    return headers


def is_document(media_type: str | None) -> bool:
    return (media_type or "").split(";", 1)[0].strip().lower() in DOCUMENT_MEDIA_TYPES


class ResponseHeaders:
    """Adds :func:`response_headers` to every HTTP response of the app it wraps."""

    def __init__(self, app: ASGIApp):
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        identifier = request_id(scope)

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                message.setdefault("headers", [])
                headers = MutableHeaders(scope=message)
                for name, value in response_headers(identifier, headers.get("content-type")).items():
                    headers.setdefault(name, value)
            await send(message)

        await self.app(scope, receive, send_with_headers)
