"""``hairport serve --embedded``: the API and a worker in one process, no Redis, over real HTTP."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time

import httpx
import pytest


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    storage = tmp_path_factory.mktemp("embedded")
    port = free_port()
    env = {**os.environ, "HAIRPORT_INSECURE_DEV": "true", "HAIRPORT_API_KEYS": "", "HAIRPORT_STORAGE_DIR": str(storage),
           # an unreachable Redis proves the embedded mode does not need one
           "HAIRPORT_REDIS_URL": "redis://127.0.0.1:1/0", "HAIRPORT_CORS_ORIGINS": "https://studio.example"}
    log = open(storage / "server.log", "wb")
    process = subprocess.Popen([sys.executable, "-m", "hairport.cli", "serve", "--embedded", "--port", str(port)],
                               env=env, stdout=log, stderr=log, start_new_session=True)
    base = f"http://127.0.0.1:{port}"
    deadline = time.time() + 60
    while time.time() < deadline:
        try:
            if httpx.get(f"{base}/readyz", timeout=1).status_code == 200:
                break
        except httpx.HTTPError:
            pass
        assert process.poll() is None, (storage / "server.log").read_text()
        time.sleep(0.3)
    else:
        raise AssertionError((storage / "server.log").read_text())
    yield base
    process.terminate()
    process.wait(20)


def test_embedded_server_runs_a_retarget_without_redis(server, tmp_path):
    from hairport.solver.io.hair import read_hair_bytes, write_hair
    from hairport.solver.synthetic import toy
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import write_character

    source = toy.toy_character(name="source")
    target = toy.toy_character(head_scale=(1.1, 0.95, 1.05), shoulder_width=0.42, name="target")
    ids = {}
    for name, character in (("source", source), ("target", target)):
        write_character(character, tmp_path / f"{name}.obj", tmp_path / f"{name}.skeleton.json")
        response = httpx.post(f"{server}/v1/characters", files={
            "mesh": (f"{name}.obj", (tmp_path / f"{name}.obj").read_bytes()),
            "skeleton": ("s.json", (tmp_path / f"{name}.skeleton.json").read_bytes())}, timeout=60)
        assert response.status_code == 201, response.text
        ids[name] = response.json()["id"]
    write_hair(tmp_path / "hair.hair", generate_groom(source, "short", 30, 10, seed=1))
    hairstyle = httpx.post(f"{server}/v1/hairstyles", data={"source_character_id": ids["source"]},
                           files={"hair": ("g.hair", (tmp_path / "hair.hair").read_bytes())}, timeout=60).json()
    job = httpx.post(f"{server}/v1/retargets", json={"hairstyle_id": hairstyle["id"], "target_character_ids": [ids["target"]],
                                                      "options": {"max_iterations": 5, "spacing": 10, "carry": 0.05},
                                                      "output_format": "hair"},
                     timeout=60).json()["jobs"][0]
    deadline = time.time() + 180
    while (state := httpx.get(f"{server}/v1/jobs/{job['id']}", timeout=10).json())["state"] not in (
            "succeeded", "failed", "cancelled"):
        assert time.time() < deadline, state
        time.sleep(0.3)
    assert state["state"] == "succeeded", state
    assert state["metrics"]["penetrating_particles"] == 0
    assert state["metrics"]["energy_spacing_per_particle"] >= 0.0  # the spacing term reached the solver
    result = httpx.get(f"{server}/v1/jobs/{job['id']}/result", timeout=30)
    assert read_hair_bytes(result.content, "hair").n_strands == 30


def test_cors_preflight_allows_the_configured_origin_only(server):
    allowed = httpx.options(f"{server}/v1/jobs", headers={"Origin": "https://studio.example",
                                                          "Access-Control-Request-Method": "GET"})
    assert allowed.status_code == 200
    assert allowed.headers["access-control-allow-origin"] == "https://studio.example"
    other = httpx.options(f"{server}/v1/jobs", headers={"Origin": "https://evil.example",
                                                        "Access-Control-Request-Method": "GET"})
    assert "access-control-allow-origin" not in other.headers


def test_serve_without_keys_or_dev_mode_refuses_to_start(tmp_path):
    env = {**os.environ, "HAIRPORT_API_KEYS": "", "HAIRPORT_INSECURE_DEV": "false", "HAIRPORT_STORAGE_DIR": str(tmp_path)}
    done = subprocess.run([sys.executable, "-m", "hairport.cli", "serve", "--port", str(free_port())], env=env,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        "hairport: error: no API keys configured: set HAIRPORT_API_KEYS, or HAIRPORT_INSECURE_DEV=true for a laptop"]
