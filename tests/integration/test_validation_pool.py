"""A real ``hairport serve`` validates uploads in its pool of child processes: a request is answered while a
large upload is being validated, refusals keep their codes, and stopping the server stops its children."""

from __future__ import annotations

import hashlib
import os
import signal
import threading
import time
from pathlib import Path

import httpx
import pytest

from tests.conftest import free_port
from tests.integration.deployment import KEY, service_env, spawn_server, stop

#: seconds the server may take to answer /healthz
READY_SECONDS = 120
#: strands (of two points) of the large upload: 11 MB as a .data file
LARGE_STRANDS = 400_000
#: the module a validating child runs
CHILD_MODULE = b"hairport.service.validation_child"


def children_of(pid: int) -> list[int]:
    """The validating children of process ``pid``."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            parent = int((entry / "stat").read_text().rpartition(")")[2].split()[1])
            command = (entry / "cmdline").read_bytes()
        except (OSError, ValueError):
            continue  # ended meanwhile
        if parent == pid and CHILD_MODULE in command:
            found.append(int(entry.name))
    return found


def state(pid: int) -> str | None:
    try:
        return (Path("/proc") / str(pid) / "stat").read_text().rpartition(")")[2].split()[0]
    except OSError:
        return None


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict:
    from hairport.solver import write_hair
    from hairport.solver.synthetic import toy
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import write_character

    folder = tmp_path_factory.mktemp("pool-inputs")
    source = toy.toy_character(name="source")
    write_character(source, folder / "source.obj", folder / "source.skeleton.json")
    write_hair(folder / "groom.data", generate_groom(source, "short", 20, 6, seed=0))
    write_hair(folder / "large.data", generate_groom(source, "short", LARGE_STRANDS, 2, seed=1))
    return {name: (folder / name).read_bytes() for name in ("source.obj", "source.skeleton.json", "groom.data",
                                                            "large.data")}


@pytest.fixture(scope="module")
def server(tmp_path_factory, redis_url, inputs):
    storage = tmp_path_factory.mktemp("pool-storage")
    env = service_env(storage, redis_url, HAIRPORT_MAX_CONCURRENT_VALIDATIONS="1")
    port = free_port()
    process = spawn_server(env, port, storage)
    api = httpx.Client(base_url=f"http://127.0.0.1:{port}", headers={"X-API-Key": KEY}, timeout=300)
    deadline = time.monotonic() + READY_SECONDS
    try:
        while True:
            try:
                if api.get("/healthz").status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            assert process.poll() is None, (storage / "serve.log").read_text()[-2000:]
            assert time.monotonic() < deadline, "the server did not start"
            time.sleep(0.3)
        character = api.post("/v1/characters", files={
            "mesh": ("source.obj", inputs["source.obj"]),
            "skeleton": ("source.skeleton.json", inputs["source.skeleton.json"])})
        assert character.status_code == 201, character.text
        yield {"process": process, "api": api, "storage": storage, "source": character.json()["id"]}
    finally:
        api.close()
        stop(process)


def test_a_request_is_answered_while_a_large_upload_validates(server, inputs):
    api, source = server["api"], server["source"]
    (child,) = children_of(server["process"].pid)  # one: HAIRPORT_MAX_CONCURRENT_VALIDATIONS=1
    os.kill(child, signal.SIGSTOP)  # the upload's validation cannot end before the child is continued
    while state(child) != "T":
        time.sleep(0.01)
    finished: list[str] = []
    answers = {}

    def upload():
        with httpx.Client(base_url=api.base_url, headers={"X-API-Key": KEY}, timeout=300) as own:
            answers["upload"] = own.post("/v1/hairstyles", data={"source_character_id": source},
                                         files={"hair": ("large.data", inputs["large.data"])})
        finished.append("upload")

    uploading = threading.Thread(target=upload)
    try:
        uploading.start()
        blob = server["storage"] / "blobs"
        sha = hashlib.sha256(inputs["large.data"]).hexdigest()
        while not list(blob.glob(f"{sha[:2]}/{sha}*")):  # stored: what is left of the request is its validation
            assert uploading.is_alive(), answers
            time.sleep(0.05)
        answers["poll"] = api.get(f"/v1/characters/{source}")
        finished.append("poll")
        assert finished == ["poll"] and uploading.is_alive()
    finally:
        os.kill(child, signal.SIGCONT)
        uploading.join()
    assert finished == ["poll", "upload"]
    assert answers["poll"].status_code == 200 and answers["poll"].json()["id"] == source
    assert answers["upload"].status_code == 201, answers["upload"].text
    assert (answers["upload"].json()["strands"], answers["upload"].json()["particles"]) == (LARGE_STRANDS,
                                                                                             2 * LARGE_STRANDS)
    assert children_of(server["process"].pid) == [child]  # the same prewarmed child did it


def test_refusals_keep_their_codes_and_keep_no_file(server, inputs):
    api, source = server["api"], server["source"]
    groom, cut = inputs["groom.data"], inputs["groom.data"][:200]
    cases = {
        "units_mismatch": ({"source_character_id": source, "units": "cm"}, groom),
        "truncated": ({"source_character_id": source}, cut),
        "no_guide_flags": ({"source_character_id": source, "guides_from": "guide"}, groom),
    }
    for code, (form, data) in cases.items():
        response = api.post("/v1/hairstyles", data=form, files={"hair": ("h.data", data)})
        assert (response.status_code, response.json()["code"]) == (422, code), response.text
        field = "guides_from" if code == "no_guide_flags" else "hair"
        assert response.json()["detail"].startswith(f"{field}: ")
    mesh = api.post("/v1/characters", files={"mesh": ("m.obj", b"v 0 0 0\nf 1 2 3\n")})
    assert mesh.status_code == 422 and mesh.json()["detail"].startswith("mesh: ")
    for data in (cut, b"v 0 0 0\nf 1 2 3\n"):
        sha = hashlib.sha256(data).hexdigest()
        assert list((server["storage"] / "blobs").glob(f"{sha[:2]}/{sha}*")) == []


def test_stopping_the_server_stops_its_validating_children(server):
    process = server["process"]
    children = children_of(process.pid)
    assert len(children) == 1
    process.send_signal(signal.SIGTERM)  # the server alone: its lifespan stops the children
    process.wait(timeout=60)
    log = (server["storage"] / "serve.log").read_text()
    # uvicorn ends by re-raising the signal it handled, after the lifespan's shutdown
    assert process.returncode == -signal.SIGTERM and "Application shutdown complete" in log, log[-2000:]
    assert [state(child) for child in children] == [None]
