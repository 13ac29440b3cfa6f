"""Headers of a real ``hairport serve`` (with a worker and the tests' own Redis): ``nosniff`` and a request id on
every response of every path (each operation of the OpenAPI document with a plausible request, the pages, their
files, errors of every kind, the 413 sent before routing, the 500 of a defect), a Content-Security-Policy on
every HTML page, and Swagger UI and ReDoc rendering in Chromium under theirs without a violation."""

from __future__ import annotations

import http.client
import json
import re
import time

import httpx
import pytest

from tests.conftest import free_port
from tests.integration.browser import chromium
from tests.integration.deployment import KEY, service_env, spawn_server, spawn_worker, stop, wait_ready

from .test_service_api import files  # noqa: F401 - the toy characters and groom

#: seconds the server and its worker may take to be ready, and a toy job to end
READY_SECONDS = 120
JOB_SECONDS = 240
#: a small upload limit, so that the 413 sent before any body is read is easy to ask for
UPLOAD_LIMIT_BYTES = 4 * 1024**2
NEW_ID = re.compile(r"[0-9a-f]{32}")
#: ReDoc's side menu shows Redocly's logo from its CDN (the bundle has no option to leave it out); the page's
#: policy blocks it, as it must block anything from another host, and the image hides itself. The only
#: violation either page may report, and no request for it ever leaves the browser
REDOC_LOGO = "https://cdn.redoc.ly/redoc/logo-mini.svg"
#: the page records every policy violation it sees
LISTEN = """window.__violations = [];
document.addEventListener('securitypolicyviolation',
  (e) => window.__violations.push([e.effectiveDirective, e.blockedURI]));"""


@pytest.fixture(scope="module")
def deployment(tmp_path_factory, redis_url, files):  # noqa: F811 - the fixture imported above
    storage = tmp_path_factory.mktemp("headers-storage")
    env = service_env(storage, redis_url, HAIRPORT_MAX_UPLOAD_BYTES=str(UPLOAD_LIMIT_BYTES))
    port = free_port()
    server = spawn_server(env, port, storage)
    worker = spawn_worker("headers", env, storage)
    base = f"http://127.0.0.1:{port}"
    try:
        wait_ready(base, server, worker, storage, "headers", READY_SECONDS)
        api = httpx.Client(base_url=base, headers={"X-API-Key": KEY}, timeout=60)
        yield {"base": base, "port": port, "api": api, "storage": storage, "ids": made(api, files)}
    finally:
        stop(worker)
        stop(server)


def made(api: httpx.Client, files) -> dict:  # noqa: F811
    """Two characters, a hairstyle, a job and a batch of one pair, both run to their end by the worker."""
    folder, ids = files["dir"], {}
    for name in ("source", "target"):
        character = api.post("/v1/characters", files={
            "mesh": (f"{name}.obj", (folder / f"{name}.obj").read_bytes()),
            "skeleton": (f"{name}.skeleton.json", (folder / f"{name}.skeleton.json").read_bytes())})
        assert character.status_code == 201, character.text
        ids[name] = character.json()["id"]
    hairstyle = api.post("/v1/hairstyles", data={"source_character_id": ids["source"], "guides": "20"},
                         files={"hair": ("groom.data", (folder / "hair.data").read_bytes())})
    assert hairstyle.status_code == 201, hairstyle.text
    ids["hairstyle"] = hairstyle.json()["id"]
    pair = {"target_character_ids": [ids["target"]], "options": {"max_iterations": 5}}
    job = api.post("/v1/retargets", json={"hairstyle_id": ids["hairstyle"], **pair})
    batch = api.post("/v1/batches", json={"hairstyle_ids": [ids["hairstyle"]], **pair})
    assert (job.status_code, batch.status_code) == (202, 202), (job.text, batch.text)
    ids["job"], ids["batch"] = job.json()["jobs"][0]["id"], batch.json()["id"]
    deadline = time.monotonic() + JOB_SECONDS
    while api.get(f"/v1/batches/{ids['batch']}").json()["state"] != "done" or api.get(
            f"/v1/jobs/{ids['job']}").json()["state"] not in ("succeeded", "failed", "cancelled"):
        assert time.monotonic() < deadline, "the jobs did not end"
        time.sleep(0.5)
    assert api.get(f"/v1/jobs/{ids['job']}").json()["state"] == "succeeded"
    return ids


def plausible_requests(ids: dict, files) -> dict[tuple[str, str], dict]:  # noqa: F811
    """A plausible request of every operation: (method, path template) -> httpx.request keywords."""
    folder = files["dir"]
    mesh = {"mesh": ("target.obj", (folder / "target.obj").read_bytes()),
            "skeleton": ("target.skeleton.json", (folder / "target.skeleton.json").read_bytes())}
    pair = {"target_character_ids": [ids["target"]], "options": {"max_iterations": 5}}
    return {
        ("post", "/v1/characters"): {"files": mesh},
        ("get", "/v1/characters"): {"params": {"limit": 10}},
        ("get", "/v1/characters/{character_id}"): {},
        ("get", "/v1/characters/{character_id}/mesh"): {},
        ("post", "/v1/hairstyles"): {"data": {"source_character_id": ids["source"], "guides": "20"},
                                     "files": {"hair": ("groom.data", (folder / "hair.data").read_bytes())}},
        ("get", "/v1/hairstyles"): {},
        ("get", "/v1/hairstyles/{hairstyle_id}"): {},
        ("post", "/v1/retargets"): {"json": {"hairstyle_id": ids["hairstyle"], **pair}},
        ("post", "/v1/batches"): {"json": {"hairstyle_ids": [ids["hairstyle"]], **pair}},
        ("get", "/v1/batches"): {"params": {"offset": 0}},
        ("get", "/v1/batches/{batch_id}"): {},
        ("get", "/v1/batches/{batch_id}/results"): {},
        ("delete", "/v1/batches/{batch_id}"): {},
        ("get", "/v1/jobs"): {"params": {"state": "succeeded"}},
        ("get", "/v1/jobs/{job_id}"): {},
        ("get", "/v1/jobs/{job_id}/result"): {"params": {"format": "obj"}},
        ("get", "/v1/jobs/{job_id}/preview.png"): {},
        ("get", "/v1/jobs/{job_id}/report"): {},
        ("get", "/v1/jobs/{job_id}/display"): {"params": {"layer": "source", "max_vertices": 5000}},
        ("get", "/v1/jobs/{job_id}/body"): {},
        ("get", "/v1/jobs/{job_id}/hairline"): {},
        ("delete", "/v1/jobs/{job_id}"): {},
        ("get", "/healthz"): {},
        ("get", "/readyz"): {},
        ("get", "/metrics"): {},
    }


def assert_headers(response: httpx.Response, what) -> None:
    assert response.headers.get("x-content-type-options") == "nosniff", (what, response.status_code)
    assert response.headers.get("x-request-id"), what
    if response.headers.get("content-type", "").startswith("text/html"):
        assert response.headers.get("content-security-policy"), what


def test_every_operation_answers_with_nosniff_and_a_request_id(deployment, files):  # noqa: F811
    api, ids = deployment["api"], deployment["ids"]
    document = api.get("/openapi.json").json()
    operations = {(method, path): operation for path, methods in document["paths"].items()
                  for method, operation in methods.items()}
    requests = plausible_requests(ids, files)
    assert set(requests) == set(operations)  # every operation is walked: a new one needs its request here
    answered = {}
    for (method, path), keywords in sorted(requests.items(), key=lambda item: item[0][0] == "delete"):
        url = re.sub(r"\{(\w+)_id\}", lambda match: ids["target" if match[1] == "character" else match[1]], path)
        response = api.request(method.upper(), url, **keywords)
        assert_headers(response, (method, url))
        assert str(response.status_code) in operations[method, path]["responses"], (method, url, response.text[:300])
        answered[method, path] = response.status_code
    # the files, the zip, and the creations answered as they should, not as errors
    assert {key: answered[key] for key in [("get", "/v1/jobs/{job_id}/result"), ("get", "/v1/jobs/{job_id}/report"),
                                           ("get", "/v1/jobs/{job_id}/preview.png"),
                                           ("get", "/v1/batches/{batch_id}/results"), ("post", "/v1/retargets"),
                                           ("post", "/v1/characters"), ("get", "/metrics")]} == {
        ("get", "/v1/jobs/{job_id}/result"): 200, ("get", "/v1/jobs/{job_id}/report"): 200,
        ("get", "/v1/jobs/{job_id}/preview.png"): 200, ("get", "/v1/batches/{batch_id}/results"): 200,
        ("post", "/v1/retargets"): 202, ("post", "/v1/characters"): 201, ("get", "/metrics"): 200}
    assert 500 not in answered.values()


def test_pages_files_and_errors_have_them_too(deployment):
    api, base = deployment["api"], deployment["base"]
    anonymous = httpx.Client(base_url=base, timeout=30)
    paths = ["/", "/ui", "/ui/", "/ui/static/index.html", "/ui/static/app.js", "/ui/static/style.css", "/docs",
             "/redoc", "/openapi.json", "/docs-assets/swagger-ui-bundle.js", "/docs-assets/swagger-ui.css",
             "/docs-assets/redoc.standalone.js", "/docs-assets/favicon.png", "/docs-assets/nothing.js", "/nowhere"]
    statuses = {}
    for path in paths:
        response = anonymous.get(path, follow_redirects=False)
        assert_headers(response, path)
        statuses[path] = response.status_code
    assert statuses == {**dict.fromkeys(paths, 200), "/": 307, "/ui": 307, "/docs-assets/nothing.js": 404,
                        "/nowhere": 404}
    errors = {"401": anonymous.get("/v1/jobs"), "405": api.put("/v1/jobs"), "options": api.options("/v1/jobs"),
              "404": api.get("/v1/jobs/" + "0" * 32), "422": api.get("/v1/jobs", params={"offset": 2**63}),
              "422 far": api.get("/v1/characters", params={"offset": 10**30})}
    assert {name: response.status_code for name, response in errors.items()} == {
        "401": 401, "405": 405, "options": 405, "404": 404, "422": 422, "422 far": 422}
    for name, response in errors.items():
        assert_headers(response, name)
        assert response.headers["content-type"] == "application/problem+json", name
    assert {errors["422"].json()["code"], errors["422 far"].json()["code"]} == {"invalid_request"}

    # the 413 of the upload limit, sent from its middleware before any of the body is read
    connection = http.client.HTTPConnection("127.0.0.1", deployment["port"], timeout=30)
    connection.putrequest("POST", "/v1/characters")
    connection.putheader("X-API-Key", KEY)
    connection.putheader("Content-Length", str(10**9))
    connection.endheaders()
    refused = connection.getresponse()
    assert refused.status == 413 and json.loads(refused.read())["code"] == "upload_too_large"
    assert refused.getheader("X-Content-Type-Options") == "nosniff" and NEW_ID.fullmatch(refused.getheader("X-Request-ID"))
    connection.close()


def test_every_html_page_has_a_policy_without_unsafe_inline(deployment):
    anonymous = httpx.Client(base_url=deployment["base"], timeout=30)
    policies = {path: anonymous.get(path).headers["content-security-policy"]
                for path in ("/ui/", "/ui/static/index.html", "/docs", "/redoc")}
    assert policies["/ui/static/index.html"] == policies["/ui/"]  # the same file, the same policy
    for path, policy in policies.items():
        directives = dict(directive.strip().split(" ", 1) for directive in policy.split(";"))
        assert "unsafe-inline" not in policy and "unsafe-eval" not in policy, path
        assert directives["object-src"] == "'none'" and directives["frame-ancestors"] == "'none'", path
        assert directives["base-uri"] == "'none'", path
        assert "http" not in policy, path  # nothing from another host
    assert "worker-src blob:" in policies["/redoc"]


def test_swagger_ui_and_redoc_render_in_chromium_without_a_policy_violation(deployment):
    base = deployment["base"]
    operations = sum(len(methods) for methods in httpx.get(f"{base}/openapi.json").json()["paths"].values())
    with chromium() as page:
        console, blocked = [], []
        page.on("console", lambda message: console.append(message.text) if message.type == "error" else None)
        page.on("requestfailed", lambda request: blocked.append((request.url, request.failure)))
        foreign = []
        page.on("request", lambda request: foreign.append(request.url) if not request.url.startswith(
            (base, "blob:", "data:")) else None)
        page.add_init_script(LISTEN)

        page.goto(f"{base}/docs")
        page.wait_for_selector(".opblock")
        assert page.locator(".opblock").count() == operations
        page.locator(".opblock-summary-path[data-path='/healthz']").click()
        page.get_by_role("button", name="Try it out").click()
        page.get_by_role("button", name="Execute").click()
        page.wait_for_selector(".live-responses-table tbody .response-col_status")
        assert page.locator(".live-responses-table tbody .response-col_status").inner_text().strip() == "200"
        assert page.evaluate("window.__violations") == [] and console == [] and page.errors == []

        page.goto(f"{base}/redoc")
        page.wait_for_selector("[data-section-id*='/operation/']")
        assert page.locator("[data-section-id*='/operation/']").count() == operations
        # its search runs in a worker made from a blob (worker-src blob:)
        page.fill("[role=search] input", "cancel")
        page.wait_for_selector("[data-role='search:results'] [role=menuitem]")
        assert page.locator("[data-role='search:results'] [role=menuitem]").count() == 2
        # its styles applied: styled-components' sheet filled through the CSSOM, perfect-scrollbar's by its hash
        assert page.evaluate("document.querySelector('style[data-styled]').sheet.cssRules.length") > 100
        assert page.evaluate("getComputedStyle(document.querySelector('.ps')).overflow") == "hidden"
        violations = page.evaluate("window.__violations")
        assert violations in ([], [["img-src", REDOC_LOGO]]), violations
        assert all(REDOC_LOGO in message for message in console), console
        assert page.errors == []
    # a request for another host was only ever made to be blocked by the policy: none left the browser
    assert {(url, dict(blocked).get(url)) for url in foreign} <= {(REDOC_LOGO, "csp")}
    assert set(blocked) <= {(REDOC_LOGO, "csp")}


def test_a_defect_is_an_internal_problem_with_the_request_id_of_its_logged_traceback(deployment, files):  # noqa: F811
    """A record the server cannot read (a character's, cut short on disk) fails its request as a defect would."""
    from hairport.records import CharacterRecord

    api, storage = deployment["api"], deployment["storage"]
    folder = files["dir"]
    created = api.post("/v1/characters", files={
        "mesh": ("source.obj", (folder / "source.obj").read_bytes()),
        "skeleton": ("source.skeleton.json", (folder / "source.skeleton.json").read_bytes())})
    assert created.status_code == 201, created.text
    record = storage / "records" / CharacterRecord.KIND / f"{created.json()['id']}.json"
    record.write_text(record.read_text()[:40])
    given = api.get(f"/v1/characters/{created.json()['id']}", headers={"X-Request-ID": "pentest-7"})
    made_up = api.get(f"/v1/characters/{created.json()['id']}", headers={"X-Request-ID": "not sane"})
    for response in (given, made_up):
        assert response.status_code == 500 and response.headers["content-type"] == "application/problem+json"
        body = response.json()
        assert body["code"] == "internal" and body["request_id"] == response.headers["x-request-id"]
        assert response.headers["x-content-type-options"] == "nosniff"
        assert response.headers["connection"] == "close"  # the server drops it: no client reuses it into a reset
        assert "Traceback" not in response.text and "ValidationError" not in response.text
    assert given.json()["request_id"] == "pentest-7" and NEW_ID.fullmatch(made_up.json()["request_id"])
    log = (storage / "serve.log").read_text()
    for response in (given, made_up):
        entry = log[log.index(f"internal error, request id {response.json()['request_id']}"):][:5000]
        assert "Traceback" in entry and "ValidationError" in entry
