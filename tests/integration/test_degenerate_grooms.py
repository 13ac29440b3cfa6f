"""Degenerate grooms end to end (solver/model/degenerate.py): the command line in a real process, and the
service with a real Redis and a real worker process. A groom of 300 strands and one collapsed onto its
root (the penetration test's case, once ``internal``) retargets; a stray strand is refused by its code."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from .deployment import KEY, in_process_app, service_env, spawn_worker

AUTH = {"Authorization": f"Bearer {KEY}"}
#: the collapsed strand's place among the 300 ordinary ones
AT = 150
JOB_TIMEOUT = 240


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Toy source and target (OBJ + skeleton JSON), the 300 + 1 collapsed-strand groom and a groom with a
    strand 1 km away, as files."""
    from hairport.solver.io.character.export import write_character
    from hairport.solver.io.hair import write_hair
    from hairport.solver.model.hair import Hair
    from hairport.solver.synthetic import toy
    from hairport.solver.synthetic.groom import generate_groom

    d = tmp_path_factory.mktemp("degenerate-inputs")
    source = toy.toy_character(name="source")
    target = toy.toy_character(head_scale=(1.1, 0.95, 1.05), neck_length=0.15, shoulder_width=0.42, name="target")
    for name, character in (("source", source), ("target", target)):
        write_character(character, d / f"{name}.obj", d / f"{name}.skeleton.json")
    groom = generate_groom(source, "long", 300, 12, seed=3)
    strands = [groom.strand(s) for s in range(groom.n_strands)]
    collapsed = Hair.from_strands(strands[:AT] + [np.repeat(strands[AT][:1], 12, axis=0)] + strands[AT:])
    write_hair(d / "collapsed.ply", collapsed)
    stray = Hair.from_strands(strands[:AT] + [strands[AT] + np.array([1e3, 0.0, 0.0])] + strands[AT:])
    write_hair(d / "stray.ply", stray)
    return d


def cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hairport.cli", *args], capture_output=True, text=True, timeout=600)


def test_the_command_line_retargets_a_groom_with_a_collapsed_strand(files, tmp_path):
    from hairport.solver.io.hair import read_hair

    out = tmp_path / "out.ply"
    done = cli("retarget", "--source", str(files / "source.obj"), "--hair", str(files / "collapsed.ply"),
               "--target", str(files / "target.obj"), "--out", str(out), "--report", str(tmp_path / "report.json"),
               "--guides", "40", "--quiet")
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    result = read_hair(out)
    assert (result.n_strands, result.n_particles) == (301, 301 * 12)
    own = result.points[result.offsets[AT]:result.offsets[AT + 1]]
    assert np.abs(own - own[0]).max() < 1e-6  # on its root (the file holds float32)
    import json

    report = json.loads((tmp_path / "report.json").read_text())
    assert report["metrics"]["penetrating_particles"] == 0
    assert any("strands have zero length" in note and f"strand(s) {AT})" in note
               for note in report["metrics"]["input"]["warnings"])


def test_the_command_line_refuses_a_stray_strand_in_one_line(files, tmp_path):
    done = cli("retarget", "--source", str(files / "source.obj"), "--hair", str(files / "stray.ply"),
               "--target", str(files / "target.obj"), "--out", str(tmp_path / "out.ply"), "--quiet")
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hairport: error:") and "Traceback" not in done.stderr
    assert "stray_strands" in lines[0] and f"strand(s) {AT}:" in lines[0]
    assert not (tmp_path / "out.ply").exists()


@pytest.fixture(scope="module")
def service(tmp_path_factory, redis_url):
    storage = tmp_path_factory.mktemp("degenerate-storage")
    env = service_env(storage, redis_url)
    with in_process_app(env) as (settings, queue, client):
        worker = spawn_worker("degenerate", env, storage)
        try:
            deadline = time.time() + 120
            while not any("degenerate" in next(iter(reply)) for reply in queue.ping_workers(0.5)):
                assert worker.poll() is None, (storage / "degenerate.log").read_text()
                assert time.time() < deadline, "the worker did not answer"
            yield client, storage
        finally:
            if worker.poll() is None:
                os.killpg(worker.pid, signal.SIGTERM)
            try:
                worker.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(worker.pid, signal.SIGKILL)


def wait_for(client, path, condition):
    deadline = time.time() + JOB_TIMEOUT
    while True:
        body = client.get(path, headers=AUTH).json()
        if condition(body):
            return body
        assert time.time() < deadline, f"timed out waiting on {path}: {body}"
        time.sleep(0.25)


def upload_character(client, files, name: str) -> str:
    response = client.post("/v1/characters", headers=AUTH, files={
        "mesh": (f"{name}.obj", (files / f"{name}.obj").read_bytes()),
        "skeleton": (f"{name}.skeleton.json", (files / f"{name}.skeleton.json").read_bytes())})
    assert response.status_code == 201, response.text
    return response.json()["id"]


def test_a_worker_retargets_the_groom_with_a_collapsed_strand(service, files):
    from hairport.solver.io.hair import read_hair_bytes

    client, storage = service
    source, target = upload_character(client, files, "source"), upload_character(client, files, "target")
    response = client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": source, "guides": "40"},
                           files={"hair": ("collapsed.ply", (files / "collapsed.ply").read_bytes())})
    assert response.status_code == 201, response.text
    hairstyle = response.json()["id"]
    ready = wait_for(client, f"/v1/hairstyles/{hairstyle}", lambda b: b["preprocessing"]["state"] in ("ready", "failed"))
    assert ready["preprocessing"]["state"] == "ready", ready
    response = client.post("/v1/retargets", headers=AUTH, json={
        "hairstyle_id": hairstyle, "target_character_ids": [target], "output_format": "ply"})
    assert response.status_code == 202, response.text
    job = response.json()["jobs"][0]["id"]
    done = wait_for(client, f"/v1/jobs/{job}", lambda b: b["state"] in ("succeeded", "failed", "cancelled"))
    assert done["state"] == "succeeded", done  # once: failed, code internal (LinAlgError)
    assert done["metrics"]["penetrating_particles"] == 0 and done["metrics"]["root_to_target_max"] < 1e-9
    assert any("strands have zero length" in note for note in done["metrics"]["input"]["warnings"])
    result = read_hair_bytes(client.get(f"/v1/jobs/{job}/result", headers=AUTH).content, "ply")
    assert result.n_strands == 301
    own = result.points[result.offsets[AT]:result.offsets[AT + 1]]
    assert np.abs(own - own[0]).max() < 1e-6
    assert "Traceback" not in (storage / "degenerate.log").read_text()


def test_the_service_refuses_a_stray_strand_at_upload(service, files):
    client, _ = service
    source = upload_character(client, files, "source")
    response = client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": source},
                           files={"hair": ("stray.ply", (files / "stray.ply").read_bytes())})
    assert response.status_code == 422, response.text
    body = response.json()
    assert body["code"] == "stray_strands" and f"strand(s) {AT}:" in body["detail"]
