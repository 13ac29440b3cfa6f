"""``/ui``: the dashboard's page and bundle served by the API itself, air-gapped (nothing from elsewhere)."""

import re

from fastapi import FastAPI
from fastapi.testclient import TestClient

from hairport.service import dashboard_ui
from hairport.service.errors import install as install_errors


def test_the_root_and_ui_lead_to_the_page_which_loads_only_what_hairport_serves(client):
    for path in ("/", "/ui"):
        response = client.get(path, follow_redirects=False)
        assert response.status_code == 307 and response.headers["location"] == "/ui/"
    page = client.get("/ui/")
    assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
    assert "default-src 'self'" in page.headers["content-security-policy"]
    sources = re.findall(r'(?:src|href)="([^"]+)"', page.text)
    assert sources and all(not re.match(r"[a-z]+://", source) for source in sources), sources
    for source in sources:
        if source.startswith("static/"):
            asset = client.get(f"/ui/{source}")
            assert asset.status_code == 200 and len(asset.content) > 1000, source
    bundle = client.get("/ui/static/app.js")
    assert bundle.headers["content-type"].startswith(("text/javascript", "application/javascript"))
    # the only address in the bundle is the XHTML namespace three.js creates its canvas in: nothing is fetched
    assert set(re.findall(r"https?://[\w./-]+", bundle.text)) == {"http://www.w3.org/1999/xhtml"}


def test_the_page_is_a_clear_503_when_the_bundle_was_not_built(tmp_path):
    app = FastAPI()
    install_errors(app)
    dashboard_ui.install(app, bundle_dir=tmp_path / "nothing-built")
    response = TestClient(app).get("/ui/")
    assert response.status_code == 503 and response.json()["code"] == "dashboard_not_built"
    assert "install hairport with pip" in response.json()["detail"]
