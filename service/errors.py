"""Errors as ``application/problem+json`` (RFC 9457) with a stable ``code`` per error."""

from __future__ import annotations

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from hairport import solver
from hairport.messages import safe_detail

PROBLEM_TYPE_BASE = "https://hairport.dev/problems/"
PROBLEM_MEDIA_TYPE = "application/problem+json"


class Problem(Exception):
    """An error response: HTTP ``status``, stable ``code``, human ``detail``."""

    def __init__(self, status: int, code: str, detail: str, title: str | None = None, headers: dict | None = None):
        super().__init__(detail)
        self.status, self.code, self.detail = status, code, detail
        self.title = title or code.replace("_", " ")
        self.headers = headers


def problem_response(status: int, code: str, detail: str, title: str | None = None, headers: dict | None = None):
    # every detail is bounded and sanitised here (ids and file text are echoed; blob names hidden)
    body = {"type": PROBLEM_TYPE_BASE + code, "title": title or code.replace("_", " "), "status": status,
            "detail": safe_detail(detail), "code": code}
    return JSONResponse(body, status_code=status, media_type=PROBLEM_MEDIA_TYPE, headers=headers)


#: codes of the HTTP errors raised by the framework itself
_HTTP_CODES = {401: "unauthorized", 404: "not_found", 405: "method_not_allowed", 413: "upload_too_large",
               415: "unsupported_media_type"}


def install(app: FastAPI) -> None:
    """Route every error through :func:`problem_response`."""

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
        code = "bad_option" if fields and fields <= set(solver.OPTION_RANGES) else "invalid_request"
        return problem_response(422, code, "; ".join(parts) or "invalid request")

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, error: StarletteHTTPException):
        code = _HTTP_CODES.get(error.status_code, f"http_{error.status_code}")
        return problem_response(error.status_code, code, str(error.detail), headers=getattr(error, "headers", None))
