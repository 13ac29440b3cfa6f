"""``/docs`` (Swagger UI) and ``/redoc`` (ReDoc) from files served by the API itself, never a CDN:
an air-gapped studio gets working pages.

The files come from the ``fastapi-offline`` wheel (MIT; Swagger UI 5 and ReDoc 2 builds, ~2.8 MB),
which ships them as package data; only its static folder is used, the pages are FastAPI's own."""

from __future__ import annotations

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


def install(app: FastAPI, docs_url: str = "/docs", redoc_url: str = "/redoc") -> None:
    """Serve the two pages and their files (the app is made with ``docs_url=None, redoc_url=None``)."""
    app.mount(ASSETS_URL, StaticFiles(directory=str(ASSETS_DIR)), name="docs-assets")

    @app.get(docs_url, include_in_schema=False)
    def swagger_ui() -> HTMLResponse:
        return get_swagger_ui_html(
            openapi_url=app.openapi_url, title=f"{app.title} - Swagger UI",
            swagger_js_url=f"{ASSETS_URL}/{SWAGGER_JS}", swagger_css_url=f"{ASSETS_URL}/{SWAGGER_CSS}",
            swagger_favicon_url=f"{ASSETS_URL}/{FAVICON}", swagger_ui_parameters=SWAGGER_PARAMETERS)

    @app.get(redoc_url, include_in_schema=False)
    def redoc() -> HTMLResponse:
        return get_redoc_html(openapi_url=app.openapi_url, title=f"{app.title} - ReDoc",
                              redoc_js_url=f"{ASSETS_URL}/{REDOC_JS}", redoc_favicon_url=f"{ASSETS_URL}/{FAVICON}",
                              with_google_fonts=False)
