"""``/docs`` (Swagger UI) and ``/redoc`` (ReDoc) from files served by the API itself, never a CDN:
an air-gapped studio gets working pages.

The files come from the ``fastapi-offline`` wheel (MIT; Swagger UI 5 and ReDoc 2 builds, ~2.8 MB),
which ships them as package data; only its static folder is used, the pages are FastAPI's own."""

from __future__ import annotations

import base64
import hashlib
import re
from importlib.resources import files

from fastapi import FastAPI
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html, swagger_ui_default_parameters
from fastapi.responses import HTMLResponse
from fastapi.staticfiles import StaticFiles

#: where the Swagger UI and ReDoc files are served
ASSETS_URL = "/docs-assets"
ASSETS_DIR = files("fastapi_offline") / "static"
SWAGGER_JS, SWAGGER_CSS, REDOC_JS, FAVICON = ("swagger-ui-bundle.js", "swagger-ui.css", "redoc.standalone.js",
                                              "favicon.png")
#: Swagger UI's defaults, without its online validator badge (it would send the document to a third party)
SWAGGER_PARAMETERS = {**swagger_ui_default_parameters, "validatorUrl": None}


#: an inline block of a page (FastAPI's pages write them without attributes)
INLINE_BLOCK = re.compile(r"<(script|style)>(.*?)</\1>", re.S)
#: what both pages load: their own files and the API's document, and images drawn from data (Swagger UI's
#: icons) or blobs (an image response shown by "Try it out"); no plugin, no <base>, no framing, no form posts
COMMON_POLICY = ("default-src 'none'; img-src 'self' data: blob:; connect-src 'self'; font-src 'self'; "
                 "object-src 'none'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'")
#: ReDoc runs its search index in a web worker it makes from a blob
REDOC_WORKERS = "worker-src blob:"
#: the <style> elements ReDoc's bundle adds, by the SHA-256 of their text: its styled-components sheet, made
#: empty and filled through the CSSOM (``insertRule``, which a policy does not govern), and the stylesheet of
#: perfect-scrollbar (with its source map) that the bundle's style loader inserts as it loads, before any
#: option (a nonce) could reach it. The second is that of the ReDoc build fastapi-offline 1.7.7 ships: another
#: build may change it, which tests/integration/test_headers.py (the page in Chromium, listening for policy
#: violations) reports
REDOC_STYLE_TEXTS = ("",)
REDOC_STYLE_HASHES = ("'sha256-QMIg+bpjm3JdElJ388KYke01izlUW0UoNOeKjpMxdgc='",)


def source_hash(text: str) -> str:
    """A policy's source allowing an inline block of exactly ``text``."""
    return f"'sha256-{base64.b64encode(hashlib.sha256(text.encode()).digest()).decode()}'"


def page_policy(page: HTMLResponse, styles: tuple[str, ...] = (), *extra: str) -> str:
    """The Content-Security-Policy of one of the pages: scripts and styles from hairport, the page's own inline
    blocks and the ``styles`` its script adds by their SHA-256 (never ``'unsafe-inline'``), with ``extra``
    directives."""
    allowed = {"script": [], "style": list(styles)}
    for tag, text in INLINE_BLOCK.findall(page.body.decode()):
        allowed[tag].append(source_hash(text))
    sources = [" ".join([f"{tag}-src", "'self'", *hashes]) for tag, hashes in allowed.items()]
    return "; ".join([*sources, COMMON_POLICY, *extra])


def with_policy(page: HTMLResponse, styles: tuple[str, ...] = (), *extra: str) -> HTMLResponse:
    page.headers["Content-Security-Policy"] = page_policy(page, styles, *extra)
    return page


def install(app: FastAPI, docs_url: str = "/docs", redoc_url: str = "/redoc") -> None:
    """Serve the two pages, each with its policy, and their files (the app is made with ``docs_url=None,
    redoc_url=None``). The pages are made once: they depend on the app's title and document URL only."""
    app.mount(ASSETS_URL, StaticFiles(directory=str(ASSETS_DIR)), name="docs-assets")
    swagger_page = with_policy(get_swagger_ui_html(
        openapi_url=app.openapi_url, title=f"{app.title} - Swagger UI",
        swagger_js_url=f"{ASSETS_URL}/{SWAGGER_JS}", swagger_css_url=f"{ASSETS_URL}/{SWAGGER_CSS}",
        swagger_favicon_url=f"{ASSETS_URL}/{FAVICON}", swagger_ui_parameters=SWAGGER_PARAMETERS))
    redoc_page = with_policy(get_redoc_html(
        openapi_url=app.openapi_url, title=f"{app.title} - ReDoc", redoc_js_url=f"{ASSETS_URL}/{REDOC_JS}",
        redoc_favicon_url=f"{ASSETS_URL}/{FAVICON}", with_google_fonts=False),
        (*map(source_hash, REDOC_STYLE_TEXTS), *REDOC_STYLE_HASHES), REDOC_WORKERS)

    @app.get(docs_url, include_in_schema=False)
    def swagger_ui() -> HTMLResponse:
        return swagger_page

    @app.get(redoc_url, include_in_schema=False)
    def redoc() -> HTMLResponse:
        return redoc_page
