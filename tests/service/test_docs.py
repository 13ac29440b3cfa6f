"""/docs and /redoc load nothing from another host: their scripts and styles are served by the API."""

import re

import pytest

#: every absolute URL in a page
URL = re.compile(r"""https?://[^\s"'<>)]+""")
#: the files a page names in src= / href=
ASSET = re.compile(r"""(?:src|href)=["']([^"']+)["']""")


@pytest.mark.parametrize("page", ["/docs", "/redoc"])
def test_a_docs_page_and_everything_it_loads_come_from_the_api(client, page):
    response = client.get(page)
    assert response.status_code == 200 and response.headers["content-type"].startswith("text/html")
    assert URL.findall(response.text) == []  # not a CDN, not a font host, not a validator
    assets = ASSET.findall(response.text)
    assert len(assets) == (3 if page == "/docs" else 2)  # css, favicon, js / favicon, js
    for asset in assets:
        served = client.get(asset)
        assert asset.startswith("/docs-assets/") and served.status_code == 200 and len(served.content) > 1000, asset
    assert "/openapi.json" in response.text
    if page == "/docs":  # Swagger UI would otherwise send the document to its online validator
        assert '"validatorUrl": null' in response.text


def test_the_swagger_ui_has_the_two_key_schemes_to_authorize_with(client):
    schemes = client.get("/openapi.json").json()["components"]["securitySchemes"]
    assert schemes == {
        "bearer": {"type": "http", "scheme": "bearer", "description": "`Authorization: Bearer <key>`"},
        "apiKey": {"type": "apiKey", "in": "header", "name": "X-API-Key", "description": "`X-API-Key: <key>`"}}


@pytest.mark.parametrize("page, tags", [("/docs", ("script",)), ("/redoc", ("style",))])
def test_a_docs_page_allows_exactly_its_inline_blocks_by_hash(client, page, tags):
    import base64
    import hashlib

    from hairport.service.docs import REDOC_STYLE_HASHES

    response = client.get(page)
    directives = dict(part.strip().split(" ", 1) for part in response.headers["content-security-policy"].split(";"))
    for tag in ("script", "style"):
        blocks = re.findall(rf"<{tag}>(.*?)</{tag}>", response.text, re.S)
        assert len(blocks) == (1 if tag in tags else 0), tag
        hashes = {f"'sha256-{base64.b64encode(hashlib.sha256(block.encode()).digest()).decode()}'" for block in blocks}
        allowed = set(directives[f"{tag}-src"].split()) - {"'self'"}
        if page == "/redoc" and tag == "style":  # and the sheets ReDoc's bundle adds (styled-components' is empty)
            hashes |= {"'sha256-47DEQpj8HBSa+/TImW+5JCeuQeRkm5NMpJWZG3hSuFU='", *REDOC_STYLE_HASHES}
        assert allowed == hashes, tag
    assert "unsafe-inline" not in str(directives) and directives["default-src"] == "'none'"
    assert ("worker-src" in directives) is (page == "/redoc")
