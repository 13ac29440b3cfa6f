"""Errors as ``application/problem+json`` (RFC 9457) with a stable ``code`` per error."""

from __future__ import annotations

import logging
import re

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from hairport.messages import safe_detail
from hairport.solver import options as solver_options
from hairport.storage import StorageUnavailable

from . import headers as response_headers

log = logging.getLogger(__name__)

PROBLEM_TYPE_BASE = "https://hairport.dev/problems/"
PROBLEM_MEDIA_TYPE = "application/problem+json"
#: ``Retry-After`` (s) of a 503 ``storage_unavailable``: an object store's outage or a restart takes seconds
STORAGE_RETRY_AFTER_SECONDS = 10


class Problem(Exception):
    """An error response: HTTP ``status``, stable ``code``, human ``detail``."""

    def __init__(self, status: int, code: str, detail: str, title: str | None = None, headers: dict | None = None):
        super().__init__(detail)
        self.status, self.code, self.detail = status, code, detail
        self.title = title or code.replace("_", " ")
        self.headers = headers


def problem_response(status: int, code: str, detail: str, title: str | None = None, headers: dict | None = None,
                     request_id: str | None = None):
    # every detail is bounded and sanitised here (ids and file text are echoed; blob names hidden)
    body = {"type": PROBLEM_TYPE_BASE + code, "title": title or code.replace("_", " "), "status": status,
            "detail": safe_detail(detail), "code": code}
    if request_id is not None:
        body["request_id"] = request_id
    return JSONResponse(body, status_code=status, media_type=PROBLEM_MEDIA_TYPE, headers=headers)


#: codes of the HTTP errors raised by the framework itself
_HTTP_CODES = {400: "bad_request", 401: "unauthorized", 404: "not_found", 405: "method_not_allowed",
               413: "upload_too_large", 415: "unsupported_media_type"}


def install(app: FastAPI) -> None:
    """Route every error through :func:`problem_response`; anything unexpected is an ``internal`` 500 whose
    request id is in its body, in its ``X-Request-ID`` header and in the server's log with the traceback."""

    @app.exception_handler(Exception)
    async def _internal(request: Request, error: Exception):
        # Starlette runs this handler in its ServerErrorMiddleware, outside every middleware: the headers that
        # service/headers.py sets on every other response are set here. The error then goes on to the server,
        # which logs it too and closes the connection: the response says so, or a client reusing the connection
        # would meet a reset
        request_id = response_headers.request_id(request.scope)
        log.error("internal error, request id %s: %s %r", request_id, request.method, request.url.path,
                  exc_info=error)
        headers = {**response_headers.response_headers(request_id, PROBLEM_MEDIA_TYPE), "Connection": "close"}
        return problem_response(500, "internal", "an unexpected error; the server logged it under this problem's "
                                                 "request_id", request_id=request_id, headers=headers)

    @app.exception_handler(StorageUnavailable)
    async def _storage(request: Request, error: StorageUnavailable):
        log.warning("storage unavailable: %s", error.reason)
        return problem_response(503, "storage_unavailable", f"the storage is unavailable ({error.reason}); nothing "
                                f"was kept, try again in {STORAGE_RETRY_AFTER_SECONDS} s",
                                headers={"Retry-After": str(STORAGE_RETRY_AFTER_SECONDS)})

    @app.exception_handler(Problem)
    async def _problem(request: Request, error: Problem):
        return problem_response(error.status, error.code, error.detail, error.title, error.headers)

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, error: RequestValidationError):
        parts = []
        for item in error.errors():
            where = ".".join(str(p) for p in item.get("loc", ()) if p not in ("body",))
            parts.append(f"{where}: {item.get('msg')}" if where else str(item.get("msg")))
        # an option outside its range (the solver's OPTION_RANGES) has the solver's own code
        fields = {str(item.get("loc", ("",))[-1]) for item in error.errors()}
        code = "bad_option" if fields and fields <= set(solver_options.OPTION_RANGES) else "invalid_request"
        return problem_response(422, code, "; ".join(parts) or "invalid request")

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, error: StarletteHTTPException):
        code = _HTTP_CODES.get(error.status_code, f"http_{error.status_code}")
        headers = getattr(error, "headers", None)
        allowed = allowed_methods(request) if error.status_code == 405 else None
        if allowed:
            headers = {**(headers or {}), "Allow": ", ".join(allowed)}
        return problem_response(error.status_code, code, str(error.detail), headers=headers)


def allowed_methods(request: Request) -> list[str]:
    """Every method the OpenAPI document gives the request's path, over all its routes (the router's own
    405 names only the first route's: GET /v1/jobs/{id} and DELETE /v1/jobs/{id} are two routes); HEAD
    with GET, as the router answers it."""
    methods = set()
    for template, operations in request.app.openapi()["paths"].items():
        pattern = "[^/]+".join(re.escape(part) for part in re.split(r"\{[^/}]+\}", template))
        if re.fullmatch(pattern, request.url.path):
            methods |= {method.upper() for method in operations}
    return sorted(methods | {"HEAD"} if "GET" in methods else methods)


#: every status the API answers with a problem: what it means, and the codes it carries (those of the
#: service; 413 and 422 also carry the codes of the file and option checks, listed as examples)
PROBLEM_STATUSES: dict[int, tuple[str, tuple[str, ...]]] = {
    400: ("the body could not be parsed (malformed multipart, or a JSON body that is not UTF-8)", ("bad_request",)),
    401: ("no API key, or an unknown one (`WWW-Authenticate: Bearer`)", ("unauthorized",)),
    404: ("no such resource for this key: what another key created is not found either", ("not_found",)),
    405: ("the path does not take this method (`Allow` lists those it takes)", ("method_not_allowed",)),
    409: ("the job has not succeeded (yet): it has no outputs; or the batch has jobs that have not ended; or the "
          "job ran before hairport saved what the dashboard draws, or its groom has no front hairline, or "
          "(`layer=wrapped`) its target was not wrapped",
          ("job_not_succeeded", "batch_not_finished", "no_scene", "no_hairline", "no_wrap")),
    410: ("the output was removed by the retention policy", ("gone",)),
    413: ("the body, an upload, a count in it or its estimated memory is above this deployment's limits",
          ("upload_too_large", "too_large", "over_memory_budget")),
    415: ("no accepted format: the file name's extension is not one this field reads, or the name has none and "
          "the content is not recognised, or the format needs a library this deployment lacks",
          ("unknown_format", "unsupported_media_type", "format_unavailable")),
    422: ("the request is invalid: a field fails the schema (`invalid_request`), or a value, file or option fails "
          "its check", ("invalid_request", "bad_units", "bad_axis", "bad_option", "no_skeleton", "too_many_targets",
                        "bad_idempotency_key", "idempotency_conflict", "units_mismatch", "hair_off_body",
                        "topology_mismatch", "truncated", "bad_header", "bad_mesh", "non_finite", "bad_attribute",
                        "unknown_prim", "no_guide_flags", "too_many_jobs", "duplicate_ids", "unknown_pair",
                        "external_reference", "stray_strands", "bad_landmarks", "bad_frames")),
    500: ("an unexpected error (a defect, not the request's fault): the body's `request_id`, also in the "
          "`X-Request-ID` header, names the server's log entry and its traceback", ("internal",)),
    503: ("the task queue or the storage is unavailable, or every upload validation process stayed busy: nothing "
          "was started or kept; retry after `Retry-After` seconds (or, at `/ui`, the dashboard was not built)",
          ("queue_unavailable", "validation_busy", "dashboard_not_built", "storage_unavailable")),
}
#: the Problem schema in the OpenAPI document (service/contract.py puts it there)
PROBLEM_SCHEMA_REF = "#/components/schemas/Problem"
#: headers a problem of a status carries
PROBLEM_HEADERS: dict[int, dict[str, dict]] = {
    401: {"WWW-Authenticate": {"description": "the scheme to authenticate with", "schema": {"type": "string"}}},
    500: {response_headers.REQUEST_ID_HEADER: {"description": "the request id the server logged the error under",
                                               "schema": {"type": "string"}}},
    503: {"Retry-After": {"description": "seconds to wait before trying again", "schema": {"type": "integer"}}},
}
#: every operation can answer this (the catch-all of :func:`install`)
INTERNAL_STATUS = 500


def problem_responses(*statuses: int) -> dict[int, dict]:
    """The ``responses=`` of a route answering ``statuses`` (and, as every route may, 500) with problems: the
    Problem schema under ``application/problem+json``, the meaning and known codes of each status, and its
    headers."""
    responses = {}
    for status in dict.fromkeys((*statuses, INTERNAL_STATUS)):
        meaning, codes = PROBLEM_STATUSES[status]
        response = {"content": {PROBLEM_MEDIA_TYPE: {"schema": {"$ref": PROBLEM_SCHEMA_REF}}},
                    "description": f"{meaning}. Codes: {', '.join(f'`{code}`' for code in codes)}."}
        if status in PROBLEM_HEADERS:
            response["headers"] = PROBLEM_HEADERS[status]
        responses[status] = response
    return responses
