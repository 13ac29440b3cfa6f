"""``/ui``: the studio dashboard, a page and its bundle (three.js included) served by the API itself, never a
CDN. The bundle is built from ``dashboard/`` when the package is built or installed (``build_backend/``) into
``service/dashboard/``; a checkout that was never installed has none, and ``/ui`` says so."""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI
from fastapi.responses import FileResponse, RedirectResponse
from fastapi.staticfiles import StaticFiles

from .errors import Problem
from .headers import SELF_ONLY_POLICY

URL = "/ui"
BUNDLE_DIR = Path(__file__).parent / "dashboard"
#: the page may load only what hairport serves (and draw into blobs: thumbnails, downloads); its files under
#: /ui/static/ (index.html too) get the same policy from service/headers.py, as every page without its own does
CONTENT_SECURITY_POLICY = SELF_ONLY_POLICY


def install(app: FastAPI, bundle_dir: Path = BUNDLE_DIR) -> None:
    """``/`` redirects to ``/ui/``, which serves the page; ``/ui/static/`` its files (503 without a bundle)."""
    index = bundle_dir / "index.html"
    if index.exists():
        app.mount(f"{URL}/static", StaticFiles(directory=str(bundle_dir)), name="dashboard")

    @app.get("/", include_in_schema=False)
    @app.get(URL, include_in_schema=False)
    def to_page() -> RedirectResponse:  # the page's files are relative to /ui/
        return RedirectResponse(f"{URL}/", status_code=307)

    @app.get(f"{URL}/", include_in_schema=False)
    def page() -> FileResponse:
        if not index.exists():
            raise Problem(503, "dashboard_not_built", f"the dashboard was not built ({bundle_dir} has no "
                                                      "index.html): install hairport with pip, which builds it "
                                                      "with Node.js")
        return FileResponse(index, media_type="text/html", headers={"Content-Security-Policy": CONTENT_SECURITY_POLICY,
                                                                     "Cache-Control": "no-cache"})
